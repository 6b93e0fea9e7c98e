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
ENU = ("east", "north", "up")
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


def _inertial(ctx: AnalysisContext) -> list[DetectorResult]:
    """Seed 000: the GNSS/INS filter, its innovation test, GLRT, MLRT and calibrated MLRT."""
    from spooflens.detectors.base import Series, Track
    from spooflens.detectors.seed000 import Seed000Options, detect, reconstructed_track
    from spooflens.navigation.imu_models import grade
    from spooflens.navigation.loosely_coupled import FilterOptions, run_filter
    from spooflens.navigation.smoother import smooth

    imu_grade = grade(ctx.options.imu_grade or "consumer_mems")
    sol = run_filter(ctx.table, ctx.options.imu_id, ctx.options.receiver_id, FilterOptions(grade=imu_grade))
    sm = smooth(sol)
    settled = sol.t > sol.t[0] + 20.0
    innovation_sigma = np.where(sol.used, np.sqrt(np.abs(np.diagonal(sol.S, axis1=1, axis2=2))), np.nan)
    nav = DetectorResult(
        "navigation",
        True,
        f"INS {sol.imu_id} + GNSS {sol.receiver_id}, grade {imu_grade.name}; "
        + (sol.alignment.method if sol.alignment else "initial state given"),
        series=[
            Series("nis", sol.t, sol.nis, "chi2(dof)"),
            # INS minus GNSS with the filter's own 1-sigma: a spoofed channel walks out of its band
            Series("innovation_position", sol.t, sol.z[:, :3], "m", components=ENU),
            Series("innovation_position_sigma", sol.t, innovation_sigma[:, :3], "m", components=ENU),
            Series("innovation_velocity", sol.t, sol.z[:, 3:], "m/s", components=ENU),
            Series("innovation_velocity_sigma", sol.t, innovation_sigma[:, 3:], "m/s", components=ENU),
        ],
        tracks=[
            Track(
                "ins_smoothed",
                sm.track_t,
                np.degrees(sm.track_llh[:, 0]),
                np.degrees(sm.track_llh[:, 1]),
                sm.track_llh[:, 2],
            )
        ],
        extras={
            "nis_mean": float(np.nanmean(sol.nis[settled])) if settled.any() else None,
            "nis_p95": float(np.nanpercentile(sol.nis[settled], 95)) if settled.any() else None,
            "nis_dof_mean": float(np.mean(sol.dof[settled])) if settled.any() else None,
            "imu_grade": imu_grade.name,
            "epochs": len(sol.t),
        },
    )
    results = detect(sol.error_model(), Seed000Options())
    incidents = [a for r in results if r.name == "mlrt_calibrated" for a in r.alarms]
    if incidents:
        first = incidents[0]
        onset = first.onset_s if first.onset_s is not None else first.start_s
        end = None if first.end_s >= sol.t[-1] - 1e-6 else first.end_s
        earlier: list[DetectorResult] = ctx.cache.get("results", [])  # type: ignore[assignment]
        velocity_honest = any(r.name == "gnss_consistency" and any(a.end_s >= onset for a in r.alarms) for r in earlier)
        nav.tracks.append(reconstructed_track(ctx.table, sol, onset, end, velocity_honest))
    return [nav, *results]


ANALYSES: list[AnalysisSpec] = [
    AnalysisSpec(
        "gnss_consistency",
        "GNSS-only: position change against reported velocity (or kinematic plausibility without velocity)",
        ("fixes",),
        _gnss_consistency,
    ),
    AnalysisSpec(
        "inertial",
        "seed 000: GNSS/INS filter; KF innovation test, GLRT, MLRT and calibrated MLRT on a position ramp",
        ("fixes", "imu"),
        _inertial,
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
        ctx.cache["results"] = results
    return results
