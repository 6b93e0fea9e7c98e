"""Batch benchmark: throughput of `spooflens batch` on a LocalCluster with 1 and 2 workers.

`spooflens bench batch` simulates `--logs` distinct ground-vehicle logs (100 Hz IMU, 10 Hz GNSS, ROS2
MCAP, `--seconds` each, seeds 0..N-1; made once into `--workdir`), then runs the whole batch into a
fresh results folder with 1 worker and with 2 workers. Throughput is logs per hour of the tasks' wall
time (first task submitted to last result: what adding workers changes); the whole run's wall time,
with the cluster's start and the fleet tables, is printed beside it. Goal: 2 workers >= 1.8 x 1 worker.
On a machine shared with other work the second core is not free: the load average is printed, and the
mean time each log took inside its task (equal for 1 and 2 workers when the cores are free; longer
with 2 workers when they compete for the CPU with other work). Beside it, the machine's own ceiling: the
same compute loop (small matrix products) in two processes at once against one alone (`core_scaling`: 2.0 on two
cores that share nothing; virtual cores that share a physical one, or its caches, give less, and no
batch of independent tasks can beat it).
"""

from __future__ import annotations

import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import click
import numpy as np
from rich.table import Table

from spooflens.output.console import console, err_console

GOAL_SPEEDUP = 1.8


def make_logs(workdir: Path, n: int, seconds: float) -> list[Path]:
    from spooflens.simulation.simulate import simulate
    from spooflens.writers import write_log

    out = []
    for seed in range(n):
        path = workdir / f"ground_{seconds:g}s_seed{seed}.mcap"
        if not path.exists():
            write_log(simulate("ground", seed=seed, duration_s=seconds).table, path, "mcap-ros2")
        out.append(path)
    return out


def _spin(steps: int) -> tuple[float, float]:
    """(start, end) on the system's monotonic clock of a compute-bound loop of small matrix products."""
    a = np.random.default_rng(0).random((15, 15))
    start = time.perf_counter()
    for _ in range(steps):
        a = a @ a
        a /= np.abs(a).max()
    return start, time.perf_counter()


def core_scaling(steps: int = 100_000) -> float:
    """Work done per second by two processes running the same loop at once, over one alone (the machine's
    ceiling for 2 workers). The clock is the system's monotonic one, so the two processes' spans compare;
    a late start only lowers the figure."""
    with ProcessPoolExecutor(2, mp_context=get_context("spawn")) as pool:
        list(pool.map(_spin, (1_000, 1_000)))  # both processes up before anything is timed
        start, end = pool.submit(_spin, steps).result()
        alone = end - start
        spans = list(pool.map(_spin, (steps, steps)))
    together = max(e for _, e in spans) - min(s for s, _ in spans)
    return 2.0 * alone / together


@click.command("batch")
@click.option("--logs", "n_logs", default=8, show_default=True, help="Number of logs.")
@click.option("--seconds", default=120.0, show_default=True, help="Length of each simulated log.")
@click.option("--workdir", type=click.Path(path_type=Path), default=Path("bench_data"), show_default=True)
def command(n_logs: int, seconds: float, workdir: Path) -> int:
    """Throughput of `spooflens batch` with 1 and 2 LocalCluster workers (goal: >= 1.8x)."""
    from spooflens.batch import run_batch

    folder = workdir / "batch_logs"
    folder.mkdir(parents=True, exist_ok=True)
    with err_console.status(f"simulating {n_logs} logs of {seconds:g} s ..."):
        logs = make_logs(folder, n_logs, seconds)
    runs = {}
    for workers in (1, 2):
        err_console.print(f"batch of {len(logs)} logs on {workers} worker(s) ...")
        load = os.getloadavg()[0]
        with tempfile.TemporaryDirectory() as tmp:
            r = run_batch(tuple(str(p) for p in logs), Path(tmp) / "results", workers=workers)
        failed = [a for a in r.analysed if a["status"] == "failed"]
        if failed:
            raise click.ClickException(f"{len(failed)} log(s) failed: {failed[0]['error']}")
        runs[workers] = (r, load)
    t = Table(
        "workers",
        "tasks wall (s)",
        "logs/h",
        "whole run (s)",
        "each log in its task (s, mean)",
        "load before",
        title=f"{len(logs)} logs",
    )
    for workers, (r, load) in runs.items():
        inside = float(np.mean([a["seconds"] for a in r.analysed]))
        t.add_row(
            str(workers),
            f"{r.tasks_s:.1f}",
            f"{len(logs) / r.tasks_s * 3600:.0f}",
            f"{r.wall_s:.1f}",
            f"{inside:.2f}",
            f"{load:.1f}",
        )
    console().print(t)
    speedup = runs[1][0].tasks_s / runs[2][0].tasks_s
    verdict = "met" if speedup >= GOAL_SPEEDUP else "MISSED"
    with err_console.status("measuring what two processes at once get from this machine ..."):
        ceiling = core_scaling()
    click.echo(
        f"throughput 2 workers / 1 worker = {speedup:.2f} (goal >= {GOAL_SPEEDUP}: {verdict}; {os.cpu_count()} cores)"
    )
    click.echo(
        f"this machine's ceiling: a compute loop in 2 processes at once does {ceiling:.2f} x the work of one alone "
        f"(2.00 on free cores); the batch reaches {speedup / ceiling:.0%} of it"
    )
    return 0
