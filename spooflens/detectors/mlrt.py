"""Seed 000's detectors on a log: the KF innovation test, GLRT, the paper's MLRT and the calibrated MLRT,
on the GNSS/INS filter's linearised error model, and the track reconstructed with the spoofed GNSS left
out. What each does, and the choices where the paper is vague (all options of `MlrtOptions`), are
declared in `ANALYSIS` (docs/detectors.md).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial

import numpy as np
from numpy.typing import NDArray

from spooflens.detectors.base import Alarm, Curve, DetectorResult, Series, Track, alarm_intervals
from spooflens.detectors.innovation_tests import position_nis, threshold
from spooflens.estimation.kalman import forward_blocks
from spooflens.estimation.marginalised_likelihood import (
    RampOffline,
    onset_posterior,
    ramp_two_filter_offline,
    step_two_filter_offline,
)
from spooflens.estimation.ramp_signature import RampPass, RampStatistics
from spooflens.estimation.statespace import LinearGaussianModel
from spooflens.navigation.loosely_coupled import FILTER_SETTLE_S
from spooflens.navigation.product import navigation_of
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.preconditions import INERTIAL_SPAN, NOISE_LEARNING, STRAPDOWN_IMU
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo, Later, probability
from spooflens.threads import both, finished, started

FloatArray = NDArray[np.float64]
POSITION_ROWS = (0, 1, 2)
KF_INNOVATION, GLRT, MLRT, MLRT_CALIBRATED = "kf_innovation", "glrt", "mlrt", "mlrt_calibrated"


@dataclass(frozen=True)
class MlrtOptions:
    kf_p_false_alarm: float = 1e-5
    glrt_p_false_alarm: float = 1e-5
    window_s: float = 30.0
    step_s: float = 1.0
    sigma_rate_mps: tuple[float, float, float] = (3.0, 3.0, 3.0)
    sigma_step_m: tuple[float, float, float] = (100.0, 100.0, 100.0)  # step prior of the onset posterior
    attacks_per_hour: float = 0.1
    posterior_alarm: float = 0.99
    settle_s: float = FILTER_SETTLE_S  # no alarms while the filter converges after its start
    max_whiteness: float = 0.5  # above it, GLRT and MLRT alarms are advisory (model does not fit the log)
    merge_gap_s: float = 5.0
    kf_threshold: float | None = None  # overrides the P_FA-derived thresholds (equal-FA benchmarks)
    glrt_threshold: float | None = None
    mlrt_threshold: float = 0.0  # the paper's rule: l > 0
    min_epochs_after_onset: int = 3  # the paper's L: candidate onsets need this many epochs after them
    offline: bool = True  # onset posterior and l_N(m) curves (skip in Monte Carlo delay runs)
    # The onset posterior uses the data up to this long after the alarm starts. A ramp pins its onset
    # within seconds; later data only bias it when the attack is not a ramp throughout (a step, a hold,
    # a meaconer): a 300 m step read with all data placed the onset 26 s early, with 5 s, 3 s.
    onset_horizon_s: float = 5.0
    # The whole-log l_N(m) curves are drawn with candidates this far apart (the two filters still run over
    # every epoch; the onset posterior near an alarm keeps every epoch): 40% of the offline pass's cost
    curve_step_s: float = 1.0


def normalised_position_innovations(eps: FloatArray, S: FloatArray) -> FloatArray:
    """(N, 3) each position innovation over its standard deviation (what `innovation_whiteness` reads)."""
    return eps[:, :3] / np.sqrt(np.maximum(np.diagonal(S, axis1=1, axis2=2)[:, :3], 1e-300))


def innovation_whiteness(
    t: FloatArray, z: FloatArray, window_s: float = 30.0, suspected: NDArray[np.bool_] | None = None
) -> float:
    """Median over `window_s` windows of the lag-1 autocorrelation of the normalised position innovations
    `z` (`normalised_position_innovations`).

    Near 0 when the model fits the log; the median over windows stays near 0 even if an attack (which
    correlates the innovations) covers a minority of the log. A real receiver and IMU the model does not
    describe (time-correlated GNSS errors, unmodelled IMU errors) show up as values near 1: then the
    sequential ramp tests are not to be trusted on this log.
    """
    edges = np.arange(t[0], t[-1] + window_s, window_s)
    bounds = np.searchsorted(t, edges)  # t increases: each window is a slice (not a mask over the log)
    values = []
    for lo, hi in itertools.pairwise(bounds):
        if suspected is not None and suspected[lo:hi].any():
            continue  # an attack correlates the innovations: the model is judged outside suspected stretches
        w = z[lo:hi]
        w = w[np.isfinite(w).all(axis=1)]
        if len(w) < 8:
            continue
        w = w - w.mean(axis=0)
        den = np.sum(w * w, axis=0)
        rho = np.sum(w[1:] * w[:-1], axis=0) / np.where(den > 0, den, np.inf)
        values.append(float(np.mean(rho)))
    return float(np.median(values)) if values else float("nan")


@dataclass(frozen=True)
class MlrtStatistics:
    t: FloatArray
    kf_nis: FloatArray
    ramp: RampStatistics
    posterior: FloatArray  # P(ramp ongoing | data so far)
    whiteness: float  # innovation_whiteness: near 0 when the model fits
    z: FloatArray  # the forward filter's normalised position innovations (for the whiteness check)


# Epochs of the forward filter's gains, S and S^-1 held at a time (a day of 1 Hz GNSS held them all:
# 0.26 GB); at least a few windows' worth, so a block's reach past its end stays a small part of it
FORWARD_BLOCK = 8192


def statistics(model: LinearGaussianModel, opts: MlrtOptions, block: int | None = None) -> MlrtStatistics:
    """The forward filter's innovations, S and gains, `block` epochs at a time (by default
    FORWARD_BLOCK, or eight windows when longer), into the KF test's NIS, the ramp statistics and the
    whiteness check: the same numbers as the filter over the whole log."""
    ramp = RampPass(
        model,
        POSITION_ROWS,
        opts.window_s,
        opts.step_s,
        np.array(opts.sigma_rate_mps),
        opts.attacks_per_hour,
        opts.min_epochs_after_onset,
    )
    N = model.n_epochs
    kf_nis, z = np.full(N, np.nan), np.full((N, 3), np.nan)
    if block is None:
        block = max(FORWARD_BLOCK, 8 * ramp.reach(1)) if N else 1  # the window in epochs near the start
    for lo, hi, fwd in forward_blocks(model, block, ramp.reach):
        ramp.add(lo, hi, fwd)
        n = hi - lo
        kf_nis[lo:hi] = position_nis(fwd)[:n]
        z[lo:hi] = normalised_position_innovations(fwd.eps[:n], fwd.S[:n])
    r = ramp.result()
    odds = np.exp(np.clip(r.log_odds, -700, 700))
    return MlrtStatistics(model.t, kf_nis, r, odds / (1.0 + odds), innovation_whiteness(model.t, z), z)


def _alarms(
    t: FloatArray, stat: FloatArray, alarm: NDArray[np.bool_], onset_idx: NDArray[np.int64] | None, opts: MlrtOptions
) -> list[Alarm]:
    alarm = alarm & (t >= t[0] + opts.settle_s)
    out = []
    for a in alarm_intervals(t, np.nan_to_num(stat, nan=-np.inf), alarm, opts.merge_gap_s):
        onset = None
        if onset_idx is not None:
            k = int(np.searchsorted(t, a.start_s))
            if onset_idx[k] >= 0:
                onset = float(t[onset_idx[k]])
        out.append(replace(a, onset_s=onset))
    return out


def detect(model: LinearGaussianModel, opts: MlrtOptions | None = None) -> list[DetectorResult]:
    """The four detectors' results (statistics, thresholds, alarms, onsets, curves)."""
    return detect_begun(model, opts)()


def detect_begun(model: LinearGaussianModel, opts: MlrtOptions | None = None) -> Callable[[], list[DetectorResult]]:
    """`detect`, begun: the offline pass over the whole log (which needs nothing of the windowed one) on
    another thread, the windowed statistics on this one; the call returned waits for the offline pass
    and makes the results. Work in between runs beside the offline pass's tail, which it would leave a
    core idle for (its backward filter is the longest single piece of the analysis)."""
    opts = opts or MlrtOptions()
    rate = np.array(opts.sigma_rate_mps)
    offline = (
        partial(ramp_two_filter_offline, model, POSITION_ROWS, rate, stride=_stride(model, opts))
        if opts.offline and model.n_epochs > 3
        else _none
    )
    pending = started(offline)
    st = statistics(model, opts)
    return partial(_results, model, opts, st, partial(finished, pending, offline))


def _results(
    model: LinearGaussianModel,
    opts: MlrtOptions,
    st: MlrtStatistics,
    offline: Callable[[], RampOffline | None],
) -> list[DetectorResult]:
    off = offline()
    t, r = st.t, st.ramp
    kf_thr = opts.kf_threshold if opts.kf_threshold is not None else threshold(opts.kf_p_false_alarm, 3)
    glrt_thr = opts.glrt_threshold if opts.glrt_threshold is not None else threshold(opts.glrt_p_false_alarm, 3)
    results = [
        DetectorResult(
            KF_INNOVATION,
            True,
            f"position NIS vs chi2(3) threshold {kf_thr:.1f}",
            _alarms(t, st.kf_nis, np.nan_to_num(st.kf_nis) > kf_thr, None, opts),
            [Series("position_nis", t, st.kf_nis, "chi2(3)", kf_thr)],
            evidence=Evidence.INERTIAL,
        ),
        DetectorResult(
            GLRT,
            True,
            f"ramp GLR over onsets within {opts.window_s:.0f} s, threshold {glrt_thr:.1f}",
            _alarms(t, r.glr, np.nan_to_num(r.glr) > glrt_thr, r.glr_onset, opts),
            [Series("glr", t, r.glr, "", glrt_thr)],
            evidence=Evidence.INERTIAL,
        ),
        DetectorResult(
            MLRT,
            True,
            "ramp MLR, flat prior of density 1 per (m/s)^3, paper's rule l > 0 "
            "(advisory: its false-alarm rate depends on units; see mlrt_calibrated)",
            _alarms(t, r.mlr, np.nan_to_num(r.mlr, nan=-np.inf) > opts.mlrt_threshold, r.mlr_onset, opts),
            [Series("l_t", t, r.mlr, "", opts.mlrt_threshold)],
            advisory=opts.mlrt_threshold == 0.0,
            evidence=Evidence.INERTIAL,
        ),
    ]
    cal = DetectorResult(
        MLRT_CALIBRATED,
        True,
        f"Bayes factor, ramp rate ~ N(0, {opts.sigma_rate_mps[0]:g} m/s) per axis, "
        f"{opts.attacks_per_hour:g} attacks/h a priori, alarm at posterior > {opts.posterior_alarm:g}",
        _alarms(t, st.posterior, st.posterior > opts.posterior_alarm, r.bf_onset, opts),
        [
            Series("posterior_attack", t, st.posterior, "probability", opts.posterior_alarm),
            Series("two_log_bf", t, r.log_bf, ""),
        ],
        evidence=Evidence.INERTIAL,
    )
    if off is not None:
        cal.alarms = [_with_onset_posterior(model, a, opts) for a in cal.alarms]
        results[2].curves.append(Curve("l_N_over_onset", off.t, off.mlr_flat, "candidate onset (s)"))
        cal.curves.append(Curve("two_log_bf_N_over_onset", off.t, off.log_bf, "candidate onset (s)"))
    results.append(cal)
    suspected = np.zeros(len(t), dtype=bool)
    for res in results:
        for al in res.alarms:
            suspected |= (t >= al.start_s - opts.window_s) & (t <= al.end_s + opts.window_s)
    whiteness = innovation_whiteness(t, st.z, suspected=suspected)
    if not np.isfinite(whiteness):  # every window suspected: judge on all of them
        whiteness = st.whiteness
    st = replace(st, whiteness=whiteness)
    if not st.whiteness <= opts.max_whiteness:  # NaN counts as not white
        note = (
            f"; MODEL MISMATCH: position innovations are not white on this log (lag-1 autocorrelation "
            f"{st.whiteness:.2f} > {opts.max_whiteness}), so this test's alarms are advisory"
        )
        for result in results[1:]:
            result.reason += note
            result.advisory = True
    for result in results:
        result.extras["innovation_whiteness"] = round(st.whiteness, 3)
    return results


def _none() -> None:
    return None


def _stride(model: LinearGaussianModel, opts: MlrtOptions) -> int:
    """Epochs between the whole-log curves' candidates (`curve_step_s` apart at the log's GNSS rate)."""
    dt = float(np.median(np.diff(model.t))) if model.n_epochs > 1 else opts.curve_step_s
    return max(1, round(opts.curve_step_s / dt)) if dt > 0 else 1


def _with_onset_posterior(model: LinearGaussianModel, a: Alarm, opts: MlrtOptions) -> Alarm:
    """MAP onset and credible interval from the data up to `onset_horizon_s` after the alarm starts."""
    last = int(np.searchsorted(model.t, min(a.end_s, a.start_s + opts.onset_horizon_s)))
    last = min(last, model.n_epochs - 1)
    lo = a.start_s - opts.window_s
    first = max(0, int(np.searchsorted(model.t, lo)) - 1)  # the candidates the posterior reads
    ramp, step = both(
        partial(ramp_two_filter_offline, model, POSITION_ROWS, np.array(opts.sigma_rate_mps), last=last, first=first),
        partial(step_two_filter_offline, model, POSITION_ROWS, np.array(opts.sigma_step_m), last=last, first=first),
    )
    # a ramp or a step, equally likely a priori: the onset's evidence is the mixture of both
    mixture = np.logaddexp(0.5 * np.nan_to_num(ramp.log_bf, nan=-np.inf), 0.5 * np.nan_to_num(step.log_bf, nan=-np.inf))
    mixture = mixture + np.log(0.5)
    log_bf = np.where(np.isfinite(ramp.log_bf) | np.isfinite(step.log_bf), 2.0 * mixture, np.nan)
    sel = (ramp.t >= lo) & (ramp.t <= model.t[last]) & np.isfinite(log_bf)
    if sel.sum() < 2:
        return a
    _, t_map, interval, _ = onset_posterior(ramp.t[sel], log_bf[sel], opts.attacks_per_hour)
    return replace(a, onset_s=t_map, onset_interval_s=interval)


def reconstructed_track(table, sol, onset_s: float, end_s: float | None, velocity_honest: bool) -> Track:
    """The INS solution with the spoofed GNSS left out from the onset to the end of the incident, smoothed
    (so GNSS after a finished attack still ties the gap down).

    Positions are always left out. The GNSS velocity is kept when the caller has evidence it stayed honest:
    the GNSS-only check saw the reported position move against the reported velocity, which is what a
    position-only spoofer (seed 000's premise) does. It keeps a consumer-grade INS from drifting away;
    without that evidence the INS coasts alone. The track's name says which was done.
    """
    from spooflens.navigation.loosely_coupled import FilterOptions, run_filter
    from spooflens.navigation.smoother import smooth
    from spooflens.navigation.strapdown import NavState

    al = sol.alignment
    initial = None if al is None else NavState(al.t0, al.lat0, al.lon0, al.h0, al.v0.copy(), al.C0.copy())
    opts = FilterOptions(
        grade=sol.grade,
        exclude_after_s=onset_s,
        exclude_until_s=end_s,
        initial=initial,
        exclude_velocity_too=not velocity_honest,
    )
    sm = smooth(run_filter(table, sol.imu_id, sol.receiver_id, opts), variances=False)
    name = (
        "reconstructed (INS + GNSS velocity, GNSS positions excluded)"
        if velocity_honest
        else "reconstructed (INS alone, GNSS excluded)"
    )
    return Track(name, sm.track_t, np.degrees(sm.track_llh[:, 0]), np.degrees(sm.track_llh[:, 1]), sm.track_llh[:, 2])


def _run(ctx: AnalysisContext) -> Later:
    return Later(detect_begun(navigation_of(ctx).model, MlrtOptions()))  # the analyses after it run meanwhile


_PAPER = "Seed 000 (MLRT for loosely coupled GNSS/INS, after Gustafsson 1996)"
_O = MlrtOptions()
_KF = threshold(_O.kf_p_false_alarm, 3)
_MODEL = (
    f"The measurement is the INS-minus-GNSS position of the GNSS/INS filter (noise learned from the log, the "
    f"receiver's errors as Gauss-Markov states: see `navigation`), attacked channels the three position rows "
    f"(the paper's ramps move position, velocity untouched). No alarm in the first {_O.settle_s:g} s while the "
    "filter settles."
)
_WHITENESS = (
    f"It assumes the filter's model fits the log: the lag-1 autocorrelation of the normalised position "
    f"innovations (median over {_O.window_s:g} s windows, leaving out the windows around the detectors' own "
    f"alarms, which an attack correlates) above {_O.max_whiteness:g} makes its alarms advisory (`MODEL "
    "MISMATCH`): drawn and listed, not counted."
)
ANALYSIS = AnalysisSpec(
    "inertial",
    "seed 000: KF innovation test, GLRT, MLRT and calibrated MLRT on a position ramp, against the GNSS/INS filter",
    ("fixes", "imu"),
    _run,
    (
        DetectorInfo(
            KF_INNOVATION,
            Evidence.INERTIAL,
            "NIS of the INS-minus-GNSS position innovation against chi-square(3)",
            f"The Kalman-filter innovation test the paper compares with: the normalised innovation squared of the "
            f"position rows. {_MODEL}",
            f"{probability(_O.kf_p_false_alarm)} per epoch",
            f"chi-square(3) at {probability(_O.kf_p_false_alarm)}: {_KF:.1f} (the paper's 25.9)",
            _PAPER,
        ),
        DetectorInfo(
            GLRT,
            Evidence.INERTIAL,
            "generalised likelihood ratio of a position ramp of unknown rate and onset",
            f"The Willsky-Jones signature of a ramp on the forward filter's innovations, its rate maximised, over "
            f"candidate onsets every {_O.step_s:g} s within the last {_O.window_s:g} s (each with at least "
            f"{_O.min_epochs_after_onset} epochs after it); onset = argmax. The paper's \"three times the "
            f"variance\" is no usable rule: the threshold is the KF test's level. {_MODEL} {_WHITENESS}",
            f"{probability(_O.glrt_p_false_alarm)} per epoch (white innovations)",
            f"{threshold(_O.glrt_p_false_alarm, 3):.1f} (chi-square(3) at {probability(_O.glrt_p_false_alarm)})",
            _PAPER,
        ),
        DetectorInfo(
            MLRT,
            Evidence.INERTIAL,
            "the paper's marginalised likelihood ratio with its rule l > 0 (advisory)",
            f"The marginalised likelihood ratio l_t(m) exactly as printed (flat prior of density 1 per (m/s)^3 on "
            f"the ramp rate, the backward information filter corrected; SEEDS.md), over the same candidate onsets "
            f"as `glrt`; the offline l_N(m) over every onset is drawn. Its rule l > 0 depends on the units of the "
            f"prior and alarms on clean runs, so its alarms are always advisory and never make an incident. "
            f"{_MODEL} {_WHITENESS}",
            "not calibrated (alarms on clean runs)",
            "l > 0 (the paper's rule)",
            _PAPER,
        ),
        DetectorInfo(
            MLRT_CALIBRATED,
            Evidence.INERTIAL,
            "Bayes factor of a ramp with a stated prior; posterior probability of an ongoing attack",
            f"Seed 000 made a proper test: ramp rate ~ N(0, {_O.sigma_rate_mps[0]:g} m/s) per axis and "
            f"{_O.attacks_per_hour:g} attacks per hour a priori turn l into a Bayes factor; alarm when the "
            f"posterior probability of an ongoing ramp exceeds {_O.posterior_alarm:g}. Onset: the MAP and 90% "
            f"credible interval of the offline two-filter posterior over onsets, from the data up to "
            f"{_O.onset_horizon_s:g} s after the alarm starts, with a ramp or a step (prior "
            f"{_O.sigma_step_m[0]:g} m per axis) equally likely (a ramp pins its onset within seconds; later "
            f"data bias it when the attack is not a ramp throughout). {_MODEL} {_WHITENESS}",
            f"posterior {_O.posterior_alarm:g} at {_O.attacks_per_hour:g} attacks/h",
            f"posterior probability of a ramp > {_O.posterior_alarm:g}",
            _PAPER,
            "On the real husky bag the innovations are white enough for the tests to count (innovation_whiteness "
            "0.156 in tests/expected/real__ros1_husky_navsat__test1.bag.json; 0.90 when the filter took the receiver's "
            "reported accuracies and white errors, which made GLRT and MLRT advisory there); "
            "`spooflens bench mlrt` compares all four at equal false-alarm rates on simulation.",
        ),
    ),
    preconditions=(STRAPDOWN_IMU, INERTIAL_SPAN, NOISE_LEARNING),
    navigated=True,
)
