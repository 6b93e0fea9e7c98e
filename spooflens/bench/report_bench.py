"""Report benchmark: the operator report of a one-hour log, its size and the time to write it.

`spooflens bench report` simulates an hour of the aircraft scenario (200 Hz IMU, 10 Hz GNSS; not
timed), drags its GNSS away with a 2 m/s ramp from 30 min on, analyses it (timed, for scale) and writes
the report (timed): the figures quoted in the README. Goal: under ~5 MB. Series are decimated for
display only; the analysis ran on every sample.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import click
from rich.table import Table

from spooflens.output.console import console, err_console

GOAL_MB = 5.0


def run_report_bench(duration_s: float = 3600.0, imu_hz: float = 200.0, gnss_hz: float = 10.0) -> dict[str, Any]:
    from spooflens.attacks import apply_attack, parse_attack
    from spooflens.output.report import build_plots, render_report
    from spooflens.pipeline.run import analyze_table
    from spooflens.simulation.simulate import SCENARIOS, simulate

    sc = replace(SCENARIOS["aircraft"], imu_hz=imu_hz, gnss_hz=gnss_hz)
    sim = simulate(sc, seed=3, duration_s=duration_s)
    table, _ = apply_attack(sim.table, parse_attack(f"ramp:rate=2,axes=en,start={duration_s / 2:g}"))
    t0 = time.perf_counter()
    analysis = analyze_table(table)
    t1 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        table.source = Path(tmp, "bench.mcap")
        table.source.write_bytes(b"bench")  # the report hashes its input: a stand-in file
        html = render_report(analysis)
        t2 = time.perf_counter()
        plots = build_plots(analysis)
    largest = max(plots, key=lambda p: len(p.svg))
    return {
        "imu_samples": len(table.imu),
        "gnss_epochs": len(table.fixes),
        "verdict": analysis.verdict.headline,
        "analysis_s": t1 - t0,
        "report_s": t2 - t1,
        "report_mb": len(html.encode()) / 1e6,
        "plots": len(plots),
        "largest_plot": f"{largest.key} ({len(largest.svg) / 1e3:.0f} kB)",
    }


def _plotly_bundle_mb() -> str:
    """Plotly's offline bundle, for comparison, if plotly happens to be installed (it is not a dependency)."""
    try:
        import plotly.offline  # type: ignore[import-not-found]
    except ImportError:
        return "plotly not installed"
    return f"{len(plotly.offline.get_plotlyjs().encode()) / 1e6:.2f} MB before any data"


@click.command("report")
@click.option("--hours", type=float, default=1.0, show_default=True, help="Length of the simulated log.")
def command(hours: float) -> int:
    """Size and time of the operator report of a one-hour 200 Hz IMU / 10 Hz GNSS log (goal < 5 MB)."""
    err_console.print(f"simulating {hours:g} h of the aircraft scenario, ramp from half-way ...")
    r = run_report_bench(3600.0 * hours)
    t = Table("figure", "value", title=f"Operator report of a {hours:g} h log")
    for key in ("imu_samples", "gnss_epochs", "verdict", "analysis_s", "report_s", "report_mb", "plots"):
        v = r[key]
        t.add_row(key, f"{v:.2f}" if isinstance(v, float) else str(v))
    t.add_row("largest plot", r["largest_plot"])
    t.add_row("goal", f"report < {GOAL_MB:g} MB: {'met' if r['report_mb'] < GOAL_MB else 'NOT met'}")
    t.add_row("plotly offline HTML, for comparison", _plotly_bundle_mb())
    console().print(t)
    return 0
