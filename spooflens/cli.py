"""The `spooflens` command line.

Commands are typed functions returning an exit code; `main()` is the thin shell that turns every
spooflens error into one line on stderr (never a traceback) and a non-zero exit.

Exit codes: 0 done; 1 internal error (a bug: rerun with --debug); 2 bad input or usage (nothing
analysed, nothing written); 3 the input was damaged and only what could be read was analysed (outputs
written); 4 the verdict is spoofing and --fail-on-spoof was given.
"""

from __future__ import annotations

import gc
import json
import os
import sys

# pandas keeps text columns in Arrow; Arrow's default allocator (mimalloc) reserves address space in
# large segments, a gigabyte beyond what a large log really uses, which an address-space limit (a
# container's, or ulimit -v) counts. The system allocator reserves what it uses. Set before pandas loads.
os.environ.setdefault("ARROW_DEFAULT_MEMORY_POOL", "system")
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

import click
from rich.table import Table

from spooflens.console import LazyGroup, console, progress, show_progress
from spooflens.early_recording import EarlyRecording
from spooflens.epoch_table import EpochTable
from spooflens.errors import NoGnssError, SpooflensError, one_line
from spooflens.evidence import label
from spooflens.navigation.imu_models import PRESETS
from spooflens.threads import side_work

if TYPE_CHECKING:
    from spooflens.pipeline import Analysis

EXIT_OK, EXIT_BUG, EXIT_INPUT, EXIT_DAMAGED, EXIT_SPOOFED = 0, 1, 2, 3, 4
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
    "report": "spooflens.report.command:report",
    "view": "spooflens.viewer:view",
    "fleet": "spooflens.fleet.command:command",
    "batch": "spooflens.batch:command",
}


def _parse_topics(values: tuple[str, ...]) -> dict[str, str]:
    topics = {}
    for v in values:
        role, sep, name = v.partition("=")
        if not sep or not role or not name:
            raise click.BadParameter(f"{v!r}: expected ROLE=/topic, e.g. fix=/gps2/fix", param_hint="--topic")
        topics[role.strip()] = name.strip()
    return topics


def _read(log: Path, topics: dict[str, str], show_progress: bool, solve_fixes: bool = True) -> EpochTable:
    """The log as an epoch table; with `solve_fixes` (every command but `inject`), receivers that logged
    only raw pseudoranges get fixes from their single-point solution (listed as computed), and the truth
    file beside the log, if any, fills the truth frame (drawn, never analysed)."""
    from readers import read_log
    from spooflens.epoch_table import checked
    from spooflens.navigation.single_point import with_solved_fixes
    from spooflens.truth import with_truth_beside

    with progress(show_progress) as report:
        table = read_log(log, topics=topics or None, progress=lambda done, total: report("reading", done, total))
    return checked(with_truth_beside(with_solved_fixes(table), log)) if solve_fixes else table


def _damaged(table: EpochTable) -> list[str]:
    return [str(s) for s in table.skipped if s.action == "lost"]


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
    from spooflens.analysis import analyses
    from spooflens.inventory import computed, skipped_or_repaired, stream_rows

    table = _read(log, _parse_topics(topics), show_progress())
    out = console()
    out.print(
        f"[bold]{table.source}[/]  format {table.format}, {table.duration_s:.1f} s, "
        f"clock {table.time_reference}, starts {table.absolute_iso(0.0)}"
    )
    streams = Table("role", "stream", "source", "type", "count", "rate (Hz)", "span (s)", "body frame", title="Streams")
    for row in stream_rows(table):
        streams.add_row(row.role, row.stream, row.source, row.type, row.count, row.rate, row.span, row.body_frame)
    out.print(streams)
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
    support = Table("analysis", "evidence", "can run", "missing", title="Analyses")
    for spec in analyses():
        missing = ", ".join(spec.missing(table))
        for d in spec.detectors:
            support.add_row(
                d.name, label(d.evidence) if d.evidence else "(product)", "no" if missing else "yes", missing
            )
    out.print(support)
    return EXIT_DAMAGED if _damaged(table) else EXIT_OK


def analyse_log(
    log: Path,
    topics: tuple[str, ...],
    imu_grade: str | None,
    quiet: bool,
    station_texts: tuple[str, ...] = (),
    recording: EarlyRecording | None = None,
) -> list[Analysis]:
    """Read and analyse LOG (its truth file beside it joins the table, for drawing only): one analysis per
    recording the log joins (usually one). `recording`: the log's recording, begun meanwhile
    (`recording_side_work`).

    A log without GNSS data raises NoGnssError before anything is written: a failed analysis leaves no
    files.
    """
    from spooflens.analysis import AnalyzeOptions
    from spooflens.detectors.references import STATION_OPTION, parse_station
    from spooflens.pipeline import analyze_segments

    try:
        given_stations = [parse_station(text) for text in station_texts]
    except ValueError as err:
        raise click.BadParameter(str(err), param_hint="--station") from None
    table = _read(log, _parse_topics(topics), not quiet and show_progress())
    require_gnss(log, table)
    with_obs = list(dict.fromkeys(table.observations["receiver_id"].astype(str)))
    for rid, *_ in given_stations:
        if rid is not None and rid not in with_obs:
            raise click.BadParameter(
                f"no receiver {rid!r} with raw observations in {log}; receivers with them: {with_obs or 'none'}",
                param_hint="--station",
            )
    options = AnalyzeOptions(imu_grade=imu_grade, extra={STATION_OPTION: given_stations} if given_stations else {})
    with progress(not quiet and show_progress()) as report:
        steps: list[str] = []

        def on_step(name: str) -> None:
            steps.append(name)
            report(f"analysing: {name}", len(steps), len(steps) + 1)

        with side_work(recording_side_work(table, recording)):
            return analyze_segments(table, options, on_step)


def recording_side_work(table: EpochTable, recording: EarlyRecording | None) -> Callable[[], None]:
    """What the analysis of `table` may do where it leaves a core idle (`threads.side_work`): begin its
    recording (a log of one recording), else import the recording's library."""
    if recording is not None and len(table.segments) < 2:
        return partial(recording.begin, table)
    return _import_writers


def _import_writers() -> None:
    """The recording's library, imported while the analysis leaves a core idle."""
    import spooflens.recording  # noqa: F401


def require_gnss(log: Path, table: EpochTable) -> None:
    """Raise NoGnssError for a log with no GNSS data at all. Raw observations or satellite reports
    without fixes (a RINEX observation file with no navigation file beside it) are still analysed: the
    detectors that need only them run (C/N0 across satellites), the others say what they lack."""
    if len(table.fixes) or len(table.observations) or len(table.satellites):
        return
    lost = "; ".join(str(s) for s in table.skipped if s.action == "lost")
    why = f"; lost: {lost}" if lost else ""
    found = f"no GNSS fixes, raw observations or satellite reports found (streams: {_stream_names(table)}{why})"
    raise NoGnssError(log, f"{found}; nothing written")


def finish(log: Path, analyses: list[Analysis], fail_on_spoof: bool) -> int:
    """The exit code of an analysis that ran: 4 spoofed (with --fail-on-spoof), 3 damaged input, else 0."""
    damaged = list(dict.fromkeys(d for a in analyses for d in _damaged(a.table)))
    if damaged:
        click.echo(f"spooflens: {log}: input damaged, analysed what could be read: {'; '.join(damaged)}", err=True)
    if fail_on_spoof and any(a.verdict.spoofed for a in analyses):
        return EXIT_SPOOFED
    return EXIT_DAMAGED if damaged else EXIT_OK


def segment_path(path: Path, k: int, n: int) -> Path:
    """An output's path for recording k of n (unchanged for a log of one recording)."""
    return path if n < 2 else path.with_name(f"{path.stem}.seg{k + 1}{path.suffix}")


def segments_summary(summaries: list[dict]) -> dict:
    """The JSON of a log that joins recordings: each recording's summary, and the verdict over all."""
    if len(summaries) == 1:
        return summaries[0]
    spoofed = [i + 1 for i, s in enumerate(summaries) if s["verdict"]["spoofed"]]
    headline = (
        f"SPOOFING DETECTED in recording(s) {', '.join(map(str, spoofed))} of {len(summaries)}"
        if spoofed
        else f"NO SPOOFING DETECTED in any of {len(summaries)} recordings"
    )
    return {"segments": summaries, "verdict": {"spoofed": bool(spoofed), "headline": headline}}


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
@quiet_option
@fail_on_spoof_option
def analyze(
    log: Path,
    output: Path | None,
    json_path: Path | None,
    html_path: Path | None,
    topics: tuple[str, ...],
    station_texts: tuple[str, ...],
    imu_grade: str | None,
    quiet: bool,
    fail_on_spoof: bool,
) -> int:
    """Analyse LOG for GNSS spoofing; write a Rerun recording and optionally a JSON summary and HTML report."""
    output = output or Path(log.name.rstrip("/")).with_suffix(".rrd")
    for hint, path in (("--output", output), ("--json", json_path), ("--html", html_path)):
        check_writable(path, hint)
    recording = EarlyRecording(output)
    try:
        analyses = analyse_log(log, topics, imu_grade, quiet, station_texts, recording)
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
            _print_analysis(summary, segment_path(output, k, n), json_path, html)
    return finish(log, analyses, fail_on_spoof)


def check_writable(path: Path | None, hint: str, may_be_folder: bool = False) -> None:
    """An output that cannot be written is a usage error, said before the log is read (it was an internal
    error after the whole analysis). `may_be_folder`: a log format written as a folder."""
    if path is None:
        return
    if path.is_dir() and not may_be_folder:
        raise click.BadParameter(f"{path} is a folder, not a file", param_hint=hint)
    _check_folder(path.parent, path, hint)


def _check_folder(folder: Path, output: Path, hint: str) -> None:
    if not folder.is_dir():
        raise click.BadParameter(f"{output}: there is no folder {folder}", param_hint=hint)
    if not os.access(folder, os.W_OK):
        raise click.BadParameter(f"{output}: the folder {folder} cannot be written", param_hint=hint)


def make_output_folder(path: Path, hint: str) -> None:
    """The folder outputs go to, made if missing; one that cannot be made is a usage error, said before
    any log is read."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise click.BadParameter(f"{path}: cannot make this folder ({err.strerror or err})", param_hint=hint) from None
    _check_folder(path, path, hint)


def write_outputs(
    analyses: list[Analysis],
    output: Path,
    json_path: Path | None,
    html_path: Path | None,
    recording: EarlyRecording | None = None,
) -> list[dict]:
    """Write the recording (always), the JSON summary and the operator report of a log's analyses (one per
    recording it joins: `.segN` outputs, one JSON), as `analyze` does (`batch` writes through here too);
    returns each recording's summary. `recording`: the recording begun during the analysis, if any."""
    from spooflens.recording import write_recording
    from spooflens.summary import build_summary

    n = len(analyses)
    summaries = []
    for k, analysis in enumerate(analyses):
        table, verdict = analysis.table, analysis.verdict
        lines = [(0.0, f"VERDICT: {verdict.headline}", "WARN" if verdict.spoofed else "INFO")]
        path = segment_path(output, k, n)
        begun = recording.take(path, table) if recording is not None else None
        write_recording(path, table, analysis.results, lines, verdict, begun)
        summaries.append(build_summary(table, analysis.results, verdict))
        if html_path:
            from spooflens.report import write_report

            write_report(segment_path(html_path, k, n), analysis)
    if json_path:
        json_path.write_text(json.dumps(segments_summary(summaries), indent=2))
    return summaries


def _stream_names(table: EpochTable) -> str:
    return ", ".join(f"{s.topic} ({s.msgtype})" for s in table.streams) or "none"


def _print_analysis(summary: dict, output: Path | None, json_path: Path | None, html_path: Path | None = None) -> None:
    out = console()
    v = summary["verdict"]
    out.print(f"[bold {'red' if v['spoofed'] else 'green'}]{v['headline']}[/]")
    for inc in v["incidents"]:
        when = f" ({inc['onset_utc']})" if inc.get("onset_utc") else ""
        kind = "incident" if inc["confidence"] != "low" else "anomaly (no second class at the same time: not spoofing)"
        apart = [e for e in inc["evidence"] if e not in inc.get("corroborating_evidence", inc["evidence"])]
        also = f"; at other times {', '.join(apart)}" if apart else ""
        end = "end of log" if inc.get("ongoing_at_end") else f"{inc['end_s']:.2f} s"
        sats = f", satellites {'+'.join(inc['satellites'])}" if inc.get("satellites") else ""
        out.print(
            f"  {kind}: onset {inc['onset_s']:.2f} s{when}, alarm {inc['start_s']:.2f} s to {end}, "
            f"evidence {', '.join(inc.get('corroborating_evidence') or inc['evidence']) or 'none confirmed'}{also} "
            f"({', '.join(inc['detectors'])}){sats}, "
            f"confidence {inc['confidence']}"
        )
    for f in v.get("findings", []):
        out.print(f"  finding: {f['text']}")
    t = Table("analysis", "evidence", "ran", "alarms", "note")
    for a in summary["analyses"]:
        alarms = str(len(a["alarms"])) + (" (advisory)" if a.get("advisory") and a["alarms"] else "")
        t.add_row(a["name"], a.get("evidence_label") or "(product)", "yes" if a["ran"] else "no", alarms, a["reason"])
    out.print(t)
    for sk in summary["skipped"]:
        out.print(f"  skipped: {sk['stream']}: {sk['action']} {sk['count']} ({sk['reason']})")
    for made in summary.get("computed", []):
        out.print(f"  computed: {made['stream']}: {made['count']} ({made['reason']})")
    written = [
        f"{what}: {path}"
        for what, path in (("recording", output), ("summary", json_path), ("report", html_path))
        if path is not None
    ]
    out.print("   ".join(written))
    if output is not None:
        out.print(f"view it with: spooflens view {output}")


@cli.command()
@click.argument("log", type=click.Path(path_type=Path))
@click.option(
    "--attack",
    "attack_text",
    required=True,
    metavar="KIND[:param=value,...]",
    help="e.g. ramp:rate=2,axes=en,start=60  (see README: attack kinds)",
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
    from spooflens.writers.rewrite import rewrite_log

    spec = parse_attack(attack_text)
    check_writable(output, "--output", may_be_folder=True)
    table = _read(log, _parse_topics(topics), show_progress(), solve_fixes=False)
    spoofed, truth = apply_attack(table, spec)
    note = rewrite_log(log, output, table, spoofed, velocities=bool(spec.params.get("vel", 0)))
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
) -> int:
    """Write a simulated log (scenarios: seed000, aircraft, ship, ground, ground_raw, dual_receiver) and its
    truth (OUTPUT.truth.csv)."""
    from dataclasses import replace

    from spooflens.simulation.observations import ObservationNoise
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
    table = run_simulation(sc, seed=seed, duration_s=seconds).table
    truth_path = write_with_truth(table, output, fmt)
    click.echo(
        f"{output}: {fmt}, scenario {scenario}, seed {seed}, {table.duration_s:.0f} s, {len(table.imu)} IMU samples, "
        f"{len(table.fixes)} fixes, {len(table.observations)} observations; truth in {truth_path}"
    )
    return EXIT_OK


@cli.group(
    cls=LazyGroup,
    lazy={
        "read": "spooflens.bench.read_bench:command",
        "nav": "spooflens.bench.nav_bench:command",
        "learning": "spooflens.bench.learning_bench:command",
        "seed000": "spooflens.bench.seed000_bench:command",
        "realworld": "spooflens.bench.realworld_bench:command",
        "report": "spooflens.bench.report_bench:command",
        "seed003": "spooflens.bench.seed003_bench:command",
        "seed004": "spooflens.bench.seed004_bench:command",
        "seed001": "spooflens.bench.seed001_bench:command",
        "seed002": "spooflens.bench.seed002_bench:command",
        "e2e": "spooflens.bench.e2e_bench:command",
        "batch": "spooflens.bench.batch_bench:command",
        "fuzz": "spooflens.bench.fuzz:command",
        "corpus": "spooflens.bench.corpus_bench:command",
    },
)
def bench() -> None:
    """Measure speed, memory and detection performance (figures quoted in the README)."""


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
