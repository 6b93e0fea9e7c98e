"""Which analyses a log supports, and running them.

Each analysis declares the inputs it needs; `analyze` runs every analysis whose inputs are present
and says, for each one it could not run, exactly what was missing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from spooflens.detectors.base import DetectorResult
from spooflens.detectors.gnss_consistency import run_gnss_consistency
from spooflens.epoch_table import EpochTable
from spooflens.errors import SpooflensError

MIN_FIXES = 3
MIN_IMU_SAMPLES = 50


def _has_fixes(table: EpochTable) -> str | None:
    n = len(table.fixes)
    return None if n >= MIN_FIXES else f"GNSS fixes ({n} found, {MIN_FIXES} needed)"


def _has_imu(table: EpochTable) -> str | None:
    n = len(table.imu)
    return None if n >= MIN_IMU_SAMPLES else f"IMU samples ({n} found, {MIN_IMU_SAMPLES} needed)"


def _has_fix_velocity(table: EpochTable) -> str | None:
    v = table.fixes[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy(dtype=float)
    return None if len(v) and np.isfinite(v).all(axis=1).any() else "GNSS velocity"


def _has_observations(table: EpochTable) -> str | None:
    return None if len(table.observations) else "raw GNSS observations (pseudoranges)"


def _has_two_receivers(table: EpochTable) -> str | None:
    n = len(table.receivers())
    return None if n >= 2 else f"two GNSS receivers ({n} found)"


REQUIREMENTS: dict[str, Callable[[EpochTable], str | None]] = {
    "fixes": _has_fixes,
    "imu": _has_imu,
    "fix_velocity": _has_fix_velocity,
    "observations": _has_observations,
    "two_receivers": _has_two_receivers,
}


@dataclass
class AnalyzeOptions:
    """User choices that analyses read (CLI flags map here)."""

    imu_id: str | None = None
    receiver_id: str | None = None
    imu_grade: str | None = None
    extra: dict[str, object] = field(default_factory=dict)


@dataclass
class AnalysisContext:
    """What an analysis runs on; shared work (the navigation solution) is computed once and cached."""

    table: EpochTable
    options: AnalyzeOptions
    cache: dict[str, object] = field(default_factory=dict)

    def cached(self, key: str, make: Callable[[], object]) -> object:
        if key not in self.cache:
            self.cache[key] = make()
        return self.cache[key]


@dataclass(frozen=True)
class AnalysisSpec:
    name: str
    description: str
    needs: tuple[str, ...]
    run: Callable[[AnalysisContext], list[DetectorResult]]

    def missing(self, table: EpochTable) -> list[str]:
        return [m for need in self.needs if (m := REQUIREMENTS[need](table)) is not None]


def _gnss_consistency(ctx: AnalysisContext) -> list[DetectorResult]:
    return [run_gnss_consistency(ctx.table.fixes)]


ANALYSES: list[AnalysisSpec] = [
    AnalysisSpec(
        "gnss_consistency",
        "GNSS-only: position change against reported velocity (or kinematic plausibility without velocity)",
        ("fixes",),
        _gnss_consistency,
    ),
]


def register(spec: AnalysisSpec) -> None:
    """Add an analysis (detector packages call this at import)."""
    if any(a.name == spec.name for a in ANALYSES):
        raise ValueError(f"analysis {spec.name!r} registered twice")
    ANALYSES.append(spec)


def run_analyses(
    table: EpochTable, options: AnalyzeOptions | None = None, on_step: Callable[[str], None] | None = None
) -> list[DetectorResult]:
    """Run every analysis the table supports; the others come back as not run, with the reason."""
    ctx = AnalysisContext(table, options or AnalyzeOptions())
    results: list[DetectorResult] = []
    for spec in ANALYSES:
        missing = spec.missing(table)
        if missing:
            results.append(DetectorResult.skipped(spec.name, "needs " + ", ".join(missing)))
            continue
        if on_step:
            on_step(spec.name)
        try:
            results.extend(spec.run(ctx))
        except SpooflensError as err:
            results.append(DetectorResult.skipped(spec.name, str(err)))
    return results
