"""Innovation tests of the GNSS velocity, and of position and velocity together, against the INS (beside
seed 000's position test, `kf_innovation`): declared in `ANALYSIS` (docs/detectors.md)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spooflens.detectors.base import DetectorResult, Series, alarm_intervals
from spooflens.estimation.kalman import ForwardResult
from spooflens.estimation.quantiles import chi2_isf
from spooflens.navigation.loosely_coupled import FILTER_SETTLE_S, NavSolution, nis_by_pattern, quadratic_forms
from spooflens.navigation.product import navigation_of
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.preconditions import INERTIAL_SPAN, NOISE_LEARNING, STRAPDOWN_IMU
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo, probability

FloatArray = NDArray[np.float64]
POSITION, VELOCITY = (0, 1, 2), (3, 4, 5)
VELOCITY_INNOVATION, JOINT_INNOVATION = "velocity_innovation", "joint_innovation"


def threshold(p_false_alarm: float = 1e-5, dof: int = 3) -> float:
    """The chi-square level of an innovation test: seed 000's 25.9 is chi2(3) at P_FA 1e-5 per epoch."""
    return float(chi2_isf(p_false_alarm, dof))


def position_nis(fwd: ForwardResult, rows: tuple[int, ...] = POSITION) -> FloatArray:
    """eps_p^T S_pp^-1 eps_p per epoch of a forward filter (seed 000's KF innovation test; NaN where the
    position was not measured)."""
    idx = np.array(rows)
    return quadratic_forms(fwd.eps[:, idx], fwd.S[:, idx][:, :, idx])


@dataclass(frozen=True)
class InnovationTestOptions:
    p_false_alarm: float = 1e-5
    settle_s: float = FILTER_SETTLE_S
    merge_gap_s: float = 5.0


def rows_nis(sol: NavSolution, rows: tuple[int, ...]) -> tuple[FloatArray, NDArray[np.int64]]:
    """NIS of the given measurement rows at every epoch they were used, and its degrees of freedom."""
    return nis_by_pattern(sol.nu, sol.S, sol.used[:, np.array(rows)], rows)


def nis_test(
    name: str, sol: NavSolution, rows: tuple[int, ...], unit_label: str, opts: InnovationTestOptions, noise: str = ""
) -> DetectorResult:
    nis, dof = rows_nis(sol, rows)
    if not (dof > 0).any():
        return DetectorResult.skipped(name, f"no epoch has {unit_label} measurements", Evidence.INERTIAL)
    threshold = np.where(dof > 0, chi2_isf(opts.p_false_alarm, np.maximum(dof, 1)), np.nan)
    ratio = nis / threshold  # one axis for every dof
    alarm = np.nan_to_num(ratio) > 1.0
    alarm &= sol.t >= sol.t[0] + opts.settle_s
    main_dof = int(np.bincount(dof[dof > 0]).argmax())
    thr_main = float(chi2_isf(opts.p_false_alarm, main_dof))
    return DetectorResult(
        name,
        True,
        f"{unit_label} NIS vs chi2({main_dof}) threshold {thr_main:.1f} (P_FA {opts.p_false_alarm:g} per epoch)"
        + (f", {noise}" if noise else ""),
        alarm_intervals(sol.t, np.nan_to_num(nis), alarm, opts.merge_gap_s),
        [
            Series(f"{name.split('_')[0]}_nis", sol.t, nis, f"chi2({main_dof})", thr_main),
            Series("nis_over_threshold", sol.t, ratio, "ratio", 1.0),
        ],
        evidence=Evidence.INERTIAL,
    )


def _run(ctx: AnalysisContext) -> list[DetectorResult]:
    nav = navigation_of(ctx)
    sol, opts = nav.solution, InnovationTestOptions()
    noise = "noise: the prior (too little clean data)" if nav.learned.is_prior else "noise learned from the log"
    return [
        nis_test(VELOCITY_INNOVATION, sol, VELOCITY, "velocity", opts, noise),
        nis_test(JOINT_INNOVATION, sol, POSITION + VELOCITY, "position and velocity", opts, noise),
    ]


_O = InnovationTestOptions()
_P = probability(_O.p_false_alarm)
_FILTER = (
    "The GNSS/INS filter of `navigation`: its noise learned from the log and the receiver's errors as "
    "Gauss-Markov states, so the yardstick is the log's own clean scatter, never the receiver's reported "
    f"accuracy (which a capture inflates). No alarm in the first {_O.settle_s:g} s while the filter settles; "
    f"alarms closer than {_O.merge_gap_s:g} s are one."
)
ANALYSIS = AnalysisSpec(
    "innovation_tests",
    "INS-minus-GNSS velocity, and position with velocity, innovation tests with noise learned from the log",
    ("fixes", "imu", "fix_velocity"),
    _run,
    (
        DetectorInfo(
            VELOCITY_INNOVATION,
            Evidence.INERTIAL,
            "NIS of the INS-minus-GNSS velocity against chi-square(dof)",
            method="The normalised innovation squared of the filter's velocity rows, against chi-square with one "
            "degree of freedom per velocity component the receiver reports (3, or 2 with east/north only). A "
            "spoofer taking a receiver over almost always moves its velocity first (the counterfeit signals' "
            "Doppler no longer matches the vehicle's motion): on real captures the velocity innovation is the "
            f"first and strongest sign, which seed 000 (position only) leaves out. {_FILTER}",
            p_false_alarm=f"{_P} per epoch",
            threshold=f"chi-square(3) at {_P}: {threshold(_O.p_false_alarm, 3):.1f} (2 dof: "
            f"{threshold(_O.p_false_alarm, 2):.1f})",
        ),
        DetectorInfo(
            JOINT_INNOVATION,
            Evidence.INERTIAL,
            "NIS of position and velocity innovations together against chi-square(dof)",
            method="The normalised innovation squared of the position and velocity rows together, against "
            f"chi-square with one degree of freedom per row measured (6 with a 3-D velocity): an attack that "
            f"moves both a little. {_FILTER}",
            p_false_alarm=f"{_P} per epoch",
            threshold=f"chi-square(6) at {_P}: {threshold(_O.p_false_alarm, 6):.1f}",
        ),
    ),
    preconditions=(STRAPDOWN_IMU, INERTIAL_SPAN, NOISE_LEARNING),
    navigated=True,
)
