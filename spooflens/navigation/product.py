"""The navigation solution as an analysis product: computed once per analysis, used by every detector
that compares GNSS with the inertial sensors, and drawn in the recording (not itself a detector).
"""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from spooflens.baseline.loaded import LoadedBaseline
from spooflens.baseline.use import coast_envelope_limit, noise_prior
from spooflens.detectors.base import SIGMA_SUFFIX, DetectorResult, Series, Track
from spooflens.epoch_table import EpochTable
from spooflens.errors import AnalysisError
from spooflens.estimation.statespace import LinearGaussianModel
from spooflens.navigation.alignment import Alignment, heading_from_course
from spooflens.navigation.imu_models import ImuGrade, grade
from spooflens.navigation.loosely_coupled import (
    ANALYSIS_NEEDS,
    FILTER_SETTLE_S,
    FilterInputs,
    FilterOptions,
    NavSolution,
    initial_state,
    prepare,
    run_prepared,
)
from spooflens.navigation.noise_learning import LearnedNoise, estimate_mount, learn_noise
from spooflens.navigation.smoother import SmoothedSolution, check_smoothable, smooth
from spooflens.navigation.strapdown import NavState
from spooflens.pipeline.preconditions import NOISE_LEARNING, STRAPDOWN_IMU
from spooflens.pipeline.registry import (
    AnalysisContext,
    AnalysisSpec,
    AnalyzeOptions,
    DetectorInfo,
    Later,
    navigation_parts,
)
from spooflens.threads import core_idle, started

NAVIGATION = "navigation"  # the analysis, its result and the solution it shares with the others
SMOOTHED_TRACK = "ins_smoothed"  # the track its result draws: the smoothed GNSS/INS solution
ENU = ("east", "north", "up")
# the navigation solution keeps the updated covariance of every tenth epoch: the smoother and continued
# runs (coasts, reconstructions) make the others again from the last kept (150 MB less per hour of 10 Hz
# GNSS, 0.4 GB per day of 1 Hz)
P_UPD_EVERY = 10


@dataclass(frozen=True)
class Navigation:
    solution: NavSolution  # P_pred holds the first epoch only (ANALYSIS_NEEDS)
    # begun in the background: the detectors after the navigation read the model, only its drawn track
    # waits for the smoother (seed 000's two passes and the smoother fill both cores)
    smoothing: Future[SmoothedSolution]
    model: LinearGaussianModel  # the linearised error model the model-based detectors run on
    learned: LearnedNoise  # the sensor noise learned from this log, and how
    inputs: FilterInputs  # what every further pass of the filter reuses (reconstruction, coasting)
    start: tuple[NavState, Alignment | None]

    @property
    def smoothed(self) -> SmoothedSolution:
        return self.smoothing.result()

    def options(self, **changes: object) -> FilterOptions:
        """The filter options of this solution, with changes (e.g. GNSS excluded over an incident)."""
        return replace(self.solution.options, **changes)  # type: ignore[arg-type]


def imu_preset(options: AnalyzeOptions) -> ImuGrade:
    """The IMU noise preset the navigation starts from (`--imu-grade`, else consumer MEMS): the prior the
    log's noise learning scales."""
    return grade(options.imu_grade or "consumer_mems")


def solve_navigation(
    table: EpochTable,
    options: AnalyzeOptions,
    exclude: tuple[tuple[float, float], ...] = (),
    aligned: tuple[FilterInputs, tuple[NavState, Alignment | None]] | None = None,
) -> Navigation:
    """Align, learn the sensors' noise from the log (leaving `exclude` out), filter and smooth.
    `aligned`: the prepared inputs and the alignment of an earlier solution of the same table and
    options (a second pass), which depend on neither the noise nor `exclude`."""
    preset = imu_preset(options)
    inputs, start = aligned if aligned is not None else _aligned(table, options, preset)
    prior = None
    if options.baseline is not None:
        prior = noise_prior(options.baseline, inputs.receiver_id, inputs.imu_id, preset.name)
    learned = learn_noise(inputs, preset, start, inputs.odometry_id, exclude, prior=prior)
    opts = FilterOptions(
        grade=learned.grade,
        noise=learned.noise,
        odometry=learned.odometry,
        record=ANALYSIS_NEEDS,
        P_upd_every=P_UPD_EVERY,
        compare=False,  # only coasts are compared with the GNSS they leave out (S_all: 56 MB a day)
    )
    with core_idle():  # the whole log's filter, alone: the other core takes queued side work
        sol = run_prepared(inputs, opts, start)
    check_smoothable(sol)  # its one failure raised here, as when the smoother ran in the foreground
    smoothing = started(partial(smooth, sol, variances=False))  # compiled, without the GIL
    return Navigation(sol, smoothing, sol.error_model(), learned, inputs, start)


def _aligned(
    table: EpochTable, options: AnalyzeOptions, preset: ImuGrade
) -> tuple[FilterInputs, tuple[NavState, Alignment | None]]:
    inputs = prepare(table, options.imu_id, options.receiver_id)
    start = initial_state(inputs, FilterOptions(grade=preset))
    mount = estimate_mount(inputs, inputs.odometry_id) if inputs.odometry_id is not None else None
    if mount is not None and start[1] is not None:
        # a wheeled vehicle moves along its forward axis: its course fixes the yaw, whatever the log's
        # orientation says (magnetic yaw is often off by a frame convention or a disturbance)
        by_course = heading_from_course(start[1], inputs.fixes, mount[0])
        if by_course is not None:
            a = by_course
            start = (NavState(a.t0, a.lat0, a.lon0, a.h0, a.v0.copy(), a.C0.copy()), a)
    return inputs, start


def navigation_of(ctx: AnalysisContext) -> Navigation:
    """The GNSS/INS solution of the log's first IMU and receiver, made once per analysis and shared by
    every analysis that needs it (raises AnalysisError if it cannot run). Where the IMU stops, one per
    stretch between its gaps: `ctx` is then one of `navigation_parts`, never the whole log's."""
    if navigation_parts(ctx)[0] is not ctx:
        raise AnalysisError(
            f"{ctx.table.source}: the IMU stops, so the navigation runs on each stretch between its gaps "
            "(navigation_parts), never across them"
        )
    nav: Navigation = ctx.cached(NAVIGATION, lambda: solve_navigation(ctx.table, ctx.options))
    return nav


def navigations(ctx: AnalysisContext) -> list[tuple[AnalysisContext, Navigation]]:
    """Each part of the log the navigation ran on (`navigation_parts`: the whole log, or the stretches
    between the IMU's gaps) with its solution, where one was made."""
    return [(part, part.cache[NAVIGATION]) for part in navigation_parts(ctx) if NAVIGATION in part.cache]


def _run(ctx: AnalysisContext) -> Later:
    nav = navigation_of(ctx)
    # the smoothed track: the detectors after this one run meanwhile
    return Later(partial(_result, nav, ctx.options.baseline))


def _result(nav: Navigation, baseline: LoadedBaseline | None = None) -> list[DetectorResult]:
    sol, sm = nav.solution, nav.smoothed
    settled = sol.t > sol.t[0] + FILTER_SETTLE_S
    sigma = np.where(sol.used, np.sqrt(np.abs(np.diagonal(sol.S, axis1=1, axis2=2))), np.nan)
    extras: dict[str, object] = {
        "receiver_id": sol.receiver_id,  # the receiver whose fixes the filter took
        "nis_mean": float(np.nanmean(sol.nis[settled])) if settled.any() else None,
        "nis_p95": float(np.nanpercentile(sol.nis[settled], 95)) if settled.any() else None,
        "nis_dof_mean": float(np.mean(sol.dof[settled])) if settled.any() else None,
        "imu_grade": sol.grade.name,
        "imu_noise_scale": nav.learned.imu_scale,
        # False: the log was too short (or suspected almost throughout) to learn its noise from
        "noise_learned": nav.learned.learned,
        "epochs": len(sol.t),
        "noise_filter_runs": nav.learned.evaluations,
    }
    taken = [f"GNSS and IMU noise {nav.learned.baseline_note()}"] if nav.learned.prior else []
    cap = coast_envelope_limit(baseline, nav.inputs.receiver_id, nav.inputs.imu_id)
    taken += [cap[1]] if cap is not None else []
    if taken:
        extras["from_baseline"] = "; ".join(taken)
    return [
        DetectorResult(
            NAVIGATION,
            True,
            f"INS {sol.imu_id} + GNSS {sol.receiver_id}"
            + (f" + odometry {sol.options.odometry.odometry_id}" if sol.options.odometry else "")
            + f"; {(sol.alignment.method if sol.alignment else 'initial state given')}; {nav.learned.describe()}",
            series=[
                Series("nis", sol.t, sol.nis, "chi2(dof)"),
                # INS minus GNSS with the filter's own 1-sigma: a spoofed channel walks out of its band
                Series("innovation_position", sol.t, sol.nu[:, :3], "m", components=ENU),
                Series("innovation_position" + SIGMA_SUFFIX, sol.t, sigma[:, :3], "m", components=ENU),
                Series("innovation_velocity", sol.t, sol.nu[:, 3:6], "m/s", components=ENU),
                Series("innovation_velocity" + SIGMA_SUFFIX, sol.t, sigma[:, 3:6], "m/s", components=ENU),
            ],
            tracks=[
                Track(
                    SMOOTHED_TRACK,
                    sm.track_t,
                    np.degrees(sm.track_llh[:, 0]),
                    np.degrees(sm.track_llh[:, 1]),
                    sm.track_llh[:, 2],
                )
            ],
            extras=extras,
        )
    ]


ANALYSIS = AnalysisSpec(
    NAVIGATION,
    "GNSS/INS filter and smoother: the inertial reference the inertial detectors compare GNSS with",
    ("fixes", "imu"),
    _run,
    (
        DetectorInfo(
            NAVIGATION,
            None,
            "the GNSS/INS solution, its innovations and the smoothed track (not a detector)",
            method="Strapdown INS (local-level ENU, Earth and transport rate) in a closed-loop loosely coupled "
            "Kalman filter with seed 000's 15-state error model and nine first-order Gauss-Markov states for the "
            "receiver's position and velocity errors and the odometry's; wheel odometry (forward speed, no "
            "lateral or vertical speed) when the log has it. Alignment from the log's attitude when it agrees "
            "with gravity, else by matching the GNSS position change with the double-integrated specific force. "
            "The sensors' noise is learned from the log by maximum likelihood of the filter's own innovations "
            "(`spooflens/navigation/noise_learning.py`), never from the receiver's reported accuracy; the "
            "smoothed track is drawn, and every inertial detector compares GNSS with this solution.",
        ),
    ),
    preconditions=(STRAPDOWN_IMU, NOISE_LEARNING),
    navigated=True,
)
