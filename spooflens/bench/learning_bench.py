"""Noise-learning benchmark: does the search reach the likelihood's optimum, and at what cost?

`spooflens bench learning` learns the sensor noise of a few logs with the analysis's own search (two
coordinate sweeps, `LearnOptions`) and again with more sweeps, and prints for each: the filter runs, the
likelihood beside the analysis's (NLL, twice the negative log-likelihood: lower is better), the IMU
noise scale and the receiver's position wander. A log whose likelihood still improves with more sweeps
had its noise stopped where the search's reach ended (one sweep moves a parameter at most 3 x sqrt(3)
times), not at the optimum. The figures are the yardstick for a cheaper or better search: the
many-sweep likelihood in fewer runs. Changing the search changes the noise every inertial detector runs
on, so the false-alarm and detection benchmarks must be run again with it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import Any

import click
from rich.table import Table

from spooflens.bench.realworld_bench import HUSKY
from spooflens.navigation.imu_models import PRESETS
from spooflens.output.console import console, err_console

SAMPLE = Path(__file__).resolve().parents[2] / "sample_logs" / "spoofed_flight.mcap"
# simulated logs: (scenario, seconds); the learning window is the first 1,500 fixes, at least 300 s
SIMULATED = (("aircraft", 400.0), ("ship", 1600.0))


def learn_with_sweeps(table: Any, sweeps: tuple[int, ...], imu_grade: str | None = None) -> list[dict[str, Any]]:
    """The noise learned from `table` (the analysis's navigation inputs and alignment, its IMU preset
    `imu_grade`) with each number of sweeps: runs, NLL, IMU scale, wander, tau and wall time."""
    from spooflens.navigation.noise_learning import LearnOptions, learn_noise
    from spooflens.navigation.product import imu_preset, solve_navigation
    from spooflens.pipeline.registry import AnalyzeOptions

    options = AnalyzeOptions(imu_grade=imu_grade)
    nav = solve_navigation(table, options)
    preset = imu_preset(options)
    rows = []
    for n in sweeps:
        t0 = time.perf_counter()
        learned = learn_noise(
            nav.inputs, preset, nav.start, nav.inputs.odometry_id, (), replace(LearnOptions(), sweeps=n)
        )
        rows.append(
            {
                "sweeps": n,
                "runs": learned.evaluations,
                "nll": learned.neg_log_likelihood,
                "imu_scale": learned.imu_scale,
                "wander_h_m": learned.noise.gm_pos_m[0],
                "tau_s": learned.noise.tau_pos_s,
                "wall_s": time.perf_counter() - t0,
                "is_the_analysis": learned.noise == nav.learned.noise and learned.imu_scale == nav.learned.imu_scale,
            }
        )
    return rows


def _simulated(name: str, seconds: float) -> Any:
    from spooflens.simulation.simulate import simulate

    return simulate(name, seed=7, duration_s=seconds).table


def _read(path: Path) -> Any:
    from readers import read_log

    return read_log(path)


def _cases(husky: Path | None) -> list[tuple[str, Callable[[], Any]]]:
    cases: list[tuple[str, Callable[[], Any]]] = [
        (f"simulated {name}, {seconds:.0f} s", partial(_simulated, name, seconds)) for name, seconds in SIMULATED
    ]
    cases.append((f"sample {SAMPLE.name}", partial(_read, SAMPLE)))
    if husky is not None and husky.exists():
        cases.append((f"real {husky.name} (husky)", partial(_read, husky)))
    return cases


@click.command("learning")
@click.option("--sweeps", default="2,3,6", show_default=True, help="Numbers of coordinate sweeps to compare.")
@click.option(
    "--imu-grade",
    type=click.Choice(sorted(PRESETS)),
    default=None,
    help="The IMU preset the search starts from (default: as the analysis, consumer_mems).",
)
@click.option(
    "--husky",
    type=click.Path(path_type=Path),
    default=HUSKY,
    show_default=True,
    help="The real husky bag (left out when missing).",
)
def command(sweeps: str, imu_grade: str | None, husky: Path) -> int:
    """The noise learning's likelihood and runs with the analysis's search and with more sweeps."""
    counts = tuple(sorted({int(s) for s in sweeps.split(",") if s.strip()}))
    if not counts or counts[0] < 1:
        raise click.BadParameter("give positive numbers of sweeps, e.g. 2,3,6", param_hint="--sweeps")
    t = Table(
        "log",
        "sweeps",
        "filter runs",
        "NLL",
        "beside the first",
        "IMU scale",
        "wander h (m)",
        "tau (s)",
        "wall (s)",
        title="noise learning: the likelihood against the number of sweeps (the analysis uses 2), IMU preset "
        + (imu_grade or "consumer_mems"),
    )
    for name, make in _cases(husky):
        with err_console.status(f"learning the noise of {name} ..."):
            rows = learn_with_sweeps(make(), counts, imu_grade)
        for r in rows:
            t.add_row(
                name if r is rows[0] else "",
                f"{r['sweeps']}" + (" (the analysis's)" if r["sweeps"] == 2 and r["is_the_analysis"] else ""),
                str(r["runs"]),
                f"{r['nll']:.1f}",
                f"{r['nll'] - rows[0]['nll']:+.1f}",
                f"{r['imu_scale']:.3g}",
                f"{r['wander_h_m']:.3g}",
                f"{r['tau_s']:.3g}",
                f"{r['wall_s']:.1f}",
            )
    console().print(t)
    return 0
