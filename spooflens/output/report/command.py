"""`spooflens report LOG -o report.html`: analyse a log and write the operator report only."""

from __future__ import annotations

import json
from pathlib import Path

import click

from spooflens.cli import (
    baseline_option,
    fail_on_jam_option,
    fail_on_spoof_option,
    imu_grade_option,
    quiet_option,
    topic_option,
)
from spooflens.service import analyse_log, finish, load_baseline_option


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
@baseline_option
@quiet_option
@fail_on_spoof_option
@fail_on_jam_option
def report(
    log: Path,
    output: Path | None,
    json_path: Path | None,
    topics: tuple[str, ...],
    imu_grade: str | None,
    baseline_path: Path | None,
    quiet: bool,
    fail_on_spoof: bool,
    fail_on_jam: bool,
) -> int:
    """Analyse LOG and write the operator report: one self-contained HTML page (opens offline anywhere)."""
    from spooflens.output.report import write_report
    from spooflens.output.summary import build_summary
    from spooflens.service import check_writable, print_analysis, segment_path, segments_summary

    output = output or Path(log.name.rstrip("/")).with_suffix(".html")
    check_writable(output, "--output")
    check_writable(json_path, "--json")
    baseline = load_baseline_option(baseline_path)
    analyses = analyse_log(log, topics, imu_grade, quiet, baseline=baseline)
    summaries = []
    for k, analysis in enumerate(analyses):
        path = segment_path(output, k, len(analyses))
        size = write_report(path, analysis)
        summary = build_summary(analysis.table, analysis.results, analysis.verdict, analysis.options.baseline)
        summaries.append(summary)
        prefix = f"recording {k + 1} of {len(analyses)}: " if len(analyses) > 1 else ""
        if quiet:
            click.echo(prefix + analysis.verdict.headline)
        else:
            print_analysis(summary, None, json_path)
            click.echo(f"{prefix}report: {path} ({size / 1e6:.2f} MB); open it in any browser, no network needed")
    if json_path:
        json_path.write_text(json.dumps(segments_summary(summaries), indent=2))
    return finish(log, analyses, fail_on_spoof, fail_on_jam)
