"""`spooflens baseline LOG... -o VEHICLE.baseline.json`: learn a vehicle's baseline from its clean logs.

Each log is analysed as `analyze` would; a log with a spoofing incident is refused, a log's anomalies
are left out (both said). What was learned is printed per quantity with its spread across the logs, and
where the logs disagree it says so.
"""

from __future__ import annotations

from pathlib import Path

import click
from rich.table import Table

from spooflens.baseline.format import Baseline, ClockBaseline, Quantity, RefusedLog, dumps
from spooflens.baseline.learn import aggregate
from spooflens.baseline.measure import LogMeasurement, measure
from spooflens.cli import imu_grade_option, topic_option
from spooflens.output.console import console, progress, show_progress
from spooflens.service import EXIT_OK, check_writable, parse_topics, read_table, require_gnss


def learn_from_logs(
    logs: list[Path], topics: dict[str, str], imu_grade: str | None, show: bool
) -> tuple[list[LogMeasurement], list[RefusedLog]]:
    """Analyse every log (a log that cannot be read is an error naming it) and measure the clean ones."""
    from spooflens.output.report.provenance import identify as file_identity
    from spooflens.pipeline.registry import AnalyzeOptions
    from spooflens.pipeline.run import analyze_segments

    measured: list[LogMeasurement] = []
    refused: list[RefusedLog] = []
    seen: dict[str, str] = {}
    with progress(show) as report:
        for i, log in enumerate(logs):
            report("analysing clean logs", i, len(logs))
            digest = file_identity(log).sha256
            if digest in seen:
                refused.append(RefusedLog(log.name, f"the same bytes as {seen[digest]} (counted once)"))
                continue
            seen[digest] = log.name
            table = read_table(log, topics, False)
            require_gnss(log, table)
            analyses = analyze_segments(table, AnalyzeOptions(imu_grade=imu_grade), clean_coasts=True)
            for k, analysis in enumerate(analyses):
                name = log.name.rstrip("/") + (f" (recording {k + 1} of {len(analyses)})" if len(analyses) > 1 else "")
                try:
                    measured.append(measure(analysis, name, digest))
                except ValueError as err:
                    refused.append(RefusedLog(name, str(err)))
        report("analysing clean logs", len(logs), len(logs))
    return measured, refused


def _num(x: float | None) -> str:
    return "-" if x is None else f"{x:.4g}"


def _agree(q: Quantity) -> str:
    if q.agree is None:
        return "one log"
    return "yes" if q.agree else "[bold red]NO: the logs disagree[/]"


def _rows(t: Table, group: str, quantities: dict[str, Quantity]) -> None:
    for name, q in quantities.items():
        v = q.values
        spread = f"{min(v):.4g} .. {max(v):.4g}" if len(v) > 1 else "-"
        unit = f" {q.unit}" if q.unit else ""
        t.add_row(group, name, _num(q.centre) + unit, _num(q.within), _num(q.between), spread, str(q.n_logs), _agree(q))


def print_baseline(b: Baseline, path: Path) -> None:
    out = console()
    out.print(f"[bold]{path}[/]: baseline of {len(b.logs)} clean log(s)")
    for log in b.logs:
        out.print(f"  learned from {log.name} ({log.duration_s:.0f} s)" + (f"; {log.note}" if log.note else ""))
    for r in b.refused:
        out.print(f"  [yellow]refused[/] {r.name}: {r.reason}")
    for rid, rx in b.receivers.items():
        fw = f", firmware {', '.join(rx.firmware)}" if rx.firmware else ""
        out.print(f"  receiver {rid}: {rx.model or 'model not named in the logs'}{fw}")
    if b.firmware:
        out.print(f"  firmware: {', '.join(b.firmware)}")
    if b.imus:
        out.print(f"  IMU: {', '.join(b.imus)}")
    t = Table(
        "what", "quantity", "centre", "within a log", "across logs", "log range", "logs", "agree", title="Learned"
    )
    for rid, rx in b.receivers.items():
        _rows(t, f"{rid} indicators", rx.indicators)
        _rows(t, f"{rid} satellite C/N0", rx.satellite_cn0)
        _rows(t, f"{rid} fix type share", rx.fix_types)
        if rx.consistency_scale:
            _rows(t, f"{rid} GNSS-only residual scale", rx.consistency_scale)
        if rx.clock is not None:
            _rows(t, f"{rid} time vs {rx.clock.clock}", _clock_quantities(rx.clock))
    if b.navigation is not None:
        n = b.navigation
        _rows(t, f"noise ({n.receiver_id}, {n.imu_id}, {n.imu_grade})", n.parameters)
        if n.coast_envelope_peak is not None:
            _rows(t, "INS coasts", {"envelope peak": n.coast_envelope_peak})
    for key, pair in b.pairs.items():
        d = pair.baseline_distance
        _rows(t, f"{key} distance", {"nu": d.nu, "sigma": d.sigma, "K_eff/K": d.k_eff_ratio})
        if pair.pseudorange_difference_sd is not None:
            p = pair.pseudorange_difference_sd
            _rows(t, f"{key} pseudorange spread", {"nu": p.nu, "sigma": p.sigma, "K_eff/K": p.k_eff_ratio})
    out.print(t)
    disagree = [f"{group}.{name}" for group, qs in _all(b) for name, q in qs.items() if q.agree is False]
    if disagree:
        out.print(
            f"[bold red]the logs disagree on {len(disagree)} quantity(ies)[/]: {', '.join(disagree)} (kept and shown; "
            "indicator levels the logs disagree on are not used as yardsticks)"
        )


def _clock_quantities(clock: ClockBaseline) -> dict[str, Quantity]:
    return {"jitter": clock.offset_scale_s} | ({"drift": clock.drift_ppm} if clock.drift_ppm is not None else {})


def _all(b: Baseline) -> list[tuple[str, dict[str, Quantity]]]:
    groups: list[tuple[str, dict[str, Quantity]]] = []
    for rid, rx in b.receivers.items():
        groups += [
            (rid, rx.indicators),
            (f"{rid}.satellite_cn0", rx.satellite_cn0),
            (f"{rid}.consistency", rx.consistency_scale),
        ]
        if rx.clock is not None:
            groups.append((f"{rid}.clock", _clock_quantities(rx.clock)))
    if b.navigation is not None:
        groups.append(("navigation", b.navigation.parameters))
    for key, pair in b.pairs.items():
        groups.append((key, {"nu": pair.baseline_distance.nu, "sigma": pair.baseline_distance.sigma}))
    return groups


@click.command("baseline")
@click.argument("logs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(path_type=Path),
    required=True,
    help="Baseline file to write (VEHICLE.baseline.json).",
)
@topic_option
@imu_grade_option
@click.option("--quiet", is_flag=True, help="Print only where the baseline was written.")
def command(logs: tuple[Path, ...], output: Path, topics: tuple[str, ...], imu_grade: str | None, quiet: bool) -> int:
    """Learn a vehicle's baseline from its clean LOGS (one receiver model and antenna installation): what
    `analyze --baseline` judges a log against, so an attack filling a whole log still shows."""
    check_writable(output, "--output")
    measured, refused = learn_from_logs(list(logs), parse_topics(topics), imu_grade, not quiet and show_progress())
    baseline = aggregate(measured, refused)
    output.write_text(dumps(baseline) + "\n", encoding="utf-8")
    if quiet:
        click.echo(f"{output}: baseline of {len(baseline.logs)} clean log(s), {len(baseline.refused)} refused")
    else:
        print_baseline(baseline, output)
    return EXIT_OK
