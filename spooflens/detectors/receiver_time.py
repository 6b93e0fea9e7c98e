"""The receiver's time against the log's own clock, a reference the spoofer of the receiver cannot move:
steps of their difference. Declared in `ANALYSIS` (docs/detectors.md)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.baseline.format import Baseline, ClockBaseline
from spooflens.baseline.use import cap, note
from spooflens.detectors.base import Alarm, DetectorResult, Finding, Series, trailing_median
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.registry import MIN_TIMED_FIXES, AnalysisContext, AnalysisSpec, DetectorInfo

FloatArray = NDArray[np.float64]
NAME = "receiver_time"


@dataclass(frozen=True)
class ReceiverTimeOptions:
    baseline_s: float = 60.0
    guard_s: float = 5.0
    z_alarm: float = 8.0
    min_step_s: float = 0.25
    min_scale_s: float = 0.001  # loggers stamp milliseconds
    min_fixes: int = 3
    min_duration_s: float = 1.0
    leap_window_s: float = 900.0  # broadcast UTC parameters come every 12.5 min
    max_leap_s: int = 2  # firmware of 2015 or later defaults to 17 or 18 of today's 18
    drift_ppm: float = 20.0  # a rate this far from the baseline's is a finding (crystals vary by a few ppm)
    min_drift_s: float = 60.0
    # a receiver's time given in whole seconds (or halves), read at instants of a cycle of its own
    resolutions_s: tuple[float, ...] = (1.0, 0.5)
    resolution_tolerance_s: float = 0.001  # every time a whole number of them, to the logger's millisecond
    wrap_tolerance: float = 0.05  # of the resolution: a wrap is one resolution step, less the drift, to 5 %
    # most of the log on one phase of the steps: a spoofer's time half a second off is on another phase
    # from its takeover on, and must not hide its own step
    resolution_share: float = 0.5


@dataclass(frozen=True)
class CoarseTime:
    """A receiver's time in whole steps of `resolution_s` (1 s: a time field filled to the second, a time
    truncated when the message was assembled) read at instants that are not locked to those steps (an
    output or gateway cycle of its own, 1.0055 s for 1 s): the offset against the log's clock saws, drifting
    by `drift` s per s as the reading instant slides through the second and wrapping back by one step each
    time it crosses one (`wraps` times). Its true value is known only to within one step."""

    resolution_s: float
    drift: float
    wraps: int


@dataclass(frozen=True)
class Step:
    """One change of the receiver's time: fixes first..last (indices) on the new time."""

    first: int
    last: int
    step_s: float
    kind: str  # "spoofing", "leap seconds" or "logger clock"


def _humane(seconds: float) -> str:
    s = abs(seconds)
    if s < 120:
        return ""
    if s < 2 * 86400:
        return f" (= {int(s // 3600)} h {int(s % 3600 // 60):02d} min)"
    return f" (= {s / 86400:.1f} days)"


@dataclass
class ReceiverClockTest:
    receiver_id: str
    t: FloatArray
    offset: FloatArray
    change: FloatArray  # offset minus its trailing baseline
    scale_s: float
    threshold_s: float
    steps: list[Step]
    coarse: CoarseTime | None = None


def _kind(
    t: FloatArray,
    x: FloatArray,
    first: int,
    last: int,
    step: float,
    scale: float,
    opts: ReceiverTimeOptions,
    monotonic: bool,
) -> str:
    """Spoofing, or one of the two steps that are not (see the module docstring). A monotonic boot clock
    cannot step, so there a receiver's time that ran on across a gap in the fixes is the receiver's step
    (a spoofer that resumes at the time of the last real fix), never the logger's."""
    period = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    tolerance = 0.5 * period + 3.0 * scale
    dt_log = t[first] - t[first - 1]
    dt_receiver = dt_log + x[first] - x[first - 1]
    if not monotonic and abs(dt_receiver - period) <= tolerance < abs(dt_log - period):
        return "logger clock"
    n = round(step)
    whole = abs(step - n) <= max(3.0 * scale, 0.02) and -opts.max_leap_s <= n <= -1
    if whole and last == len(t) - 1 and t[first] - t[0] <= opts.leap_window_s:
        return "leap seconds"
    return "spoofing"


def offset_scale(x: FloatArray, floor: float) -> float:
    """Robust sigma of the offset's latency jitter from fix-to-fix differences: a step moves one difference,
    however long the attack lasts (a scale read off the change against the baseline grows with it)."""
    dx = np.diff(x)
    if not len(dx):
        return floor
    return max(1.4826 * float(np.median(np.abs(dx - np.median(dx)))) / np.sqrt(2.0), floor)


def _on_one_phase(phase: FloatArray, q: float, tol: float) -> float:
    """The share of the times on their commonest phase (mod `q`, to `tol`): 1.0 for a time in whole steps."""
    bins = max(round(q / tol), 1)
    k = np.round(phase / q * bins).astype(np.int64) % bins
    counts = np.bincount(k, minlength=bins)
    near = counts + np.roll(counts, 1) + np.roll(counts, -1)  # a time on a bin's edge
    return float(near.max()) / len(phase)


def coarse_time(t: FloatArray, x: FloatArray, scale: float, opts: ReceiverTimeOptions) -> CoarseTime | None:
    """The sawtooth of a coarse receiver time (`CoarseTime`), or None. All three must hold: the receiver's
    times (`x + t`, up to a constant) whole numbers of steps of a resolution at least the alarm's least step
    (most of them: `resolution_share`);
    the offset drifting steadily (its median rate over a baseline minute more than the alarm's jitter
    allowance); and wraps, each one step against the drift (less the drift over its interval), no more of
    them than the drift over the log accounts for (one per step drifted, and one more). A spoofer's clock
    moves the offset by its own amount and keeps it there: no wrap of exactly one step that the drift then
    undoes."""
    if len(t) < 3:
        return None
    dt, dx = np.diff(t), np.diff(x)
    ok = dt > 0
    if ok.sum() < 2:
        return None
    drift = float(np.median(dx[ok] / dt[ok]))
    if abs(drift) * opts.baseline_s <= opts.z_alarm * scale:
        return None
    for q in sorted(opts.resolutions_s, reverse=True):
        if q < opts.min_step_s:
            continue
        if _on_one_phase(np.mod(x + t, q), q, opts.resolution_tolerance_s) < opts.resolution_share:
            continue
        jump = dx - drift * dt - (-np.sign(drift) * q)
        wraps = int(np.sum(np.abs(jump) <= max(opts.wrap_tolerance * q, opts.z_alarm * scale)))
        # how many steps the offset drifted: its change end to end with the wraps taken out (the median rate
        # of a sawtooth read at its own cycle can be a fifth short, and a stretch holding three wraps 170 s
        # apart in 400 s was then one wrap too many)
        drifted = abs(float(x[-1] - x[0]) + np.sign(drift) * q * wraps) / q
        # a stretch from just before one wrap to just after the next holds two wraps over one step of drift,
        # less the drift of its first and last sample: the step's tolerance of each wrap (aava-n2k cut at
        # 105.3-285.3 s: 2 wraps, 0.971 steps drifted, and was a false clock step)
        if 1 <= wraps <= drifted + 1 + opts.wrap_tolerance:
            return CoarseTime(q, drift, wraps)
    return None


def time_resolution_s(t: FloatArray, x: FloatArray, opts: ReceiverTimeOptions | None = None) -> float:
    """The resolution of a receiver's sawing coarse time (`coarse_time`; t and x finite, t sorted), else 0:
    how far its offset moves with no move of its time."""
    opts = opts or ReceiverTimeOptions()
    coarse = coarse_time(t, x, offset_scale(x, opts.min_scale_s), opts)
    return coarse.resolution_s if coarse is not None else 0.0


def judge_receiver(
    rid: str,
    t: FloatArray,
    x: FloatArray,
    opts: ReceiverTimeOptions,
    monotonic: bool = False,
    scale_cap: float = np.inf,
) -> ReceiverClockTest:
    """The steps of one receiver's time offset (t sorted, x finite). Fixes inside a step are left out of
    the baseline of the fixes after it, so the return to the old time is not a second step. `scale_cap`:
    the largest jitter the vehicle's clean logs allow (a baseline's): a spoofer's jittery clock cannot
    raise the alarm level."""
    scale = min(offset_scale(x, opts.min_scale_s), max(scale_cap, opts.min_scale_s))
    thr = max(opts.z_alarm * scale, opts.min_step_s)
    coarse = coarse_time(t, x, scale, opts)
    if coarse is not None:  # the offset and its baseline both lie within one step of the resolution
        thr += coarse.resolution_s
    clean = x.copy()
    base = trailing_median(t, clean[:, None], opts.baseline_s, opts.guard_s)[:, 0]
    change = x - base
    steps: list[Step] = []
    i = 1
    while i < len(t):
        over = np.isfinite(change[i:]) & (np.abs(np.nan_to_num(change[i:])) > thr)
        run = np.flatnonzero(over)
        if not len(run):
            break
        k0 = i + int(run[0])
        k_end = k0
        while k_end + 1 < len(t) and over[k_end + 1 - i]:
            k_end += 1
        if k_end - k0 + 1 < opts.min_fixes or t[k_end] - t[k0] < opts.min_duration_s:
            i = k_end + 1
            continue
        away = np.abs(x[k0:] - base[k0]) > thr
        last = len(t) - 1  # back on the frozen baseline for min_fixes fixes in a row ends it
        for b in np.flatnonzero(~away).tolist():
            if b + opts.min_fixes <= len(away) and not away[b : b + opts.min_fixes].any():
                last = k0 + b - 1
                break
        step = float(np.median(x[k0 : last + 1]) - base[k0])
        steps.append(Step(k0, last, step, _kind(t, x, k0, last, step, scale, opts, monotonic)))
        clean[k0 : last + 1] = np.nan
        base[last + 1 :] = trailing_median(t, clean[:, None], opts.baseline_s, opts.guard_s)[:, 0][last + 1 :]
        change[last + 1 :] = x[last + 1 :] - base[last + 1 :]
        i = last + 1
    return ReceiverClockTest(rid, t, x, change, scale, thr, steps, coarse)


def _finding(test: ReceiverClockTest, s: Step, clock: str) -> Finding:
    t0, t1 = float(test.t[s.first]), float(test.t[s.last])
    until = "to the end of the log" if s.last == len(test.t) - 1 else f"until {t1:.1f} s"
    moved = f"{s.step_s:+.3f} s{_humane(s.step_s)}"
    text = {
        "spoofing": f"{test.receiver_id}: the receiver's time moved {moved} against {clock} at "
        f"{t0:.1f} s, {until}: a spoofer's clock or a recording replayed",
        "leap seconds": f"{test.receiver_id}: the receiver's UTC moved by exactly {round(s.step_s)} s at {t0:.1f} "
        "s: it learned the leap seconds from the broadcast UTC parameters (not counted)",
        "logger clock": f"{test.receiver_id}: the logger's clock stepped by {-s.step_s:+.3f} s at {t0:.1f} s while "
        "the receiver's time ran on (not counted)",
    }[s.kind]
    return Finding(text, t0, t1, receiver_id=test.receiver_id)


def _coarse_finding(test: ReceiverClockTest, c: CoarseTime, clock: str) -> Finding:
    text = (
        f"{test.receiver_id}: the receiver's time is given in whole steps of {c.resolution_s:g} s, read at instants "
        f"of a cycle of its own: against {clock} it drifts {c.drift * 1e3:+.1f} ms/s and wraps back by "
        f"{c.resolution_s:g} s ({c.wraps} time(s)), a sawtooth; changes within the resolution are not counted"
    )
    return Finding(text, float(test.t[0]), float(test.t[-1]), receiver_id=test.receiver_id)


def run_receiver_time(
    fixes: pd.DataFrame,
    opts: ReceiverTimeOptions | None = None,
    clock: str = "the log's own clock",
    monotonic: bool = False,
    baseline: Baseline | None = None,
) -> DetectorResult:
    """The test for every receiver with its own time; `clock` and `monotonic` say what the readers put it
    against (the table's `time_offset.clock` and `time_offset.monotonic` metadata). With a baseline of
    the same clock, the jitter scale is capped by the clean logs' allowance and a drift unlike theirs is
    a finding."""
    opts = opts or ReceiverTimeOptions()
    result = DetectorResult(name=NAME, ran=True, evidence=Evidence.LOG_CLOCK)
    words = []
    for rid, rx in fixes.groupby("receiver_id", sort=False):
        x = rx["time_offset_s"].to_numpy(dtype=float)
        t = rx["t_s"].to_numpy(dtype=float)
        ok = np.isfinite(x)
        if ok.sum() < MIN_TIMED_FIXES:
            continue
        known = _clock_baseline(baseline, str(rid), clock, monotonic)
        scale_cap = np.inf
        if known is not None:
            scale_cap = cap(known.offset_scale_s)
            if np.isfinite(scale_cap):
                note(result, f"{rid}: jitter scale at most {scale_cap * 1e3:.1f} ms (the clean logs' allowance)")
            drift = _drift_finding(str(rid), t[ok], x[ok], known, opts)
            if drift is not None:
                result.findings.append(drift)
        test = judge_receiver(str(rid), t[ok], x[ok], opts, monotonic, scale_cap)
        words.append(f"{rid}: robust sigma {test.scale_s * 1e3:.1f} ms, alarm level {test.threshold_s:.3f} s")
        if test.coarse is not None:
            words[-1] += f" (raised by its time's resolution, {test.coarse.resolution_s:g} s)"
            result.findings.append(_coarse_finding(test, test.coarse, clock))
        result.series.append(Series(f"{rid}/time_offset", test.t, test.offset, "s"))
        result.series.append(Series(f"{rid}/offset_change", test.t, test.change, "s", test.threshold_s))
        for s in test.steps:
            result.findings.append(_finding(test, s, clock))
            if s.kind != "spoofing":
                continue
            moved = np.abs(test.offset[s.first : s.last + 1] - (test.offset[s.first] - test.change[s.first]))
            peak = s.first + int(np.argmax(moved))
            confirmed = min(s.first + opts.min_fixes - 1, s.last)
            result.alarms.append(
                Alarm(
                    float(test.t[confirmed]),
                    float(test.t[s.last]),
                    float(moved[peak - s.first] / test.threshold_s),
                    float(test.t[peak]),
                    onset_s=float(test.t[s.first]),
                    onset_interval_s=(float(test.t[s.first - 1]), float(test.t[s.first])),
                    receiver_id=str(rid),
                )
            )
        result.extras[f"{rid}/steps_s"] = [round(s.step_s, 6) for s in test.steps]
    if not words:
        return DetectorResult.skipped(
            NAME, f"no receiver has {MIN_TIMED_FIXES} fixes with their own time", Evidence.LOG_CLOCK
        )
    result.reason = f"against {clock}: " + "; ".join(words)
    result.alarms.sort(key=lambda a: a.start_s)
    return result


def drift_ppm(t: FloatArray, x: FloatArray) -> tuple[float, float]:
    """The offset's rate (ppm) from the medians of its first and last thirds (a step or a few late messages
    inside a third do not move it), and its standard error from the offset's jitter (NaN, NaN when the
    log is too short to tell)."""
    if len(t) < 9 or t[-1] - t[0] < 10.0:
        return float("nan"), float("nan")
    third = len(t) // 3
    dt = float(np.median(t[-third:]) - np.median(t[:third]))
    if dt <= 0:
        return float("nan"), float("nan")
    rate = float((np.median(x[-third:]) - np.median(x[:third])) / dt * 1e6)
    # the median of a third has 1.2533 sigma / sqrt(n) of error; two of them differ
    error = 1.2533 * offset_scale(x, 1e-6) * np.sqrt(2.0 / third) / dt * 1e6
    return rate, float(error)


def _clock_baseline(baseline: Baseline | None, rid: str, clock: str, monotonic: bool) -> ClockBaseline | None:
    """The baseline's clock behaviour of this receiver, when it is against the same kind of clock."""
    rx = baseline.receivers.get(rid) if baseline is not None else None
    if rx is None or rx.clock is None or rx.clock.clock != clock or rx.clock.monotonic != monotonic:
        return None
    return rx.clock


def _drift_finding(
    rid: str, t: FloatArray, x: FloatArray, known: ClockBaseline, opts: ReceiverTimeOptions
) -> Finding | None:
    """A finding when the receiver's time runs at another rate against a monotonic log clock than in the
    clean logs (a spoofer on a free-running clock of its own): beyond `drift_ppm`, the logs' spread
    thrice and the rate's own error five times, over a log long enough to tell (`min_drift_s`)."""
    q = known.drift_ppm
    if q is None or not known.monotonic or t[-1] - t[0] < opts.min_drift_s:
        return None
    rate, error = drift_ppm(t, x)
    off = rate - q.centre
    if not np.isfinite(off) or abs(off) <= max(opts.drift_ppm, 3.0 * (q.between or 0.0), 5.0 * error):
        return None
    return Finding(
        f"{rid}: the receiver's time ran {rate:+.1f} ppm against the log's clock; in the vehicle's clean logs "
        f"{q.centre:+.1f} ppm ({q.n_logs} log(s)): a clock of its own (a spoofer's) or another logger",
        float(t[0]),
        float(t[-1]),
        receiver_id=rid,
    )


def _run(ctx: AnalysisContext) -> list[DetectorResult]:
    meta = ctx.table.metadata
    clock = meta.get("time_offset.clock", "the log's own clock")
    loaded = ctx.options.baseline
    return [
        run_receiver_time(
            ctx.table.fixes,
            clock=clock,
            monotonic=meta.get("time_offset.monotonic") == "yes",
            baseline=loaded.content if loaded is not None else None,
        )
    ]


_O = ReceiverTimeOptions()
ANALYSIS = AnalysisSpec(
    NAME,
    "the receiver's time against the log's own clock",
    ("fixes", "time_offset"),
    _run,
    (
        DetectorInfo(
            NAME,
            Evidence.LOG_CLOCK,
            "steps of the receiver's time against the log's own clock",
            method="A receiver's time comes from the signals it tracks; the log's clock (the autopilot's boot clock, "
            "the phone's elapsed-realtime clock, the logging host's time) does not. Their difference "
            "(`time_offset_s`: PX4 time_utc_usec, ArduPilot GWk/GMS, GnssLogger Fix, NMEA with logger times, ROS "
            "sensor_msgs/TimeReference, tlog GPS_RAW_INT) stays constant but for the logger's crystal drift and each "
            "message's latency. A spoofer that does not copy GNSS time to a fraction of a second moves it at once "
            "and keeps it moved: a signal generator run from a navigation file made earlier (gps-sdr-sim's usual "
            "use), a recording of the sky replayed later, a spoofer on a clock of its own. Per receiver the "
            f"offset's change against its median over the {_O.baseline_s:g} s ending {_O.guard_s:g} s before, "
            f"against max({_O.z_alarm:g} robust sigma, {_O.min_step_s:g} s), the sigma from fix-to-fix differences "
            f"(a step moves one of them, however long the attack lasts); {_O.min_fixes} fixes over at least "
            f"{_O.min_duration_s:g} s open an alarm, which lasts while the offset stays off the baseline frozen "
            "where it opened; the onset interval runs from the last fix on the old time to the first on the new "
            "one, and the return to the old time is no second step. Two steps are findings, not alarms: UTC "
            f"moving back by exactly 1 to {_O.max_leap_s} s in the receiver's first {_O.leap_window_s / 60:g} "
            "minutes, held to the log's end (a receiver that started with an old firmware's default leap seconds "
            "learns the broadcast ones within 12.5 min; no default is ahead of today's 18), and a step of the "
            "logger's clock (the receiver's time advanced by a fix period between two fixes, the logger's did "
            "not: a host clock set by NTP; only where the log's clock is a host's, never against a monotonic boot "
            "clock). A receiver's time given in whole seconds (or halves) and read at instants of a cycle of its own "
            "(an NMEA 2000 gateway that sends 129029 with the second it was assembled in every 1.005 s) saws: the "
            "offset drifts as the reading instant slides through the second and wraps back by one second each time "
            "it crosses one. Where most of the receiver's times are whole steps of such a resolution, the offset "
            "drifts steadily and wraps by one step against the drift, no more often than the drift accounts for, "
            "the alarm level is raised by the resolution (the offset and its baseline both lie within one step "
            "of it) and the sawtooth is a finding. A spoofer's time moves the whole band and keeps it there; moves "
            "within the resolution are not seen. A spoofer synchronised to GNSS time, or a meaconer's microseconds "
            "of delay, is not seen.",
            p_false_alarm="rule thresholds: none seen on real logs",
            threshold=f"max({_O.z_alarm:g} robust sigma, {_O.min_step_s:g} s) for {_O.min_fixes} fixes and "
            f"{_O.min_duration_s:g} s (plus the resolution of a sawing coarse time)",
            checked="Real clean logs: the ArduPilot flight `flightdata_center_0003.bin` (5 Hz GPS rows, robust "
            "sigma 20 ms), the Pixel 6 GnssLogger fixes (1 ms) and its NMEA (16 ms) raise nothing; the ArduPilot "
            "flight with `inject --attack capture:start=20,drag=step,offset=300,clock=3600.5` is SPOOFING, high "
            "(GNSS-only, receiver self-report and log clock), from 24.0 s to the end; the Pixel 6 log with "
            "`capture:start=200,clock=-30.5` alarms from the first fix after the takeover (204 s, interval "
            "198-204 s). The Aava's NMEA 2000 capture `corpus/signalk/aava-n2k.data` (129029 times to the whole "
            "second, sent every 1.005 s: -5 ms/s, three wraps) raises nothing but the sawtooth's finding, where "
            "its wraps were four log-clock incidents; the same capture with a spoofer 30 s or -2 s off GNSS "
            "time from 200 s (attacked in the table) is SPOOFING, high, from the takeover "
            "(`tests/detectors/test_receiver_time.py`).",
        ),
    ),
)
