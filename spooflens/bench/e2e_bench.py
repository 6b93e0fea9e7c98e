"""End-to-end benchmark: read, analyse, write, as `spooflens analyze` does, each in a fresh process.

In depth: docs/benchmarks.md."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import click
from rich.table import Table

from spooflens.bench.common import measure_in_child, peak_rss_mb
from spooflens.bench.e2e_plot import E2EFigures, plot_e2e
from spooflens.compile import aot
from spooflens.output.console import console, err_console

GOALS = {"e2e_s": 5.0, "e2e_rss_mb": 1024.0, "read_s": 1.5, "voyage_rss_mb": 2048.0, "first_run_s": 2.0}
ISSUE_ROSBAGS_LOOP_S = 7.9  # the rosbags loop on the machine the 5 s goal was set on (issue 13)
# the machine's speed moves the seconds by a third between sessions; a ratio to that loop moves less
GOAL_E2E_BY_LOOP = GOALS["e2e_s"] / ISSUE_ROSBAGS_LOOP_S
COLD_FIRST_RUN = "empty numba cache (every kernel compiled)"
SAMPLE = Path(__file__).resolve().parents[2] / "sample_logs" / "spoofed_flight.mcap"


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


class _Stages:
    """Wall and CPU time of consecutive stages, and the peak RSS when each ended."""

    def __init__(self) -> None:
        self.rows: list[dict[str, Any]] = []
        self._name: str | None = None
        self._t = self._c = 0.0

    def start(self, name: str) -> None:
        self.stop()
        self._name, self._t, self._c = name, time.perf_counter(), _cpu_s()

    def stop(self) -> None:
        if self._name is not None:
            self.rows.append(
                {
                    "stage": self._name,
                    "wall_s": time.perf_counter() - self._t,
                    "cpu_s": _cpu_s() - self._c,
                    "peak_rss_mb": peak_rss_mb(),
                }
            )
        self._name = None


def analyse_end_to_end(log: str, out_dir: str) -> dict[str, Any]:
    """What `spooflens analyze LOG -o .rrd --json .json` does, stage by stage (runs in a fresh process)."""
    stages = _Stages()
    stages.start("import")
    from spooflens.output.early_recording import EarlyRecording
    from spooflens.pipeline.registry import AnalyzeOptions
    from spooflens.pipeline.run import analyze_table
    from spooflens.service import read_table, recording_side_work, write_outputs
    from spooflens.threads import side_work

    stages.start("read")
    table = read_table(Path(log), {}, False)
    stages.start("analysis: start")
    out = Path(out_dir)
    recording = EarlyRecording(out / "e2e.rrd")
    with side_work(recording_side_work(table, recording)):  # as `analyze` does: the recording begun meanwhile
        analysis = analyze_table(table, AnalyzeOptions(), lambda step: stages.start(f"analysis: {step}"))
    stages.start("recording + JSON")
    write_outputs([analysis], out / "e2e.rrd", out / "e2e.json", None, recording)
    stages.stop()
    return {
        "stages": stages.rows,
        "cpu_s": _cpu_s(),
        "verdict": analysis.verdict.headline,
        "passes": analysis.passes,
        "imu_samples": len(table.imu),
        "gnss_epochs": len(table.fixes),
        "rrd_mb": (out / "e2e.rrd").stat().st_size / 1e6,
    }


def profile_analysis(log: str, out_file: str) -> dict[str, Any]:
    """cProfile of the analysis of `log` (reading not included) written to `out_file`, and the bytes each
    part of the navigation product holds."""
    import cProfile
    import io
    import pstats

    from spooflens.navigation.product import solve_navigation
    from spooflens.pipeline.registry import AnalyzeOptions
    from spooflens.pipeline.run import analyze_table
    from spooflens.service import read_table

    table = read_table(Path(log), {}, False)
    profiler = cProfile.Profile()
    profiler.enable()
    analyze_table(table, AnalyzeOptions())
    profiler.disable()
    text = io.StringIO()
    stats = pstats.Stats(profiler, stream=text).sort_stats("cumulative")
    stats.print_stats(r"spooflens|readers", 60)
    nav = solve_navigation(table, AnalyzeOptions())
    held = held_bytes({"navigation": nav, "table": table})
    Path(out_file).write_text(text.getvalue() + "\n\nMemory held (MB):\n" + json.dumps(held, indent=1))
    return {"held_mb": held}


def held_bytes(roots: dict[str, Any], min_mb: float = 1.0) -> dict[str, float]:
    """MB of every numpy array and DataFrame reachable through dataclass fields, dicts and finished
    futures (the smoothed solution) from `roots` (each array counted once, under the first path that
    reaches it), largest first."""
    import dataclasses
    from concurrent.futures import Future

    import numpy as np
    import pandas as pd

    seen: set[int] = set()
    out: dict[str, float] = {}

    def visit(path: str, obj: Any, depth: int) -> None:
        if depth > 6 or id(obj) in seen:
            return
        seen.add(id(obj))
        if isinstance(obj, np.ndarray):
            out[path] = obj.nbytes / 1e6
        elif isinstance(obj, pd.DataFrame):
            out[path] = float(obj.memory_usage(deep=False, index=False).sum()) / 1e6
        elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
            for f in dataclasses.fields(obj):
                visit(f"{path}.{f.name}", getattr(obj, f.name), depth + 1)
        elif isinstance(obj, Future) and obj.done() and obj.exception() is None:
            visit(f"{path}.result()", obj.result(), depth + 1)
        elif isinstance(obj, dict):
            for k, v in obj.items():
                visit(f"{path}[{k}]", v, depth + 1)
        elif isinstance(obj, tuple | list) and len(obj) < 50:
            for i, v in enumerate(obj):
                visit(f"{path}[{i}]", v, depth + 1)

    for name, root in roots.items():
        visit(name, root, 0)
    return {k: round(v, 1) for k, v in sorted(out.items(), key=lambda kv: -kv[1]) if v >= min_mb}


def rosbags_loop(log: str) -> dict[str, Any]:
    from spooflens.bench.read_bench import read_with_rosbags

    c0 = _cpu_s()
    n = read_with_rosbags(log)
    return {"messages": n, "cpu_s": _cpu_s() - c0}


def write_aircraft_hour(path: str, attack: str = "") -> int:
    """`spooflens simulate aircraft --seconds 3600` (seed 0), with `attack` injected when given."""
    from spooflens.simulation.simulate import simulate, write_with_truth

    table = simulate("aircraft", seed=0, duration_s=3600.0).table
    if attack:
        from spooflens.attacks import apply_attack, parse_attack

        table, _ = apply_attack(table, parse_attack(attack))
    write_with_truth(table, Path(path), "mcap-ros2")
    return len(table.imu)


def write_gnss_only(path: str) -> int:
    """A 10 min simulated ship log with its GNSS fixes only (ROS2 MCAP): the kind of log (an NMEA, RINEX
    or u-blox receiver log) whose analysis runs no compiled kernel and never imports numba."""
    from dataclasses import replace

    from spooflens.schema import FRAMES, empty_frame
    from spooflens.simulation.simulate import simulate
    from spooflens.writers import write_log

    table = simulate("ship", seed=0, duration_s=600.0).table
    gnss_only = replace(table, **{name: empty_frame(name) for name in FRAMES if name != "fixes"})
    write_log(gnss_only, Path(path), "mcap-ros2")
    return len(gnss_only.fixes)


def write_voyage(path: str, hours: float, block_h: float = 2.0) -> int:
    """A ship voyage of `hours` (100 Hz IMU, 1 Hz GNSS) written to one ROS2 MCAP in blocks.

    The whole trajectory is generated at once only at the GNSS rate's scale of memory: each block of
    `block_h` hours is simulated as the scenario's first `block_h` hours with its own seed, shifted in
    time and translated so it continues where the previous block ended (position, and time stamps),
    then its messages are appended. So memory is one block's, whatever the voyage's length. The blocks
    are independent in their sensor errors (biases restart at each block's turn-on values): a voyage
    made of legs, which is what the benchmark needs (linearity and bounded memory), not a navigation
    truth.
    """
    from spooflens.bench.voyage import write_blocks

    return write_blocks(Path(path), hours, block_h)


def first_run(log: str, cold_cache: bool, ahead_of_time: bool = True) -> dict[str, Any]:
    """Wall time of `spooflens analyze LOG` in a new process; with `cold_cache`, numba's cache is an empty
    directory and the kernels compiled ahead of time are not used (every kernel compiled, as on a machine
    where nothing precompiled them); without `ahead_of_time`, only numba's cache is used."""
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ)
        if cold_cache:
            env["NUMBA_CACHE_DIR"] = str(Path(tmp, "numba"))
        if cold_cache or not ahead_of_time:
            env[aot.ENV] = "0"
        cmd = [sys.executable, "-m", "spooflens.cli", "analyze", log, "-o", str(Path(tmp, "x.rrd")), "--quiet"]
        t0 = time.perf_counter()
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False, cwd=tmp)
        wall = time.perf_counter() - t0
    return {"wall_s": wall, "exit": done.returncode, "verdict": done.stdout.strip()[-120:]}


def first_run_parts(log: str, out_dir: str) -> dict[str, Any]:
    """Where a first run's time goes, in one new process: the imports `analyze` makes, reading, the
    analysis (a kernel not compiled ahead of time imports numba and loads it from numba's cache at its
    first call) and the recording; then the same analysis and recording again in that process, which
    load nothing. The process's own start is not counted."""
    stages = _Stages()
    stages.start("imports of spooflens analyze")
    from spooflens.output.early_recording import EarlyRecording
    from spooflens.pipeline.registry import AnalyzeOptions
    from spooflens.pipeline.run import analyze_segments
    from spooflens.service import read_table, recording_side_work, write_outputs
    from spooflens.threads import side_work

    stages.start("read")
    table = read_table(Path(log), {}, False)
    verdicts = []
    numba_imported = False
    out = Path(out_dir)
    for k, when in enumerate(("first", "again, same process")):
        stages.start(f"analysis ({when})")
        recording = EarlyRecording(out / f"parts{k}.rrd")
        with side_work(recording_side_work(table, recording)):
            analyses = analyze_segments(table, AnalyzeOptions())
        if k == 0:
            numba_imported = "numba" in sys.modules
        stages.start("recording + JSON" + (" (again)" if k else ""))
        write_outputs(analyses, out / f"parts{k}.rrd", out / f"parts{k}.json", None, recording)
        verdicts.append([a.verdict.headline for a in analyses])
    stages.stop()
    return {"stages": stages.rows, "verdicts": verdicts, "numba_imported": numba_imported}


def _first_runs(
    log: Path,
    label: str,
    repeat: int,
    ahead_of_time: bool = True,
    table: Table | None = None,
    drawn: list[tuple[str, list[float]]] | None = None,
) -> Table:
    """`repeat` first runs of `spooflens analyze LOG` (kernels as installed), the median beside the goal,
    as a row of `table` (a new one by default); their wall times appended to `drawn` under `label`."""
    err_console.print(f"first run of `spooflens analyze` on {log.name} ({label}) ...")
    runs = [first_run(str(log), cold_cache=False, ahead_of_time=ahead_of_time) for _ in range(repeat)]
    if drawn is not None:
        drawn.append((label, [float(r["wall_s"]) for r in runs]))
    median = _median_run(runs)
    t = table or Table(f"first run of spooflens analyze {log.name}", "wall (s)", "goal", "")
    t.add_row(
        label + (f", median of {repeat}" if repeat > 1 else ""),
        f"{median['wall_s']:.1f}" + _spread(runs),
        f"< {GOALS['first_run_s']:g}",
        _met(median["wall_s"], GOALS["first_run_s"]),
    )
    return t


def _ensure(path: Path, make: str, *args: Any) -> None:
    if not path.exists():
        err_console.print(f"making {path} ...")
        try:
            measure_in_child(__name__, make, str(path), *args)
        except subprocess.CalledProcessError as err:
            path.unlink(missing_ok=True)
            last = (err.stderr.strip().splitlines() or ["no output"])[-1]
            raise click.ClickException(f"making {path} failed: {last}") from err


def _median_run(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The run of median wall time (the lower middle one of an even count)."""
    return sorted(runs, key=lambda r: float(r["wall_s"]))[(len(runs) - 1) // 2]


def _spread(runs: list[dict[str, Any]]) -> str:
    walls = [float(r["wall_s"]) for r in runs]
    return f" ({min(walls):.2f}-{max(walls):.2f})" if len(walls) > 1 else ""


def _stage_table(title: str, rows: list[dict[str, Any]]) -> Table:
    t = Table("stage", "wall (s)", "CPU (s)", "peak RSS after (MB)", title=title)
    for r in rows:
        t.add_row(r["stage"], f"{r['wall_s']:.2f}", f"{r['cpu_s']:.2f}", f"{r['peak_rss_mb']:.0f}")
    return t


def _met(value: float, goal: float) -> str:
    return "met" if value <= goal else "MISSED"


@click.command("e2e")
@click.option("--workdir", type=click.Path(path_type=Path), default=Path("bench_data"), show_default=True)
@click.option("--hours", default="1,4,24", show_default=True, help="Voyage lengths to analyse (comma separated).")
@click.option("--skip-voyage", is_flag=True, help="Only the 1 h aircraft log and the first run.")
@click.option("--profile", "profile_file", type=click.Path(path_type=Path), default=None, help="cProfile text here.")
@click.option(
    "--spoofed",
    is_flag=True,
    help="Also the same hour with GNSS dragged 2 m/s from 30 min (incident confirmation and second pass timed).",
)
@click.option(
    "--repeat",
    default=1,
    show_default=True,
    type=click.IntRange(1, 20),
    help="Analyse the clean hour and make the first run this many times each: the median and the spread.",
)
@click.option(
    "--memory-limit-mb",
    default=12000.0,
    show_default=True,
    help="A voyage analysis that needs more memory stops (MemoryError) instead of pressing on the machine.",
)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(path_type=Path),
    default=None,
    help="Draw the figures here (.svg, .png, .pdf): the hour by stage, the voyage against its length, the first runs.",
)
def command(
    workdir: Path,
    hours: str,
    skip_voyage: bool,
    profile_file: Path | None,
    spoofed: bool,
    repeat: int,
    memory_limit_mb: float,
    plot_path: Path | None,
) -> int:
    """The 1 h aircraft log end to end (stages, peak RSS, vs rosbags), a voyage at 1/4/24 h, the first run."""
    workdir.mkdir(parents=True, exist_ok=True)
    out = console()
    out.print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} (shared: wall > CPU when busy)")
    hour = workdir / "aircraft_1h.mcap"
    _ensure(hour, "write_aircraft_hour")
    runs = []
    for k in range(repeat):
        with tempfile.TemporaryDirectory() as tmp:
            err_console.print(f"analysing the 1 h aircraft log end to end ({k + 1} of {repeat}) ...")
            runs.append(measure_in_child(__name__, "analyse_end_to_end", str(hour), tmp))
    e2e = _median_run(runs)
    loop = measure_in_child(__name__, "rosbags_loop", str(hour))
    r = e2e["result"]
    drawn = E2EFigures(
        hour_stages=[(s["stage"], float(s["wall_s"])) for s in r["stages"]],
        hour_wall_s=float(e2e["wall_s"]),
        hour_goal_s=GOALS["e2e_s"],
        hour_goal_by_loop_s=GOAL_E2E_BY_LOOP * float(loop["result"]["cpu_s"]),
        voyage_rss_goal_mb=GOALS["voyage_rss_mb"],
        first_run_goal_s=GOALS["first_run_s"],
    )
    out.print(
        _stage_table(f"1 h aircraft log ({r['imu_samples']} IMU, {r['gnss_epochs']} GNSS): {r['verdict']}", r["stages"])
    )
    read = next(s for s in r["stages"] if s["stage"] == "read")
    rows = [
        (
            "end to end wall (s)" + (f", median of {repeat}" if repeat > 1 else ""),
            f"{e2e['wall_s']:.2f}" + _spread(runs),
            f"<= {GOALS['e2e_s']:g}",
            _met(e2e["wall_s"], GOALS["e2e_s"]),
        ),
        ("end to end CPU (s)", f"{r['cpu_s']:.2f}", "", ""),
        (
            "peak RSS (MB)",
            f"{e2e['peak_rss_mb']:.0f}",
            f"<= {GOALS['e2e_rss_mb']:g}",
            _met(e2e["peak_rss_mb"], GOALS["e2e_rss_mb"]),
        ),
        ("reading wall (s)", f"{read['wall_s']:.2f}", f"<= {GOALS['read_s']:g}", _met(read["wall_s"], GOALS["read_s"])),
        ("reading CPU (s)", f"{read['cpu_s']:.2f}", f"<= {GOALS['read_s']:g}", _met(read["cpu_s"], GOALS["read_s"])),
        ("rosbags deserialise loop wall / CPU (s)", f"{loop['wall_s']:.2f} / {loop['result']['cpu_s']:.2f}", "", ""),
        (
            "reading / rosbags loop (CPU)",
            f"{read['cpu_s'] / loop['result']['cpu_s']:.2f}",
            "<= 1",
            _met(read["cpu_s"] / loop["result"]["cpu_s"], 1.0),
        ),
        (
            "end to end wall / rosbags loop CPU",
            f"{e2e['wall_s'] / loop['result']['cpu_s']:.2f}",
            f"<= {GOAL_E2E_BY_LOOP:.2f}",
            _met(e2e["wall_s"] / loop["result"]["cpu_s"], GOAL_E2E_BY_LOOP),
        ),
        ("recording size (MB)", f"{r['rrd_mb']:.1f}", "", ""),
    ]
    t = Table("figure", "value", "goal", "", title="1 h aircraft log: figures beside their goals")
    for row in rows:
        t.add_row(*row)
    out.print(t)
    if spoofed:
        ramp = workdir / "aircraft_1h_ramp.mcap"
        _ensure(ramp, "write_aircraft_hour", "ramp:rate=2,axes=en,start=1800")
        with tempfile.TemporaryDirectory() as tmp:
            err_console.print("analysing the spoofed 1 h aircraft log end to end ...")
            run = measure_in_child(__name__, "analyse_end_to_end", str(ramp), tmp)
        rs = run["result"]
        title = f"1 h aircraft log, ramp from 30 min: {rs['verdict']} ({rs['passes']} passes)"
        out.print(_stage_table(title, rs["stages"]))
        out.print(
            f"end to end {run['wall_s']:.1f} s wall, {rs['cpu_s']:.1f} s CPU, peak RSS {run['peak_rss_mb']:.0f} MB"
        )
    if profile_file is not None:
        err_console.print(f"profiling the analysis into {profile_file} ...")
        prof = measure_in_child(__name__, "profile_analysis", str(hour), str(profile_file))
        held = Table("array", "MB", title="what the navigation product and the table hold (largest first)")
        for k, v in list(prof["result"]["held_mb"].items())[:25]:
            held.add_row(k, f"{v:.0f}")
        out.print(held)
    if not skip_voyage:
        drawn.voyage = _voyage(workdir, [float(h) for h in hours.split(",") if h.strip()], memory_limit_mb)
    firsts = drawn.first_runs
    t = _first_runs(SAMPLE, "kernels as installed (compiled ahead of time at install)", repeat, drawn=firsts)
    _first_runs(SAMPLE, "numba's cache only (SPOOFLENS_AOT=0)", repeat, ahead_of_time=False, table=t, drawn=firsts)
    cold = first_run(str(SAMPLE), cold_cache=True)
    firsts.append((COLD_FIRST_RUN, [float(cold["wall_s"])]))
    t.add_row(COLD_FIRST_RUN, f"{cold['wall_s']:.1f}", "", "")
    out.print(t)
    with tempfile.TemporaryDirectory() as tmp:
        parts = measure_in_child(__name__, "first_run_parts", str(SAMPLE), tmp)
    numba = "numba imported" if parts["result"]["numba_imported"] else "numba never imported"
    title = f"first run of spooflens analyze {SAMPLE.name}, by part (one process; its start not counted; {numba})"
    out.print(_stage_table(title, parts["result"]["stages"]))
    gnss_log = workdir / "ship_gnss_only_10min.mcap"
    _ensure(gnss_log, "write_gnss_only")
    out.print(_first_runs(gnss_log, "no IMU: no compiled kernel runs, numba is not imported", repeat, drawn=firsts))
    if plot_path is not None:
        plot_e2e(drawn, plot_path)
        out.print(f"plot: {plot_path}")
    return 0


def _voyage(workdir: Path, hours: list[float], limit_mb: float) -> list[tuple[float, float, float, float]]:
    """Analyse a voyage of each length; returns (hours, wall s, CPU s, peak RSS MB) of those that ran."""
    out = console()
    done: list[tuple[float, float, float, float]] = []
    out.print("Ship voyage, 100 Hz IMU, 1 Hz GNSS (a line per length as it is done):")
    out.print("  length  IMU samples  wall (s)  CPU (s)  CPU per hour (s)  peak RSS (MB)  goal < 2048 MB")
    longest: dict[str, Any] | None = None
    for h in hours:
        path = workdir / f"ship_{h:g}h.mcap"
        _ensure(path, "write_voyage", h)
        err_console.print(f"analysing the {h:g} h voyage ...")
        with tempfile.TemporaryDirectory() as tmp:
            try:
                run = measure_in_child(__name__, "analyse_end_to_end", str(path), tmp, memory_limit_mb=limit_mb)
            except subprocess.CalledProcessError as err:
                last = (err.stderr.strip().splitlines() or ["no output"])[-1][:100]
                out.print(f"  {h:>4g} h  FAILED (memory capped at {limit_mb:g} MB): {last}")
                continue
        r = run["result"]
        out.print(
            f"  {h:>4g} h  {r['imu_samples']:>11}  {run['wall_s']:>8.1f}  {r['cpu_s']:>7.1f}  {r['cpu_s'] / h:>16.1f}"
            f"  {run['peak_rss_mb']:>13.0f}  {_met(run['peak_rss_mb'], GOALS['voyage_rss_mb'])}  ({r['verdict'][:60]})"
        )
        done.append((h, float(run["wall_s"]), float(r["cpu_s"]), float(run["peak_rss_mb"])))
        if h == max(hours):
            longest = r
    if longest is not None:  # where the longest voyage's time and memory go
        out.print(_stage_table(f"the {max(hours):g} h voyage by stage", longest["stages"]))
    return done
