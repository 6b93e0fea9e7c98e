"""GNSS against the vessel's compass and speed log, a reference a spoofer of the receiver cannot move: the
residual of GNSS velocity over what the heading, the speed through the water and a fitted current
explain. Declared in `ANALYSIS` (docs/detectors.md)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.constants import NMEA_GNSS_TALKERS
from spooflens.detectors.base import (
    Alarm,
    DetectorResult,
    Finding,
    Series,
    Track,
    alarm_intervals,
    nearest,
    rise_start,
    trailing_median,
)
from spooflens.geodesy import enu_to_geodetic, metres_per_radian
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo

FloatArray = NDArray[np.float64]
NAME = "heading_reference"
MIN_REFERENCED_FIXES = 20
# a speed log reading outside these times the GNSS speed along the heading (over the fixes not alarmed
# on) is stuck, fouled or garbage, not off by a calibration error (some per cent) or a current (a good
# part of a slow boat's speed); wide, so that a drag filling much of the log cannot switch it off
LOG_SCALE = (0.2, 5.0)


@dataclass(frozen=True)
class HeadingReferenceOptions:
    window_s: float = 10.0  # the track statistic's trailing window
    z_alarm: float = 8.0
    min_duration_s: float = 5.0
    merge_gap_s: float = 5.0
    floor_mps: float = 0.2
    heading_floor_deg: float = 2.0
    max_age_s: float = 5.0  # a heading or water speed further than this from a fix is not used
    quiet_level: float = 0.5  # of the alarm level: below it an epoch is quiet (the onset search starts there)
    hold_sigma: float = 5.0  # an incident lasts while GNSS is this far from the dead reckoning
    # the change statistic's baseline: the median of the residual over this long, ending `window_s` before
    baseline_s: float = 120.0


@dataclass(frozen=True)
class Reference:
    """The compass heading and the log's speed through the water, interpolated at given times."""

    heading_id: str
    t: FloatArray
    sin: FloatArray
    cos: FloatArray
    water_t: FloatArray
    water: FloatArray

    def at(self, t: FloatArray, max_age_s: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(sin, cos of the heading, speed through the water) at t; NaN where no sample is near enough."""
        s = np.interp(t, self.t, self.sin)
        c = np.interp(t, self.t, self.cos)
        norm = np.hypot(s, c)  # interpolating across a turn shortens the vector: back to unit length
        far = nearest(t, self.t)[1] > max_age_s
        s = np.where(far | (norm < 1e-6), np.nan, s / np.maximum(norm, 1e-6))
        c = np.where(far | (norm < 1e-6), np.nan, c / np.maximum(norm, 1e-6))
        if len(self.water_t):
            w = np.where(nearest(t, self.water_t)[1] > max_age_s, np.nan, np.interp(t, self.water_t, self.water))
        else:
            w = np.full(len(t), np.nan)
        return s, c, w


def reference(headings: pd.DataFrame) -> Reference | None:
    """The compass stream with the most rows (never a GNSS talker's), and every speed-log sample."""
    own = headings[~headings["talker"].astype(str).isin(NMEA_GNSS_TALKERS)]
    if own.empty:
        return None
    best = own["heading_id"].value_counts().index[0]
    h = own[own["heading_id"] == best].sort_values("t_s")
    rad = np.radians(h["heading_deg"].to_numpy(dtype=float))
    water = own[np.isfinite(own["water_speed_mps"].to_numpy(dtype=float))].sort_values("t_s")
    return Reference(
        str(best),
        h["t_s"].to_numpy(dtype=float),
        np.sin(rad),
        np.cos(rad),
        water["t_s"].to_numpy(dtype=float),
        water["water_speed_mps"].to_numpy(dtype=float),
    )


def _design(sin_h: FloatArray, cos_h: FloatArray, water: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Rows of the linear model of GNSS velocity given the reference: the along-heading row only where
    the log gives the speed through the water, the across row always. Returns (A (n, 2, 3), offset
    (n, 2)) with v_along - STW = c . u and v_across = c . p + leeway (u the heading's unit vector, p
    starboard, c the current east/north). The log's scale is not a parameter: a vessel that holds two
    headings leaves no redundancy to fit it, and then an attack on a third of the log moved the fit."""
    n = len(sin_h)
    A = np.zeros((n, 2, 3))
    A[:, 0, 0], A[:, 0, 1] = sin_h, cos_h
    A[:, 1, 0], A[:, 1, 1], A[:, 1, 2] = cos_h, -sin_h, 1.0
    offset = np.stack([water, np.zeros(n)], axis=1)
    return A, offset


def _project(v: FloatArray, sin_h: FloatArray, cos_h: FloatArray) -> FloatArray:
    """GNSS velocity (east, north) along and across (to starboard) the heading."""
    return np.stack([v[:, 0] * sin_h + v[:, 1] * cos_h, v[:, 0] * cos_h - v[:, 1] * sin_h], axis=1)


def _fit(y: FloatArray, A: FloatArray, use: NDArray[np.bool_]) -> FloatArray:
    """Current (east, north) and leeway, robust to an attack filling a good part of the log: least absolute
    deviations first (iteratively reweighted), then Tukey's biweight at 4.685 of their MAD, which gives
    rows far off (the attacked ones) no weight at all. Huber alone was pulled a third of the way to a 2 m/s
    drag covering a third of a log."""
    rows = use[:, None] & np.isfinite(y) & np.isfinite(A).all(axis=2)
    a = A[rows]
    b = y[rows]
    theta = np.zeros(A.shape[2])
    if len(b) < A.shape[2]:
        return theta
    # a small ridge: with a steady heading and no speed log, the current across the bow and the leeway
    # are one number; the smallest theta that explains it is as good as any
    ridge = 1e-6 * np.eye(A.shape[2])

    def solve(w: FloatArray) -> FloatArray:
        aw = a * w[:, None]
        return np.asarray(np.linalg.solve(aw.T @ a + ridge, aw.T @ b), dtype=float)

    w = np.ones(len(b))
    for _ in range(20):  # L1 by IRLS
        theta = solve(w)
        w = 1.0 / np.maximum(np.abs(b - a @ theta), 1e-3)
    r = b - a @ theta
    scale = max(1.4826 * float(np.median(np.abs(r))), 1e-3)
    for _ in range(10):
        u = r / (4.685 * scale)
        w = np.where(np.abs(u) < 1.0, (1.0 - u**2) ** 2, 0.0)
        if w.sum() < A.shape[2]:
            break
        theta = solve(w)
        r = b - a @ theta
    return theta


def _log_scale(
    v: FloatArray, sin_h: FloatArray, cos_h: FloatArray, water: FloatArray, use: NDArray[np.bool_]
) -> float | None:
    """The speed log's reading over the GNSS speed along the heading (medians over the moving fixes in
    `use`), or None without a log: near 1 for a log and a current that are what they seem."""
    along = _project(v, sin_h, cos_h)[:, 0]
    moving = use & np.isfinite(water) & np.isfinite(along) & (np.abs(along) > 0.5)
    if moving.sum() < MIN_REFERENCED_FIXES:
        return None
    return float(np.median(water[moving]) / max(float(np.median(along[moving])), 1e-3))


def _residual(v: FloatArray, sin_h: FloatArray, cos_h: FloatArray, water: FloatArray, use: NDArray[np.bool_]):
    """(residual (n, 2) along/across, fitted theta): GNSS velocity minus what the reference and the fitted
    current and leeway explain; NaN along where the log gives no speed through the water."""
    A, offset = _design(sin_h, cos_h, water)
    y = _project(v, sin_h, cos_h) - offset
    theta = _fit(y, A, use)
    return y - A @ theta, theta


def _z(r: FloatArray, quiet: NDArray[np.bool_], floor: float) -> tuple[FloatArray, FloatArray]:
    """Per component |r - median| / max(1.4826 MAD over the quiet epochs, floor), combined over both
    components (hypot); and each component's scale (NaN for a component with too few values)."""
    out = np.zeros(len(r))
    scales = np.full(r.shape[1], np.nan)
    for j in range(r.shape[1]):
        x = r[:, j]
        ok = quiet & np.isfinite(x)
        if ok.sum() < 5:
            continue
        med = float(np.median(x[ok]))
        scales[j] = max(1.4826 * float(np.median(np.abs(x[ok] - med))), floor)
        out = np.hypot(out, np.nan_to_num(np.abs(x - med) / scales[j]))
    return out, scales


def _earth(r: FloatArray, sin_h: FloatArray, cos_h: FloatArray) -> FloatArray:
    """Along/across residuals back to east/north where both are known (a turn does not rotate a current
    misfit there); across alone stays as it is."""
    both = np.asarray(np.isfinite(r).all(axis=1), dtype=bool)
    e = r[:, 0] * sin_h + r[:, 1] * cos_h
    n = r[:, 0] * cos_h - r[:, 1] * sin_h
    return np.where(both[:, None], np.stack([e, n], axis=1), r)


@dataclass(frozen=True)
class ReceiverTest:
    receiver_id: str
    t: FloatArray
    z: dict[str, FloatArray]  # channel -> combined robust z of the residual (its level)
    z_change: dict[str, FloatArray]  # channel -> the same of its change against the trailing baseline
    # channel -> (residual in east/north where both are known (n, 2), its trailing baseline (n, 2), the
    # change's scale per component (2,)): what an open alarm is judged against, frozen at its onset
    change_parts: dict[str, tuple[FloatArray, FloatArray, FloatArray]]
    residual: dict[str, FloatArray]  # channel -> (n, 2) along/across, m/s
    current: FloatArray  # (east, north) m/s, fitted
    leeway: float
    # per fix interval, GNSS displacement minus the compass and log's (east, north, m): NaN without a
    # speed log. Summed from before an incident, it is how far GNSS is from where the vessel went.
    offset_step: FloatArray
    # per fix interval, where the compass, the log and the fitted current and leeway moved the vessel
    # (east, north, m): the dead reckoning, NaN without a speed log
    reckoned_step: FloatArray
    track_scale: float  # m/s, the track residual's scale
    has_log: bool = False  # a speed log was used
    log_scale: float | None = None  # its reading / GNSS speed along the heading (None: GNSS hardly moved)
    log_dropped: float | None = None  # the implausible scale of a speed log left out


def _velocities(fixes: pd.DataFrame, opts: HeadingReferenceOptions) -> tuple[FloatArray, dict[str, FloatArray]]:
    """Fix times and each channel's GNSS velocity (east, north) at them: the track over the trailing
    window (per interval, weighted by its length) and the receiver's own velocity."""
    t = fixes["t_s"].to_numpy(dtype=float)
    lat = np.radians(fixes["lat_deg"].to_numpy(dtype=float))
    lon = np.radians(fixes["lon_deg"].to_numpy(dtype=float))
    mlat, mlon = metres_per_radian(lat, np.zeros(len(lat)))
    dt = np.diff(t)
    dlon = (np.diff(lon) + np.pi) % (2 * np.pi) - np.pi
    d = np.stack([dlon * 0.5 * (mlon[1:] + mlon[:-1]), np.diff(lat) * 0.5 * (mlat[1:] + mlat[:-1])], axis=1)
    ok = (dt > 0) & (dt <= opts.max_age_s) & np.isfinite(d).all(axis=1)
    channels = {"track": np.where(ok[:, None], d / np.where(dt > 0, dt, 1.0)[:, None], np.nan)}
    v = fixes[["vel_e_mps", "vel_n_mps"]].to_numpy(dtype=float)
    if np.isfinite(v).all(axis=1).sum() >= MIN_REFERENCED_FIXES:
        channels["velocity"] = v
    return t, channels


def _windowed(t_mid: FloatArray, dt: FloatArray, r: FloatArray, t: FloatArray, window_s: float) -> FloatArray:
    """Each interval's residual averaged over the intervals that end in (t - window, t], per component
    (with no speed log the along component is NaN throughout and the across one still counts)."""
    t_end = t_mid + dt / 2
    hi = np.searchsorted(t_end, t, side="right")
    lo = np.searchsorted(t_end, t - window_s, side="right")
    out = np.full((len(t), r.shape[1]), np.nan)
    for j in range(r.shape[1]):
        ok = np.isfinite(r[:, j])
        w = np.where(ok, dt, 0.0)
        cr = np.concatenate([[0.0], np.cumsum(np.where(ok, r[:, j], 0.0) * w)])
        cw = np.concatenate([[0.0], np.cumsum(w)])
        span = cw[hi] - cw[lo]
        out[:, j] = np.where(span >= window_s / 2, (cr[hi] - cr[lo]) / np.maximum(span, 1e-9), np.nan)
    return out


def judge_receiver(
    fixes: pd.DataFrame, ref: Reference, opts: HeadingReferenceOptions, exclude: NDArray[np.bool_] | None = None
) -> ReceiverTest | None:
    """Both channels of one receiver's fixes (sorted by time) against the reference; `exclude` marks
    fixes left out of the fit and the scale (a first pass's alarms). A speed log reading outside
    `LOG_SCALE` times the GNSS speed along the heading (stuck, fouled) is not used: the test falls back
    to across the bow."""
    t, channels = _velocities(fixes, opts)
    if len(t) < MIN_REFERENCED_FIXES:
        return None
    sin_f, cos_f, water_f = ref.at(t, opts.max_age_s)
    if np.isfinite(sin_f).sum() < MIN_REFERENCED_FIXES:
        return None
    quiet_fix = ~exclude if exclude is not None else np.ones(len(t), dtype=bool)
    speed = float(np.nanmedian(water_f)) if np.isfinite(water_f).any() else None
    z: dict[str, FloatArray] = {}
    z_change: dict[str, FloatArray] = {}
    change_parts: dict[str, tuple[FloatArray, FloatArray, FloatArray]] = {}
    residual: dict[str, FloatArray] = {}
    theta = np.zeros(3)
    offset_step = np.full((len(t) - 1, 2), np.nan)
    reckoned_step = np.full((len(t) - 1, 2), np.nan)
    for name, v in channels.items():
        if name == "track":
            t_mid, dt = 0.5 * (t[1:] + t[:-1]), np.diff(t)
            s, c, w = ref.at(t_mid, opts.max_age_s)
            use = quiet_fix[1:] & quiet_fix[:-1]
            r_int, theta_c = _residual(v, s, c, w, use)
            along_of = (s, c, w, use)
            r = _windowed(t_mid, dt, r_int, t, opts.window_s)
            # the dead reckoning: the log along the heading (sin, cos), the fitted current, the leeway to
            # starboard (cos, -sin); what GNSS moved beyond it is the offset
            ce, cn, leeway = theta_c
            reckoned_step = np.stack([w * s + ce + leeway * c, w * c + cn - leeway * s], axis=1) * dt[:, None]
            offset_step = v * dt[:, None] - reckoned_step
        else:
            r, theta_c = _residual(v, sin_f, cos_f, water_f, quiet_fix)
            along_of = (sin_f, cos_f, water_f, quiet_fix)
        if name == "velocity" or "velocity" not in channels:
            theta = theta_c  # the Doppler velocity's fit is the finer one to report
            log_scale = _log_scale(v, *along_of)
        gnss_speed = float(np.nanmedian(np.hypot(v[:, 0], v[:, 1]))) if np.isfinite(v).any() else 0.0
        typical = speed if speed is not None else gnss_speed
        floor = float(np.hypot(opts.floor_mps, typical * np.sin(np.radians(opts.heading_floor_deg))))
        residual[name] = r
        z[name], scales = _z(r, quiet_fix, floor)
        # the change: against the residual's own median over the two minutes before the window, in
        # east/north where both components are known; it needs no baseline from the whole log, so an
        # attack filling most of the log still shows where it began
        flat = _earth(r, sin_f, cos_f)
        baseline = trailing_median(t, flat, opts.baseline_s, opts.window_s)
        z_change[name], change_scales = _z(flat - baseline, quiet_fix, floor)
        change_parts[name] = (flat, baseline, change_scales)
        if name == "track":
            track_scale = float(np.nanmax(scales))
    if log_scale is not None and not LOG_SCALE[0] <= log_scale <= LOG_SCALE[1]:
        fallback = judge_receiver(fixes, replace(ref, water_t=np.zeros(0), water=np.zeros(0)), opts, exclude)
        if fallback is not None:
            return replace(fallback, log_dropped=log_scale)
    return ReceiverTest(
        str(fixes["receiver_id"].iloc[0]),
        t,
        z,
        z_change,
        change_parts,
        residual,
        theta[:2],
        float(theta[2]),
        offset_step,
        reckoned_step,
        track_scale,
        bool(np.isfinite(water_f).any()),
        log_scale,
    )


def _from_onset(test: ReceiverTest, k: int) -> FloatArray:
    """Every fix's residual against the baseline as it was at fix k (frozen there, before the attack
    could enter it), as a combined robust z over the alarm level, the largest channel."""
    out = np.zeros(len(test.t))
    for flat, baseline, scales in test.change_parts.values():
        frozen = baseline[k]
        z = np.zeros(len(test.t))
        for j in range(flat.shape[1]):
            if np.isfinite(frozen[j]) and np.isfinite(scales[j]):
                z = np.hypot(z, np.nan_to_num(np.abs(flat[:, j] - frozen[j]) / scales[j]))
        out = np.maximum(out, z)
    return out


def _alarms(test: ReceiverTest, opts: HeadingReferenceOptions) -> list[Alarm]:
    """Alarms opened by the change statistic (beyond the alarm level for `min_duration_s`) and lasting
    while the residual stays beyond it against the baseline frozen at the onset. The level against the
    whole log's fit opens none: when an attack fills most of the log the fitted current is the attacked
    one and the clean stretch looks off. The onset is where the change's rise began; its interval runs
    from there to the first fix the change left its quiet level at."""
    t = test.t
    change = _score(test.z_change, opts)
    opened = [
        a
        for a in alarm_intervals(t, change, change >= 1.0, opts.merge_gap_s)
        if a.end_s - a.start_s >= opts.min_duration_s
    ]
    out: list[Alarm] = []
    for a in opened:
        if out and a.start_s <= out[-1].end_s:
            continue
        k, last_quiet = rise_start(t, change, a.start_s, opts.quiet_level)
        rise = min(last_quiet + 1, len(t) - 1)
        against_onset = _from_onset(test, k) / opts.z_alarm
        k_end = int(np.searchsorted(t, a.end_s))
        stop = np.flatnonzero(against_onset[k_end:] < 1.0)
        end = float(t[max(k_end + int(stop[0]) - 1, k_end)] if len(stop) else t[-1])
        inside = (t >= a.start_s) & (t <= end)
        peak = int(np.argmax(np.where(inside, np.maximum(change, against_onset), -np.inf)))
        out.append(
            Alarm(
                a.start_s,
                max(end, a.end_s),
                float(max(change[peak], against_onset[peak])),
                float(t[peak]),
                onset_s=float(t[k]),
                onset_interval_s=(float(t[k]), float(t[rise])),
            )
        )
    return out


def _held(test: ReceiverTest, alarm: Alarm, opts: HeadingReferenceOptions) -> Alarm:
    """The alarm, lasting while GNSS stays away from where the compass and log put the vessel since the
    last quiet fix before the onset: a jump is seen by the track only while its window holds it, but the
    offset it left lasts. The dead reckoning's own error grows with time (the track's scale per second,
    e.g. a current that is not quite the fitted one), so an offset is held while it is beyond
    `hold_sigma` of sqrt(window^2 + elapsed^2) x scale. Needs the speed log (along the heading too)."""
    a = int(np.searchsorted(test.t, alarm.onset_s if alarm.onset_s is not None else alarm.start_s))
    e = int(np.searchsorted(test.t, alarm.end_s))
    steps = test.offset_step[a:]
    if e >= len(test.t) - 1 or not np.isfinite(steps).all(axis=1).any():
        return alarm
    offset = np.hypot(*np.cumsum(np.nan_to_num(steps), axis=0).T)  # at fixes a+1, a+2, ...
    elapsed = test.t[a + 1 :] - test.t[a]
    held = offset > opts.hold_sigma * test.track_scale * np.hypot(opts.window_s, elapsed)
    after = np.arange(a + 1, len(test.t)) > e
    released = np.flatnonzero(after & ~held)
    last = int(released[0]) + a if len(released) else len(test.t) - 1  # the last fix still held
    if last <= e:
        return alarm
    return replace(alarm, end_s=float(test.t[last]))


RECKONED = "reconstructed (compass, speed log and the fitted current; GNSS left out)"


def _dead_reckoned(test: ReceiverTest, fixes: pd.DataFrame, alarm: Alarm) -> Track | None:
    """Where the vessel went over an alarm by its compass and speed log alone, from the last quiet fix
    before the onset: the reconstructed track (how far GNSS went from it is what the verdict reports)."""
    a = int(np.searchsorted(test.t, alarm.onset_s if alarm.onset_s is not None else alarm.start_s))
    e = min(int(np.searchsorted(test.t, alarm.end_s)), len(test.t) - 1)
    steps = test.reckoned_step[a:e]
    if e <= a or not np.isfinite(steps).all(axis=1).all():
        return None
    enu = np.vstack([np.zeros(2), np.cumsum(steps, axis=0)])
    lat, lon, h = enu_to_geodetic(
        np.c_[enu, np.zeros(len(enu))],
        float(fixes["lat_deg"].iloc[a]),
        float(fixes["lon_deg"].iloc[a]),
        float(fixes["height_m"].iloc[a]) if "height_m" in fixes else 0.0,
    )
    return Track(RECKONED, test.t[a : e + 1], lat, lon, h)


def _incidents(test: ReceiverTest, alarms: list[Alarm], opts: HeadingReferenceOptions) -> list[Alarm]:
    """Each alarm held while its offset lasts. An alarm that starts where a held one was released is the
    jump back (GNSS returned to where the vessel is, which is why the hold ended), not a new attack."""
    out: list[Alarm] = []
    released_at: float | None = None
    for a in alarms:
        if released_at is not None and (a.onset_s or a.start_s) <= released_at + opts.merge_gap_s:
            continue
        h = _held(test, a, opts)
        released_at = h.end_s if h.end_s > a.end_s and h.end_s < test.t[-1] else None
        out.append(h)
    return out


def _log_words(test: ReceiverTest) -> str:
    if test.log_scale is not None:
        return f"and speed log (reading {test.log_scale:.2f} x the GNSS speed along the heading)"
    if test.has_log:
        return "and speed log"
    if test.log_dropped is not None:
        return (
            f"(speed log not used: it reads {test.log_dropped:.2f} x the GNSS speed along the heading, stuck or "
            "fouled; across the bow only)"
        )
    return "(no speed log: across the bow only)"


def _score(z: dict[str, FloatArray], opts: HeadingReferenceOptions) -> FloatArray:
    """The largest channel's z over the alarm level."""
    return np.max(np.stack(list(z.values())), axis=0) / opts.z_alarm


def run_heading_reference(
    fixes: pd.DataFrame, headings: pd.DataFrame, opts: HeadingReferenceOptions | None = None
) -> DetectorResult:
    opts = opts or HeadingReferenceOptions()
    ref = reference(headings)
    if ref is None:
        streams = ", ".join(f"{h} ({n} rows)" for h, n in headings["heading_id"].value_counts(sort=False).items())
        why = (
            f"headings from GNSS talkers only ({streams}): a heading a GNSS receiver or a bus relabelling every "
            "sentence as GP gives is no reference independent of GNSS"
            if len(headings)
            else "no compass heading in the log (a GNSS receiver's heading is no reference)"
        )
        return DetectorResult.skipped(NAME, why, Evidence.HEADING)
    tests: list[tuple[ReceiverTest, list[Alarm]]] = []
    fixes_of: dict[str, pd.DataFrame] = {}
    for _, rows in fixes.groupby("receiver_id", sort=True):
        rows = rows.sort_values("t_s").reset_index(drop=True)
        first = judge_receiver(rows, ref, opts)
        if first is None:
            continue
        alarmed = np.zeros(len(first.t), dtype=bool)
        for a in _alarms(first, opts):
            alarmed |= (first.t >= (a.onset_s or a.start_s)) & (first.t <= a.end_s)
        # the current, the leeway and the scale refitted without what the first pass alarmed on
        final = judge_receiver(rows, ref, opts, alarmed) if alarmed.any() else first
        if final is not None:
            tests.append((final, _incidents(final, _alarms(final, opts), opts)))
            fixes_of[final.receiver_id] = rows
    if not tests:
        return DetectorResult.skipped(
            NAME,
            f"fewer than {MIN_REFERENCED_FIXES} fixes within {opts.max_age_s:g} s of a compass heading",
            Evidence.HEADING,
        )
    result = DetectorResult(
        NAME,
        True,
        f"{'; '.join(f'{t.receiver_id} against {ref.heading_id} {_log_words(t)}' for t, _ in tests)}: GNSS "
        f"track and velocity changing by {opts.z_alarm:g} robust sigma for {opts.min_duration_s:g} s",
        sorted((a for _, alarms in tests for a in alarms), key=lambda a: a.start_s),
        evidence=Evidence.HEADING,
    )
    for test, alarms in tests:
        rid = test.receiver_id
        for a in alarms:
            track = _dead_reckoned(test, fixes_of[rid], a)
            if track is not None:
                result.tracks.append(track)
        level, change = _score(test.z, opts), _score(test.z_change, opts)
        # strength: the change, what opens an alarm; level: the residual against the whole log's fit
        # (drawn, it opens none: an attack filling most of a log makes its clean stretch look off)
        result.series.append(Series(f"{rid}/strength", test.t, change, "x alarm level", 1.0))
        result.series.append(Series(f"{rid}/level", test.t, level, "x alarm level", None))
        for name, r in test.residual.items():
            result.series.append(Series(f"{rid}/{name}_residual", test.t, r, "m/s", None, ("along", "across")))
        for a in alarms:
            inside = (test.t >= a.start_s) & (test.t <= a.end_s)
            peaks = []
            for name, r in test.residual.items():
                seg = np.where(np.isfinite(r[inside]), np.abs(r[inside]), -1.0)
                if seg.size and seg.max() >= 0:
                    j = int(np.argmax(seg.max(axis=0)))
                    peaks.append(f"{name} {('along', 'across')[j]} {float(seg.max()):.1f} m/s")
            result.findings.append(
                Finding(
                    f"{rid} against the vessel's heading {_log_words(test)}: {', '.join(peaks)} off what the compass"
                    f" and the fitted current ({test.current[0]:+.1f} E, {test.current[1]:+.1f} N m/s) explain "
                    f"({a.start_s:.1f}-{a.end_s:.1f} s)",
                    a.start_s,
                    a.end_s,
                    receiver_id=rid,
                )
            )
    return result


def _run(ctx: AnalysisContext) -> list[DetectorResult]:
    return [run_heading_reference(ctx.table.fixes, ctx.table.frame("headings"))]


_O = HeadingReferenceOptions()
ANALYSIS = AnalysisSpec(
    NAME,
    "GNSS track and velocity against the vessel's compass heading and speed log",
    ("fixes", "headings"),
    _run,
    (
        DetectorInfo(
            NAME,
            Evidence.HEADING,
            "GNSS motion the vessel's compass and speed log cannot explain",
            method="A ship moves along its heading at its speed through the water, plus the water's current and a "
            "little leeway, none of which a spoofer of the receiver can move. The compass (NMEA HDT, HDG, THS; a "
            "GNSS talker's heading, e.g. a dual-antenna GPHDT, is never a reference: the spoofer moves it) and the "
            "speed log (VHW) give the first two. Per receiver, two GNSS velocities: the track (each fix interval's "
            f"displacement split along and across the heading at its middle, over a trailing {_O.window_s:g} s "
            "window) and the receiver's own (Doppler) velocity; the residual is GNSS velocity minus the compass "
            "and log's, minus a current (east, north) and leeway fitted to the log (least absolute deviations, then "
            "Tukey's biweight; refitted without the first pass's alarms). With no speed log only the motion across "
            f"the bow is judged, and so with a log reading under {LOG_SCALE[0]:g} or over {LOG_SCALE[1]:g} times "
            "the GNSS speed along the heading over the fixes not alarmed on (stuck, fouled). An alarm opens when "
            f"the residual changes against its own median over the {_O.baseline_s:g} s ending {_O.window_s:g} s "
            "before (in east/north where both components are known, so a turn does not rotate a current misfit "
            f"into a change; a current changing over minutes is no alarm) by {_O.z_alarm:g} robust sigma for "
            f"{_O.min_duration_s:g} s, the sigma 1.4826 MAD over the log, floored at hypot({_O.floor_mps:g} m/s, "
            f"the log's median speed x sin {_O.heading_floor_deg:g} deg). It lasts while the residual stays beyond "
            "that against the baseline frozen at the onset, and with the speed log while GNSS stays more than "
            f"{_O.hold_sigma:g} sigma off the dead reckoning from the last quiet fix (a jump is seen by the track "
            "only while its window holds it; the offset it left lasts). With the speed log each alarm also returns "
            "the reconstructed track: where the compass, the log and the fitted current moved the vessel from the "
            "last quiet fix, GNSS left out. The residual against the whole log's fit is drawn but opens nothing "
            "(when an attack fills most of a log, the fitted current is the attacked one). A drift slower than the "
            "baseline (tenths of a m/s per minute) is not seen.",
            p_false_alarm="rule thresholds (not a calibrated rate)",
            threshold=f"{_O.z_alarm:g} robust sigma of change for {_O.min_duration_s:g} s",
            checked="On the real chartplotter log `gpsd_bundg_zeus_9.log` (148 s, SDHDG compass, SDVHW log) the "
            "statistic stays below 0.46 of its alarm level; the same log with a 30 m or 3 km jump at 70 s, or a "
            "2 m/s drag from 100 s, is SPOOFING with the heading class; a 3 km jump is held to the log's end, or to "
            "110 s when GNSS comes back then, a 30 m jump about 35 s (`tests/detectors/test_heading_reference.py`; "
            "the attacks are injected, not recorded). Sensitivity: about 2.3 m/s of drag at 6 m/s through the "
            "water, any jump of tens of metres.",
        ),
    ),
)
