"""Receiver self-report as evidence: what the receiver logs about itself (accuracies, satellites, DOP,
noise, AGC, C/N0, its own spoofing state; what only a jammer does is
`spooflens.detectors.interference`'s) against its own baseline in the log and the
documented normal ranges; with a vehicle's baseline (`analyze --baseline`), also against the levels of
the vehicle's clean logs (`receiver_levels`, docs/baseline.md). Declared in `ANALYSIS` (docs/detectors.md)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.baseline.format import Baseline
from spooflens.baseline.indicators import INDICATORS as SPREADS
from spooflens.baseline.use import level_scale, level_z, note
from spooflens.detectors.base import (
    Alarm,
    DetectorResult,
    Finding,
    Series,
    alarm_intervals,
    center_scale,
    onsets_after_quiet,
    robust_z,
    trailing_max,
)
from spooflens.estimation.quantiles import largest_of_k_as_normal, two_sided_as_one_sided
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo
from spooflens.schema import SpoofingFlag

FloatArray = NDArray[np.float64]
NAME = "receiver_evidence"
LEVELS = "receiver_levels"  # the level test, with a vehicle baseline only


@dataclass(frozen=True)
class Indicator:
    column: str
    label: str
    direction: int  # +1 rise is suspicious, -1 drop is, 0 any change
    floor: float  # smallest robust scale (absolute)
    relative_floor: float = 0.0  # ... or this fraction of the median, whichever is larger


INDICATORS: tuple[Indicator, ...] = (
    Indicator("h_acc_m", "reported horizontal accuracy", +1, 0.05, 0.15),
    Indicator("v_acc_m", "reported vertical accuracy", +1, 0.05, 0.15),
    Indicator("vel_acc_mps", "reported speed accuracy", +1, 0.01, 0.15),
    Indicator("sats_used", "satellites used", -1, 1.0),
    Indicator("hdop", "HDOP", +1, 0.05, 0.1),
    Indicator("vdop", "VDOP", +1, 0.05, 0.1),
    Indicator("noise_per_ms", "noise level", +1, 2.0, 0.03),
    Indicator("jamming_indicator", "jamming indicator", +1, 3.0, 0.1),
    Indicator("agc", "AGC", 0, 10.0, 0.03),
    Indicator("cn0_mean_dbhz", "mean C/N0", 0, 1.0),
)
# the way each moves under interference (a jammer): a change only that way is no spoofing evidence
INTERFERENCE_DIRECTION = {"noise_per_ms": +1, "jamming_indicator": +1, "agc": -1, "cn0_mean_dbhz": -1}
LABELS = {ind.column: ind.label for ind in INDICATORS}
# indicators that are one estimate of the receiver's, counted once towards the indicators that must agree: the
# three accuracies are read off one covariance, the two DOPs off one geometry (a fix gone bad moves all three
# accuracies, and one worse fix is not three witnesses)
ONE_ESTIMATE = {"h_acc_m": "accuracy", "v_acc_m": "accuracy", "vel_acc_mps": "accuracy", "hdop": "dop", "vdop": "dop"}


@dataclass(frozen=True)
class ReceiverEvidenceOptions:
    z_alarm: float = 6.0
    z_clip: float = 20.0
    min_indicators: int = 2
    window_s: float = 5.0
    min_duration_s: float = 1.0
    merge_gap_s: float = 10.0
    gap_factor: float = 4.0
    max_plausible_cn0_dbhz: float = 50.0
    min_reference_s: float = 20.0  # the baseline is learned from at least this long a stretch ...
    min_reference_fraction: float = 0.1  # ... and this fraction of the log
    min_changed_s: float = 10.0  # a change of state to learn around lasts this long at least
    # the level test against a baseline
    level_window_s: float = 60.0
    min_level_values: int = 10
    z_level: float = 3.0
    min_families: int = 2
    min_level_s: float = 30.0
    # ... or families together: this many or more, each at least `joint_each` the attack's way, their
    # deviates (each at most `z_level` either way) summed over sqrt(families logged) beyond `z_level`
    joint_min_families: int = 3
    joint_each: float = 1.0


def reference_epochs(t: FloatArray, fx: pd.DataFrame, opts: ReceiverEvidenceOptions) -> tuple[NDArray[np.bool_], float]:
    """The epochs the baseline is learned from, and where they end (NaN: the whole log).

    The log's own median is the baseline while the receiver's state is the same most of the time. A
    takeover that lasts to the end of a log can fill half of it or more, and then the whole-log median
    is the attack's state: the attack looks normal and the clean part odd. So the log is split where the
    receiver's directional indicators (accuracies, satellites used, DOP, noise, jamming indicator: each
    with a direction in which it gets worse) worsen most, jointly. The split is located like a CUSUM's
    change point (the second largest of the indicators' mean shifts in their bad directions, two must
    agree, weighted by sqrt(n_before n_after / n)); it counts when the shift of the medians there,
    against the median and robust scale before it, passes `z_alarm`. Then the part before it, when long
    enough to learn from, is the baseline. A receiver improving after a cold start, or AGC and C/N0
    changing at take-off (no bad direction), never moves the baseline.
    """
    everything = np.ones(len(t), dtype=bool)
    n = len(t)
    if n < 20:
        return everything, float("nan")
    first = t[0] + max(opts.min_reference_s, opts.min_reference_fraction * float(t[-1] - t[0]))
    lo, hi = int(np.searchsorted(t, first)), int(np.searchsorted(t, t[-1] - opts.min_changed_s))
    if hi <= lo:
        return everything, float("nan")
    columns = []
    for ind in INDICATORS:
        x = fx[ind.column].to_numpy(dtype=float)
        if ind.direction != 0 and np.isfinite(x).sum() >= 10 and np.nanstd(x) > 0.0:
            columns.append((ind, x))
    if len(columns) < 2:
        return everything, float("nan")
    k = np.arange(lo, hi)
    shifts = np.full((len(columns), len(k)), -np.inf)
    for i, (ind, x) in enumerate(columns):
        ok = np.isfinite(x)
        _, scale = center_scale(x, ind.floor, ind.relative_floor)
        total, count = np.cumsum(np.where(ok, x, 0.0)), np.cumsum(ok)
        nb, na = count[k - 1], count[-1] - count[k - 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            mean_b, mean_a = total[k - 1] / nb, (total[-1] - total[k - 1]) / na
        shifts[i] = np.where((nb >= 5) & (na >= 5), ind.direction * (mean_a - mean_b) / scale, -np.inf)
    joint = np.sort(shifts, axis=0)[-2]
    located = joint * np.sqrt(k * (n - k) / n)
    if not np.isfinite(located).any() or np.nanmax(located) <= 0.0:
        return everything, float("nan")
    split = int(k[np.nanargmax(located)])
    robust = []
    for ind, x in columns:
        before, after = x[:split], x[split:]
        if np.isfinite(before).sum() >= 5 and np.isfinite(after).sum() >= 5:
            med, scale = center_scale(before, ind.floor, ind.relative_floor)
            robust.append(ind.direction * (float(np.nanmedian(after)) - med) / scale)
    if len(robust) < 2 or sorted(robust)[-2] <= opts.z_alarm:
        return everything, float("nan")
    return np.arange(n) < split, float(t[split])


def _fix_gaps(t: FloatArray, factor: float) -> FloatArray:
    """Gap before each fix in median periods minus one (0 for a regular fix): a lost fix shows here."""
    if len(t) < 3:
        return np.zeros(len(t))
    dt = np.diff(t)
    period = float(np.median(dt))
    return np.r_[0.0, np.clip(dt / max(period, 1e-9) - 1.0, 0.0, None)] * (6.0 / max(factor - 1.0, 1e-9))


@dataclass
class LevelTest:
    alarms: list[Alarm]
    series: list[Series]
    findings: list[Finding]
    reason: str


def level_test(
    rid: str, t: FloatArray, fx: pd.DataFrame, baseline: Baseline, opts: ReceiverEvidenceOptions
) -> LevelTest | None:
    """Each indicator's level (median over the trailing `level_window_s`) against the vehicle's baseline
    (see the module docstring); None when the baseline has no level of this receiver's indicators."""
    index = pd.to_timedelta(t, unit="s")
    window = pd.Timedelta(seconds=opts.level_window_s)
    zs: dict[str, FloatArray] = {}
    used, left = [], []
    for ind in INDICATORS:
        q, spec = baseline.indicator(rid, ind.column), SPREADS.get(ind.column)
        if q is None or spec is None:
            continue
        if q.agree is False:
            left.append(ind.label)
            continue
        x = pd.Series(fx[ind.column].to_numpy(dtype=float), index=index)
        if x.notna().sum() < opts.min_level_values:
            continue
        rolled = x.rolling(window, min_periods=opts.min_level_values)
        med, count = rolled.median().to_numpy(dtype=float), rolled.count().to_numpy(dtype=float)
        zs[ind.column] = level_z(q, spec, med, count)
        spread = level_scale(q, spec)
        used.append(f"{ind.label} {q.centre:.4g} " + (f"x/ {np.exp(spread):.3g}" if spec.log else f"+- {spread:.2g}"))
    if not zs:
        return None
    families = sorted({SPREADS[c].family for c in zs})
    by_family = np.stack(
        [
            np.nanmax(
                np.stack([np.nan_to_num(z, nan=-np.inf) for c, z in zs.items() if SPREADS[c].family == f]), axis=0
            )
            for f in families
        ],
        axis=1,
    )
    beyond = by_family > opts.z_level
    joint = joint_level(zs, opts)
    raised = (beyond.sum(axis=1) >= opts.min_families) | (joint > opts.z_level)
    two = (
        np.sort(np.where(np.isfinite(by_family), by_family, 0.0), axis=1)[:, -opts.min_families]
        if len(families) >= opts.min_families
        else np.zeros(len(t))
    )
    score = np.fmax(two, joint)
    alarms = [
        Alarm(
            a.start_s,
            a.end_s,
            a.peak_statistic,
            a.peak_s,
            max(a.start_s - opts.level_window_s, float(t[0])),
            (max(a.start_s - opts.level_window_s, float(t[0])), a.start_s),
            rid,
        )
        for a in alarm_intervals(t, score, raised, opts.merge_gap_s)
        if a.end_s - a.start_s >= opts.min_level_s
    ]
    findings = []
    for a in alarms:
        inside = (t >= a.start_s) & (t <= a.end_s)
        moved = []
        # over a whole log the typical level says more than the peak (the takeover's transient)
        typical = {c: _median(z[inside]) for c, z in zs.items()}
        for c in sorted(typical, key=lambda c: -typical[c]):
            if typical[c] > opts.joint_each:
                q = baseline.indicator(rid, c)
                assert q is not None
                level = _median(fx[c].to_numpy(dtype=float)[inside])
                moved.append(f"{LABELS[c]} {level:.4g} (baseline {q.centre:.4g}, z {typical[c]:.1f})")
        together = np.nan_to_num(joint[inside], nan=-np.inf).max()
        how = (
            f"; {opts.joint_min_families} or more families together, joint z up to {together:.1f}"
            if together > opts.z_level
            else ""
        )
        findings.append(
            Finding(
                f"{rid}: indicator levels off the vehicle's baseline: {', '.join(moved)}{how} "
                f"({a.start_s:.1f}-{a.end_s:.1f} s)",
                a.start_s,
                a.end_s,
                receiver_id=rid,
            )
        )
    reason = f"levels against the baseline ({', '.join(used)})"
    if left:
        reason += f"; not against it where its logs disagree ({', '.join(left)})"
    series = [
        Series(f"{rid}/level_score", t, score, "level z", opts.z_level),
        Series(f"{rid}/level_joint", t, joint, "level z", opts.z_level),
    ]
    series.append(
        Series(f"{rid}/level_z", t, np.stack(list(zs.values()), axis=1), "level z", None, tuple(LABELS[c] for c in zs))
    )
    return LevelTest(alarms, series, findings, reason)


def _median(x: FloatArray) -> float:
    """The median of the values that are there (-inf when none is)."""
    x = x[~np.isnan(x)]
    return float(np.median(x)) if len(x) else float("-inf")


def family_deviates(zs: dict[str, FloatArray]) -> dict[str, FloatArray]:
    """Each family's level z as one standard normal deviate for a clean log: an indicator that may move
    either way as the one-sided deviate of its two-sided p-value, and a family's largest as the deviate of
    its p-value among the family's k (NaN where none of its indicators has a level yet). Summed, the
    largest of several and a |z| would each add more than a clean log's share."""
    members: dict[str, list[FloatArray]] = {}
    for c, z in zs.items():
        spec = SPREADS[c]
        members.setdefault(spec.family, []).append(two_sided_as_one_sided(z) if spec.direction == 0 else z)
    return {
        f: largest_of_k_as_normal(np.fmax.reduce(np.stack(zz), axis=0), len(zz)) for f, zz in sorted(members.items())
    }


def joint_level(zs: dict[str, FloatArray], opts: ReceiverEvidenceOptions) -> FloatArray:
    """The families' level deviates together (Stouffer: their sum over the square root of how many are
    logged, a standard normal deviate for a clean log whose families vary independently), where at least
    `joint_min_families` of them lie `joint_each` or more the attack's way; NaN elsewhere. A takeover moves
    every family a little (a capture's noise x1.15, AGC x0.9, C/N0 +4 dB, each two or three spreads of the
    vehicle's clean days), none far enough alone. Each family counts at most `z_level` either way, so one
    family far off (more noise from the vehicle's own electronics) is still one family, and one that moved
    the other way (C/N0 down, as a jammer or an obstructed sky moves it) counts against."""
    deviates = family_deviates(zs)
    d = np.clip(np.stack(list(deviates.values()), axis=1), -opts.z_level, opts.z_level)
    logged = (~np.isnan(d)).sum(axis=1)
    if d.shape[1] < opts.joint_min_families:
        return np.full(len(d), np.nan)
    agreeing = np.sort(np.nan_to_num(d, nan=-np.inf), axis=1)[:, -opts.joint_min_families]
    together = np.nansum(d, axis=1) / np.sqrt(np.maximum(logged, 1))
    return np.where((logged >= opts.joint_min_families) & (agreeing >= opts.joint_each), together, np.nan)


# fixes an indicator needs before its own baseline means anything
MIN_EPOCHS = 10


def check_receiver(
    rid: str, fx: pd.DataFrame, opts: ReceiverEvidenceOptions, baseline: Baseline | None = None
) -> DetectorResult | None:
    t = fx["t_s"].to_numpy(dtype=float)
    if len(t) < MIN_EPOCHS:
        return None
    z_cols: dict[str, FloatArray] = {}
    not_interference: dict[str, FloatArray] = {}  # each indicator's z the way interference does not move it
    labels: dict[str, str] = {}
    reference, reference_end = reference_epochs(t, fx, opts)
    for ind in INDICATORS:
        x = fx[ind.column].to_numpy(dtype=float)
        if np.isfinite(x).sum() < MIN_EPOCHS or (np.nanstd(x) == 0.0 and ind.column != "sats_used"):
            continue
        q = baseline.indicator(rid, ind.column) if baseline is not None else None
        floor = max(ind.floor, q.within or 0.0) if q is not None and q.agree is not False else ind.floor
        z_cols[ind.column] = np.clip(
            robust_z(x, ind.direction, floor, ind.relative_floor, reference), -opts.z_clip, opts.z_clip
        )
        jam_way = INTERFERENCE_DIRECTION.get(ind.column, 0)
        if not jam_way:
            not_interference[ind.column] = np.nan_to_num(z_cols[ind.column], nan=0.0)
        elif ind.direction == 0:  # a move either way counts: the one a jammer does not make is spoofing-like
            other_way = robust_z(x, -jam_way, floor, ind.relative_floor, reference)
            not_interference[ind.column] = np.clip(np.nan_to_num(other_way, nan=0.0), 0.0, opts.z_clip)
        else:  # it counts only the way a jammer moves it
            not_interference[ind.column] = np.zeros(len(t))
        labels[ind.column] = ind.label
    gaps = _fix_gaps(t, opts.gap_factor)
    if gaps.any():
        z_cols["fix_gap"] = np.clip(gaps, 0, opts.z_clip)
        not_interference["fix_gap"] = z_cols["fix_gap"]
        labels["fix_gap"] = "fix lost (gap)"
    flags = fx["spoofing_flag"].to_numpy()
    spoof_flag = flags == SpoofingFlag.INDICATED
    cn0 = fx["cn0_mean_dbhz"].to_numpy(dtype=float)
    too_strong = np.nan_to_num(cn0) > opts.max_plausible_cn0_dbhz
    if not z_cols and not spoof_flag.any() and not too_strong.any():
        return None
    names = list(z_cols)
    Z = np.stack([z_cols[n] for n in names], axis=1) if names else np.zeros((len(t), 0))
    Zw = np.stack([trailing_max(t, Z[:, i], opts.window_s) for i in range(Z.shape[1])], axis=1) if names else Z
    beyond = np.nan_to_num(Zw, nan=0.0) > opts.z_alarm
    # per estimate (`ONE_ESTIMATE`): its indicators' largest windowed z
    estimates = sorted({ONE_ESTIMATE.get(n, n) for n in names})
    columns = [[i for i, n in enumerate(names) if ONE_ESTIMATE.get(n, n) == e] for e in estimates]
    Ze = np.stack([np.fmax.reduce(Zw[:, c], axis=1) for c in columns], axis=1) if names else Z
    count = (np.nan_to_num(Ze, nan=0.0) > opts.z_alarm).sum(axis=1).astype(float)
    other = np.stack([trailing_max(t, not_interference[n], opts.window_s) for n in names], axis=1) if names else Z
    joint = (count >= opts.min_indicators) & ((other > opts.z_alarm).sum(axis=1) >= 1)
    # the score: the second largest windowed z of the estimates (the weaker of the two strongest agreeing)
    score = np.sort(np.nan_to_num(Ze, nan=0.0), axis=1)[:, -2] if Ze.shape[1] >= 2 else np.zeros(len(t))
    raised = joint | spoof_flag | too_strong
    alarms = [
        a
        for a in alarm_intervals(t, np.maximum(score, count), raised, opts.merge_gap_s)
        if a.end_s - a.start_s >= opts.min_duration_s or spoof_flag[(t >= a.start_s) & (t <= a.end_s)].sum() >= 2
    ]
    quiet = (count == 0) & ~spoof_flag
    result = DetectorResult(
        NAME,
        True,
        f"{rid}: {len(names)} indicator(s) against the log's own baseline"
        + (f" ({', '.join(labels[n] for n in names)})" if names else "")
        + (
            f", learned before {reference_end:.1f} s (where the receiver's indicators worsen together)"
            if np.isfinite(reference_end)
            else ""
        )
        + "; receiver flags and documented ranges",
        onsets_after_quiet(t, quiet, raised, alarms, rid),
        [
            Series(f"{rid}/joint_score", t, score, "robust z", opts.z_alarm),
            Series(f"{rid}/indicators_beyond", t, count, "count", float(opts.min_indicators)),
        ],
        evidence=Evidence.RECEIVER,
    )
    if names:
        result.series.append(Series(f"{rid}/robust_z", t, Z, "robust z", None, tuple(labels[n] for n in names)))
    for a in result.alarms:
        inside = (t >= a.start_s) & (t <= a.end_s)
        moved = [labels[n] for i, n in enumerate(names) if beyond[inside, i].any()]
        what = []
        if moved:
            what.append("indicators out of their baseline: " + ", ".join(moved))
        if spoof_flag[inside].any():
            what.append("the receiver's own spoofing flag raised")
        if too_strong[inside].any():
            what.append(f"mean C/N0 above {opts.max_plausible_cn0_dbhz:g} dB-Hz (stronger than the sky gives)")
        result.findings.append(
            Finding(f"{rid}: {'; '.join(what)} ({a.start_s:.1f}-{a.end_s:.1f} s)", a.start_s, a.end_s, receiver_id=rid)
        )
    return result


def run_receiver_evidence(
    fixes: pd.DataFrame, opts: ReceiverEvidenceOptions | None = None, baseline: Baseline | None = None
) -> DetectorResult:
    opts = opts or ReceiverEvidenceOptions()
    merged = DetectorResult(NAME, True, evidence=Evidence.RECEIVER)
    notes = []
    for rid, fx in fixes.groupby("receiver_id", sort=False):
        r = check_receiver(str(rid), fx.reset_index(drop=True), opts, baseline)
        if r is None:
            continue
        merged.alarms += r.alarms
        merged.series += r.series
        merged.findings += r.findings
        notes.append(r.reason)
    if not notes:
        most = int(fixes.groupby("receiver_id", sort=False).size().max()) if len(fixes) else 0
        if most < MIN_EPOCHS:
            why = f"needs {MIN_EPOCHS} fixes of a receiver for its indicators' own baseline ({most} found)"
        else:
            why = (
                "the receiver logs no quality indicator, or none that moves (accuracy, satellites, DOP, noise, "
                "jamming, AGC, C/N0, spoofing state)"
            )
        return DetectorResult.skipped(NAME, why, Evidence.RECEIVER)
    merged.reason = "; ".join(notes)
    merged.alarms.sort(key=lambda a: a.start_s)
    return merged


def run_receiver_levels(
    fixes: pd.DataFrame, baseline: Baseline, opts: ReceiverEvidenceOptions | None = None
) -> DetectorResult:
    """The level test of every receiver the baseline knows (`LEVELS`, evidence: vehicle baseline)."""
    opts = opts or ReceiverEvidenceOptions()
    result = DetectorResult(LEVELS, True, evidence=Evidence.VEHICLE_BASELINE)
    notes = []
    for rid, fx in fixes.groupby("receiver_id", sort=False):
        fx = fx.reset_index(drop=True)
        levels = level_test(str(rid), fx["t_s"].to_numpy(dtype=float), fx, baseline, opts)
        if levels is None:
            continue
        result.alarms += levels.alarms
        result.series += levels.series
        result.findings += levels.findings
        notes.append(f"{rid}: {levels.reason}")
    if not notes:
        return DetectorResult.skipped(
            LEVELS, "the baseline has no indicator level of this log's receivers", Evidence.VEHICLE_BASELINE
        )
    result.reason = "; ".join(notes)
    result.alarms.sort(key=lambda a: a.start_s)
    return result


def _run(ctx: AnalysisContext) -> list[DetectorResult]:
    loaded = ctx.options.baseline
    if loaded is None:
        return [run_receiver_evidence(ctx.table.fixes)]
    result = run_receiver_evidence(ctx.table.fixes, baseline=loaded.content)
    if result.ran:
        note(result, "each indicator's scale at least its typical scale in the clean logs")
    levels = run_receiver_levels(ctx.table.fixes, loaded.content)
    if levels.ran:
        note(levels, "the indicators' levels in the clean logs and how far they vary between them")
    return [result, levels]


_O = ReceiverEvidenceOptions()
ANALYSIS = AnalysisSpec(
    NAME,
    "receiver self-report: indicators against the log's own baseline, the receiver's flags, documented ranges",
    ("fixes",),
    _run,
    (
        DetectorInfo(
            NAME,
            Evidence.RECEIVER,
            "the receiver's own indicators changing together, its spoofing state, implausible C/N0",
            method="A receiver under a takeover says so in many small ways: it loses satellites several at once "
            "and re-acquires them, its DOP and reported accuracies inflate, its noise and jamming indicators rise, "
            "its AGC moves, its C/N0 drops and then sits above its old level, its own spoofing state goes up. None "
            "is proof (a bridge, a tunnel, a turn away from the sky do some of them too), so this "
            "class alone never makes a spoofing verdict. Per receiver, every indicator it logs ("
            + ", ".join(ind.label for ind in INDICATORS)
            + ", and losses of fix: gaps beyond "
            f"{_O.gap_factor:g} median periods) gets a directional robust z against its median and 1.4826 MAD in "
            "this log (floored per indicator, so a constant one is not infinitely sensitive). The baseline is the "
            "whole log, or, when the accuracies, satellites used, DOP, noise and jamming indicator worsen "
            "together at one time and stay worse (a takeover lasting to the end can fill most of the log, and "
            "then the whole log's median is the attack's state), the part before it. An alarm needs "
            f"{_O.min_indicators} indicators beyond {_O.z_alarm:g} robust sigma within {_O.window_s:g} s of each "
            f"other for {_O.min_duration_s:g} s (the three accuracies are one indicator, read off one covariance, "
            "and the two DOPs one), one of them not the way a jammer moves it (noise or jamming "
            "indicator up, AGC or C/N0 down: the interference detector reads those), the receiver's own "
            "spoofing flag (as decoded by the log's "
            "message definition), or a mean C/N0 above "
            f"{_O.max_plausible_cn0_dbhz:g} dB-Hz (stronger than the sky gives a small antenna, so a log "
            "attacked from its first fix still shows it). Onset: the last fix before the alarm with no indicator "
            "beyond its level, or where none was (half of a short log attacked sets its own baseline), the last "
            "fix before it where its alarm condition did not hold.",
            p_false_alarm="rule thresholds (not a calibrated rate)",
            threshold=f"{_O.min_indicators} indicators beyond {_O.z_alarm:g} robust sigma within {_O.window_s:g} s; "
            f"the receiver's spoofing flag; mean C/N0 > {_O.max_plausible_cn0_dbhz:g} dB-Hz",
        ),
    ),
)
