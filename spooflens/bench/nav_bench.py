"""Navigation benchmark: filter + smoother over one hour of 200 Hz IMU and 10 Hz GNSS.

`spooflens bench nav` simulates the hour (not timed), then times, in a fresh process each, the
closed-loop filter and the RTS smoother (compiled kernels warmed up on a short log first, so the
figure is the steady-state cost, and the one-off compilation is reported separately). The smoother is
timed as an analysis runs it (the smoothed error and track alone) and with its variances too.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import click
from rich.table import Table

from spooflens.bench.common import measure_in_child
from spooflens.output.console import console, err_console


def _scenario(duration_s: float, imu_hz: float, gnss_hz: float):
    from spooflens.simulation.simulate import SCENARIOS

    return replace(SCENARIOS["aircraft"], imu_hz=imu_hz, gnss_hz=gnss_hz), duration_s


def filter_and_smoother(duration_s: float, imu_hz: float, gnss_hz: float) -> dict[str, float]:
    import numpy as np

    from spooflens.navigation.loosely_coupled import FilterOptions, run_filter
    from spooflens.navigation.smoother import smooth
    from spooflens.simulation.simulate import simulate

    sc, _ = _scenario(duration_s, imu_hz, gnss_hz)
    t0 = time.perf_counter()
    warm = simulate(sc, seed=0, duration_s=30.0)
    warm_sol = run_filter(warm.table, options=FilterOptions(grade=sc.imu_grade))
    smooth(warm_sol)
    smooth(warm_sol, variances=False)
    compile_s = time.perf_counter() - t0
    sim = simulate(sc, seed=1, duration_s=duration_s)
    t1 = time.perf_counter()
    sol = run_filter(sim.table, options=FilterOptions(grade=sc.imu_grade))
    t2 = time.perf_counter()
    smooth(sol, variances=False)
    t3 = time.perf_counter()
    smooth(sol)
    t4 = time.perf_counter()
    return {
        "imu_samples": len(sim.table.imu),
        "gnss_epochs": len(sol.t),
        "compile_and_warmup_s": compile_s,
        "filter_s": t2 - t1,
        "smoother_s": t3 - t2,
        "smoother_with_variances_s": t4 - t3,
        "nis_mean": float(np.nanmean(sol.nis)),
    }


def run_nav_bench(duration_s: float = 3600.0, imu_hz: float = 200.0, gnss_hz: float = 10.0) -> dict[str, Any]:
    r = measure_in_child(__name__, "filter_and_smoother", duration_s, imu_hz, gnss_hz)
    out = dict(r["result"])
    out["peak_rss_mb"] = r["peak_rss_mb"]
    out["filter_plus_smoother_s"] = out["filter_s"] + out["smoother_s"]
    return out


@click.command("nav")
@click.option("--duration", default=3600.0, show_default=True, help="Seconds of flight to simulate.")
def command(duration: float) -> int:
    """Filter + smoother time and memory for 200 Hz IMU and 10 Hz GNSS (goal: one hour under 5 s)."""
    with err_console.status("simulating and running the filter and smoother..."):
        r = run_nav_bench(duration)
    t = Table("measure", "value", title=f"{duration:.0f} s: {r['imu_samples']} IMU samples, {r['gnss_epochs']} epochs")
    for key, fmt in (
        ("filter_s", "{:.2f} s"),
        ("smoother_s", "{:.2f} s (as an analysis runs it: the smoothed error and track)"),
        ("smoother_with_variances_s", "{:.2f} s (the smoothed variances too)"),
        ("filter_plus_smoother_s", "{:.2f} s"),
        ("compile_and_warmup_s", "{:.1f} s (once per machine; numba caches it)"),
        ("peak_rss_mb", "{:.0f} MB"),
        ("nis_mean", "{:.2f} (dof 6)"),
    ):
        t.add_row(key, fmt.format(r[key]))
    console().print(t)
    goal = 5.0 * duration / 3600.0
    click.echo(
        f"filter + smoother {r['filter_plus_smoother_s']:.2f} s; goal < {goal:.1f} s: "
        + ("met" if r["filter_plus_smoother_s"] < goal else "MISSED")
    )
    return 0
