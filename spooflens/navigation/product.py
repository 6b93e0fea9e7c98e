"""The navigation solution as an analysis product: computed once per analysis, used by every detector
that compares GNSS with the inertial sensors, and drawn in the recording (not itself a detector).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spooflens.analysis import AnalysisContext, AnalysisSpec, AnalyzeOptions, DetectorInfo
from spooflens.detectors.base import DetectorResult, Series, Track
from spooflens.epoch_table import EpochTable
from spooflens.navigation.imu_models import grade
from spooflens.navigation.loosely_coupled import FilterOptions, NavSolution, run_filter
from spooflens.navigation.smoother import SmoothedSolution, smooth
from spooflens.statespace import LinearGaussianModel

ENU = ("east", "north", "up")


@dataclass(frozen=True)
class Navigation:
    solution: NavSolution
    smoothed: SmoothedSolution
    model: LinearGaussianModel  # the linearised error model the model-based detectors run on


def solve_navigation(table: EpochTable, options: AnalyzeOptions) -> Navigation:
    imu_grade = grade(options.imu_grade or "consumer_mems")
    sol = run_filter(table, options.imu_id, options.receiver_id, FilterOptions(grade=imu_grade))
    return Navigation(sol, smooth(sol), sol.error_model())


def _run(ctx: AnalysisContext) -> list[DetectorResult]:
    nav = ctx.navigation()
    sol, sm = nav.solution, nav.smoothed
    settled = sol.t > sol.t[0] + 20.0
    sigma = np.where(sol.used, np.sqrt(np.abs(np.diagonal(sol.S, axis1=1, axis2=2))), np.nan)
    return [
        DetectorResult(
            "navigation",
            True,
            f"INS {sol.imu_id} + GNSS {sol.receiver_id}, grade {sol.grade.name}; "
            + (sol.alignment.method if sol.alignment else "initial state given"),
            series=[
                Series("nis", sol.t, sol.nis, "chi2(dof)"),
                # INS minus GNSS with the filter's own 1-sigma: a spoofed channel walks out of its band
                Series("innovation_position", sol.t, sol.nu[:, :3], "m", components=ENU),
                Series("innovation_position_sigma", sol.t, sigma[:, :3], "m", components=ENU),
                Series("innovation_velocity", sol.t, sol.nu[:, 3:6], "m/s", components=ENU),
                Series("innovation_velocity_sigma", sol.t, sigma[:, 3:6], "m/s", components=ENU),
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
                "imu_grade": sol.grade.name,
                "epochs": len(sol.t),
            },
        )
    ]


ANALYSIS = AnalysisSpec(
    "navigation",
    "GNSS/INS filter and smoother: the inertial reference the inertial detectors compare GNSS with",
    ("fixes", "imu"),
    _run,
    (DetectorInfo("navigation", None, "the GNSS/INS solution, its innovations and the smoothed track"),),
)
