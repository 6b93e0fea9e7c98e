"""`spooflens report LOG -o report.html`: analyse a log and write the operator report only."""

from __future__ import annotations

import json
from pathlib import Path

import click

from spooflens.cli import (
    analyse_log,
    fail_on_spoof_option,
    finish,
    imu_grade_option,
    quiet_option,
    topic_option,
)


@click.command()
@click.argument("log", type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(path_type=Path),
    default=None,
    help="HTML report to write (default: LOG name with .html, in the current directory).",
)
@click.option("--json", "json_path", type=click.Path(path_type=Path), default=None, help="Also write the summary.")
@topic_option
@imu_grade_option
@quiet_option
@fail_on_spoof_option
def report(
    log: Path,
    output: Path | None,
    json_path: Path | None,
    topics: tuple[str, ...],
    imu_grade: str | None,
    quiet: bool,
    fail_on_spoof: bool,
) -> int:
    """Analyse LOG and write the operator report: one self-contained HTML page (opens offline anywhere)."""
    from spooflens.cli import _print_analysis
    from spooflens.report import write_report
    from spooflens.summary import build_summary

    analysis = analyse_log(log, topics, imu_grade, quiet)
    output = output or Path(log.name.rstrip("/")).with_suffix(".html")
    size = write_report(output, analysis)
    summary = build_summary(analysis.table, analysis.results, analysis.verdict)
    if json_path:
        json_path.write_text(json.dumps(summary, indent=2))
    if quiet:
        click.echo(analysis.verdict.headline)
    else:
        _print_analysis(summary, None, json_path)
        click.echo(f"report: {output} ({size / 1e6:.2f} MB); open it in any browser, no network needed")
    return finish(log, analysis, fail_on_spoof)
