"""Innovation tests of the GNSS velocity, and of position and velocity together, against the INS.

A spoofer taking a receiver over almost always moves its velocity first (the counterfeit signals'
Doppler no longer matches the vehicle's motion), and on real captures the velocity innovation is the
first and strongest sign (seed 000 tests position only). Both tests use the filter whose noise was
learned from the log, so the yardstick is the log's own clean scatter, never the receiver's reported
accuracy (which a capture inflates):

- `velocity_innovation`: NIS of the INS-minus-GNSS velocity rows against chi-square(dof) (3, or 2 when
  the log has east/north only) at P_FA 1e-5 per epoch;
- `joint_innovation`: NIS of position and velocity rows together against chi-square(dof) at 1e-5.

The position test alone is seed 000's `kf_innovation`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spooflens.detectors.base import DetectorResult, Series, alarm_intervals
from spooflens.estimation.kalman import ForwardResult
from spooflens.estimation.quantiles import chi2_isf
from spooflens.navigation.loosely_coupled import NavSolution, nis_by_pattern, quadratic_forms
from spooflens.navigation.product import navigation_of
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo

FloatArray = NDArray[np.float64]
POSITION, VELOCITY = (0, 1, 2), (3, 4, 5)


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
    settle_s: float = 20.0
    merge_gap_s: float = 5.0


def rows_nis(sol: NavSolution, rows: tuple[int, ...]) -> tuple[FloatArray, NDArray[np.int64]]:
    """NIS of the given measurement rows at every epoch they were used, and its degrees of freedom."""
    return nis_by_pattern(sol.nu, sol.S, sol.used[:, np.array(rows)], rows)


def nis_test(
    name: str, sol: NavSolution, rows: tuple[int, ...], unit_label: str, opts: InnovationTestOptions
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
        f"{unit_label} NIS vs chi2({main_dof}) threshold {thr_main:.1f} (P_FA {opts.p_false_alarm:g} per epoch), "
        "noise learned from the log",
        alarm_intervals(sol.t, np.nan_to_num(nis), alarm, opts.merge_gap_s),
        [
            Series(f"{name.split('_')[0]}_nis", sol.t, nis, f"chi2({main_dof})", thr_main),
            Series("nis_over_threshold", sol.t, ratio, "ratio", 1.0),
        ],
        evidence=Evidence.INERTIAL,
    )


def _run(ctx: AnalysisContext) -> list[DetectorResult]:
    sol = navigation_of(ctx).solution
    opts = InnovationTestOptions()
    return [
        nis_test("velocity_innovation", sol, VELOCITY, "velocity", opts),
        nis_test("joint_innovation", sol, POSITION + VELOCITY, "position and velocity", opts),
    ]


ANALYSIS = AnalysisSpec(
    "innovation_tests",
    "INS-minus-GNSS velocity, and position with velocity, innovation tests with noise learned from the log",
    ("fixes", "imu", "fix_velocity"),
    _run,
    (
        DetectorInfo(
            "velocity_innovation",
            Evidence.INERTIAL,
            "NIS of the INS-minus-GNSS velocity against chi-square(dof)",
            "The velocity innovation of the GNSS/INS filter (noise learned from the log, receiver errors as "
            "Gauss-Markov states) against chi-square(3), or (2) with east/north only, at P_FA 1e-5 per epoch: "
            "a takeover moves the receiver's Doppler velocity first.",
            "1e-5 per epoch",
        ),
        DetectorInfo(
            "joint_innovation",
            Evidence.INERTIAL,
            "NIS of position and velocity innovations together against chi-square(dof)",
            "Position and velocity innovations of the same filter together against chi-square(6) at P_FA 1e-5 "
            "per epoch: catches attacks that move both a little.",
            "1e-5 per epoch",
        ),
    ),
)
