"""GNSS-only consistency: does the reported position move the way the reported velocity says (or, without
a velocity, the way a vehicle can)? Declared in `ANALYSIS` (docs/detectors.md)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.baseline.use import consistency_caps, note
from spooflens.detectors.base import Alarm, DetectorResult, Series, alarm_intervals, onsets_after_quiet
from spooflens.estimation.quantiles import chi2_isf, halfnorm_ppf
from spooflens.geodesy import enu_rotation, geodetic_to_ecef, geodetic_to_enu
from spooflens.gnss.resolution import decimal_step, position_steps_m, speed_step_mps
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo, probability

FloatArray = NDArray[np.float64]
NAME = "gnss_consistency"


@dataclass(frozen=True)
class ConsistencyOptions:
    window_s: float = 10.0
    p_false_alarm: float = 1e-5  # per epoch, as seed 000's KF test
    min_scale_m: float = 0.05  # floor on the robust scale: simulated or quantised logs can have MAD 0
    max_gap_factor: float = 3.0  # a window containing a gap this many median periods long is not judged
    velocity_with_every_fix: float = 0.9  # fraction of fixes with a velocity above which a missing one is unknown
    course_unknown_below_mps: float = 2.0  # ... beside a known speed this low (a braking car stops within a second)
    min_epochs_to_learn: int = 10  # judged epochs a receiver's own noise scale is read off (without a baseline)
    held_course_speed_mps: float = 1.0  # below this, a course repeated exactly is held, not measured
    held_course_run: int = 3
    # more separate bursts over the threshold than this (and than 5 times the design's count): the
    # receiver's residual is heavier-tailed than Gaussian and the threshold is raised (`tail_offset`)
    min_bursts_to_recalibrate: int = 5
    # a receiver whose velocity lags its fixes (a filtered or relayed velocity: a car's NMEA speed 1 s behind its
    # positions, read as a steady residual on every on-ramp): the velocity taken this much later, in steps of
    # `lag_step_s`, where that lowers the residual's mean square (`velocity_lag`) by at least `lag_min_gain`
    max_velocity_lag_s: float = 2.0
    lag_step_s: float = 0.25
    lag_min_gain: float = 0.3
    lag_cap_sigma: float = 5.0
    lag_min_speed_change_mps: float = 2.0


# 25th percentile of |N(0, 1)|: the scale is read off the quietest quarter of the residuals, which
# stays right while up to three quarters of the log is attacked (a MAD breaks down at one half).
_Q25_ABS_NORMAL = halfnorm_ppf(0.25)


def _robust_scale(x: FloatArray, floor: float) -> FloatArray:
    """Per-column noise scale of a residual that is zero-mean without attack.

    Exact zeros are left out: a stretch of frozen fixes with zero velocity (a hover spoofer, a receiver
    repeating its last fix) has no noise at all, and would otherwise become the "quietest quarter" and
    make the honest rest of the log look anomalous.
    """
    a = np.where(np.abs(x) > 1e-9, np.abs(x), np.nan)
    q = np.array([np.nanpercentile(c, 25) if np.isfinite(c).any() else np.nan for c in a.T])
    return np.asarray(np.maximum(np.nan_to_num(q / _Q25_ABS_NORMAL, nan=floor), floor), dtype=float)


def window_first(t: FloatArray, opts: ConsistencyOptions) -> NDArray[np.intp]:
    """Each epoch's window's first epoch: the first at most `window_s` before it."""
    return np.searchsorted(t, t - opts.window_s, side="left")


def _window_velocity_residual(
    t: FloatArray,
    ecef: FloatArray,
    to_enu: FloatArray,
    v: FloatArray,
    opts: ConsistencyOptions,
    unknown_t: FloatArray | None = None,
) -> FloatArray:
    """D_k for every epoch; NaN where the window is incomplete, spans a gap or a fix without velocity
    (`unknown_t`: a receiver stopping writes its speed without a course; a velocity drawn straight across
    it moved a braking car 3.6 m it never went). The displacement is taken in the local frame at fix k
    (`to_enu`, ECEF -> ENU per fix), where the receiver states its velocity: in the first fix's frame an
    aircraft 50 km on would see its frame tilted by 0.45 degrees, 7 m over a 900 m window."""
    dt = np.diff(t)
    integral = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (v[1:] + v[:-1]) * dt[:, None], axis=0)])
    j = window_first(t, opts)
    d = np.einsum("kij,kj->ki", to_enu, ecef - ecef[j]) - (integral - integral[j])
    period = np.median(dt) if len(dt) else np.inf
    gap = np.concatenate([[0.0], np.maximum.accumulate(np.where(dt > opts.max_gap_factor * period, t[1:], 0.0))])
    incomplete = (t - t[0] < opts.window_s * 0.999) | (gap > t[j]) | ~np.all(np.isfinite(d), axis=1)
    if unknown_t is not None and len(unknown_t):
        unknown = np.sort(unknown_t)
        incomplete |= np.searchsorted(unknown, t) > np.searchsorted(unknown, t[j], side="right")
    d[incomplete] = np.nan
    return d


def velocity_lag(
    t: FloatArray,
    ecef: FloatArray,
    to_enu: FloatArray,
    v: FloatArray,
    opts: ConsistencyOptions,
    unknown_t: FloatArray | None = None,
) -> tuple[float, FloatArray, FloatArray]:
    """(lag, velocity, residual): how much later the receiver's velocity belongs to its fixes (0: as written),
    the velocity read that much later, and the window residual with it. A lag shows only while the vehicle's
    speed changes (the residual's quiet quarter never sees it), so it is weighed by the mean square of the
    horizontal residual, each epoch's held at `lag_cap_sigma` of the scale as written (a step or a drag of the
    position counts the same at every lag: it does not follow the vehicle's own accelerations), and taken
    where that falls by `lag_min_gain`."""
    as_written = _window_velocity_residual(t, ecef, to_enu, v, opts, unknown_t)
    judged = np.isfinite(as_written[:, :2]).all(axis=1)
    # windows over which the velocity changed enough for a lag to show (a receiver at rest has none to read)
    j = window_first(t, opts)
    changing = judged & (np.hypot(*(v[:, :2] - v[j, :2]).T) >= opts.lag_min_speed_change_mps)
    if changing.sum() < opts.min_epochs_to_learn:
        return 0.0, v, as_written
    horizontal = np.where(np.isfinite(as_written[:, :2]), as_written[:, :2], 0.0)
    cap = opts.lag_cap_sigma * _robust_scale(horizontal, opts.min_scale_m)

    def loss(r: FloatArray) -> float:
        return float(np.mean(np.minimum(np.abs(r[judged, :2]), cap) ** 2))

    best = (0.0, v, as_written)
    best_loss = (1.0 - opts.lag_min_gain) * loss(as_written)
    for lag in np.arange(opts.lag_step_s, opts.max_velocity_lag_s + 1e-9, opts.lag_step_s):
        later = np.stack([np.interp(t + lag, t, v[:, i]) for i in range(3)], axis=1)
        r = _window_velocity_residual(t, ecef, to_enu, later, opts, unknown_t)
        if (this := loss(r)) < best_loss or (not best[0] and this <= best_loss):  # the first of the least
            best, best_loss = (float(lag), later, r), this
    return best


def _velocity_unknown(t: FloatArray, v: FloatArray, good: NDArray[np.bool_], opts: ConsistencyOptions) -> FloatArray:
    """Times of fixes whose velocity the receiver did not know: missing where it writes velocity with (nearly)
    every fix, beside a known one slow enough that the receiver may have come to rest (it writes a speed
    without a course there). Elsewhere a missing velocity is a sentence not sent (a yacht's network relaying
    a GLL alone) and is interpolated between its neighbours, as one written at a lower rate than the fixes."""
    if good.mean() < opts.velocity_with_every_fix or good.all() or not good.any():
        return np.zeros(0)
    speed = np.hypot(v[good, 0], v[good, 1])
    known_t = t[good]
    missing = np.flatnonzero(~good)
    after = np.clip(np.searchsorted(known_t, t[missing]), 0, len(known_t) - 1)
    before = np.clip(after - 1, 0, len(known_t) - 1)
    slow = np.minimum(speed[before], speed[after]) < opts.course_unknown_below_mps
    return np.asarray(t[missing[slow]], dtype=float)


def _second_difference(t: FloatArray, p: FloatArray) -> FloatArray:
    """Acceleration implied by three consecutive fixes (m/s^2), stamped at the last of the three (NaN at the
    first two): a detector may not alarm before the fix that shows the jump has arrived."""
    a = np.full_like(p, np.nan)
    if len(t) >= 3:
        v = np.diff(p, axis=0) / np.diff(t)[:, None]
        a[2:] = np.diff(v, axis=0) / (0.5 * (t[2:] - t[:-2]))[:, None]
    return a


def tail_offset(bursts: list[Alarm], n_epochs: int, opts: ConsistencyOptions) -> float:
    """How far to raise the threshold of a receiver whose residual is heavier-tailed than the Gaussian the
    test assumes (`bursts`: alarm intervals of the statistic's excess over its threshold), 0 when it is not.

    Real receivers' errors are time-correlated and their velocity may be filtered or relayed with a lag,
    so a Gaussian fitted to the quietest quarter underestimates the tail: a yacht's 4 h log had 194
    bursts where the design expects 0.07. Only bursts no longer than the window count: a receiver's own
    excursions last about its errors' correlation time, while a drag holds the alarm for as long as it
    lasts (a weak ramp over most of a log alarms in dozens of long bursts, which must not teach the test
    its tail). Their peaks' excesses over the threshold are modelled as exponential (peaks over threshold;
    a Gaussian residual's chi-square tail has a mean excess of 2), the mean excess read off their median
    (robust while attacks make fewer than half of them), and the threshold raised to where the design's
    count of bursts, `p_false_alarm` per epoch, is expected above it. An attack that moves position against
    velocity by more than the receiver's own worst moments is still caught; one hidden in them is left to
    the other classes."""
    design = opts.p_false_alarm * n_epochs
    excess = [b.peak_statistic for b in bursts if b.end_s - b.start_s <= opts.window_s]
    n = len(excess)
    if n < max(opts.min_bursts_to_recalibrate, 5 * design):
        return 0.0
    beta = float(np.median(excess)) / np.log(2.0)
    return beta * float(np.log(n / max(design, 1e-12)))


class Residual(NamedTuple):
    """One receiver's residual: its mode, times, residual (N, 3), robust scale per ENU axis (never below
    `floor`), the floor the log's written resolution sets on that scale (`written_floor`), and per epoch the
    distance its window travelled on a course the receiver held rather than measured (`held_course`, m)."""

    mode: str
    t: FloatArray
    r: FloatArray
    scale: FloatArray
    floor: FloatArray
    held: NDArray[np.bool_]  # no measured direction: a course held at rest, or a speed alone
    held_m: FloatArray
    speed_only: NDArray[np.bool_]


def held_course(v: FloatArray, opts: ConsistencyOptions) -> NDArray[np.bool_]:
    """Fixes whose velocity repeats its course exactly at low speed: below a threshold receivers hold their
    last course and scale it by the speed (a 2013 copter's GPS at 127.73 deg for 8 fixes while it drifted
    west at 0.2 m/s; a moored yacht's 188.0 for a minute), so its direction is no measurement. A course
    measured at under 1 m/s moves by degrees from fix to fix; `held_course_run` equal ones in a row are held."""
    speed = np.hypot(v[:, 0], v[:, 1])
    course = np.arctan2(v[:, 0], v[:, 1])
    slow = np.isfinite(speed) & (speed > 0) & (speed < opts.held_course_speed_mps)
    same = np.zeros(len(speed), dtype=bool)
    same[1:] = slow[1:] & slow[:-1] & (np.abs(np.diff(course)) < 1e-9)
    edges = np.diff(np.r_[0, same.astype(np.int8), 0])
    held = np.zeros(len(speed), dtype=bool)
    for a, b in zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(), strict=True):
        if b - a + 1 >= opts.held_course_run:  # repeats a..b-1 of the fix before a
            held[a - 1 : b] = True
    return held


def written_floor(
    lat: FloatArray, lon: FloatArray, h: FloatArray, v: FloatArray | None, t: FloatArray, opts: ConsistencyOptions
) -> FloatArray:
    """The residual's noise scale per ENU axis (m, or m/s^2 without velocity) that rounding alone gives,
    from the steps the log writes position and velocity with (`spooflens.gnss.resolution`).

    With velocity, the residual is a position change less a velocity integral over `window_s`: two
    rounded positions (variance q^2/12 each) and a speed whose rounding error can hold over the window
    (a moored boat reporting 0.0 kn while its fix creeps by 0.0001'), (W q_v)^2/12. Without velocity it is
    a second difference of three rounded positions: q / (sqrt(2) dt^2)."""
    q_pos = position_steps_m(lat, lon, h)
    if v is None:
        dt = float(np.median(np.diff(t))) if len(t) > 1 else np.inf
        return np.asarray(q_pos / (np.sqrt(2.0) * dt**2) if dt > 0 else np.zeros(3), dtype=float)
    horizontal = max(speed_step_mps(np.hypot(v[:, 0], v[:, 1])), decimal_step(v[:, 0]), decimal_step(v[:, 1]))
    q_vel = np.array([horizontal, horizontal, decimal_step(v[:, 2])])
    return np.asarray(np.sqrt(q_pos**2 / 6.0 + (opts.window_s * q_vel) ** 2 / 12.0), dtype=float)


def residual(fixes: pd.DataFrame, opts: ConsistencyOptions) -> Residual:
    """One receiver's residual and its robust scale."""
    t = fixes["t_s"].to_numpy(dtype=float)
    lat, lon, h = (fixes[c].to_numpy(dtype=float) for c in ("lat_deg", "lon_deg", "height_m"))
    v = fixes[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy(dtype=float, copy=True)
    speed = fixes["speed_mps"].to_numpy(dtype=float) if "speed_mps" in fixes else np.full(len(t), np.nan)
    # a speed written without a direction (slow or at rest: an NMEA RMC with a blank course) gives no velocity
    # to integrate but a distance the window allows, as a course held at rest does
    speed_only = ~np.isfinite(v[:, :2]).all(axis=1) & np.isfinite(speed)
    v[speed_only, :2] = 0.0
    has_velocity = np.isfinite(v[:, :2]).all(axis=1).mean() >= 0.5
    if has_velocity:
        # a receiver that reports east/north velocity only is checked horizontally (not discarded)
        vertical = np.isfinite(v[:, 2]).mean() >= 0.5
        mode = "position change vs reported velocity" + ("" if vertical else " (horizontal: no vertical velocity)")
        good = np.isfinite(v[:, :2]).all(axis=1) & (np.isfinite(v[:, 2]) | ~vertical)
        unknown_t = _velocity_unknown(t, v, good, opts)
        t, v, lat, lon, h, speed, speed_only = (x[good] for x in (t, v, lat, lon, h, speed, speed_only))
        ecef, to_enu = geodetic_to_ecef(lat, lon, h), enu_rotation(lat, lon)
        if not vertical:
            v = v.copy()
            v[:, 2] = 0.0
        lag, v, r = velocity_lag(t, ecef, to_enu, v, opts, unknown_t)
        if lag:
            mode += f"; velocity {lag:g} s behind the fixes (read {lag:g} s later: a filtered or relayed velocity)"
        if not vertical:
            r[:, 2] = np.nan
        floor = written_floor(lat, lon, h, np.where(speed_only[:, None], np.c_[speed, 0 * v[:, 1:]], v), t, opts)
        # the distance each window covered on a held course or at a speed alone: known in length, not direction
        held = held_course(v, opts) | speed_only
        held_speed = np.where(speed_only, speed, np.where(held, np.hypot(v[:, 0], v[:, 1]), 0.0))
        travel = np.concatenate([[0.0], np.cumsum(0.5 * (held_speed[1:] + held_speed[:-1]) * np.diff(t))])
        held_m = travel - travel[window_first(t, opts)]
    else:
        mode = "kinematic plausibility (no reported velocity)"
        r = _second_difference(t, geodetic_to_enu(lat, lon, h, lat[0], lon[0], h[0]))
        floor = written_floor(lat, lon, h, None, t, opts)
        held, held_m, speed_only = np.zeros(len(t), dtype=bool), np.zeros(len(t)), np.zeros(len(t), dtype=bool)
    floor = np.maximum(floor, opts.min_scale_m)
    clean = np.where(np.isfinite(r), r, 0.0)
    scale = np.maximum(_robust_scale(clean, opts.min_scale_m), floor)
    return Residual(mode, t, r, scale, floor, held, held_m, speed_only)


def check_receiver(
    fixes: pd.DataFrame, opts: ConsistencyOptions, scale_cap: tuple[str, FloatArray] | None = None
) -> tuple[Residual, FloatArray, FloatArray, FloatArray | None]:
    """Run the check on one receiver's fixes: (its residual, normalised residual (N,3), statistic (N,), the
    scale when a cap applied, else None). `scale_cap`: (mode, per-axis largest scale the vehicle's clean logs
    allow), from a baseline, applied when its mode is the log's: a log attacked throughout cannot teach
    the check that the attack is its noise; never below what the log's rounding alone gives."""
    res = residual(fixes, opts)
    scale = res.scale
    capped = scale_cap is not None and scale_cap[0] == res.mode
    if scale_cap is not None and capped:
        cap = scale_cap[1]
        scale = np.maximum(np.where(np.isfinite(cap), np.minimum(scale, cap), scale), res.floor)
    # a held course leaves the window's velocity integral off by up to the distance travelled on it
    held = np.c_[res.held_m, res.held_m, np.zeros_like(res.held_m)]
    z = res.r / np.sqrt(scale**2 + held**2)
    stat = np.where(np.isfinite(z).any(axis=1), np.nansum(z**2, axis=1), np.nan)
    return res, z, stat, scale if capped else None


def _fixes(n: int) -> str:
    return "fix" if n == 1 else "fixes"


def run_gnss_consistency(
    fixes: pd.DataFrame,
    opts: ConsistencyOptions | None = None,
    scale_caps: dict[str, tuple[str, FloatArray]] | None = None,
) -> DetectorResult:
    """The check for every receiver in a fixes frame (schema `fixes`). `scale_caps`: receiver id -> (the
    check's mode, the per-axis cap on its scale) from a baseline; used where the mode is the log's."""
    opts = opts or ConsistencyOptions()
    threshold = float(chi2_isf(opts.p_false_alarm, 3))
    result = DetectorResult(name=NAME, ran=True, evidence=Evidence.GNSS_ONLY)
    modes = []
    for rid, rx in fixes.groupby("receiver_id", sort=False):
        if len(rx) < 3:
            continue
        res, z, stat, scale = check_receiver(rx.reset_index(drop=True), opts, (scale_caps or {}).get(str(rid)))
        mode, t = res.mode, res.t
        judged = int(np.isfinite(res.r).any(axis=1).sum())
        if 0 < judged < opts.min_epochs_to_learn and scale is None:
            # a noise scale read off three residuals is no scale: a phone's 5 fixes over 80 s read 62,187
            need = opts.min_epochs_to_learn
            modes.append(f"{rid}: not judged: {judged} epochs to learn its noise from ({mode}), {need} needed")
            continue
        if res.held.any():
            course, alone = int((res.held & ~res.speed_only).sum()), int(res.speed_only.sum())
            slow = f"below {opts.held_course_speed_mps:g} m/s"
            which = [f"{course} {_fixes(course)} on a course held {slow}"] * bool(course)
            which += [f"{alone} {_fixes(alone)} with a speed alone"] * bool(alone)
            mode += f"; {' and '.join(which)} (no measured direction: the window allows the distance travelled)"
        checked: NDArray[np.bool_] = np.asarray(np.isfinite(res.r).any(axis=0), dtype=bool)
        if np.any(checked & (res.floor > opts.min_scale_m) & (res.scale <= res.floor)):
            unit = "m" if res.mode.startswith("position change") else "m/s^2"
            floors = "/".join(f"{f:.2g}" for f in res.floor[checked])
            axes = "/".join(a for a, c in zip(("east", "north", "up"), list(checked), strict=True) if c)
            mode += f"; residual scale held at {floors} {unit} ({axes}) or more, what the log's rounding of "
            mode += "position" + (" and velocity" if unit == "m" else "") + " alone gives"
        if scale is not None:
            axes = "/".join(f"{s:.2g}" for s in scale)
            note(result, f"{rid}: residual scale at most the baseline's allowance: {axes} (east/north/up)")
        dof = np.isfinite(z).sum(axis=1)
        excess = np.nan_to_num(stat, nan=0.0) - np.where(
            dof > 0, chi2_isf(opts.p_false_alarm, np.maximum(dof, 1)), np.inf
        )
        alarms = alarm_intervals(t, excess, excess > 0, merge_gap_s=opts.window_s)
        # a baseline that lowered the scale is the yardstick: a log off it must not teach its own tail
        raised = 0.0 if scale is not None else tail_offset(alarms, len(t), opts)
        if raised > 0:
            mode += (
                f"; {len(alarms)} bursts over the threshold where {opts.p_false_alarm * len(t):.2g} were expected: "
                f"residual heavier-tailed than Gaussian, threshold raised by {raised:.1f}"
            )
            alarms = alarm_intervals(t, excess, excess > raised, merge_gap_s=opts.window_s)
        modes.append(f"{rid}: {mode}")
        alarms = [replace(a, peak_statistic=float(stat[np.searchsorted(t, a.peak_s)])) for a in alarms]
        result.alarms += onsets_after_quiet(t, np.nan_to_num(stat) <= 3.0, excess > raised, alarms, str(rid))
        result.series.append(Series(f"{rid}/statistic", t, stat, "chi2(3)", threshold + raised))
        result.series.append(Series(f"{rid}/normalised_residual", t, z, "sigma", None, ("east", "north", "up")))
    if not modes:
        return DetectorResult.skipped(NAME, "no receiver has 3 or more fixes")
    if not any(np.isfinite(series.values).any() for series in result.series):
        span = float(fixes["t_s"].max() - fixes["t_s"].min())
        few = [m for m in modes if ": not judged: " in m]
        why = f"no epoch to judge: no {opts.window_s:g} s of fixes without a gap (the log spans {span:.1f} s)"
        return DetectorResult.skipped(NAME, "; ".join(few) if few else why)
    result.reason = "; ".join(modes)
    result.alarms.sort(key=lambda a: a.start_s)
    return result


def _run(ctx: AnalysisContext) -> list[DetectorResult]:
    baseline = ctx.options.baseline
    caps = consistency_caps(baseline.content, ctx.table) if baseline is not None else None
    return [run_gnss_consistency(ctx.table.fixes, scale_caps=caps)]


_O = ConsistencyOptions()
_P = probability(_O.p_false_alarm)
ANALYSIS = AnalysisSpec(
    NAME,
    "GNSS-only: position change against reported velocity (or kinematic plausibility without velocity)",
    ("fixes",),
    _run,
    (
        DetectorInfo(
            NAME,
            Evidence.GNSS_ONLY,
            f"position change over {_O.window_s:g} s against the integral of the reported velocity",
            method="A receiver computes velocity from Doppler and position from code ranges in separate channels, "
            "and a spoofer dragging the position slowly rarely keeps the two consistent (seed 000's premise). Per "
            f"receiver, over a sliding {_O.window_s:g} s window, D = (p_k - p_j) - integral of v dt, the "
            "displacement taken in the local frame at fix k, where the receiver states its velocity (in the first "
            "fix's frame a fast aircraft 50 km on sees a 0.45-degree tilt: 7 m over a 900 m window). A window "
            f"across a gap longer than {_O.max_gap_factor:g} median fix periods is not judged, nor one holding a "
            "fix without velocity where the receiver writes velocity with at least "
            f"{_O.velocity_with_every_fix:.0%} of its fixes (a receiver stopping writes its speed without a course). "
            "Each axis over a scale read off the quietest quarter of the log (the 25th percentile of |D|, exact "
            f"zeros of frozen fixes left out, floored at {_O.min_scale_m:g} m and at what the log's own rounding "
            "gives: its position and speed steps, read off the numbers, q^2/6 for two rounded positions and "
            "(W q_v)^2/12 for a rounded speed held over the window), which adapts to each receiver and stays right "
            "while up to three quarters of the log is attacked; a receiver with fewer than "
            f"{_O.min_epochs_to_learn} epochs to read it from is not judged. A course repeated exactly at under "
            f"{_O.held_course_speed_mps:g} m/s for {_O.held_course_run} fixes is held, not measured (receivers "
            "hold their last course at rest), and so is a speed written without a course (an NMEA RMC at rest, an "
            "Android fix without a bearing): each window allows, per horizontal axis, the distance travelled on "
            "it. A receiver whose velocity lags its fixes (a filtered or relayed NMEA speed) leaves a residual "
            "wherever the vehicle speeds up or turns: its velocity is read up to "
            f"{_O.max_velocity_lag_s:g} s later, in {_O.lag_step_s:g} s steps, where that lowers the mean square of "
            f"the horizontal residual (each epoch's held at {_O.lag_cap_sigma:g} scales, so a step or a drag counts "
            f"the same at every lag) by {_O.lag_min_gain:.0%} over at least {_O.min_epochs_to_learn} windows whose "
            f"velocity changed by {_O.lag_min_speed_change_mps:g} m/s. "
            "The sum of squares against chi-square with one degree of freedom per axis "
            "(3, or 2 for a receiver without vertical velocity). Without reported velocity: kinematic "
            "plausibility, the acceleration implied by three consecutive fixes, normalised the same way (steps "
            "and jumps, not slow ramps). Real receivers' residuals are heavier-tailed than that Gaussian "
            "(time-correlated errors, a velocity filtered or relayed with a lag): where a receiver alarms in "
            f"at least {_O.min_bursts_to_recalibrate} bursts no longer than the window (and 5 times the design's "
            "count), their peaks' excesses over the threshold are modelled as exponential (peaks over "
            "threshold; the mean excess from their median) and the threshold raised to where the design's count "
            "of bursts is expected above it; longer bursts (a drag holds the alarm) never teach it, nor does a "
            "log whose scale a baseline lowered. Onset: the last epoch before the alarm where the statistic was "
            "at its quiet level (3), or where none was, the last one under its threshold; alarms closer than "
            f"{_O.window_s:g} s are one.",
            p_false_alarm=f"{_P} per epoch",
            threshold=f"chi-square(3) at {_P}: {float(chi2_isf(_O.p_false_alarm, 3)):.1f} "
            f"(2 axes: {float(chi2_isf(_O.p_false_alarm, 2)):.1f}), raised on a heavy-tailed receiver",
        ),
    ),
)
