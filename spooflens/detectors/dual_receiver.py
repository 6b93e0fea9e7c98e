"""Seed 003's dual-receiver detectors: under one spoofer antenna the distance between two receivers and
the spread of their pseudorange differences collapse; with the baseline vector known, the baseline error
grows. Declared in `ANALYSIS` (docs/detectors.md), with the choices where the paper is vague (all
options of `DualReceiverOptions`)."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.baseline.format import Baseline, RicePair
from spooflens.baseline.use import note
from spooflens.detectors.base import Alarm, Bars, DetectorResult, Histogram, Series, alarm_intervals
from spooflens.detectors.statistics.rayleigh import (
    Calibration,
    calibrate,
    fixed_calibration,
    paper_boundary,
    rayleigh_scale,
    scale_changepoint,
)
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import ecef_to_enu_vectors, geodetic_to_ecef
from spooflens.gnss.same_receiver import ReceiverGroup, group_receivers, receiver_groups
from spooflens.gnss.stations import Station, stations
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.preconditions import INDEPENDENT_RECEIVERS, SURVEYED_SITES, known_stations
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo, probability

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

COLLAPSE = "baseline_collapse"
PR_COLLAPSE = "pseudorange_difference_collapse"
BASELINE_ERROR = "baseline_error"


@dataclass(frozen=True)
class DualReceiverOptions:
    window_s: float = 10.0
    min_window: int = 5
    # the window grows (doubling, up to `max_window_s`) until it holds this many effectively independent
    # samples: receivers' errors wander for minutes, so 10 s of them are one sample, whose lower 1e-5
    # quantile is a hundredth of the clean scale, and a real collapse (to the receivers' own tracking noise
    # under the spoofer, a tenth of a consumer receiver's scatter) stayed above it
    min_effective_window: float = 3.0
    max_window_s: float = 120.0
    # the clean part a pair's distance model is fitted on, at least, for its collapses to count: two
    # receivers' errors wander over minutes (multipath, the atmosphere, orbits), and a shorter stretch holds
    # too few of their swings to know the distance's floor (a boat's two receivers, cut to 90 s, came from
    # 13 m to 4 m apart by themselves). On less the collapses are shown, not counted
    min_clean_s: float = 300.0
    p_false_alarm: float = 1e-5  # per epoch, each detector
    max_collapse_ratio: float = 0.5  # a collapse at least halves the clean part's window scale
    min_baseline_error_m: float = 5.0  # below it a baseline error is multipath or a receiver's jump
    max_gap_factor: float = 2.5
    epoch_tolerance_s: float = 0.02  # receivers' epoch tags of one instant differ by their clocks' ms
    min_common_satellites: int = 4
    merge_gap_s: float = 5.0


@dataclass(frozen=True)
class AlignedPair:
    """Two receivers' positions at common epochs (the sparser receiver's)."""

    a: str
    b: str
    t: FloatArray
    ecef_a: FloatArray
    ecef_b: FloatArray
    lat: FloatArray  # receiver a, deg (the local frame of the baseline)
    lon: FloatArray

    @property
    def label(self) -> str:
        return f"{self.a}-{self.b}"

    def baseline_enu(self) -> FloatArray:
        """p_a - p_b in the local ENU frame of receiver a at each epoch."""
        return ecef_to_enu_vectors(self.lat, self.lon, self.ecef_a - self.ecef_b)


def _ecef(fx: pd.DataFrame) -> FloatArray:
    return geodetic_to_ecef(
        fx["lat_deg"].to_numpy(float), fx["lon_deg"].to_numpy(float), fx["height_m"].to_numpy(float)
    )


def _interpolate(t_to: FloatArray, t: FloatArray, x: FloatArray, max_gap_s: float) -> FloatArray:
    """x (rows at times t) at times t_to, linearly between neighbours at most `max_gap_s` apart; NaN elsewhere."""
    out = np.full((len(t_to), x.shape[1]), np.nan)
    if len(t) < 2:
        exact = np.isin(t_to, t)
        out[exact] = x[np.searchsorted(t, t_to[exact])]
        return out
    i = np.clip(np.searchsorted(t, t_to, side="right"), 1, len(t) - 1)
    t0, t1 = t[i - 1], t[i]
    inside = (t_to >= t0) & (t_to <= t1) & (t1 - t0 <= max_gap_s)
    w = np.where(t1 > t0, (t_to - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0)[:, None]
    val = x[i - 1] * (1.0 - w) + x[i] * w
    out[inside] = val[inside]
    return out


def align_pair(fx_a: pd.DataFrame, fx_b: pd.DataFrame, a: str, b: str, opts: DualReceiverOptions) -> AlignedPair:
    """Both receivers at the epochs of the one with fewer fixes; the other interpolated within its gap bound."""
    ta, tb = fx_a["t_s"].to_numpy(float), fx_b["t_s"].to_numpy(float)
    pa, pb = _ecef(fx_a), _ecef(fx_b)
    swap = len(tb) < len(ta)
    t_ref, p_ref, t_oth, p_oth = (tb, pb, ta, pa) if swap else (ta, pa, tb, pb)
    period = float(np.median(np.diff(t_oth))) if len(t_oth) > 1 else 0.0
    other = _interpolate(t_ref, t_oth, p_oth, opts.max_gap_factor * period + 1e-9)
    ok = np.isfinite(other).all(axis=1)
    t, p_ref, other = t_ref[ok], p_ref[ok], other[ok]
    ecef_a, ecef_b = (other, p_ref) if swap else (p_ref, other)
    lat = np.interp(t, ta, fx_a["lat_deg"].to_numpy(float)) if len(ta) else np.zeros(len(t))
    lon = np.interp(t, ta, fx_a["lon_deg"].to_numpy(float)) if len(ta) else np.zeros(len(t))
    return AlignedPair(a, b, t, ecef_a, ecef_b, lat, lon)


def known_baseline(stations: dict[str, Station], pair: AlignedPair) -> tuple[FloatArray | None, str]:
    """The baseline vector p_a - p_b in ENU per epoch when it is known: both receivers are known stations
    (`spooflens.detectors.references.stations`: `--station`, or RINEX headers that their first minutes of
    fixes stay at; a spoofer moves the fixes later, never the survey). Else None."""
    if pair.a in stations and pair.b in stations:
        sa, sb = stations[pair.a], stations[pair.b]
        b = np.broadcast_to(sa.ecef_m - sb.ecef_m, pair.ecef_a.shape)
        headers = all(st.source.startswith("RINEX header") for st in (sa, sb))
        source = "surveyed sites (RINEX APPROX POSITION)" if headers else f"known stations ({sa.source}; {sb.source})"
        return ecef_to_enu_vectors(pair.lat, pair.lon, b), source
    return None, ""


def pseudorange_differences(
    obs: pd.DataFrame, fixes_b: pd.DataFrame, a: str, b: str, opts: DualReceiverOptions
) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
    """Per common epoch: (t, SD of rho_a,i - rho_b,i over the common satellites (eq. 13 corrected), N).

    Receivers tag epochs by their own clocks, so "the same" epoch can differ by milliseconds; receiver
    b's pseudoranges are carried to a's tag along each satellite's range rate (its velocity on the line of
    sight from b's fix), which differs between satellites by up to 1.6 km/s.
    """
    cols = ["t_s", "sv_id", "pseudorange_m", "sv_x_m", "sv_y_m", "sv_z_m", "sv_vx_mps", "sv_vy_mps", "sv_vz_mps"]
    oa = obs.loc[obs["receiver_id"].astype(str) == a, cols[:3]].dropna()
    ob = obs.loc[obs["receiver_id"].astype(str) == b, cols].dropna(subset=cols[:3])
    empty = (np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64))
    if not len(oa) or not len(ob):
        return empty
    tick = opts.epoch_tolerance_s
    oa = oa.assign(key=np.round(oa["t_s"].to_numpy(float) / tick).astype(np.int64), sv=oa["sv_id"].astype(str))
    ob = ob.assign(key=np.round(ob["t_s"].to_numpy(float) / tick).astype(np.int64), sv=ob["sv_id"].astype(str))
    m = pd.merge_asof(
        oa.sort_values("t_s"),
        ob.rename(columns={"t_s": "t_b"}).sort_values("t_b")[["t_b", "sv", *cols[2:]]],
        left_on="t_s",
        right_on="t_b",
        by="sv",
        direction="nearest",
        tolerance=tick,
        suffixes=("_a", "_b"),
    ).dropna(subset=["pseudorange_m_b"])
    if not len(m):
        return empty
    d = m["pseudorange_m_a"].to_numpy(float) - m["pseudorange_m_b"].to_numpy(float)
    dt = m["t_s"].to_numpy(float) - m["t_b"].to_numpy(float)
    if len(fixes_b) and np.any(dt != 0):
        rx = np.stack(
            [np.interp(m["t_b"].to_numpy(float), fixes_b["t_s"].to_numpy(float), c) for c in _ecef(fixes_b).T], axis=1
        )
        sv = m[["sv_x_m", "sv_y_m", "sv_z_m"]].to_numpy(float)
        u = (sv - rx) / np.linalg.norm(sv - rx, axis=1, keepdims=True)
        rate = np.sum(u * m[["sv_vx_mps", "sv_vy_mps", "sv_vz_mps"]].to_numpy(float), axis=1)
        d = d - np.nan_to_num(rate) * dt
    frame = pd.DataFrame({"epoch": m["t_s"].to_numpy(float), "system": m["sv"].str[:1].to_numpy(), "d": d})
    # two passes, one mean per (epoch, system): the clock difference is removed before squaring
    frame["dev2"] = (frame["d"] - frame.groupby(["epoch", "system"])["d"].transform("mean")) ** 2
    g = frame.groupby("epoch")
    n = g["d"].size().to_numpy()
    dof = n - g["system"].nunique().to_numpy()
    sd = np.where(dof > 0, np.sqrt(g["dev2"].sum().to_numpy() / np.maximum(dof, 1)), np.nan)
    t = g["d"].size().index.to_numpy(float)
    enough = n >= opts.min_common_satellites
    return t[enough], sd[enough], n[enough].astype(np.int64)


def _period(t: FloatArray) -> float:
    return max(float(np.median(np.diff(t))) if len(t) > 1 else 1.0, 1e-9)


def window_samples(t: FloatArray, opts: DualReceiverOptions) -> int:
    return max(opts.min_window, round(opts.window_s / _period(t)))


@dataclass(frozen=True)
class Episode:
    """One alarm interval of a rule: the alarm and the estimated onset of the change."""

    alarm: Alarm
    onset_index: int
    end_index: int


@dataclass(frozen=True)
class RuleResult:
    """One windowed rule on one pair: the statistic, its calibration and alarm, and the per-epoch rule."""

    t: FloatArray
    x: FloatArray
    scale: FloatArray
    cal: Calibration
    alarm: BoolArray
    per_epoch: Calibration  # the same statistic one sample at a time (rule 1 or 2)
    episodes: tuple[Episode, ...]
    flagged: BoolArray  # samples from each episode's onset to its end
    sigma_s: float  # Rayleigh scale of the flagged samples (0 without any, eq. 14)
    boundary: float  # the paper's (sigma_GNSS - sigma_S)/2


def _episodes(
    t: FloatArray, x: FloatArray, scale: FloatArray, alarm: BoolArray, k: int, upper: bool, gap: float
) -> tuple[Episode, ...]:
    """Alarm intervals with the onset where the scale changed (two-segment ML over the 3K samples before)."""
    # the peak of a collapse is the smallest window scale, of a baseline error the largest
    stat = np.nan_to_num(scale if upper else -scale, nan=-np.inf)
    out = []
    for a in alarm_intervals(t, stat, alarm, gap):
        j = int(np.searchsorted(t, a.start_s))
        lo = max(j - 3 * k, 0)
        onset = scale_changepoint(x, lo, j) if j - lo >= 3 else max(j - k, 0)
        peak = float(scale[int(np.searchsorted(t, a.peak_s))])
        end = int(np.searchsorted(t, a.end_s))
        out.append(Episode(replace(a, peak_statistic=peak, onset_s=float(t[onset])), onset, end))
    return tuple(out)


def _beyond_floor(cal: Calibration, scale: FloatArray, opts: DualReceiverOptions, upper: bool) -> BoolArray:
    """The physical floors: a baseline error above `min_baseline_error_m`, a collapse to at most
    `max_collapse_ratio` of the clean part's scale."""
    if upper:
        return np.nan_to_num(scale) > opts.min_baseline_error_m
    clean_scale = float(np.sqrt(cal.nu**2 / 2.0 + cal.sigma**2))
    return np.nan_to_num(scale, nan=np.inf) <= opts.max_collapse_ratio * clean_scale


def collapse_rule(
    t: FloatArray, x: FloatArray, opts: DualReceiverOptions, upper: bool = False, prior: RicePair | None = None
) -> RuleResult:
    """Rule 3/4 (window of K) and rule 1/2 (K = 1) on a statistic; `upper` for the baseline error (alarm when
    the scale grows; Rayleigh). `prior`: the statistic's null model from the vehicle's clean logs (a
    baseline), used in place of the one fitted on this log."""
    k = window_samples(t, opts)
    if prior is not None:
        nu, sigma, ratio = prior.nu.centre, prior.sigma.centre, prior.k_eff_ratio.centre
        cal, scale, alarm = fixed_calibration(x, k, opts.p_false_alarm, nu, sigma, ratio * k, upper)
        alarm &= _beyond_floor(cal, scale, opts, upper)
        per_epoch, _, _ = fixed_calibration(x, 1, opts.p_false_alarm, nu, sigma, 1.0, upper)
    else:
        cal, scale, alarm = calibrate(x, k, opts.p_false_alarm, upper=upper, rayleigh_only=upper)
        # a fit on fewer than three windows of clean samples is a fit on every sample, a collapse included:
        # it cannot tell a collapse from the pair's own wander, and raises nothing
        alarm &= _beyond_floor(cal, scale, opts, upper) & cal.calibrated
        # the short window stays: a collapse to almost nothing shows in it at once; the long one sees a collapse
        # to the receivers' tracking noise that the short one's threshold is far below. It grows only while
        # the log holds three such windows of clean samples: two receivers' errors wander for minutes, and a
        # window of most of a short log found their natural approach a collapse (a boat's two receivers, a
        # 150 s stretch)
        longest = max(k, round(opts.max_window_s / _period(t)))
        short_alarm = alarm
        while not upper and cal.k_eff < opts.min_effective_window and k < longest:
            wider = min(2 * k, longest)
            cal_w, scale_w, alarm_w = calibrate(x, wider, opts.p_false_alarm, upper=upper, rayleigh_only=upper)
            if not cal_w.calibrated:
                break
            k, cal, scale = wider, cal_w, scale_w
            alarm = (alarm_w & _beyond_floor(cal, scale, opts, upper)) | short_alarm
        per_epoch, _, _ = calibrate(x, 1, opts.p_false_alarm, upper=upper, rayleigh_only=upper)
    episodes = _episodes(t, x, scale, alarm, k, upper, opts.merge_gap_s)
    flagged = np.zeros(len(t), dtype=bool)
    for ep in episodes:
        flagged[ep.onset_index : ep.end_index + 1] = True
    sigma_s = rayleigh_scale(x[flagged]) if flagged.any() else 0.0
    boundary = paper_boundary(cal.rayleigh_sigma, sigma_s)
    return RuleResult(t, x, scale, cal, alarm, per_epoch, episodes, flagged, sigma_s, boundary)


def clean_seconds(rule: RuleResult) -> float:
    """How long the clean part the rule's model was fitted on lasts (its samples times the sampling period)."""
    return float(np.count_nonzero(rule.cal.clean) * _period(rule.t)) if len(rule.t) else 0.0


def _alarms(rule: RuleResult, receivers: tuple[str, ...]) -> list[Alarm]:
    """The rule's alarms, one per receiver of the pair (a single spoofer feeds both)."""
    return [replace(ep.alarm, receiver_id=rid) for ep in rule.episodes for rid in receivers]


class _Distribution(Protocol):
    """A fitted distribution (a frozen scipy.stats one): what the histogram bars need of it."""

    def cdf(self, x: FloatArray) -> FloatArray: ...


def _histogram_bars(x: FloatArray, edges: FloatArray, label: str, fits: list[tuple[str, _Distribution]]) -> list[Bars]:
    x = x[np.isfinite(x)]
    counts = np.histogram(x, edges)[0].astype(float)
    bars = [Bars(label, counts)]
    for name, dist in fits:
        bars.append(Bars(name, len(x) * np.diff(dist.cdf(edges)), fitted=True))
    return bars


def rule_histograms(rule: RuleResult, name: str, x_label: str) -> list[Histogram]:
    """The statistic's distribution in clean and in flagged windows, each with its fitted densities."""
    from scipy import stats  # the fitted densities: imported where drawn

    out = []
    clean = rule.x[~rule.flagged & np.isfinite(rule.x)]
    if len(clean) >= 5:
        lo, hi = np.percentile(clean, [0.0, 99.5])
        span = max(hi - lo, 1e-6)
        lo = 0.0 if lo < 0.5 * span else lo - 0.1 * span
        edges = np.linspace(lo, hi + 0.1 * span, 41)
        fits: list[tuple[str, _Distribution]] = [
            (f"Rayleigh fit, sigma_GNSS {rule.cal.rayleigh_sigma:.3g}", stats.rayleigh(scale=rule.cal.rayleigh_sigma))
        ]
        if rule.cal.nu > 0:
            fits.append(
                (
                    f"Rice fit, nu {rule.cal.nu:.4g}, sigma {rule.cal.sigma:.3g}",
                    stats.rice(rule.cal.nu / rule.cal.sigma, scale=rule.cal.sigma),
                )
            )
        out.append(
            Histogram(f"{name}_clean", edges, tuple(_histogram_bars(clean, edges, "clean windows", fits)), x_label, "m")
        )
    flagged = rule.x[rule.flagged & np.isfinite(rule.x)]
    if len(flagged) >= 2:
        hi = float(np.percentile(flagged, 99.5))
        edges = np.linspace(0.0, max(hi * 1.1, 1e-3), 41)
        fits = [(f"Rayleigh fit, sigma_S {rule.sigma_s:.3g}", stats.rayleigh(scale=max(rule.sigma_s, 1e-9)))]
        out.append(
            Histogram(
                f"{name}_flagged", edges, tuple(_histogram_bars(flagged, edges, "flagged windows", fits)), x_label, "m"
            )
        )
    return out


def _facts(rule: RuleResult) -> dict[str, object]:
    c = rule.cal
    return {
        "window_samples": c.k,
        "effective_window": round(c.k_eff, 2),
        "rice_nu": round(c.nu, 4),
        "rice_sigma": round(c.sigma, 4),
        "sigma_gnss_rayleigh": round(c.rayleigh_sigma, 4),
        "sigma_s_rayleigh": round(rule.sigma_s, 4),
        "threshold": round(c.threshold, 4),
        "per_epoch_threshold": round(rule.per_epoch.threshold, 4),
        "paper_boundary": round(rule.boundary, 4),
        "calibrated_on_clean_part": c.calibrated,
        "clean_fraction": round(float(c.clean.mean()) if len(c.clean) else 0.0, 3),
    }


def _rule_series(prefix: str, rule: RuleResult, stat_name: str, per_epoch_rule: str) -> list[Series]:
    t = rule.t
    return [
        Series(f"{prefix}/{stat_name}", t, rule.x, "m", rule.per_epoch.threshold),
        Series(f"{prefix}/window_scale", t, rule.scale, "m", rule.cal.threshold),
        Series(f"{prefix}/paper_boundary", t, np.full(len(t), rule.boundary), "m"),
    ]


def _new(name: str) -> DetectorResult:
    return DetectorResult(name, True, evidence=Evidence.SECOND_RECEIVER)


def detect(
    table: EpochTable,
    opts: DualReceiverOptions | None = None,
    groups: list[ReceiverGroup] | None = None,
    known: dict[str, Station] | None = None,
    baseline: Baseline | None = None,
) -> list[DetectorResult]:
    """The three dual-receiver detectors over every pair of independent receivers (the first against each
    other one; `groups`: the log's receivers as the receivers they are, `group_receivers` by default;
    `known`: the known stations, `stations` by default); with a vehicle's `baseline`, the collapse rules judge
    against the null models of its clean logs."""
    opts = opts or DualReceiverOptions()
    groups = group_receivers(table) if groups is None else groups
    known = stations(table, {})[0] if known is None else known
    receivers = [g.receivers[0] for g in groups]
    collapse, pr, err = _new(COLLAPSE), _new(PR_COLLAPSE), _new(BASELINE_ERROR)
    notes: dict[str, list[str]] = {COLLAPSE: [], PR_COLLAPSE: [], BASELINE_ERROR: []}
    one = "; ".join(g.describe() for g in groups if len(g.receivers) > 1)
    for pair_notes in notes.values():
        pair_notes += [one] if one else []
    short: list[tuple[str, list[Alarm]]] = []  # pairs whose clean part is too short for their collapses to count
    fitted = 0
    for a, b in itertools.product(receivers[:1], receivers[1:]):
        pair = align_pair(table.fixes_of(a), table.fixes_of(b), a, b, opts)
        if len(pair.t) < 3 * opts.min_window:
            notes[COLLAPSE].append(f"{a}-{b}: only {len(pair.t)} common epochs")
            continue
        d_enu = pair.baseline_enu()
        dist = np.linalg.norm(d_enu[:, :2], axis=1)
        pair_model = baseline.pairs.get(f"{a}|{b}") if baseline is not None else None
        rule = collapse_rule(pair.t, dist, opts, prior=pair_model.baseline_distance if pair_model else None)
        if pair_model is not None:
            note(
                collapse,
                f"{pair.label}: the clean logs' distance model (Rice nu {rule.cal.nu:.3g} m, sigma "
                f"{rule.cal.sigma:.3g} m, K_eff/K {pair_model.baseline_distance.k_eff_ratio.centre:.2g})",
            )
        collapse.series += _rule_series(pair.label, rule, "baseline_distance", "rule 1")
        collapse.series.append(Series(f"{pair.label}/baseline_distance_3d", pair.t, np.linalg.norm(d_enu, axis=1), "m"))
        fitted += 1
        clean_s = clean_seconds(rule)
        if pair_model is None and clean_s < opts.min_clean_s:
            short.append((f"{pair.label}: {clean_s:.0f} s of clean distance", _alarms(rule, (a, b))))
        else:
            collapse.alarms += _alarms(rule, (a, b))
        collapse.histograms += rule_histograms(rule, f"{pair.label}/baseline_distance", "baseline distance (m)")
        collapse.extras[pair.label] = _facts(rule)
        notes[COLLAPSE].append(
            f"{pair.label}: horizontal distance {np.nanmedian(dist):.2f} m, window {rule.cal.k} samples "
            f"(K_eff {rule.cal.k_eff:.1f}), scale threshold {rule.cal.threshold:.3g} m "
            f"(paper's boundary {rule.boundary:.3g} m)"
        )
        pr_prior = pair_model.pseudorange_difference_sd if pair_model is not None else None
        _pseudorange_rule(table, pair, opts, pr, notes[PR_COLLAPSE], pr_prior)
        _baseline_error_rule(known, pair, d_enu, opts, err, notes[BASELINE_ERROR])
    if short:
        why = (
            f"{'; '.join(w for w, _ in short)}: two receivers' errors wander over minutes, and the distance's "
            f"floor needs at least {opts.min_clean_s:.0f} s of clean samples to be known"
        )
        if len(short) == fitted:  # no pair long enough: its collapses are shown, not counted
            collapse.alarms += [alarm for _, alarms in short for alarm in alarms]
            collapse.advisory = True
            why += ", so this test's alarms are advisory"
        else:
            why += "; that pair's collapses are not counted"
        notes[COLLAPSE].append(why)
    out = []
    for res in (collapse, pr, err):
        if not res.series:
            why = "; ".join(notes[res.name]) or "no receiver pair with enough common epochs"
            out.append(DetectorResult.skipped(res.name, why, Evidence.SECOND_RECEIVER))
            continue
        res.reason = "; ".join(notes[res.name])
        res.alarms.sort(key=lambda x: x.start_s)
        out.append(res)
    return out


def _pseudorange_rule(
    table: EpochTable,
    pair: AlignedPair,
    opts: DualReceiverOptions,
    res: DetectorResult,
    notes: list[str],
    prior: RicePair | None = None,
) -> None:
    t, sd, n = pseudorange_differences(table.observations, table.fixes_of(pair.b), pair.a, pair.b, opts)
    if len(t) < 3 * opts.min_window:
        notes.append(
            f"{pair.label}: pseudoranges of both receivers at {len(t)} common epochs with "
            f">= {opts.min_common_satellites} common satellites (needs raw observations of both)"
        )
        return
    rule = collapse_rule(t, sd, opts, prior=prior)
    if prior is not None:
        note(
            res,
            f"{pair.label}: the clean logs' model of the spread (Rice nu {rule.cal.nu:.3g} m, "
            f"sigma {rule.cal.sigma:.3g} m)",
        )
    res.series += _rule_series(pair.label, rule, "difference_sd", "rule 2")
    res.series.append(Series(f"{pair.label}/common_satellites", t, n.astype(float), "satellites"))
    res.alarms += _alarms(rule, (pair.a, pair.b))
    res.histograms += rule_histograms(rule, f"{pair.label}/difference_sd", "SD of pseudorange differences (m)")
    res.extras[pair.label] = _facts(rule)
    notes.append(
        f"{pair.label}: median SD {np.nanmedian(sd):.3g} m over {int(np.median(n))} common satellites, window "
        f"{rule.cal.k} (K_eff {rule.cal.k_eff:.1f}), threshold {rule.cal.threshold:.3g} m"
    )


def _baseline_error_rule(
    known: dict[str, Station],
    pair: AlignedPair,
    d_enu: FloatArray,
    opts: DualReceiverOptions,
    res: DetectorResult,
    notes: list[str],
) -> None:
    b_enu, source = known_baseline(known, pair)
    if b_enu is None:
        notes.append(f"{pair.label}: baseline vector unknown (not both known stations)")
        return
    e = np.linalg.norm((d_enu - b_enu)[:, :2], axis=1)
    rule = collapse_rule(pair.t, e, opts, upper=True)
    res.series += _rule_series(pair.label, rule, "baseline_error", "rule 1 on the error")[:2]
    res.alarms += _alarms(rule, (pair.a, pair.b))
    res.histograms += rule_histograms(rule, f"{pair.label}/baseline_error", "horizontal baseline error (m)")
    res.extras[pair.label] = _facts(rule) | {
        "baseline_source": source,
        "baseline_m": round(float(np.linalg.norm(b_enu[0])), 3),
    }
    notes.append(
        f"{pair.label}: baseline {np.linalg.norm(b_enu[0]):.2f} m from {source}; error scale "
        f"{rule.cal.sigma:.3g} m, alarm above {max(rule.cal.threshold, opts.min_baseline_error_m):.3g} m"
    )


def _run(ctx: AnalysisContext) -> list[DetectorResult]:
    known = known_stations(ctx)[0]
    loaded = ctx.options.baseline
    baseline = loaded.content if loaded is not None else None
    return detect(ctx.table, DualReceiverOptions(), receiver_groups(ctx), known, baseline)  # type: ignore[arg-type]


_PAPER = "Seed 003 (Dobryakova, Lemieszewski, Ochin: dual-receiver detection of a single-antenna spoofer)"
_O = DualReceiverOptions()
_P = probability(_O.p_false_alarm)
_CHOICES = (
    "Distances are horizontal (the Rayleigh/Rice model is two-dimensional and vertical errors are larger; "
    "the 3-D distance of eq. 9 is drawn beside). A receiver at another rate is interpolated (linearly, in "
    f"ECEF) onto the sparser one's epochs, only between samples at most {_O.max_gap_factor:g} of its median "
    f"period apart. The window is {_O.window_s:g} s and at least {_O.min_window} samples, ending at the "
    "previous sample (eq. 18). The threshold comes from the false-alarm rate per epoch under a Rice model of "
    "the log's clean part with an effective window for time-correlated samples "
    "(`spooflens.detectors.statistics.rayleigh`); the paper's boundary (sigma_GNSS - sigma_S)/2 is drawn "
    "beside, not used. Onset: the two-segment maximum-likelihood change of scale over the 3K samples before."
)
ANALYSIS = AnalysisSpec(
    "dual_receiver",
    "seed 003: two receivers on one vehicle: baseline collapse, pseudorange-difference collapse, baseline error",
    ("fixes", "two_receivers"),
    _run,
    (
        DetectorInfo(
            COLLAPSE,
            Evidence.SECOND_RECEIVER,
            "windowed Rayleigh scale of the distance between two receivers falling (rules 1 and 3)",
            method="One transmitting antenna gives every receiver in its reach the same position (eqs. 7a-7h), so "
            "the distance between two receivers collapses: the maximum-likelihood Rayleigh scale of a sliding "
            f"window of distances (rule 3, eq. 19) against its threshold, and at most {_O.max_collapse_ratio:g} "
            "of the clean part's window scale (a floor that keeps an imperfectly fitting model, heavy-tailed real "
            f"errors, from calling spoofing). {_CHOICES}",
            p_false_alarm=f"{_P} per epoch (Rice model of the clean part, effective window)",
            threshold=f"the window scale's {_P} quantile under the clean part's Rice model, and "
            f"<= {_O.max_collapse_ratio:g} of its scale",
            paper=_PAPER,
        ),
        DetectorInfo(
            PR_COLLAPSE,
            Evidence.SECOND_RECEIVER,
            "spread of the two receivers' pseudorange differences over common satellites vanishing (rules 2 and 4)",
            method="Under one spoofer antenna the two receivers' pseudoranges differ by a constant (D1 - D2), so "
            "their standard deviation over the common satellites (eq. 13, corrected to a variance; one mean per "
            "satellite system, each has its own clock difference) falls to the receivers' own noise: windowed "
            "Rayleigh scale (rule 4), calibrated like the baseline collapse on its own clean part. Epochs both "
            f"logged (within {_O.epoch_tolerance_s:g} s, receiver b's pseudoranges carried to a's tag along each "
            f"satellite's range rate) with {_O.min_common_satellites} or more common satellites; needs raw "
            f"observations of both. {_CHOICES}",
            p_false_alarm=f"{_P} per epoch (Rice model of the clean part, effective window)",
            threshold=f"the window scale's {_P} quantile under the clean part's Rice model, and "
            f"<= {_O.max_collapse_ratio:g} of its scale",
            paper=_PAPER,
        ),
        DetectorInfo(
            BASELINE_ERROR,
            Evidence.SECOND_RECEIVER,
            "|p1 - p2 - b| against the known baseline vector (two known stations)",
            method="With the baseline vector known (both receivers known stations) the horizontal baseline error "
            "is Rayleigh when nothing is wrong, and grows to the baseline's length under a single-antenna spoofer "
            "(or to the offset of a spoofer that moves one receiver): the sharper statistic for a long baseline. "
            f"Windowed Rayleigh scale above its threshold and above {_O.min_baseline_error_m:g} m (below, a "
            f"baseline error is multipath or a receiver's jump). {_CHOICES}",
            p_false_alarm=f"{_P} per epoch (Rayleigh model of the clean part, effective window)",
            threshold=f"the window scale's {_P} quantile under the clean part's Rayleigh model, and "
            f"{_O.min_baseline_error_m:g} m",
            paper=_PAPER,
            preconditions=(SURVEYED_SITES,),
        ),
    ),
    preconditions=(INDEPENDENT_RECEIVERS,),
)
