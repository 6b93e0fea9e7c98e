"""Seed 001 on a log: each satellite's pseudorange rate against an independent velocity (the INS over a
window, or a known station). The statistics are in `spooflens.detectors.statistics.pseudorange_rate`,
the references in `references`; what the detectors do is declared in `ANALYSIS` (docs/detectors.md)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np
from numpy.typing import NDArray

from spooflens.detectors.base import Alarm, DetectorResult, Finding, Series, alarm_intervals
from spooflens.detectors.references import Reference, ins_reference, station_reference
from spooflens.detectors.statistics.pseudorange_rate import (
    RateOptions,
    fit_velocity_error,
    normalised_components,
    rate_residuals,
    t_statistic,
    t_threshold,
    window_for_bias,
)
from spooflens.detectors.statistics.scales import lag1_autocorrelation, threshold
from spooflens.errors import SpooflensError
from spooflens.estimation.quantiles import t_isf
from spooflens.gnss.grid import ObservationGrid, observation_grid
from spooflens.gnss.stations import stations
from spooflens.navigation.product import navigation_of
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.preconditions import (
    CARRIER_CONTINUITY,
    INDEPENDENT_REFERENCE,
    STRAPDOWN_IMU,
    unmet_preconditions,
)
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo, probability

FloatArray = NDArray[np.float64]
ENU = ("east", "north", "up")
NAME, TTEST = "range_rate", "range_rate_ttest"


@dataclass(frozen=True)
class RangeRateOptions:
    p_false_alarm: float = 1e-5  # per epoch, both rules
    window_s: float = 5.0  # free-INS window of the inertial reference
    bias_mps: float = 0.1  # the bias the t-test window is sized for (the paper's velocity pull)
    p_detect: float = 0.9
    k_max: int = 60  # longest t-test window, epochs
    max_whiteness: float = 0.5
    tail_dof: float = 8.0  # Student-t degrees of freedom of each component's tail (module notes)
    rate: RateOptions = field(default_factory=RateOptions)


@dataclass(frozen=True)
class ReceiverStatistics:
    receiver_id: str
    reference: Reference
    t: FloatArray
    dv: FloatArray  # (E, 3) m/s
    z: FloatArray  # (E, 3) normalised
    statistic: FloatArray  # (E,) the largest |normalised component|
    sigma: FloatArray  # (3,) typical scale of each component (m/s)
    sv_id: NDArray[np.str_]
    residual: FloatArray  # (E, S) rate residual after the fit, m/s
    named: list[NDArray[np.int64]]
    delay_step: NDArray[np.bool_]
    step_m: FloatArray
    source: str
    heading_error_rad: float  # the reference-error term per m/s of velocity change over the free run


def receiver_statistics(
    ctx: AnalysisContext, receiver_id: str, ref_of: Callable[[ObservationGrid], Reference], opts: RangeRateOptions
) -> ReceiverStatistics:
    grid = observation_grid(ctx.table, receiver_id)
    ref = ref_of(grid)
    res = rate_residuals(grid, ref, ctx.table.ionosphere, opts.rate)
    fit = fit_velocity_error(res, grid.systems)
    z, sigma_ref, heading = normalised_components(fit.fit.d_enu, fit.fit.cov_unit, fit.sigma_unit, ref.dynamics_mps)
    geometric = fit.sigma_unit**2 * np.diagonal(fit.fit.cov_unit, axis1=1, axis2=2)
    sigma = np.sqrt(np.nanmedian(geometric, axis=0) + sigma_ref**2) if np.isfinite(geometric).any() else sigma_ref
    statistic = np.where(np.isfinite(z).all(axis=1), np.max(np.abs(np.nan_to_num(z)), axis=1), np.nan)
    return ReceiverStatistics(
        receiver_id,
        ref,
        grid.t_s,
        fit.fit.d_enu,
        z,
        statistic,
        sigma,
        grid.sv_id,
        fit.fit.residual,
        fit.named(),
        res.delay_step,
        res.step_m,
        res.source,
        heading,
    )


def _alarms(st: ReceiverStatistics, stat: FloatArray, alarm: NDArray[np.bool_], merge_gap_s: float) -> list[Alarm]:
    """Alarm intervals naming the satellites found at their first epoch. An alarm whose reference was
    restarted after an earlier alarm began (the INS had then seen the spoofed fixes) names none: its
    disagreement may be the reference's."""
    out: list[Alarm] = []
    for a in alarm_intervals(st.t, np.nan_to_num(stat, nan=-np.inf), alarm, merge_gap_s):
        first = int(np.searchsorted(st.t, a.start_s))
        tainted = any(st.reference.contaminated(first, b.start_s) for b in out)
        sats = () if tainted else tuple(str(s) for s in st.sv_id[st.named[first]])
        # the change happened between the last quiet epoch and the first alarmed one
        prev = np.flatnonzero(st.t < a.start_s)
        interval = (float(st.t[prev[-1]]), a.start_s) if len(prev) else None
        out.append(
            replace(a, receiver_id=st.receiver_id, satellites=sats, onset_s=a.start_s, onset_interval_s=interval)
        )
    return out


def _step_findings(st: ReceiverStatistics, alarms: list[Alarm]) -> list[Finding]:
    """Satellites whose code and carrier jumped together inside an alarm: a change of the signal's delay."""
    out = []
    for a in alarms:
        inside = (st.t >= a.start_s) & (st.t <= a.end_s)
        e, s = np.nonzero(st.delay_step & inside[:, None])
        if not len(e):
            continue
        k = e.min()
        parts = [f"{st.sv_id[j]} {st.step_m[k, j]:+.1f} m" for j in np.flatnonzero(st.delay_step[k])]
        later = int(np.sum(e > k))
        out.append(
            Finding(
                f"receiver {st.receiver_id}: code and carrier jumped together at {st.t[k]:.1f} s (a change of the "
                "signal's delay, not a cycle slip): "
                + ", ".join(parts)
                + (f"; {later} more such step(s) later in the alarm" if later else ""),
                float(st.t[k]),
                float(st.t[e.max()]),
                tuple(sorted({str(st.sv_id[j]) for j in s})),
                st.receiver_id,
            )
        )
    return out


def component_threshold(p_false_alarm: float, n_samples: int, rho: float, tail_dof: float) -> tuple[float, float]:
    """Threshold on the largest of the three normalised components: Student t with nu = min(tail_dof,
    n_eff - 1) degrees of freedom at p_false_alarm / 6 (two-sided, three components), n_eff the effective
    number of samples the scales were read from. Returns (threshold, nu)."""
    _, n_eff = threshold(p_false_alarm, n_samples, rho)
    nu = float(np.clip(n_eff - 1.0, 2.0, tail_dof))
    return t_isf(p_false_alarm / 6.0, nu), nu


def detect(stats_list: list[ReceiverStatistics], opts: RangeRateOptions) -> list[DetectorResult]:
    evidence = stats_list[0].reference.evidence
    per_sample = DetectorResult(NAME, True, evidence=evidence)
    ttest = DetectorResult(TTEST, True, evidence=evidence)
    notes, tnotes = [], []
    for st in stats_list:
        dt = float(np.nanmedian(np.diff(st.t))) if len(st.t) > 1 else 1.0
        gap = 2.5 * dt
        rho = lag1_autocorrelation(st.z)
        thr, nu = component_threshold(opts.p_false_alarm, int(np.isfinite(st.statistic).sum()), rho, opts.tail_dof)
        alarm = np.nan_to_num(st.statistic) > thr
        alarms = _alarms(st, st.statistic, alarm, gap)
        per_sample.alarms += alarms
        per_sample.findings += _step_findings(st, alarms)
        rid = st.receiver_id
        per_sample.series += [
            Series(f"{rid}/velocity_error", st.t, st.dv, "m/s", None, ENU),
            Series(f"{rid}/statistic", st.t, st.statistic, "max |z|", thr),
            Series(f"{rid}/normalised", st.t, st.z, "sigma", None, ENU),
            Series(f"{rid}/rate_residual", st.t, st.residual, "m/s", None, tuple(st.sv_id)),
        ]
        notes.append(
            f"{rid}: {st.source} rates vs {st.reference.description}; scale E/N/U "
            + "/".join(f"{s:.3g}" for s in st.sigma)
            + " m/s"
            + (
                f" + {np.degrees(st.heading_error_rad):.2f} deg x velocity change"
                if st.heading_error_rad > 1e-4
                else ""
            )
            + f", lag-1 autocorrelation {rho:.2f}, threshold |z| > {thr:.1f} (t({nu:.0f}) tails)"
        )
        # windowed t-test per component, K sized on the east and north scales (the paper's components)
        alpha = opts.p_false_alarm / 3.0  # three components tested each epoch
        K, pd = window_for_bias(opts.bias_mps, float(np.max(st.sigma[:2])), alpha, opts.p_detect, opts.k_max)
        gamma = t_threshold(alpha, K)
        T = np.stack([t_statistic(st.dv[:, i], K) for i in range(3)], axis=1)
        peak = np.nanmax(np.abs(T), axis=1, initial=0.0)
        talarms = _alarms(st, peak, peak >= gamma, gap)
        # the change may have started anywhere in the window that first rejected
        talarms = [
            replace(a, onset_interval_s=(float(st.t[max(int(np.searchsorted(st.t, a.start_s)) - K, 0)]), a.start_s))
            for a in talarms
        ]
        ttest.alarms += talarms
        ttest.series += [Series(f"{rid}/t_statistic", st.t, T, "t", gamma, ENU)]
        whiteness = rho
        tnotes.append(
            f"{rid}: K = {K} epochs for a {opts.bias_mps:g} m/s bias (P'_D {pd:.2f}), threshold |T| >= {gamma:.3g}; "
            f"lag-1 autocorrelation {whiteness:.2f}"
        )
        ttest.extras[f"{rid}/window_K"] = K
        ttest.extras[f"{rid}/lag1_autocorrelation"] = round(whiteness, 3)
        if not whiteness <= opts.max_whiteness:
            ttest.advisory = True
            tnotes[-1] += (
                f"; MODEL MISMATCH: the statistic is not independent from epoch to epoch (lag-1 autocorrelation "
                f"> {opts.max_whiteness}), so this test's alarms are advisory"
            )
        per_sample.extras[f"{rid}/scale_enu_mps"] = [round(float(s), 6) for s in st.sigma]
    per_sample.reason = f"P_FA {opts.p_false_alarm:g} per epoch; " + "; ".join(notes)
    ttest.reason = f"windowed t-test at alpha {opts.p_false_alarm:g} per epoch; " + "; ".join(tnotes)
    for r in (per_sample, ttest):
        r.alarms.sort(key=lambda a: a.start_s)
    return [per_sample, ttest]


def _skipped(reason: str) -> list[DetectorResult]:
    return [
        DetectorResult.skipped(NAME, reason, Evidence.INERTIAL),
        DetectorResult.skipped(TTEST, reason, Evidence.INERTIAL),
    ]


def run(ctx: AnalysisContext, opts: RangeRateOptions | None = None) -> list[DetectorResult]:
    opts = opts or RangeRateOptions()
    table = ctx.table
    with_obs = list(dict.fromkeys(table.observations["receiver_id"].astype(str)))
    if len(table.imu) and not unmet_preconditions((STRAPDOWN_IMU,), ctx):  # the INS first, then a station
        try:
            nav = navigation_of(ctx)
        except SpooflensError as err:
            return _skipped(f"needs the INS reference, which could not be computed: {err}")
        rid = nav.solution.receiver_id
        if rid not in with_obs:
            return _skipped(
                f"the navigation receiver {rid!r} has no raw observations (receivers with them: {with_obs})"
            )
        chosen: list[tuple[str, Callable[[ObservationGrid], Reference]]] = [
            (rid, lambda g: ins_reference(ctx, g, opts.window_s))
        ]
    else:
        found, _ = stations(table, ctx.options.extra)  # there is one: the precondition independent_reference
        chosen = [(rid, partial(station_reference, station=st)) for rid, st in found.items()]
    computed = [receiver_statistics(ctx, rid, ref, opts) for rid, ref in chosen]
    computed = [c for c in computed if np.isfinite(c.statistic).any()]
    if not computed:
        return _skipped("no epoch had enough satellites with rates and a reference to solve")
    return detect(computed, opts)


_PAPER = "Seed 001 (Chang et al. 2022, INS-aided pseudorange-rate consistency)"
_O = RangeRateOptions()
_P = probability(_O.p_false_alarm)
_REFERENCE = (
    "Measured rate: the carrier-phase difference over the epoch interval (eq. 8), cycle slips screened (the "
    "change of code minus carrier separates a slip, the carrier alone, from a change of the signal's delay, "
    "code and carrier together; with Doppler, a carrier change off the Doppler trapezoid), the Doppler "
    "trapezoid where the carrier slipped (weighed with the Doppler's own scatter about the intact carriers, "
    "not as a carrier), instantaneous Doppler or logged rates in logs without carrier; "
    f"intervals over {_O.rate.max_interval_s:g} s not used, elevations below {_O.rate.elevation_mask_deg:g} deg "
    "left out. Predicted: the rate a receiver at the reference would see from the broadcast orbit and clock "
    "(eq. 17, frame and direction errata fixed: SEEDS.md). Per epoch, weighted least squares of measured minus "
    "predicted gives dv = v_signals - v_reference (E, N, U) and a clock drift per satellite system. Reference: "
    f"with an IMU fit for strapdown, the INS restarted from the GNSS/INS state {_O.window_s:g} s before each "
    "epoch and propagated alone (evidence: inertial; an attack is seen against a clean reference for its first "
    f"{_O.window_s:g} s, alarms of later restarts name no satellites; restarts wait until the filter settled "
    "and the alignment ended, so an attack in the first minute is left to the others); else a known station, "
    "zero velocity (evidence: known station)."
)
ANALYSIS = AnalysisSpec(
    NAME,
    "seed 001: each satellite's pseudorange rate (carrier phase, Doppler) against an independent velocity "
    "(the INS over a window, or a known station)",
    ("observations", "satellite_states"),
    run,
    (
        DetectorInfo(
            NAME,
            Evidence.INERTIAL,
            "velocity the signals imply minus the reference velocity (E, N, U), per epoch",
            method=f"{_REFERENCE} The paper's per-sample rule, on each component of dv over its scale: the "
            "least-squares geometry times the robust scale of the rate residuals (the quietest quarter, refined), "
            "plus the reference's own error and a heading term growing with the velocity change over the free run, "
            "both fitted to the log by a likelihood whose terms are capped at 4 sigma (a minority of attacked "
            "epochs does not move them). The largest normalised component against a Student-t tail: the reference "
            "is the aided filter's state propagated for a few seconds, which lags whenever the dynamics change, "
            "so its errors are heavier-tailed than Gaussian; nu = min("
            f"{_O.tail_dof:g}, n_eff - 1), n_eff the effective number of samples the scales rest on, at "
            f"{_P} / 6 (two-sided, three components). The paper's own thresholds (a normal fit to "
            "the first 200 s of clean data at P_FA 0.01) suit a benchmark with a clean twin of the log, not a "
            "forensic log whose first 200 s may be attacked: `spooflens bench range_rate` applies them. Alarms "
            "name the satellites whose code and carrier jumped together, else those a residual test on the rates "
            "sets apart, else all used (they agree on a wrong velocity).",
            p_false_alarm=f"{_P} per epoch",
            threshold=f"largest |z| against t(nu) at {_P}/6, nu <= {_O.tail_dof:g}: "
            f"{float(t_isf(_O.p_false_alarm / 6.0, _O.tail_dof)):.1f} sigma at nu = {_O.tail_dof:g}",
            paper=_PAPER,
        ),
        DetectorInfo(
            TTEST,
            Evidence.INERTIAL,
            "windowed t-test of each velocity-error component (eqs. 21-26)",
            method=f"{_REFERENCE} The paper's windowed one-sample t-test of each component of dv over the last K "
            f"epochs, K from the noncentral t so that a {_O.bias_mps:g} m/s bias is seen with probability "
            f"{_O.p_detect:g} (the paper's step 4 with its inequality corrected), at most {_O.k_max} epochs; "
            f"threshold t_(1-alpha/2)(K-1) at alpha {_P} / 3 (three components). The t-test assumes "
            f"independent samples: when the statistic's lag-1 autocorrelation exceeds {_O.max_whiteness:g} (a "
            "drifting INS reference makes it smooth) its alarms are advisory.",
            p_false_alarm=f"{_P} per epoch (independent samples)",
            threshold=f"|T| >= t_(1-alpha/2)(K-1), alpha {_P}/3",
            paper=_PAPER,
        ),
    ),
    preconditions=(INDEPENDENT_REFERENCE, CARRIER_CONTINUITY),
    navigated=True,  # the INS reference: run on each stretch the navigation ran on
)
