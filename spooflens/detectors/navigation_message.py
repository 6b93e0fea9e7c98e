"""The satellites' own navigation messages as a receiver decoded them from the signals in the log: their
time, their age and orbit jumps. Declared in `ANALYSIS` (docs/detectors.md)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spooflens.detectors.base import Alarm, DetectorResult, Finding, Series
from spooflens.gnss.ephemeris import GpsEphemerides, record_positions
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo

NAME = "navigation_message"


@dataclass(frozen=True)
class NavigationMessageOptions:
    max_offset_s: float = 30.0
    max_age_s: float = 4 * 3600.0
    max_jump_m: float = 100.0


def _describe_s(seconds: float) -> str:
    a = abs(seconds)
    return f"{a / 86400:.1f} days" if a >= 86400 else f"{a / 3600:.1f} h" if a >= 3600 else f"{a:.0f} s"


def _describe_m(metres: float) -> str:
    return f"{metres / 1000:.1f} km" if metres >= 1000 else f"{metres:.0f} m"


@dataclass(frozen=True)
class _Check:
    alarms: list[Alarm]
    findings: list[Finding]


def _orbit_jumps(
    eph: GpsEphemerides, order: np.ndarray, t_of: float, end_s: float, opts: NavigationMessageOptions
) -> _Check:
    """One satellite's records in reception order: a new record that disagrees with the last trusted one."""
    alarms: list[Alarm] = []
    findings: list[Finding] = []
    trusted = int(order[0])
    suspect_from: float | None = None
    worst = 0.0
    sv = str(eph.sv_id[trusted])
    for i in (int(k) for k in order[1:]):
        if abs(float(eph.toe_s[i] - eph.toe_s[trusted])) > opts.max_age_s:
            if suspect_from is None:
                trusted = i  # the trusted orbit is out of its fit span there: nothing to compare with
            continue
        t = np.array([eph.toe_s[i]])
        p_new, c_new = record_positions(eph, np.array([i]), t)
        p_old, c_old = record_positions(eph, np.array([trusted]), t)
        jump = float(max(np.linalg.norm(p_new - p_old), abs((c_new - c_old)[0])))
        received = float(eph.received_s[i]) - t_of
        if jump > opts.max_jump_m:
            if suspect_from is None:
                suspect_from, worst = received, jump
            worst = max(worst, jump)
            continue
        if suspect_from is not None:  # back to an orbit that agrees with the trusted one
            alarms.append(Alarm(suspect_from, received, worst, suspect_from, suspect_from, satellites=(sv,)))
            findings.append(_jump_finding(sv, suspect_from, received, worst))
            suspect_from = None
        trusted = i
    if suspect_from is not None:
        alarms.append(Alarm(suspect_from, end_s, worst, suspect_from, suspect_from, satellites=(sv,)))
        findings.append(_jump_finding(sv, suspect_from, end_s, worst))
    return _Check(alarms, findings)


def _jump_finding(sv: str, start: float, end: float, jump: float) -> Finding:
    return Finding(
        f"{sv}'s broadcast orbit jumped {_describe_m(jump)} at {start:.1f} s: its new ephemeris disagrees with "
        "the one it broadcast before (a counterfeit navigation message)",
        start,
        end,
        (sv,),
    )


def _flagged(
    eph: GpsEphemerides, order: np.ndarray, bad: np.ndarray, t_of: float, end_s: float, what: str, value: np.ndarray
) -> _Check:
    """Records of one satellite flagged by a per-record test: from the first bad one's reception to the
    next good one's (or the log's end)."""
    alarms: list[Alarm] = []
    findings: list[Finding] = []
    sv = str(eph.sv_id[order[0]])
    received = eph.received_s[order] - t_of
    flags = bad[order]
    k = 0
    while k < len(order):
        if not flags[k]:
            k += 1
            continue
        start = k
        while k < len(order) and flags[k]:
            k += 1
        end = float(received[k]) if k < len(order) else end_s
        peak = float(np.max(np.abs(value[order[start:k]])))
        alarms.append(
            Alarm(float(received[start]), end, peak, float(received[start]), float(received[start]), satellites=(sv,))
        )
        findings.append(Finding(f"{sv}: {what} {_describe_s(peak)}", float(received[start]), end, (sv,)))
    return _Check(alarms, findings)


def run_navigation_message(ctx: AnalysisContext, opts: NavigationMessageOptions | None = None) -> DetectorResult:
    opts = opts or NavigationMessageOptions()
    table = ctx.table
    eph = table.ephemerides
    origin = table.gps_seconds(0.0)
    if eph is None or origin is None or not np.isfinite(eph.received_s).any():
        return DetectorResult.skipped(
            NAME, "no navigation messages decoded from the log's signals", Evidence.RAW_MEASUREMENT
        )
    t_of = float(np.asarray(origin).reshape(-1)[0])
    end_s = table.duration_s
    offset = eph.message_offset_s
    age = eph.toe_s - eph.received_s
    late = np.isfinite(offset) & (np.abs(offset) > opts.max_offset_s)
    stale = np.isfinite(age) & (np.abs(age) > opts.max_age_s)
    result = DetectorResult(NAME, ran=True, evidence=Evidence.RAW_MEASUREMENT)
    received = np.isfinite(eph.received_s)
    for sv in sorted(set(eph.sv_id[received].tolist())):
        idx = np.flatnonzero((eph.sv_id == sv) & received)
        order = idx[np.argsort(eph.received_s[idx], kind="stable")]
        for check in (
            _flagged(eph, order, late, t_of, end_s, "navigation message time off the receiver's clock by", offset),
            _flagged(eph, order, stale, t_of, end_s, "broadcast an ephemeris whose toe is from the time received", age),
            _orbit_jumps(eph, order, t_of, end_s, opts),
        ):
            result.alarms += check.alarms
            result.findings += check.findings
    t = eph.received_s[received] - t_of
    k = np.argsort(t)
    result.series.append(Series("message_time_offset", t[k], np.abs(offset[received][k]), "s", opts.max_offset_s))
    result.alarms.sort(key=lambda a: a.start_s)
    result.reason = (
        f"{int(received.sum())} ephemerides of {len(set(eph.sv_id[received].tolist()))} satellites decoded from "
        f"the signals; message time within {opts.max_offset_s:g} s, toe within {opts.max_age_s / 3600:g} h, "
        f"successive orbits within {opts.max_jump_m:g} m"
    )
    return result


_O = NavigationMessageOptions()
ANALYSIS = AnalysisSpec(
    NAME,
    "the satellites' navigation messages as decoded from the log's signals: time, age and orbit jumps",
    ("received_ephemerides",),
    lambda ctx: [run_navigation_message(ctx)],
    (
        DetectorInfo(
            NAME,
            Evidence.RAW_MEASUREMENT,
            "navigation messages a spoofer wrote: off the receiver's clock, another day's orbit, or an orbit jump",
            method="A counterfeit signal carries a navigation message the spoofer wrote (open SDR spoofers broadcast "
            "orbits from a RINEX file of another day, re-dated or not). Where the receiver passes the messages on "
            "(u-blox RXM-SFRBX, GnssLogger Nav: GPS LNAV and Galileo I/NAV; never the orbits of an RTCM3 stream, "
            "which a base station received), three checks per satellite need nothing but the messages and the "
            f"receiver's clock: a subframe's own time (its HOW) more than {_O.max_offset_s:g} s from the "
            "receiver's GPS time when it came (a real one is on time to the output latency, about a second); an "
            f"ephemeris whose toe is more than {_O.max_age_s / 3600:g} h from its reception (another day's orbit); "
            "a new ephemeris disagreeing with the satellite's previous one by more than "
            f"{_O.max_jump_m:g} m in position or clock at the new toe (each upload is a fit to one orbit), flagged "
            "until the satellite's message agrees with the trusted one again. Its references are the satellite's "
            "own earlier broadcast and the receiver's clock, kept by every other satellite.",
            p_false_alarm="rule thresholds far outside what real broadcasts do",
            threshold=f"{_O.max_offset_s:g} s; {_O.max_age_s / 3600:g} h; {_O.max_jump_m:g} m",
        ),
    ),
)
