"""The `spooflens` command line.

Commands are typed functions returning an exit code; `main()` is the thin shell that turns every
spooflens error into one line on stderr (never a traceback) and a non-zero exit.

Exit codes: 0 done; 1 internal error (a bug: rerun with --debug); 2 bad input or usage (nothing
analysed); 3 the input was damaged and only what could be read was analysed (outputs written).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import click
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from spooflens.epoch_table import EpochTable
from spooflens.errors import NoGnssError, SpooflensError

EXIT_OK, EXIT_BUG, EXIT_INPUT, EXIT_DAMAGED = 0, 1, 2, 3
err_console = Console(stderr=True)


def _console() -> Console:
    """Stdout console; wide when not a terminal, so piped tables are not truncated."""
    return Console() if sys.stdout.isatty() else Console(width=160)


def _parse_topics(values: tuple[str, ...]) -> dict[str, str]:
    topics = {}
    for v in values:
        role, sep, name = v.partition("=")
        if not sep or not role or not name:
            raise click.BadParameter(f"{v!r}: expected ROLE=/topic, e.g. fix=/gps2/fix", param_hint="--topic")
        topics[role.strip()] = name.strip()
    return topics


@contextmanager
def _progress(enabled: bool) -> Iterator[Callable[[str, int, int], None]]:
    """Yields report(task, done, total); draws rich bars on stderr when enabled."""
    if not enabled:
        yield lambda task, done, total: None
        return
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=err_console,
        transient=True,
    ) as bar:
        tasks: dict[str, int] = {}

        def report(task: str, done: int, total: int) -> None:
            if task not in tasks:
                tasks[task] = bar.add_task(task, total=max(total, 1))
            bar.update(tasks[task], completed=done, total=max(total, 1))

        yield report


def _read(log: Path, topics: dict[str, str], show_progress: bool, solve_fixes: bool = True) -> EpochTable:
    """The log as an epoch table; with `solve_fixes`, receivers that logged only raw pseudoranges get
    fixes from their single-point solution (listed among the repairs)."""
    from readers import read_log
    from spooflens.navigation.single_point import with_solved_fixes

    with _progress(show_progress) as report:
        table = read_log(log, topics=topics or None, progress=lambda done, total: report("reading", done, total))
    return with_solved_fixes(table) if solve_fixes else table


def _damaged(table: EpochTable) -> list[str]:
    return [str(s) for s in table.skipped if s.action == "lost"]


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
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
    help="Assign a topic to a role: fix, fix2, imu, vel, odom, truth; for RINEX logs nav=FILE names the "
    "navigation file. Repeatable.",
)


@cli.command()
@click.argument("log", type=click.Path(path_type=Path))
@topic_option
def inspect(log: Path, topics: tuple[str, ...]) -> int:
    """List the streams of LOG, what was skipped, and which analyses it supports."""
    from spooflens.analysis import ANALYSES

    table = _read(log, _parse_topics(topics), sys.stderr.isatty())
    console = _console()
    console.print(
        f"[bold]{table.source}[/]  format {table.format}, {table.duration_s:.1f} s, "
        f"clock {table.time_reference}, starts {table.absolute_iso(0.0)}"
    )
    streams = Table("role", "stream", "topic", "type", "count", "rate (Hz)", "span (s)", "body frame", title="Streams")
    for s in table.streams:
        streams.add_row(
            s.role,
            s.stream_id,
            s.topic,
            s.msgtype,
            str(s.count),
            f"{s.rate_hz:.2f}",
            f"{s.first_s:.1f}-{s.last_s:.1f}",
            s.body_frame or "",
        )
    console.print(streams)
    if table.skipped:
        console.print("[bold]Skipped or repaired[/]")
        for s in table.skipped:
            console.print(f"  {s}")
    support = Table("analysis", "can run", "missing", title="Analyses")
    for spec in ANALYSES:
        missing = spec.missing(table)
        support.add_row(spec.name, "yes" if not missing else "no", ", ".join(missing))
    console.print(support)
    return EXIT_DAMAGED if _damaged(table) else EXIT_OK


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
@topic_option
@click.option(
    "--imu-grade", default=None, help="IMU noise preset for the INS (default: from the log or consumer_mems)."
)
@click.option("--quiet", is_flag=True, help="No progress bars or tables; errors only.")
def analyze(
    log: Path, output: Path | None, json_path: Path | None, topics: tuple[str, ...], imu_grade: str | None, quiet: bool
) -> int:
    """Analyse LOG for GNSS spoofing; write a Rerun recording and optionally a JSON summary."""
    from spooflens.analysis import AnalyzeOptions, run_analyses
    from spooflens.recording import write_recording
    from spooflens.summary import build_summary
    from spooflens.verdict import decide

    table = _read(log, _parse_topics(topics), not quiet and sys.stderr.isatty())
    output = output or Path(log.name).with_suffix(".rrd")
    with _progress(not quiet and sys.stderr.isatty()) as report:
        steps: list[str] = []

        def on_step(name: str) -> None:
            steps.append(name)
            report(f"analysing: {name}", len(steps), len(steps) + 1)

        results = run_analyses(table, AnalyzeOptions(imu_grade=imu_grade), on_step)
        verdict = decide(results)
        lines = [(0.0, f"VERDICT: {verdict.headline}", "WARN" if verdict.spoofed else "INFO")]
        write_recording(output, table, results, lines)
    summary = build_summary(table, results, verdict)
    if json_path:
        json_path.write_text(json.dumps(summary, indent=2))
    if not quiet:
        _print_analysis(summary, output, json_path)
    if not len(table.fixes):
        raise NoGnssError(
            log,
            f"no GNSS fixes found (streams: {_stream_names(table)}); "
            f"recording written to {output} with what could be read",
        )
    damaged = _damaged(table)
    if damaged:
        click.echo(f"spooflens: {log}: input damaged, analysed what could be read: {'; '.join(damaged)}", err=True)
        return EXIT_DAMAGED
    return EXIT_OK


def _stream_names(table: EpochTable) -> str:
    return ", ".join(f"{s.topic} ({s.msgtype})" for s in table.streams) or "none"


def _print_analysis(summary: dict, output: Path, json_path: Path | None) -> None:
    console = _console()
    v = summary["verdict"]
    console.print(f"[bold {'red' if v['spoofed'] else 'green'}]{v['headline']}[/]")
    for inc in v["incidents"]:
        when = f" ({inc['onset_utc']})" if inc.get("onset_utc") else ""
        label = "incident" if inc["confidence"] != "low" else "GNSS-only anomaly (not called spoofing)"
        console.print(
            f"  {label}: onset {inc['onset_s']:.2f} s{when}, alarm {inc['start_s']:.2f}-{inc['end_s']:.2f} s, "
            f"detectors {', '.join(inc['detectors'])}, confidence {inc['confidence']}"
        )
    t = Table("analysis", "ran", "alarms", "note")
    for a in summary["analyses"]:
        t.add_row(a["name"], "yes" if a["ran"] else "no", str(len(a["alarms"])), a["reason"])
    console.print(t)
    for s in summary["skipped"]:
        console.print(f"  skipped: {s['stream']}: {s['action']} {s['count']} ({s['reason']})")
    console.print(f"recording: {output}" + (f"   summary: {json_path}" if json_path else ""))
    console.print(f"view it with: rerun {output}")


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
    table = _read(log, _parse_topics(topics), sys.stderr.isatty(), solve_fixes=False)
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
    default="mcap-ros2",
    show_default=True,
    help="mcap-ros2, mcap-ros1, mcap-json, mcap-protobuf, ros1bag, ros2bag-sqlite3, ros2bag-mcap, csv, ulog.",
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
    help="'synthetic' (GPS-like Walker 24/6/1) or a RINEX navigation file whose satellites to use.",
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


@cli.group()
def bench() -> None:
    """Measure speed, memory and detection performance (figures quoted in the README)."""


@bench.command("read")
@click.option("--duration", default=3600.0, show_default=True, help="Seconds of log to synthesise.")
@click.option("--workdir", type=click.Path(path_type=Path), default=Path("bench_data"), show_default=True)
def bench_read(duration: float, workdir: Path) -> int:
    """Reader speed and memory on a synthetic 200 Hz IMU + 10 Hz fix ROS2 MCAP, beside rosbags."""
    from spooflens.bench.read_bench import run_read_bench

    workdir.mkdir(parents=True, exist_ok=True)
    with err_console.status("writing the synthetic MCAP and reading it twice..."):
        r = run_read_bench(workdir, duration_s=duration)
    t = Table(
        "reader",
        "wall (s)",
        "messages/s",
        "peak RSS (MB)",
        title=f"{r['messages']} messages, {r['file_mb']:.0f} MB MCAP ({r['file']})",
    )
    for name, run in r["runs"].items():
        t.add_row(name, f"{run['wall_s']:.2f}", f"{run['messages_per_s']:,.0f}", f"{run['peak_rss_mb']:.0f}")
    _console().print(t)
    verdict = "goal met" if r["ratio_wall"] <= 1.0 else "goal MISSED"
    click.echo(
        f"wall-time ratio spooflens/rosbags = {r['ratio_wall']:.2f} (goal <= 1.0: {verdict}); peak RSS goal < 1024 MB"
    )
    return EXIT_OK


@bench.command("nav")
@click.option("--duration", default=3600.0, show_default=True, help="Seconds of flight to simulate.")
def bench_nav(duration: float) -> int:
    """Filter + smoother time and memory for 200 Hz IMU and 10 Hz GNSS (goal: one hour under 5 s)."""
    from spooflens.bench.nav_bench import run_nav_bench

    with err_console.status("simulating and running the filter and smoother..."):
        r = run_nav_bench(duration)
    t = Table("measure", "value", title=f"{duration:.0f} s: {r['imu_samples']} IMU samples, {r['gnss_epochs']} epochs")
    for key, fmt in (
        ("filter_s", "{:.2f} s"),
        ("smoother_s", "{:.2f} s"),
        ("filter_plus_smoother_s", "{:.2f} s"),
        ("compile_and_warmup_s", "{:.1f} s (once per machine; numba caches it)"),
        ("peak_rss_mb", "{:.0f} MB"),
        ("nis_mean", "{:.2f} (dof 6)"),
    ):
        t.add_row(key, fmt.format(r[key]))
    _console().print(t)
    goal = 5.0 * duration / 3600.0
    click.echo(
        f"filter + smoother {r['filter_plus_smoother_s']:.2f} s; goal < {goal:.1f} s: "
        + ("met" if r["filter_plus_smoother_s"] < goal else "MISSED")
    )
    return EXIT_OK


@bench.command("seed000")
@click.option("--runs", default=100, show_default=True, help="Monte Carlo runs per case of the paper's scenario.")
@click.option("--hours", default=200, show_default=True, help="Attack-free hours for the equal false-alarm part.")
@click.option(
    "--husky",
    "husky_path",
    type=click.Path(path_type=Path),
    default=Path(__file__).resolve().parents[1].parent / "shared/real/ros1_husky_navsat/test1.bag",
    show_default=True,
    help="Real clean log for the real-data part (skipped if missing).",
)
@click.option("--json", "json_path", type=click.Path(path_type=Path), default=None, help="Write all figures here.")
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(path_type=Path),
    default=None,
    help="Write a PNG of the delay distributions here.",
)
@click.option("--quick", is_flag=True, help="Fewer runs everywhere (a smoke test, not the reported figures).")
def bench_seed000(
    runs: int, hours: int, husky_path: Path, json_path: Path | None, plot_path: Path | None, quick: bool
) -> int:
    """Seed 000's Table 1 (KF, GLRT, MLRT delays), false alarms, equal-FA delays, real data, runtime."""
    from spooflens.bench import seed000_bench as sb

    if quick:
        runs, hours = min(runs, 5), min(hours, 10)
    opts = sb.BenchOptions(runs=runs, equal_fa_hours=hours)
    out: dict[str, object] = {}
    with _progress(sys.stderr.isatty()) as report:
        out["paper"] = sb.paper_scenario(opts, lambda d, n: report("paper scenario (Monte Carlo)", d, n))
        out["minimum_rate"] = sb.minimum_rate(opts, runs=8 if quick else 40)
        out["equal_fa"] = sb.equal_false_alarm(opts, hours, lambda d, n: report("attack-free hours", d, n))
    if husky_path.exists():
        out["husky"] = sb.husky(husky_path)
    out["runtime"] = sb.runtime()
    _print_seed000(out, runs)
    if json_path:
        json_path.write_text(json.dumps(out, indent=1, default=str))
    if plot_path:
        sb.plot(out, plot_path)
        click.echo(f"plot: {plot_path}")
    return EXIT_OK


def _fmt(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def _print_seed000(out: dict, runs: int) -> None:
    from spooflens.bench import seed000_bench as sb

    console = _console()
    paper = out["paper"]
    t = Table(
        "method",
        *[f"{c} m/s" for c in ("2", "3", "5")],
        "25 m/s up",
        "clean runs alarmed",
        title=f"Seed 000 scenario, {runs} runs: median delay s [25-75%] (detected %)  | paper Table 1",
    )
    for m, cases in paper["delays"].items():
        cells = []
        for key in ("en:2", "en:3", "en:5", "u:25"):
            med, lo, hi, frac = sb.summarise(cases[key])
            cells.append(f"{_fmt(med)} [{_fmt(lo)}-{_fmt(hi)}] ({100 * frac:.0f}%)")
        t.add_row(m, *cells, f"{100 * paper['false_alarm_fraction'][m]:.0f}%")
    for name, row in sb.PAPER_TABLE1.items():
        vertical = f"{sb.PAPER_VERTICAL_MLRT}" if name == "MLRT" else ""
        t.add_row(f"paper: {name}", *[_fmt(row[r]) for r in (2, 3, 5)], vertical, "")
    console.print(t)
    mr = out["minimum_rate"]
    console.print(
        f"smallest east+north ramp detected in >= 50% of runs (paper: MLRT {sb.PAPER_MIN_RATE} m/s): "
        + ", ".join(f"{m} {_fmt(v)}" for m, v in mr["minimum_rate"].items())
    )
    eq = out["equal_fa"]
    t = Table(
        "method",
        *[f"{r} m/s @ {fa:g}/1000h" for r in ("2", "5") for fa in (1.0, 10.0, 100.0)],
        title=f"Equal false-alarm rates ({eq['hours']} attack-free hours, Gumbel tail): median delay s",
    )
    for m, d in eq["delays"].items():
        t.add_row(m, *[_fmt(d[r][fa]) for r in ("2", "5") for fa in (1.0, 10.0, 100.0)])
    console.print(t)
    if "husky" in out:
        t = Table(
            "husky bag",
            *out["husky"]["clean"].keys(),
            title="Real data (husky, consumer IMU): alarms when clean, delay (s) of the first alarm after "
            "an injected ramp's onset",
        )
        for label, res in out["husky"].items():
            key = "alarms" if label == "clean" else "delay_after_200_s"
            t.add_row(
                label,
                *[
                    (f"{v[key]:.1f}" if isinstance(v[key], float) else f"{v[key]}" if v[key] is not None else "-")
                    + (" (advisory)" if v["advisory"] else "")
                    for v in res.values()
                ],
            )
        console.print(t)
    rt = out["runtime"]
    console.print(
        f"runtime: all seed-000 detectors (online + offline l_N(m)) over {rt['epochs']:.0f} epochs "
        f"(1 h of 10 Hz GNSS): {rt['detectors_s']:.1f} s (goal < 10 s)"
    )


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
        click.echo(f"spooflens: error: {err}", err=True)
        return EXIT_INPUT
    except Exception as err:
        if debug:
            raise
        click.echo(f"spooflens: internal error: {type(err).__name__}: {err} (rerun with --debug for details)", err=True)
        return EXIT_BUG
    return int(code or 0)


if __name__ == "__main__":
    sys.exit(main())
