"""The `spooflens` command line.

Commands are typed functions returning an exit code; `main()` is the thin shell that turns every
spooflens error into one line on stderr (never a traceback) and a non-zero exit (the codes:
`spooflens.service`). What the commands share with `report`, `batch`, `fleet` and the benches is there too.
"""

from __future__ import annotations

import gc
import os
import sys

# pandas keeps text columns in Arrow; Arrow's default allocator (mimalloc) reserves address space in
# large segments, a gigabyte beyond what a large log really uses, which an address-space limit (a
# container's, or ulimit -v) counts. The system allocator reserves what it uses. Set before pandas loads.
os.environ.setdefault("ARROW_DEFAULT_MEMORY_POOL", "system")
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

import click
from rich.table import Table

from spooflens.errors import SpooflensError, one_line
from spooflens.navigation.imu_models import PRESETS
from spooflens.output.console import LazyGroup, console, show_progress
from spooflens.output.early_recording import EarlyRecording
from spooflens.pipeline.evidence import label
from spooflens.service import (
    EXIT_BUG,
    EXIT_DAMAGED,
    EXIT_INPUT,
    EXIT_OK,
    analyse_log,
    check_writable,
    damage,
    finish,
    load_baseline_option,
    parse_topics,
    print_analysis,
    read_table,
    segment_path,
    write_outputs,
)

if TYPE_CHECKING:
    pass

# `simulate --format` choices (spooflens.writers.WRITERS) and those written as directories
SIMULATE_FORMATS = (
    "mcap-ros2",
    "mcap-ros1",
    "mcap-json",
    "mcap-protobuf",
    "ros1bag",
    "ros2bag-sqlite3",
    "ros2bag-mcap",
    "csv",
    "ulog",
    "rinex",
)
DIRECTORY_FORMATS = ("csv", "rinex", "ros2bag-sqlite3", "ros2bag-mcap")

# Commands that live in modules of their own: name -> "module:attribute" (imported when used).
COMMANDS: dict[str, str] = {
    "baseline": "spooflens.baseline.command:command",
    "report": "spooflens.output.report.command:report",
    "view": "spooflens.output.viewer:view",
    "fleet": "spooflens.fleet.command:command",
    "batch": "spooflens.batch:command",
}


@click.group(cls=LazyGroup, lazy=COMMANDS, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="spooflens")
@click.option("--debug", is_flag=True, help="Show tracebacks instead of one-line errors.")
@click.pass_context
def cli(ctx: click.Context, debug: bool) -> None:
    """Forensic analysis of GNSS spoofing in vehicle logs."""
    ctx.obj = {"debug": debug}


topic_option = click.option(
    "--topic",
    "topics",
    multiple=True,
    metavar="ROLE=/name",
    help="Assign a topic to a role: fix, fix2, imu, vel, odom, truth; for logs of raw observations (RINEX, "
    "UBX, GnssLogger, DataFlash) nav=FILE names the navigation file. Repeatable.",
)


@cli.command()
@click.argument("log", type=click.Path(path_type=Path))
@topic_option
def inspect(log: Path, topics: tuple[str, ...]) -> int:
    """List the streams of LOG, what was skipped, and which analyses it supports."""
    from spooflens.inventory import computed, skipped_or_repaired, stream_rows, without_gnss
    from spooflens.pipeline.preconditions import unmet_preconditions
    from spooflens.pipeline.registry import AnalysisContext, AnalyzeOptions, analyses

    table = read_table(log, parse_topics(topics), show_progress())
    out = console()
    out.print(
        f"[bold]{table.source}[/]  format {table.format}, {table.duration_s:.1f} s, "
        f"clock {table.time_reference}, starts {table.absolute_iso(0.0)}"
    )
    streams = Table("role", "stream", "source", "type", "count", "rate (Hz)", "span (s)", "body frame", title="Streams")
    for row in stream_rows(table):
        streams.add_row(row.role, row.stream, row.source, row.type, row.count, row.rate, row.span, row.body_frame)
    out.print(streams)
    if nothing := without_gnss(table):
        out.print(f"[bold]{nothing}[/]")
    lost, made = skipped_or_repaired(table), computed(table)
    if lost:
        out.print("[bold]Skipped or repaired[/]")
        for skipped in lost:
            out.print(f"  {skipped}")
    if made:
        out.print("[bold]Computed[/]")
        for c in made:
            out.print(f"  {c.stream}: {c.count} ({c.reason})")
    # the names `analyze` reports its results under: each detector, and each analysis product
    # and what each one's model requires of the data (its preconditions), checked as `analyze` checks them
    support = Table("analysis", "evidence", "can run", "missing, or what its model requires", title="Analyses")
    ctx = AnalysisContext(table, AnalyzeOptions())
    for spec in analyses():
        missing = spec.missing(table)
        for d in spec.detectors:
            unmet = [] if missing else unmet_preconditions(d.preconditions, ctx)
            why = ", ".join(dict.fromkeys(missing)) or "; ".join(u.text for u in unmet)
            stops = bool(missing) or any(u.stops for u in unmet)
            support.add_row(d.name, label(d.evidence) if d.evidence else "(product)", "no" if stops else "yes", why)
    out.print(support)
    return EXIT_DAMAGED if damage(table) else EXIT_OK


station_option = click.option(
    "--station",
    "station_texts",
    multiple=True,
    metavar="[RX=]LAT,LON,H",
    help="A receiver's known position (deg, deg, m above the ellipsoid) for the known-station detectors; "
    "without RX= the first receiver with observations. Repeatable.",
)
quiet_option = click.option("--quiet", is_flag=True, help="Print only the one-line verdict (no progress, no tables).")
fail_on_spoof_option = click.option(
    "--fail-on-spoof", is_flag=True, help="Exit with code 4 when the verdict is spoofing (for scripts and pipelines)."
)
fail_on_jam_option = click.option(
    "--fail-on-jam",
    is_flag=True,
    help="Exit with code 5 when the verdict names jamming / interference (4 for spoofing wins).",
)
baseline_option = click.option(
    "--baseline",
    "baseline_path",
    type=click.Path(path_type=Path),
    default=None,
    metavar="VEHICLE.baseline.json",
    help="The vehicle's baseline (`spooflens baseline`): detectors judge the log against its clean logs, so an "
    "attack filling the whole log still shows. A baseline of another receiver model is refused.",
)
imu_grade_option = click.option(
    "--imu-grade",
    type=click.Choice(sorted(PRESETS)),
    default=None,
    help="IMU noise preset for the INS (default: from the log or consumer_mems).",
)


@cli.command()
@click.argument("log", type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(path_type=Path),
    default=None,
    help="Rerun recording to write (default: LOG name with .rrd, in the current directory).",
)
@click.option(
    "--json",
    "json_path",
    type=click.Path(path_type=Path),
    default=None,
    help="Also write the machine-readable summary here.",
)
@click.option(
    "--html",
    "html_path",
    type=click.Path(path_type=Path),
    default=None,
    help="Also write the operator report (one self-contained HTML page) here.",
)
@topic_option
@station_option
@imu_grade_option
@baseline_option
@quiet_option
@fail_on_spoof_option
@fail_on_jam_option
def analyze(
    log: Path,
    output: Path | None,
    json_path: Path | None,
    html_path: Path | None,
    topics: tuple[str, ...],
    station_texts: tuple[str, ...],
    imu_grade: str | None,
    baseline_path: Path | None,
    quiet: bool,
    fail_on_spoof: bool,
    fail_on_jam: bool,
) -> int:
    """Analyse LOG for GNSS spoofing; write a Rerun recording and optionally a JSON summary and HTML report."""
    output = output or Path(log.name.rstrip("/")).with_suffix(".rrd")
    for hint, path in (("--output", output), ("--json", json_path), ("--html", html_path)):
        check_writable(path, hint)
    baseline = load_baseline_option(baseline_path)
    recording = EarlyRecording(output)
    try:
        analyses = analyse_log(log, topics, imu_grade, quiet, station_texts, recording, baseline)
        summaries = write_outputs(analyses, output, json_path, html_path, recording)
    finally:
        recording.abandon()  # begun for an analysis that failed (a taken one is written and in place)
    n = len(analyses)
    for k, (analysis, summary) in enumerate(zip(analyses, summaries, strict=True)):
        if n > 1 and not quiet:
            console().print(f"[bold]recording {k + 1} of {n}[/] (each of the log's {n} recordings on its own)")
        if quiet:
            click.echo((f"recording {k + 1} of {n}: " if n > 1 else "") + analysis.verdict.headline)
        else:
            html = segment_path(html_path, k, n) if html_path else None
            print_analysis(summary, segment_path(output, k, n), json_path, html)
    return finish(log, analyses, fail_on_spoof, fail_on_jam)


@cli.command()
@click.argument("log", type=click.Path(path_type=Path))
@click.option(
    "--attack",
    "attack_text",
    required=True,
    metavar="KIND[:param=value,...]",
    help="e.g. ramp:rate=2,axes=en,start=60  (attack kinds: docs/simulation-and-attacks.md)",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(path_type=Path),
    required=True,
    help="Spoofed copy, in the input's format (its attack truth goes to OUTPUT.attack.json).",
)
@topic_option
def inject(log: Path, attack_text: str, output: Path, topics: tuple[str, ...]) -> int:
    """Write a spoofed copy of LOG with an attack injected, plus its ground truth."""
    from spooflens.attacks import apply_attack, parse_attack, sidecar_path
    from spooflens.attacks.spec import JAMMING_KINDS
    from spooflens.writers.rewrite import rewrite_log, unwritten_changes

    spec = parse_attack(attack_text)
    check_writable(output, "--output", may_be_folder=True)
    table = read_table(log, parse_topics(topics), show_progress(), solve_fixes=False)
    spoofed, truth = apply_attack(table, spec)
    # interference makes the receiver's velocity noisier, and a capture after it moves it with the drag
    jamming = spec.kind in JAMMING_KINDS
    note = rewrite_log(log, output, table, spoofed, velocities=bool(spec.params.get("vel", 0)) or jamming)
    if jamming:
        missing = unwritten_changes(table, spoofed, read_table(output, parse_topics(topics), False, solve_fixes=False))
        if missing:
            note += f"; not in the copy (the format or its writer has no place for them): {', '.join(missing)}"
    truth.write(sidecar_path(output))
    click.echo(
        f"{output}: {spec} on {', '.join(truth.receivers)}"
        + (f" (satellites {'+'.join(truth.satellites)})" if truth.satellites else "")
        + f" from {truth.start_s:.1f} s to {truth.end_s:.1f} s; "
        f"{note}; truth in {sidecar_path(output)}"
    )
    return EXIT_OK


@cli.command()
@click.argument("scenario")
@click.option("-o", "--output", type=click.Path(path_type=Path), required=True, help="Log to write.")
@click.option(
    "--format",
    "fmt",
    type=click.Choice(SIMULATE_FORMATS),
    default="mcap-ros2",
    show_default=True,
    help="Output format. csv, rinex and the ROS2 bags are directories of files.",
)
@click.option("--seconds", type=float, default=None, help="Duration (default: the scenario's own).")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed: same seed, same log.")
@click.option("--imu-hz", type=float, default=None, help="IMU rate (default: the scenario's).")
@click.option("--gnss-hz", type=float, default=None, help="GNSS rate (default: the scenario's).")
@click.option("--raw", is_flag=True, help="Receivers log raw observations and report their own solution of them.")
@click.option(
    "--constellation",
    default="synthetic",
    show_default=True,
    help="'synthetic' (GPS-like Walker 24/6/1), 'synthetic_gps_galileo' (and Galileo's 24/3/1), or a RINEX "
    "navigation file whose satellites to use.",
)
@click.option(
    "--sky",
    is_flag=True,
    help="The receiver reports its sky (per-satellite C/N0 by elevation, elevation, azimuth, used) and logs "
    "the indicators real receivers do (AGC, noise, jamming indicator, accuracies).",
)
@click.option(
    "--jam",
    "jam_text",
    default=None,
    metavar="START,END,DEPTH",
    help="A jammer from START to END s whose full power lowers every satellite's C/N0 by DEPTH dB (spooflens "
    "inject's `jam` attack on the simulated receiver, with --sky); its truth goes to OUTPUT.attack.json.",
)
def simulate(
    scenario: str,
    output: Path,
    fmt: str,
    seconds: float | None,
    seed: int,
    imu_hz: float | None,
    gnss_hz: float | None,
    raw: bool,
    constellation: str,
    sky: bool,
    jam_text: str | None,
) -> int:
    """Write a simulated log (scenarios: seed000, aircraft, ship, ground, ground_raw, dual_receiver) and its
    truth (OUTPUT.truth.csv)."""
    from dataclasses import replace

    from spooflens.simulation.observations import ObservationNoise
    from spooflens.simulation.sensors import ReceiverModel
    from spooflens.simulation.simulate import SCENARIOS, write_with_truth
    from spooflens.simulation.simulate import simulate as run_simulation

    if scenario not in SCENARIOS:
        raise click.UsageError(f"unknown scenario {scenario!r}; scenarios are {sorted(SCENARIOS)}")
    sc = SCENARIOS[scenario]
    sc = replace(
        sc,
        imu_hz=imu_hz or sc.imu_hz,
        gnss_hz=gnss_hz or sc.gnss_hz,
        observations=sc.observations or (ObservationNoise() if raw else None),
        constellation=constellation,
    )
    if fmt in DIRECTORY_FORMATS and output.suffix:
        raise click.BadParameter(
            f"{output}: --format {fmt} writes a directory of files; give a name without an extension "
            f"(e.g. {output.with_suffix('')})",
            param_hint="-o",
        )
    if raw and fmt not in ("csv", "rinex"):
        click.echo(f"note: {fmt} has no place for raw observations; the csv and rinex formats keep them", err=True)
    if fmt == "rinex":
        click.echo(
            "note: RINEX holds only the observations (and a navigation file); IMU and fixes are not written", err=True
        )
    jam = parse_jam(jam_text) if jam_text is not None else None
    if (sky or jam is not None) and sc.observations is None:
        sc = replace(sc, receiver=sc.receiver or ReceiverModel(), satellite_reports=True)
    table = run_simulation(sc, seed=seed, duration_s=seconds).table
    jammed, clean = "", table
    if jam is not None:
        from spooflens.attacks import apply_attack, parse_attack, sidecar_path

        start, end, depth = jam
        table, attack = apply_attack(table, parse_attack(f"jam:start={start},end={end},cn0={depth},seed={seed}"))
        attack.write(sidecar_path(output))
        jammed = f"; jammed from {start:g} s to {end:g} s, {depth:g} dB (attack truth in {sidecar_path(output)})"
    truth_path = write_with_truth(table, output, fmt)
    if jam is not None and fmt != "rinex":
        from spooflens.writers.rewrite import unwritten_changes

        missing = unwritten_changes(clean, table, read_table(output, {}, False, solve_fixes=False))
        if missing:
            click.echo(f"note: {fmt} has no place for the jamming's {', '.join(missing)}", err=True)
    click.echo(
        f"{output}: {fmt}, scenario {scenario}, seed {seed}, {table.duration_s:.0f} s, {len(table.imu)} IMU samples, "
        f"{len(table.fixes)} fixes, {len(table.observations)} observations, {len(table.satellites)} satellite "
        f"reports; truth in {truth_path}{jammed}"
    )
    return EXIT_OK


def parse_jam(text: str) -> tuple[float, float, float]:
    """`--jam START,END,DEPTH` as numbers, END after START and DEPTH positive."""
    parts = [p.strip() for p in text.split(",")]
    try:
        start, end, depth = (float(p) for p in parts)
    except ValueError:
        raise click.BadParameter(f"{text!r}: expected START,END,DEPTH, e.g. 120,180,15", param_hint="--jam") from None
    if not (0 <= start < end) or depth <= 0:
        raise click.BadParameter(f"{text!r}: needs 0 <= START < END and DEPTH > 0 dB", param_hint="--jam")
    return start, end, depth


@cli.group(
    cls=LazyGroup,
    lazy={
        "read": "spooflens.bench.read_bench:command",
        "nav": "spooflens.bench.nav_bench:command",
        "learning": "spooflens.bench.learning_bench:command",
        "mlrt": "spooflens.bench.mlrt_bench:command",
        "realworld": "spooflens.bench.realworld_bench:command",
        "report": "spooflens.bench.report_bench:command",
        "dual_receiver": "spooflens.bench.dual_receiver_bench:command",
        "fleet": "spooflens.bench.fleet_bench:command",
        "range_rate": "spooflens.bench.range_rate_bench:command",
        "pr_change": "spooflens.bench.pr_change_bench:command",
        "e2e": "spooflens.bench.e2e_bench:command",
        "batch": "spooflens.bench.batch_bench:command",
        "fuzz": "spooflens.bench.fuzz:command",
        "corpus": "spooflens.bench.corpus_bench:command",
        "baseline": "spooflens.bench.baseline_bench:command",
        "windows": "spooflens.bench.windows_bench:command",
    },
)
def bench() -> None:
    """Measure speed, memory and detection performance (figures in docs/benchmarks.md)."""


@cli.command()
def schema() -> int:
    """Print the epoch-table schema (columns, units, dtypes) as Markdown."""
    from spooflens.schema import schema_markdown

    click.echo(schema_markdown())
    return EXIT_OK


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the command, map errors to one line and an exit code."""
    debug = "--debug" in (argv if argv is not None else sys.argv[1:])
    try:
        code = cli.main(args=argv, prog_name="spooflens", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("spooflens: aborted", err=True)
        return 130
    except click.ClickException as err:
        err.show()
        return EXIT_INPUT
    except SpooflensError as err:
        if debug:
            raise
        click.echo(f"spooflens: error: {one_line(str(err), 2000)}", err=True)
        return EXIT_INPUT
    except Exception as err:
        if debug:
            raise
        click.echo(f"spooflens: internal error: {one_line(err)} (rerun with --debug for details)", err=True)
        return EXIT_BUG
    return int(code or 0)


def run() -> NoReturn:
    """The console script: `main`, then the process ends. What is still alive goes to the permanent
    generation first (`gc.freeze`), so the interpreter's last collection does not walk every object of
    pandas, numba and Rerun only to free them: 0.15 s of a small log's 2 s run."""
    code = main()
    gc.freeze()
    sys.exit(code)


if __name__ == "__main__":
    run()
