"""u-blox UBX captures (a receiver's binary output, often mixed with NMEA and RTCM3) to an EpochTable.

One file is one receiver (`ubx`). The capture is framed (`frames.py`: every checksum verified, what is
not UBX counted), and each message the reader uses is mapped in `messages.py`:

- `satellites` from NAV-SAT: per satellite and epoch its C/N0, elevation, azimuth, pseudorange
  residual, whether the receiver used it, and its health, as the receiver reports them.
- `fixes` from NAV-PVT (position, NED velocity, hAcc/vAcc/sAcc, numSV, fixType), with, at the same
  iTOW, NAV-DOP (hdop, vdop), NAV-SAT (`cn0_mean_dbhz`) and NAV-STATUS (`spoofing_state` raw,
  `spoofing_flag` decoded); MON-RF (block 0) or MON-HW (`jamming_state`, `agc`, `noise_per_ms`,
  `jamming_indicator`) and SEC-SIG (jamming/spoofing state per signal) join the epoch they follow in
  the stream (they carry no time). NAV-PVAT (sensor fusion) and LOG-BATCH (fixes batched in the
  receiver's memory) have NAV-PVT's layout and are read as it. An epoch without NAV-PVT is assembled from
  the messages before it (`legacy.py`: NAV-POSLLH or NAV-POSECEF/NAV-SOL position, NAV-VELNED or
  NAV-VELECEF/NAV-SOL velocity, NAV-SOL or NAV-STATUS fix type). A capture with no UBX fix takes its
  fixes from the receiver's own NMEA output in the same stream (GGA/RMC..., read by `readers.nmea`);
  with UBX fixes that NMEA is the same solution again and is counted, not used. A capture with neither
  takes them from the receiver's stored position log read back (LOG-RETRIEVEPOS: position, hAcc, height
  above mean sea level, ground speed and heading, fixType, numSV), each record at its own UTC date and
  time, sorted by it (metadata `fixes.source` says these are stored fixes, not live output); beside live
  fixes the stored log is counted, not mixed in.
- `satellites` from NAV-SVINFO (u-blox's single satellite numbering) when there is no NAV-SAT.
- `observations` from RXM-RAWX: one row per satellite (its L1-band signal, as the RINEX reader picks),
  pseudorange, Doppler (`pseudorange_rate_mps` = -Doppler x wavelength), carrier phase, C/N0, ids
  RINEX-style. A carrier only with cpValid; one the receiver says is not continuous with the
  satellite's previous epoch is marked (`carrier_arc_start`, `readers.carrier_arcs`, counted as
  flagged): halfCyc 0 (half-cycle
  unresolved), subHalfCyc toggled, lock time restarted, or another signal tracked. GPS, Galileo and
  BeiDou satellite states from the broadcast ephemerides in the capture's
  own RXM-SFRBX messages (`readers/lnav.py`, `readers/inav.py`) and in the RTCM3 stream fed to it
  (`readers/rtcm_ephemeris.py`), else from a RINEX navigation file
  (`--topic nav=FILE`, or one beside the capture covering its time), so RAIM and the raw-measurement
  detectors run on the capture.
- `receiver_status` from MON-RF/MON-HW/SEC-SIG in a capture without any fix (`_receiver_status`): the
  monitor's word with no position, at the epochs they follow (none: one output cycle per second).
- `satellites` from the NMEA GSV in the stream when the capture has no NAV-SAT (with or without fixes).
- `imu` from ESF-RAW / ESF-MEAS (gyro and accelerometer, vehicle frame FRD) when present.
- `headings` from NMEA HDT/THS in the stream (a dual-antenna receiver's heading).

Time: GPS time from NAV iTOW in the week of the first message in the file that states one (NAV-PVT
with a valid date, NAV-TIMEGPS, NAV-TIMEUTC, NAV-SOL with its week set, RXM-RAWX, TIM-TP; else the
NMEA dates in the stream): a week learned partway dates the epochs before it too, one recording
(`time_reference` "gps"). Without any, `relative` (seconds of the GPS week), said so in the metadata
and the skipped list. A capture with nothing to analyse is refused by what it holds (`refusal.py`:
time only, no fix, configuration and status). MON-VER (and a gpsd header's device line) go into
`table.metadata`, with the meaning applied to each receiver enum; empty messages are a host's polls.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from pyubx2.ubxtypes_core import UBX_MSGIDS

from readers import NothingToJudgeError, ReaderFormat
from readers.carrier_arcs import arc_starts, ublox_breaks
from readers.inav import GALILEO_GNSS_ID, InavDecoder
from readers.lnav import LnavDecoder
from readers.nmea.assembly import Assembled
from readers.orbits import ORBIT_SYSTEMS
from readers.raw_states import add_satellite_states, ephemeris_stream, nav_stream, navigation_for
from readers.rtcm_ephemeris import RTCM_EPHEMERIS, rtcm_ephemerides
from readers.ubx import messages as m
from readers.ubx.frames import Frames, UbxFrame, fletcher, split_frames
from readers.ubx.legacy import TIME_ONLY, legacy_fix
from readers.ubx.refusal import refusal
from spooflens.epoch_table import (
    EpochTable,
    Skipped,
    StreamInfo,
    build_table,
    gps_ns_of_unix_ns,
    gps_seconds_of_unix_ns,
    unix_ns_of_gps_ns,
)
from spooflens.errors import ReaderError
from spooflens.gnss.ephemeris import GpsEphemerides
from spooflens.schema import SpoofingFlag

Progress = Callable[[int, int], None]
RECEIVER = "ubx"
WEEK_S = 604_800
NS = 1_000_000_000
ESF_TICKS = (1e-3, 39.0625e-6, 1e-6)  # candidate sensor time-tag units (s)


@dataclass
class _Epoch:
    itow_ms: int
    values: dict[str, float] = field(default_factory=dict)
    has_pvt: bool = False
    pvt_seen: bool = False  # a NAV-PVT came for this epoch, fix or not: its verdict is the receiver's
    parts: dict[str, float] = field(default_factory=dict)  # a fix in parts (legacy messages), merged
    parts_from: set[str] = field(default_factory=set)  # which legacy messages gave them


@dataclass(frozen=True)
class _Stored:
    """One record of the receiver's stored position log read back (LOG-RETRIEVEPOS)."""

    entry: int  # its index in the log: the order it is retrieved in
    utc_ns: int | None  # its own UTC date and time, None when it states none
    values: dict[str, float] | None  # its fix in schema names, None when it is no fix


@dataclass
class _State:
    epochs: dict[int, _Epoch] = field(default_factory=dict)
    current: int | None = None
    pending: dict[str, float] = field(default_factory=dict)  # untimed values before the first epoch
    gps_refs: list[float] = field(default_factory=list)  # GPS seconds known from week-bearing messages
    rawx: list[m.RawxEpoch] = field(default_factory=list)
    sfrbx: list[tuple[bytes, float | None]] = field(default_factory=list)  # payload, receiver time then
    navsat: list[m.NavSat] = field(default_factory=list)
    esf: list[tuple[str, int, int | None, dict[str, float]]] = field(default_factory=list)
    metadata: dict[str, str] = field(default_factory=dict)
    used: Counter[str] = field(default_factory=Counter)
    unused: Counter[str] = field(default_factory=Counter)
    bad: Counter[str] = field(default_factory=Counter)
    first_error: str = ""
    no_fix: int = 0
    time_only: int = 0  # NAV-PVT fixType 5: a timing receiver's time-only fix
    not_fixes: Counter[str] = field(default_factory=Counter)  # legacy epochs that are no fix, by reason
    polls: Counter[str] = field(default_factory=Counter)  # empty messages: a host's poll requests
    unused_as_repeat: Counter[str] = field(default_factory=Counter)  # legacy messages beside NAV-PVT
    svinfo: list[m.NavSat] = field(default_factory=list)  # NAV-SVINFO, used when there is no NAV-SAT
    leap_s: float | None = None  # GPS - UTC as NAV-TIMEGPS reports it
    # every monitor message (MON-RF, MON-HW, SEC-SIG): the epoch it follows (None before any), its cycle
    # (a new one each time a message name repeats: a receiver sends each once per output cycle), values
    monitor: list[tuple[int | None, int, dict[str, float]]] = field(default_factory=list)
    monitor_cycle: set[str] = field(default_factory=set)
    anchor_of: str = ""  # the message that dated the capture first
    stored: list[_Stored] = field(default_factory=list)  # the stored log's records, as retrieved

    def held(self) -> Counter[str]:
        """How many of each UBX message the capture holds, used or not."""
        held: Counter[str] = Counter()
        for counts in (self.used, self.unused, self.polls, self.bad, self.unused_as_repeat):
            held.update(counts)
        return held

    def epoch(self, itow: int) -> _Epoch:
        if itow not in self.epochs:
            self.epochs[itow] = _Epoch(itow, dict(self.pending))
            self.pending.clear()
        self.current = itow
        return self.epochs[itow]

    def untimed(self, values: dict[str, float], name: str = "") -> None:
        target = self.epochs[self.current].values if self.current is not None else self.pending
        target.update(values)
        if name:
            if name in self.monitor_cycle:
                self.monitor_cycle.clear()
            self.monitor_cycle.add(name)
            cycle = (self.monitor[-1][1] + (len(self.monitor_cycle) == 1)) if self.monitor else 0
            self.monitor.append((self.current, cycle, dict(values)))


def _name(frame: UbxFrame) -> str:
    key = (frame.msg_class, frame.msg_id)
    if key in m.MSG:
        return m.MSG[key]
    name = UBX_MSGIDS.get(bytes(key))
    return str(name) if name else f"UBX 0x{frame.msg_class:02x} 0x{frame.msg_id:02x}"


def _anchor(state: _State, gps_s: float | None, name: str) -> None:
    """A GPS time the capture states (with its week): dates the whole capture from the first one."""
    if gps_s is None or not math.isfinite(gps_s) or gps_s < WEEK_S:
        return
    if not state.gps_refs:
        state.anchor_of = name
    state.gps_refs.append(gps_s)


def _handle(state: _State, frame: UbxFrame) -> None:
    name = _name(frame)
    if not frame.payload:  # every output of a receiver has a payload; an empty one is a host's poll
        state.polls[name] += 1
        return
    if name not in m.MSG.values():
        state.unused[name] += 1
        return
    if name not in m.LEGACY_FIX:
        state.used[name] += 1
    if name == "RXM-RAWX":
        raw = m.rawx(frame)
        state.rawx.append(raw)
        _anchor(state, raw.gps_s, name)
        return
    if name == "NAV-SVINFO":
        state.svinfo.append(m.nav_svinfo(frame))
        return
    if name == "RXM-SFRBX":
        state.sfrbx.append((frame.payload, state.gps_refs[-1] if state.gps_refs else None))
        return
    if name in ("ESF-RAW", "ESF-MEAS"):
        for tag, sample in m.esf_samples(name, frame):
            state.esf.append((name, tag, state.current, sample))
        return
    if name == "NAV-SAT":
        sat = m.nav_sat(frame)
        state.epoch(sat.itow_ms).values["cn0_mean_dbhz"] = sat.cn0_mean
        state.navsat.append(sat)
        return
    msg = m.parse(frame)
    if name in m.PVT_LIKE:
        epoch = state.epoch(int(msg.iTOW))
        epoch.pvt_seen = True
        values = m.pvt_values(msg)
        utc = m.pvt_utc_ns(msg)
        if utc is not None:
            _anchor(state, float(gps_seconds_of_unix_ns(utc)), name)
        if values is None:
            state.no_fix += 1
            state.time_only += int(getattr(msg, "fixType", 0) == 5)
        elif not epoch.has_pvt:  # NAV-PVAT beside NAV-PVT is the same solution
            epoch.values.update(values)
            epoch.has_pvt = True
    elif name in m.LEGACY_FIX:
        epoch = state.epoch(int(msg.iTOW))
        epoch.parts_from.add(name)
        if name == "NAV-POSLLH":
            epoch.parts.update(m.posllh_values(msg))
        elif name == "NAV-VELNED":
            epoch.parts.update(m.velned_values(msg))
        else:
            epoch.parts.update(m.ecef_values(msg))
        if name == "NAV-SOL":
            epoch.parts.update(m.fix_status(msg))
            _anchor(state, m.sol_gps_s(msg), name)
    elif name == "NAV-DOP":
        state.epoch(int(msg.iTOW)).values.update({"hdop": float(msg.hDOP), "vdop": float(msg.vDOP)})
    elif name == "NAV-STATUS":
        epoch = state.epoch(int(msg.iTOW))
        epoch.values.update(m.status_values(msg))
        status = m.fix_status(msg)
        epoch.parts.update({k: v for k, v in status.items() if k not in epoch.parts})  # NAV-SOL's first
    elif name == "NAV-TIMEGPS":
        state.epoch(int(msg.iTOW))
        if int(getattr(msg, "weekValid", 0)) and int(getattr(msg, "towValid", 0)):
            _anchor(state, int(msg.week) * WEEK_S + int(msg.iTOW) / 1000 + int(msg.fTOW) * 1e-9, name)
        if int(getattr(msg, "leapSValid", 0)):
            state.leap_s = float(msg.leapS)
    elif name == "NAV-TIMEUTC":
        state.epoch(int(msg.iTOW))
        utc = m.timeutc_utc_ns(msg)
        if utc is not None:
            _anchor(state, float(gps_seconds_of_unix_ns(utc)), name)
    elif name == "TIM-TP":
        pulse = m.tim_tp_week_tow(msg)
        if pulse is not None:
            week, tow, on_utc = pulse
            gps_s = week * WEEK_S + tow
            if on_utc:  # a week and time of week counted on UTC from the GPS epoch
                gps_s = float(gps_seconds_of_unix_ns(round((m.GPS_EPOCH_UNIX_S + gps_s) * NS)))
            _anchor(state, gps_s, name)
    elif name == "MON-RF":
        state.untimed(m.mon_rf_values(frame, msg), name)
    elif name == "MON-HW":
        state.untimed(m.mon_hw_values(msg), name)
    elif name == "SEC-SIG":
        state.untimed(m.sec_sig_values(msg), name)
    elif name == "MON-VER":
        state.metadata.update(m.mon_ver(msg))
    elif name == "LOG-RETRIEVEPOS":  # dated by itself, not by iTOW: kept apart from the live epochs
        entry = int(getattr(msg, "entryIndex", -1))
        state.stored.append(_Stored(entry, m.retrievepos_utc_ns(msg), m.retrievepos_values(msg)))


def _gps_of_itow(itows: np.ndarray, ref_s: float) -> np.ndarray:
    """GPS seconds of iTOWs (ms), each in the week that puts it within half a week of `ref_s`."""
    week0 = math.floor(ref_s / WEEK_S)
    t = week0 * WEEK_S + itows / 1000.0
    return t + WEEK_S * np.round((ref_s - t) / WEEK_S)


_FIX_COLUMNS = (
    "lat_deg",
    "lon_deg",
    "height_m",
    "vel_e_mps",
    "vel_n_mps",
    "vel_u_mps",
    "h_acc_m",
    "v_acc_m",
    "vel_acc_mps",
    "sats_used",
    "hdop",
    "vdop",
    "cn0_mean_dbhz",
    "spoofing_state",
)


def _first(values: dict[str, float], *names: str) -> float:
    return next((values[n] for n in names if math.isfinite(values.get(n, math.nan))), math.nan)


def _fix_epochs(state: _State) -> list[tuple[int, dict[str, float]]]:
    """(iTOW, values) of every epoch with a fix: NAV-PVT's (or PVAT's, LOG-BATCH's), else the one its
    legacy messages assemble; counts which legacy messages were used, and which repeated NAV-PVT."""
    out = []
    for e in state.epochs.values():
        if e.pvt_seen:
            for name in e.parts_from:
                state.unused_as_repeat[name] += 1
            if e.has_pvt:
                out.append((e.itow_ms, e.values))
            continue
        if not e.parts_from:
            continue
        fix, why = legacy_fix(e.parts)
        if fix is None:
            state.not_fixes[why] += 1
            continue
        for name in e.parts_from:
            state.used[name] += 1
        out.append((e.itow_ms, {**e.values, **fix}))
    return out


def _fixes(state: _State, epochs: list[tuple[int, dict[str, float]]], ref_s: float | None) -> pd.DataFrame | None:
    if not epochs:
        return None
    itow = np.array([i for i, _ in epochs], dtype=np.float64)
    t_s = _gps_of_itow(itow, ref_s) if ref_s is not None else itow / 1000.0
    reports = {s.itow_ms: s for s in (state.navsat or state.svinfo)}
    for e_itow, v in epochs:  # from the epoch's satellite report what the fix message did not say
        report = reports.get(e_itow)
        if report is not None:
            v.setdefault("cn0_mean_dbhz", report.cn0_mean)
            if not math.isfinite(v.get("sats_used", math.nan)):
                v["sats_used"] = float(np.nansum(report.rows["used"]))
    return _fix_frame(np.round(t_s * NS).astype(np.int64), [v for _, v in epochs])


def _fix_frame(t_ns: np.ndarray, rows: list[dict[str, float]]) -> pd.DataFrame:
    """The fixes frame of the receiver's fixes (schema names, monitor values by preference) at `t_ns`."""
    cols: dict[str, Any] = {"t_ns": t_ns, "receiver_id": RECEIVER}
    for c in _FIX_COLUMNS:
        cols[c] = np.array([e.get(c, math.nan) for e in rows])
    cols["fix_type"] = np.array([e["fix_type"] for e in rows]).astype(np.int8)
    sec_spoof = np.array([e.get("sec_spoofing_state", math.nan) for e in rows])
    cols["spoofing_state"] = np.where(np.isfinite(cols["spoofing_state"]), cols["spoofing_state"], sec_spoof)
    cols["spoofing_flag"] = np.array([int(m.spoofing_flag(s)) for s in cols["spoofing_state"]], dtype=np.int8)
    for out, names in _MONITOR_COLUMNS.items():
        cols[out] = np.array([_first(e, *names) for e in rows])
    return pd.DataFrame(cols)


# each indicator column and the monitor values it is taken from, in order of preference
_MONITOR_COLUMNS = {
    "jamming_state": ("sec_jamming_state", "rf_jamming_state", "hw_jamming_state"),
    "noise_per_ms": ("noise_per_ms", "hw_noise_per_ms"),
    "agc": ("agc", "hw_agc"),
    "jamming_indicator": ("jamming_indicator", "hw_jamming_indicator"),
}


# what the messages spooflens reads no column from are, where the type's name does not say it
UNUSED_WHY = {
    "LOG-RETRIEVEPOSEXTRA": "the stored log's odometer records (distance travelled: no column for it)",
    "LOG-RETRIEVESTRING": "text the host wrote into the receiver's stored log",
}
STORED = "LOG-RETRIEVEPOS"
STORED_SOURCE = (
    "the receiver's stored position log read back (UBX LOG-RETRIEVEPOS): fixes it recorded earlier, not its "
    "live output; each at its own UTC date and time (whole seconds)"
)


def _stored_log_fixes(
    state: _State, live: bool, skipped: list[Skipped], metadata: dict[str, str]
) -> pd.DataFrame | None:
    """The fixes of the receiver's stored log on GPS time, from each record's own date, sorted by it: the log
    is retrieved in entry order, which a log that wrapped (oldest entries overwritten) does not keep in time.
    None beside `live` fixes: the receiver's past and its present are not one stream."""
    if not state.stored:
        return None
    if live:
        why = "the receiver's stored log read back beside its live fixes (not mixed into them)"
        skipped.append(Skipped(STORED, why, len(state.stored)))
        return None
    no_fix = sum(r.values is None for r in state.stored)
    if no_fix:
        skipped.append(Skipped(STORED, "stored-log records without a fix (fixType 0 or 5)", no_fix))
    undated = sum(r.values is not None and r.utc_ns is None for r in state.stored)
    if undated:
        skipped.append(Skipped(STORED, "stored-log records without a valid date and time", undated))
    fixes = [(r.utc_ns, r.entry, r.values) for r in state.stored if r.values is not None and r.utc_ns is not None]
    if not fixes:
        return None
    utc = np.array([u for u, _, _ in fixes], dtype=np.int64)
    backwards = int((np.diff(utc) < 0).sum())
    if backwards:
        why = "stored-log records retrieved in entry order, not in time order: sorted by their own date and time"
        skipped.append(Skipped(STORED, why, backwards, "repaired"))
        metadata["fixes.order"] = f"{why} (time went backwards {backwards} times in entry order)"
    order = np.argsort(utc, kind="stable")
    skipped.append(
        Skipped(
            STORED,
            "height above mean sea level (hMSL, no geoid separation): taken as the ellipsoidal height "
            "(error up to ~100 m)",
            len(fixes),
            "repaired",
        )
    )
    metadata["fixes.source"] = STORED_SOURCE
    return _fix_frame(gps_ns_of_unix_ns(utc[order]), [fixes[i][2] for i in order.tolist()])


def _count_undated_beside_stored(skipped: list[Skipped], *frames: pd.DataFrame | None) -> None:
    """The live rows of a capture that dates nothing of its own (seconds of an unknown week) are left out:
    nothing puts them on the stored log's clock, and a guessed week would misplace them."""
    for frame in frames:
        if frame is not None:
            why = "live output of a capture that states no date, beside the stored log's dated fixes: no clock for it"
            skipped.append(Skipped(RECEIVER, why, len(frame), "undated"))


def _receiver_status(state: _State, ref_s: float | None) -> tuple[pd.DataFrame | None, str]:
    """The monitor messages of a capture without a fix, one row per output instant: at the epoch they
    follow (the first epoch's for those before it); in a capture that has no epoch at all, one output
    cycle per second in the order received (u-blox's default rate; said in the metadata)."""
    if not state.monitor:
        return None, ""
    first = next(iter(state.epochs), None)
    merged: dict[tuple[int, int], dict[str, float]] = {}
    for itow, cycle, values in state.monitor:
        itow = itow if itow is not None else first
        key = (0, itow) if itow is not None else (1, cycle)
        merged.setdefault(key, {}).update(values)
    keys = list(merged)
    rows = list(merged.values())
    timed = np.array([k[0] == 0 for k in keys])
    if timed.all():
        itows = np.array([k[1] for k in keys], dtype=np.float64)
        t_s = _gps_of_itow(itows, ref_s) if ref_s is not None else itows / 1000.0
        how = "each at the navigation epoch it follows"
    else:
        t_s = np.array([k[1] for k in keys], dtype=np.float64)
        how = "no time in the capture: one output cycle per second, in the order received"
    cols: dict[str, Any] = {"t_ns": np.round(t_s * NS).astype(np.int64), "receiver_id": RECEIVER}
    for out, names in _MONITOR_COLUMNS.items():
        cols[out] = np.array([_first(e, *names) for e in rows])
    cols["spoofing_state"] = np.array([_first(e, "sec_spoofing_state") for e in rows])
    return pd.DataFrame(cols), how


def _observations(state: _State, ref_s: float | None, skipped: list[Skipped]) -> tuple[pd.DataFrame | None, int]:
    parts = []
    no_pr = 0
    for epoch in state.rawx:
        rows = m.rawx_rows(epoch)
        keep = np.isfinite(rows["pseudorange_m"])
        no_pr += int((~keep).sum())
        t_s = epoch.gps_s
        if t_s < WEEK_S:  # week 0: a receiver that does not know its week yet; the capture's own date
            t_s = float(_gps_of_itow(np.array([t_s * 1000.0]), ref_s)[0]) if ref_s is not None else t_s
        parts.append(pd.DataFrame({k: v[keep] for k, v in rows.items()}).assign(t_ns=round(t_s * NS)))
    if not parts:
        return None, 0
    df = pd.concat(parts, ignore_index=True)
    df["receiver_id"] = RECEIVER
    # the receiver's word on each carrier's continuity: lock time, half-cycle state, signal tracked
    sv, t_ns = df["sv_id"].to_numpy(), df["t_ns"].to_numpy(np.int64)
    trk, lock, sig = (df.pop(c).to_numpy() for c in m.RAWX_TRACKING)
    breaks = ublox_breaks(sv, t_ns, trk, lock, sig)
    df["carrier_arc_start"] = arc_starts(RECEIVER, df["carrier_phase_cycles"].to_numpy(float), breaks, skipped)
    return df, no_pr


def _satellites(state: _State, ref_s: float | None) -> pd.DataFrame | None:
    """NAV-SAT (else NAV-SVINFO): what the receiver says about every satellite it tracks, one row per
    satellite and epoch."""
    reports = state.navsat or state.svinfo
    if not reports:
        return None
    itow = np.concatenate([np.full(len(s.rows["sv_id"]), s.itow_ms, dtype=np.float64) for s in reports])
    t_s = _gps_of_itow(itow, ref_s) if ref_s is not None else itow / 1000.0
    cols: dict[str, Any] = {k: np.concatenate([s.rows[k] for s in reports]) for k in reports[0].rows}
    return pd.DataFrame({"t_ns": np.round(t_s * NS).astype(np.int64), "receiver_id": RECEIVER, **cols})


def _broadcast_ephemerides(state: _State, ref_s: float | None, skipped: list[Skipped]) -> GpsEphemerides | None:
    """GPS and Galileo ephemerides decoded from the capture's RXM-SFRBX messages (None when none assemble)."""
    if not state.sfrbx:
        return None
    lnav, inav = LnavDecoder(), InavDecoder()
    bad = 0
    for payload, now in state.sfrbx:
        when = ref_s if now is None else now  # before the first epoch: its time
        try:
            if payload[:1] == bytes([GALILEO_GNSS_ID]):
                inav.add(payload, when)
            else:
                lnav.add(payload, ref_s, when)
        except ValueError:
            bad += 1
    if bad:
        skipped.append(Skipped("RXM-SFRBX", "subframe messages of impossible length", bad, "lost"))
    skipped.extend(lnav.dropped("RXM-SFRBX") + inav.dropped("RXM-SFRBX"))
    records = lnav.records() + inav.records()
    return GpsEphemerides.from_records(records, lnav.iono) if records else None


def _with_satellite_states(
    state: _State,
    obs: pd.DataFrame,
    path: Path,
    topics: Mapping[str, str] | None,
    ref_s: float | None,
    rtcm_frames: list[bytes],
    skipped: list[Skipped],
) -> tuple[pd.DataFrame, StreamInfo | None, GpsEphemerides | None]:
    """RAWX rows with the sv_* columns and the ephemerides used: the capture's own subframes and the
    orbits of the RTCM3 stream fed to it, else a RINEX navigation file."""
    t0_ns = int(obs["t_ns"].min())
    own = _broadcast_ephemerides(state, ref_s, skipped)
    fed, rtcm_skipped = rtcm_ephemerides(rtcm_frames, ref_s)
    skipped.extend(rtcm_skipped)
    parts = [e for e in (own, GpsEphemerides.from_records(fed) if fed else None) if e is not None]
    if parts:
        eph = parts[0] if len(parts) == 1 else GpsEphemerides.combined(parts)
        sources = [s for s, e in (("RXM-SFRBX", own), ("RTCM3 1019/1042/1046", fed)) if e]
        present = {sv[:1] for sv in eph.satellites()}
        systems = ", ".join(name for k, name in ORBIT_SYSTEMS.items() if k in present)
        stream = ephemeris_stream(eph, RECEIVER, "UBX", f"{' + '.join(sources)} ({systems})", len(eph), t0_ns)
        return add_satellite_states(obs, eph, RECEIVER, skipped), stream, eph
    reason = (
        "no GPS, Galileo or BeiDou ephemeris in the capture (RXM-SFRBX, RTCM3 1019/1042/1046) and no "
        "navigation file covers it (give one with --topic nav=FILE); no satellite states"
    )
    nav = navigation_for(path, topics, obs["t_ns"].to_numpy() / 1e9, skipped) if ref_s is not None else None
    rows = add_satellite_states(obs, nav.ephemerides if nav else None, RECEIVER, skipped, reason)
    if nav is None:
        return rows, None, None
    return rows, nav_stream(nav, t0_ns), nav.ephemerides


def _imu(state: _State, ref_s: float | None, skipped: list[Skipped]) -> pd.DataFrame | None:
    """ESF samples on GPS time: the tag unit fitted to the navigation epochs the messages follow."""
    if not state.esf:
        return None
    tags = np.array([t for _, t, _, _ in state.esf], dtype=np.float64)
    tags += np.concatenate(([0], np.cumsum(np.diff(tags) < -(2.0**31)))) * 2.0**32  # counter wrap
    itow = np.array([math.nan if c is None else c for _, _, c, _ in state.esf], dtype=np.float64)
    known = np.isfinite(itow)
    if not known.any():
        skipped.append(Skipped("ubx_esf", "IMU samples before any navigation epoch: no time", len(tags)))
        return None
    epoch_s = np.full(len(tags), np.nan)
    epoch_s[known] = _gps_of_itow(itow[known], ref_s) if ref_s is not None else itow[known] / 1000.0
    default = 39.0625e-6 if state.esf[0][0] == "ESF-RAW" else 1e-3
    tick = default
    if known.sum() > 2 and np.ptp(epoch_s[known]) > 1.0 and np.ptp(tags[known]) > 0:
        slope = np.polyfit(tags[known], epoch_s[known], 1)[0]
        if slope > 0:
            tick = min(ESF_TICKS, key=lambda c: abs(math.log(slope / c)))
    # a sample is measured after the epoch its message follows (and before the next one): the samples
    # right after an epoch bound the offset from below, so take the top of the spread (robust quantile)
    offset = float(np.quantile(epoch_s[known] - tags[known] * tick, 0.95))
    t_ns = np.round((tags * tick + offset) * NS).astype(np.int64)
    frame = pd.DataFrame([v for _, _, _, v in state.esf]).assign(t_ns=t_ns, imu_id="ubx_esf")
    state.metadata["imu.time_tag_unit_s"] = f"{tick:g}"
    skipped.append(
        Skipped(
            "ubx_esf",
            f"IMU time tags ({tick:g} s per tick) aligned to GPS time by the first samples after each "
            "navigation epoch (to within the message latency)",
            len(frame),
            "repaired",
        )
    )
    return frame


def _nmea_assembled(frames: Frames, path: Path, use_fixes: bool, skipped: list[Skipped]) -> Assembled | None:
    """The receiver's NMEA output in the stream, assembled by the NMEA reader on its own clock."""
    from readers.nmea import decode_scan
    from readers.nmea.assembly import assemble
    from readers.nmea.lines import scan_sentences

    if not frames.nmea:
        return None
    blob = b"\n".join(line.text for line in frames.nmea) + b"\n"
    part = decode_scan(scan_sentences(path, blob), "")
    out = assemble([part], [] if not use_fixes else skipped)
    if use_fixes:
        skipped.extend(s for s in part.skipped if s.reason != "sentence type spooflens does not use")
    else:
        why = "NMEA sentences in the stream: the same receiver's solution again (the UBX fixes used)"
        skipped.append(Skipped("NMEA", why, len(part.decoded)))
    return out


DAY_NS = 86_400 * NS


def _first_unix_ns(out: Assembled | None) -> int | None:
    """The earliest time of the NMEA output when it is dated (UTC ns), else None."""
    if out is None or out.time_reference != "unix":
        return None
    firsts = [int(df["t_ns"].min()) for df in (out.fixes, out.headings, out.satellites) if df is not None and len(df)]
    return min(firsts) if firsts else None


def _nmea_on_clock(
    df: pd.DataFrame | None, out: Assembled, reference: str, anchor_ns: int | None, leap_s: float
) -> pd.DataFrame | None:
    """NMEA rows moved onto the capture's clock. Dated NMEA (UTC) goes onto GPS time; undated NMEA (UTC
    seconds of its first day) onto the day of `anchor_ns` (the capture's first UBX time: GPS ns, or GPS
    seconds of the week when nothing is dated), the whole day nearest to it."""
    if df is None or not len(df):
        return None
    t = df["t_ns"].to_numpy(dtype=np.int64)
    if out.time_reference == "unix":
        return df.assign(t_ns=gps_ns_of_unix_ns(t)) if reference == "gps" else df
    if anchor_ns is None:
        return df
    if reference == "gps":
        utc_anchor = int(unix_ns_of_gps_ns(anchor_ns))
        day0 = utc_anchor - utc_anchor % DAY_NS
        t = t + day0
        t = t + round((utc_anchor - int(t.min())) / DAY_NS) * DAY_NS
        return df.assign(t_ns=gps_ns_of_unix_ns(t))
    t = t + round(leap_s * NS)  # GPS seconds of the week: UTC time of day + GPS - UTC, on the week's day
    t = t + (anchor_ns - anchor_ns % DAY_NS)
    return df.assign(t_ns=t + round((anchor_ns - int(t.min())) / DAY_NS) * DAY_NS)


def _header_metadata(comments: list[str]) -> dict[str, str]:
    """gpsd's header: its description lines, and the receiver model/firmware from its DEVICE line."""
    out: dict[str, str] = {}
    text = [c for c in comments if c and not c.startswith(("[", "{"))]
    if text:
        out["log_header"] = " | ".join(text[:12])
    for c in comments:
        if not c.startswith("["):
            continue
        try:
            devices = json.loads(c)
        except ValueError:
            continue
        for d in devices if isinstance(devices, list) else []:
            if isinstance(d, dict) and d.get("driver") == "u-blox":
                sub = ", ".join(str(d[k]) for k in ("subtype", "subtype1") if d.get(k))
                if sub:
                    out["receiver.gpsd_device"] = sub
    return out


def read_ubx(path: Path, topics: Mapping[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    """Read a u-blox UBX capture (UBX mixed with NMEA, RTCM3 and text) into an EpochTable."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as err:
        raise ReaderError(path, f"cannot read: {err.strerror or err}") from err
    if not data:
        raise ReaderError(path, "file is empty (0 bytes)")
    frames = split_frames(data)
    state = _State()
    for i, frame in enumerate(frames.ubx):
        try:
            _handle(state, frame)
        except m.ParseErrors as err:
            name = _name(frame)
            state.bad[name] += 1
            state.first_error = state.first_error or f"{name} at byte {frame.offset}: {err}"
        if progress and i % 2000 == 0:
            progress(i, len(frames.ubx))
    skipped: list[Skipped] = []
    unused_topics = {k: v for k, v in (topics or {}).items() if k != "nav"}
    if unused_topics:
        note = f"--topic other than nav= is not used for UBX logs ({unused_topics})"
        skipped.append(Skipped("<ubx>", note, len(unused_topics)))
    for what, n in frames.bad.items():
        skipped.append(Skipped("UBX", what, n, "lost"))
    if frames.garbage_bytes:
        skipped.append(
            Skipped("bytes", "bytes that are no UBX, NMEA or RTCM3 frame (cut frames, garbage)", frames.garbage_bytes)
        )
    for num, n in sorted(frames.rtcm.items()):
        if num not in RTCM_EPHEMERIS:
            skipped.append(Skipped(f"RTCM3 {num}", "RTCM3 corrections fed to the receiver (not used)", n))
    for name, n in sorted(state.unused.items()):
        skipped.append(Skipped(name, UNUSED_WHY.get(name, "UBX message type spooflens does not use"), n))
    for name, n in sorted(state.polls.items()):
        skipped.append(Skipped(name, "poll requests the host sent to the receiver (no data)", n))
    for name, n in state.bad.items():
        skipped.append(Skipped(name, f"UBX messages pyubx2 cannot decode ({state.first_error})", n, "lost"))
    if state.no_fix:
        why = "NAV-PVT without a fix (fixType 0/5, gnssFixOK 0 or invalid position)"
        skipped.append(Skipped(RECEIVER, why, state.no_fix))

    fix_epochs = _fix_epochs(state)
    for why, n in sorted(state.not_fixes.items()):
        skipped.append(Skipped(RECEIVER, f"epochs whose position messages are no fix: {why}", n))
    for name, n in sorted(state.unused_as_repeat.items()):
        skipped.append(Skipped(name, "the epoch's NAV-PVT says it all (its solution, or that there is none)", n))
    if state.navsat and state.svinfo:
        why = "satellite reports beside NAV-SAT's (NAV-SAT used)"
        skipped.append(Skipped("NAV-SVINFO", why, len(state.svinfo)))
    nmea = _nmea_assembled(frames, path, not fix_epochs, skipped)
    metadata: dict[str, str] = {}
    live = bool(fix_epochs) or (nmea is not None and nmea.fixes is not None)
    stored_fixes = _stored_log_fixes(state, live, skipped, metadata)
    ref_s = state.gps_refs[0] if state.gps_refs else None
    nmea_utc = _first_unix_ns(nmea)
    if ref_s is None and nmea_utc is not None:  # the receiver's NMEA dates give the week
        ref_s = float(gps_seconds_of_unix_ns(nmea_utc))
        state.anchor_of = "the NMEA dates (RMC/ZDA) in the stream"
    reference = "gps" if ref_s is not None else "relative"
    if ref_s is not None:
        metadata["clock"] = f"GPS time: iTOW in the week of {state.anchor_of}, the capture's first dated message"
    elif stored_fixes is not None:
        reference = "gps"
        metadata["clock"] = "GPS time: each stored-log record's own UTC date and time (leap seconds added)"
    else:
        epochs = len(state.epochs) + len(state.rawx)
        why = (
            "no date anywhere in the capture (no week in NAV-PVT, NAV-TIMEGPS, NAV-TIMEUTC, NAV-SOL, RXM-RAWX, "
            "TIM-TP, nor an NMEA date): relative time, seconds of the GPS week"
        )
        metadata["clock"] = why
        skipped.append(Skipped("<ubx>", why, max(epochs, 1), "undated"))
    fixes = stored_fixes if stored_fixes is not None else _fixes(state, fix_epochs, ref_s)
    obs, no_pr = _observations(state, ref_s, skipped)
    nav_info, ephemerides = None, None
    if obs is not None:
        obs, nav_info, ephemerides = _with_satellite_states(
            state, obs, path, topics, ref_s, frames.rtcm_ephemerides, skipped
        )
    else:
        if state.sfrbx:
            skipped.append(
                Skipped("RXM-SFRBX", "subframes without RXM-RAWX observations to use them", len(state.sfrbx))
            )
        for num in sorted(RTCM_EPHEMERIS & set(frames.rtcm)):
            why = "RTCM3 ephemerides fed to the receiver, without RXM-RAWX observations to use them"
            skipped.append(Skipped(f"RTCM3 {num}", why, frames.rtcm[num]))
    imu = _imu(state, ref_s, skipped)
    satellites = _satellites(state, ref_s)
    if stored_fixes is not None and ref_s is None:
        _count_undated_beside_stored(skipped, satellites, obs, imu)
        satellites = obs = imu = None
    headings, nmea_fixes, nmea_streams = None, None, []
    if nmea is not None:
        anchor_ns = anchor_ns_of(ref_s, fixes, obs, satellites)
        leap = leap_of(state)
        headings = _nmea_on_clock(nmea.headings, nmea, reference, anchor_ns, leap)
        nmea_streams = [s for s in nmea.streams if s.role == "heading"]
        if fixes is None:
            nmea_fixes = _nmea_on_clock(nmea.fixes, nmea, reference, anchor_ns, leap)
        placed = headings is not None or nmea_fixes is not None
        if nmea.time_reference == "relative" and anchor_ns is not None and placed:
            metadata["clock.nmea"] = "undated NMEA put on the UBX clock's day" + (
                "" if reference == "gps" else f" with GPS - UTC = {leap:g} s"
            )
        if reference == "relative" and nmea.time_reference == "unix":
            reference = "unix"  # nothing in UBX to put them on: the NMEA dates are the clock
    fixes_from_nmea = fixes is None and nmea_fixes is not None and nmea is not None
    if fixes_from_nmea and nmea_fixes is not None and nmea is not None:
        ids = dict.fromkeys(nmea_fixes["receiver_id"].astype(str))
        rename = {r: RECEIVER if len(ids) == 1 else f"{RECEIVER}/{r}" for r in ids}
        fixes = nmea_fixes.assign(receiver_id=nmea_fixes["receiver_id"].map(rename))
        nmea_streams = [
            StreamInfo(s.role, rename.get(s.stream_id, s.stream_id), "NMEA in the UBX stream", s.msgtype, s.count)
            for s in nmea.streams
            if s.role in ("fix", "heading")
        ]
    status = None
    if fixes is None:  # a receiver without a fix: what its monitors said is still read
        status, how = _receiver_status(state, ref_s)
        if status is not None:
            metadata["clock.receiver_status"] = how
    if satellites is None and nmea is not None:
        # the receiver's sky as its NMEA states it (GSV C/N0 per satellite) when no NAV-SAT does, on the
        # capture's clock as its headings are: the interference and satellite-signal tests read it
        satellites = _nmea_on_clock(nmea.satellites, nmea, reference, anchor_ns_of(ref_s, obs), leap_of(state))
        if satellites is not None:
            ids = dict.fromkeys(satellites["receiver_id"].astype(str))
            rename = {r: RECEIVER if len(ids) == 1 else f"{RECEIVER}/{r}" for r in ids}
            satellites = satellites.assign(receiver_id=satellites["receiver_id"].map(rename))
            per_receiver = satellites.groupby("receiver_id")["t_ns"].nunique()
            nmea_streams += [
                StreamInfo("satellites", str(rid), "NMEA in the UBX stream", "NMEA GSV/GSA", int(n))
                for rid, n in per_receiver.items()
            ]
    streams: list[StreamInfo] = []
    if stored_fixes is not None:
        streams.append(StreamInfo("fix", RECEIVER, "UBX stored log", f"UBX {STORED}", len(stored_fixes)))
    elif fixes is not None and not fixes_from_nmea:
        kinds = " ".join(k for k in (*m.PVT_LIKE, *m.LEGACY_FIX, "NAV-DOP", "NAV-STATUS", *_UNTIMED) if state.used[k])
        streams.append(StreamInfo("fix", RECEIVER, "UBX", f"UBX {kinds}", len(fixes)))
    streams += nmea_streams
    if obs is not None:
        streams.append(StreamInfo("observations", RECEIVER, "UBX", "UBX RXM-RAWX", len(state.rawx)))
        if no_pr:
            skipped.append(Skipped(RECEIVER, "RAWX signals without a valid pseudorange (prValid 0)", no_pr))
        if nav_info is not None:
            streams.append(nav_info)
    if imu is not None:
        streams.append(StreamInfo("imu", "ubx_esf", "UBX", "UBX ESF-RAW/ESF-MEAS", len(imu), body_frame="FRD"))
    if status is not None:
        kinds = " ".join(k for k in _UNTIMED if state.used[k])
        streams.append(StreamInfo("receiver_status", RECEIVER, "UBX", f"UBX {kinds}", len(status)))
    if satellites is not None and (state.navsat or state.svinfo):
        kind = "NAV-SAT" if state.navsat else "NAV-SVINFO"
        n_reports = len(state.navsat or state.svinfo)
        streams.append(StreamInfo("satellites", RECEIVER, "UBX", f"UBX {kind}", n_reports))
    if fixes is None and obs is None and imu is None and satellites is None and headings is None and status is None:
        # a sound capture of messages none of which is a fix (a timing receiver's, navigation messages
        # alone, a configuration session) is analysed to a NO VERDICT naming them; one of no message refused
        held = state.held()
        time_only = state.time_only + state.not_fixes[TIME_ONLY]
        why = refusal(held, time_only, state.no_fix + sum(state.not_fixes.values()), frames, nmea)
        if held or frames.nmea:
            raise NothingToJudgeError(path, why, "ubx", skipped)
        raise ReaderError(path, why, "ubx")
    metadata = {**_header_metadata(frames.comments), **state.metadata, **metadata}
    metadata |= {
        "enum.spoofing_state": m.SPOOF_MEANING,
        "enum.jamming_state": m.JAM_MEANING,
        "enum.fix_type": m.FIX_MEANING,
    }
    metadata["enum.spoofing_flag"] = f"{int(SpoofingFlag.INDICATED)} when spoofing_state >= 2"
    frames_ns = {
        "fixes": fixes,
        "observations": obs,
        "imu": imu,
        "headings": headings,
        "satellites": satellites,
        "receiver_status": status,
    }
    table = build_table(
        path,
        "ubx",
        reference,
        {k: v for k, v in frames_ns.items() if v is not None},
        streams,
        skipped,
        metadata=metadata,
    )
    table.ephemerides = ephemerides
    return table


_UNTIMED = ("MON-RF", "MON-HW", "SEC-SIG")


def anchor_ns_of(ref_s: float | None, *frames: pd.DataFrame | None) -> int | None:
    """Where undated NMEA goes: the capture's GPS time, else its first UBX time."""
    return round(ref_s * NS) if ref_s is not None else _first_ubx_ns(*frames)


def leap_of(state: _State) -> float:
    return state.leap_s if state.leap_s is not None else 18.0


def _first_ubx_ns(*frames: pd.DataFrame | None) -> int | None:
    firsts = [int(df["t_ns"].min()) for df in frames if df is not None and len(df)]
    return min(firsts) if firsts else None


def looks_like_ubx(head: bytes) -> bool:
    """The head holds at least one complete UBX frame with a valid checksum."""
    pos = head.find(b"\xb5\x62")
    while 0 <= pos <= len(head) - 8:
        length = head[pos + 4] | (head[pos + 5] << 8)
        end = pos + 8 + length
        if end <= len(head) and fletcher(head[pos + 2 : end - 2]) == head[end - 2 : end]:
            return True
        pos = head.find(b"\xb5\x62", pos + 1)
    return False


RTCM_LEAD_BYTES = 1 << 18  # an RTK rover's capture can open with a burst of corrections before any UBX


def _is_ubx(path: Path, head: bytes) -> bool:
    if not path.is_file():
        return False
    if looks_like_ubx(head):
        return True
    if not split_frames(head).rtcm:  # a capture that opens with RTCM3: look further for its UBX
        return False
    with path.open("rb") as f:
        return looks_like_ubx(f.read(RTCM_LEAD_BYTES))


FORMATS = (
    ReaderFormat(
        "ubx",
        "u-blox UBX capture (NAV-PVT, NAV-SAT, NAV-STATUS, RXM-RAWX, MON-RF, SEC-SIG, ESF; mixed NMEA/RTCM3 skipped)",
        read_ubx,
        _is_ubx,
        rewrite="spooflens.writers.ubx_rewrite:rewrite_ubx",
    ),
)
