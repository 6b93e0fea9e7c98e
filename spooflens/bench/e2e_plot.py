"""The figures of `spooflens bench e2e` drawn (`--plot PATH`): what a reader would rather look at than read.

Three panels: the 1 h aircraft log's wall time by stage beside the 5 s goal and the goal as a ratio to the
rosbags loop measured in the same run; the voyage's wall time, CPU and peak RSS against its length (is time
linear, is memory bounded below 2 GB?); the first runs' medians with their spread beside the 2 s goal.
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.axes import Axes


@dataclass
class E2EFigures:
    """What `bench e2e` measured, as it measured it (empty parts are not drawn)."""

    hour_stages: list[tuple[str, float]] = field(default_factory=list)  # (stage, wall s) of the median run
    hour_wall_s: float = float("nan")
    hour_goal_s: float = 5.0
    hour_goal_by_loop_s: float = float("nan")  # the goal's ratio to the rosbags loop, times this run's loop
    voyage: list[tuple[float, float, float, float]] = field(default_factory=list)  # (h, wall s, CPU s, peak MB)
    voyage_rss_goal_mb: float = 2048.0
    first_runs: list[tuple[str, list[float]]] = field(default_factory=list)  # (label, wall s of each run)
    first_run_goal_s: float = 2.0


def plot_e2e(figures: E2EFigures, path: Path) -> None:
    """Write the panels to `path` (its suffix picks the format: .svg, .png, .pdf)."""
    from matplotlib.figure import Figure

    parts = (("hour", figures.hour_stages), ("voyage", figures.voyage), ("first", figures.first_runs))
    panels = [name for name, measured in parts if measured]
    if not panels:
        raise ValueError("nothing measured to draw")
    fig = Figure(figsize=(6.5 * len(panels), 4.2), layout="constrained")
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, panel in zip(axes, panels, strict=True):
        if panel == "hour":
            _hour(ax, figures)
        elif panel == "voyage":
            _voyage(ax, figures)
        else:
            _first(ax, figures)
    fig.savefig(path)


def _hour(ax: Axes, f: E2EFigures) -> None:
    from matplotlib import colormaps

    left = 0.0
    colours = colormaps["tab20"].colors  # type: ignore[attr-defined]
    for k, (stage, wall) in enumerate(f.hour_stages):
        ax.barh(0, wall, left=left, color=colours[k % len(colours)], label=f"{stage} {wall:.2f} s")
        left += wall
    ax.axvline(f.hour_goal_s, color="k", ls="--", lw=1, label=f"goal {f.hour_goal_s:g} s")
    if math.isfinite(f.hour_goal_by_loop_s):
        by_loop = f"goal as a ratio to the rosbags loop: {f.hour_goal_by_loop_s:.2f} s"
        ax.axvline(f.hour_goal_by_loop_s, color="r", ls=":", lw=1.5, label=by_loop)
    ax.set_yticks([])
    ax.set_xlabel("wall time (s)")
    ax.set_title(f"1 h aircraft log end to end: {f.hour_wall_s:.2f} s (median run)")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.18), ncols=2, fontsize=7, frameon=False)


def _voyage(ax: Axes, f: E2EFigures) -> None:
    hours = [v[0] for v in f.voyage]
    ax.plot(hours, [v[1] for v in f.voyage], "o-", label="wall (s)")
    ax.plot(hours, [v[2] for v in f.voyage], "s-", label="CPU (s)")
    longest = max(f.voyage, key=lambda v: v[0])
    ax.plot([0, longest[0]], [0, longest[2]], color="0.6", ls=":", lw=1, label="CPU linear through the longest")
    ax.set_xlabel("voyage length (h)")
    ax.set_ylabel("time (s)")
    rss = ax.twinx()
    rss.plot(hours, [v[3] for v in f.voyage], "^--", color="#c44e52", label="peak RSS (MB)")
    rss.axhline(f.voyage_rss_goal_mb, color="#c44e52", ls=":", lw=1)
    rss.set_ylim(0, max(f.voyage_rss_goal_mb, max(v[3] for v in f.voyage)) * 1.1)
    rss.set_ylabel("peak RSS (MB); goal: below the dotted line", color="#c44e52", fontsize=8)
    lines = ax.get_legend_handles_labels()
    more = rss.get_legend_handles_labels()
    ax.legend(lines[0] + more[0], lines[1] + more[1], loc="upper left", fontsize=7)
    ax.set_title("ship voyage (100 Hz IMU, 1 Hz GNSS)")


def _first(ax: Axes, f: E2EFigures) -> None:
    labels = [textwrap.fill(label, 26) for label, _ in f.first_runs]
    for k, (_, walls) in enumerate(f.first_runs):
        ordered = sorted(walls)
        median = ordered[(len(ordered) - 1) // 2]
        ax.bar(k, median, color="#4c72b0")
        ax.vlines(k, ordered[0], ordered[-1], color="k", lw=1)
        ax.scatter([k] * len(walls), walls, s=8, color="k", zorder=3)
        label = f"{median:.2f} s"
        ax.annotate(label, (k, median), xytext=(0, 3), textcoords="offset points", ha="center", va="bottom", size=8)
    ax.axhline(f.first_run_goal_s, color="k", ls="--", lw=1, label=f"goal < {f.first_run_goal_s:g} s")
    ax.set_xticks(range(len(labels)), labels, fontsize=7)
    ax.set_ylabel("wall time (s)")
    ax.set_yscale("log")
    ax.set_ylim(top=max(max(walls) for _, walls in f.first_runs) * 3)  # room for the labels above the bars
    ax.legend(loc="upper right", fontsize=7)
    ax.set_title("first `spooflens analyze` (median; each run a dot)")
