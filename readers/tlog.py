"""MAVLink telemetry logs (`.tlog`, as Mission Planner and QGroundControl record them) into an EpochTable.

A tlog is the ground station's copy of the vehicle's telemetry: each MAVLink packet (v1 or v2) is
preceded by the 8-byte big-endian UNIX microsecond time the ground station received it. pymavlink's
`mavlogfile` parses it (built directly: `mavutil.mavlink_connection` would execute a path that looks
like a program). Only the vehicle that sent most GPS_RAW_INT messages is read.

- `GPS_RAW_INT` (receiver `GPS_RAW_INT`) and `GPS2_RAW` (receiver `GPS2_RAW`) -> fixes: lat/lon 1e-7
  deg, `alt_ellipsoid` (mm) when sent, else the AMSL `alt` (metadata says which), ground speed and
  course -> horizontal ENU velocity, `eph`/`epv` -> hdop/vdop, `h_acc`/`v_acc`/`vel_acc`,
  `satellites_visible`, `fix_type` (0-1 no fix: dropped).
- `SCALED_IMU`, `SCALED_IMU2`, `SCALED_IMU3` (mG, mrad/s; ArduPilot's `RAW_IMU` carries the same
  scaled values and is used when no SCALED_IMU is there) -> IMU, body FRD; `ATTITUDE` (NED Euler
  angles) -> the quaternion columns, as for DataFlash ATT.
- `EKF_STATUS_REPORT` (ArduPilot: velocity, horizontal position and height "variances", which are the
  square roots of its EKF's test ratios) and `ESTIMATOR_STATUS` (PX4: `vel_ratio`, `pos_horiz_ratio`,
  `pos_vert_ratio`) -> the `autopilot_ekf` frame's test ratios (no innovations: telemetry has none),
  stamped with the ground station's receive time when the message has no time of its own.
- `GLOBAL_POSITION_INT` is the autopilot's fused estimate, not a receiver: counted as not used.

Time: the messages' own boot-time stamps (`time_boot_ms`, or `time_usec` when it is not a UNIX time),
put on UTC with `SYSTEM_TIME` (the vehicle's own GPS-derived UNIX time, median offset) when it was
sent, else with the ground station's receive times (median offset; link latency included). A GPS
message whose `time_usec` is a UNIX time (ArduPilot's: the receiver's own) is placed by the ground
station's receive time less the link's latency (the median of the receive times against the boot-stamped
messages' own) instead, since a spoofer moves the receiver's time; that time against the ground
station's clock is `time_offset_s`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import os
import struct
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from readers import NothingToJudgeError, ReaderFormat
from readers.ardupilot import attitude_at
from spooflens.constants import STANDARD_GRAVITY
from spooflens.epoch_table import EpochTable, Skipped, StreamInfo, build_table, log_clock, time_offset_s
from spooflens.errors import ReaderError
from spooflens.schema import FixType

Progress = Callable[[int, int], None]
G0 = STANDARD_GRAVITY
UNIX_US_MIN = 946_684_800_000_000  # 2000-01-01: a time_usec above this is a UNIX time
_FIX = {
    2: FixType.FIX_2D,
    3: FixType.FIX_3D,
    4: FixType.DGNSS,
    5: FixType.RTK_FLOAT,
    6: FixType.RTK_FIXED,
    7: FixType.FIX_3D,
    8: FixType.DGNSS,
}
GPS_KINDS = ("GPS_RAW_INT", "GPS2_RAW")  # a fix each; the receiver id is the message's name
IMU_KINDS = ("SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3", "RAW_IMU")
WANTED = [
    *GPS_KINDS,
    *IMU_KINDS,
    "ATTITUDE",
    "SYSTEM_TIME",
    "HEARTBEAT",
    "GLOBAL_POSITION_INT",
    "EKF_STATUS_REPORT",
    "ESTIMATOR_STATUS",
    "BAD_DATA",
]
# the autopilot's GNSS test ratios (above 1: GNSS rejected) -> autopilot_ekf columns. ArduPilot's
# EKF_STATUS_REPORT calls them variances; they are the square roots of its EKF's test ratios
EKF_RATIOS = {
    "EKF_STATUS_REPORT": {
        "vel_test_ratio": "velocity_variance",
        "pos_test_ratio": "pos_horiz_variance",
        "hgt_test_ratio": "pos_vert_variance",
    },
    "ESTIMATOR_STATUS": {
        "vel_test_ratio": "vel_ratio",
        "pos_test_ratio": "pos_horiz_ratio",
        "hgt_test_ratio": "pos_vert_ratio",
    },
}
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_TYPE_GCS = 6


@dataclasses.dataclass
class Telemetry:
    """The wanted messages of a tlog: type -> [(ground station time s, source system, fields)], how many bad
    packets were met, and where each GPS message's packet starts in the file (`GPS_KINDS` -> byte
    offsets, in the order of `messages`)."""

    messages: dict[str, list[tuple[float, int, dict]]]
    bad: int
    offsets: dict[str, list[int]]
    counts: dict[str, int] = dataclasses.field(default_factory=dict)  # every kind of message met, wanted or not

    def of_system(self, system: int) -> Telemetry:
        """Only the messages (and GPS packet offsets) `system` sent."""
        kept = {k: [i for i, (_, s, _) in enumerate(v) if s == system] for k, v in self.messages.items()}
        return Telemetry(
            {k: [self.messages[k][i] for i in idx] for k, idx in kept.items()},
            self.bad,
            {k: [v[i] for i in kept.get(k, [])] for k, v in self.offsets.items()},
            self.counts,
        )


def read_telemetry(path: Path) -> Telemetry:
    """Parse `path` with pymavlink's tlog reader (never `mavlink_connection`: see the module docstring)."""
    os.environ.setdefault("MAVLINK20", "1")  # the v2 dialect parses v1 and v2 packets alike
    from pymavlink import mavutil

    mavutil.set_dialect("ardupilotmega")
    out: dict[str, list[tuple[float, int, dict]]] = {}
    offsets: dict[str, list[int]] = {k: [] for k in GPS_KINDS}
    bad = 0
    counts: dict[str, int] = {}
    wanted = set(WANTED)
    chatter = io.StringIO()
    try:
        with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
            log = mavutil.mavlogfile(str(path), robust_parsing=True)
            while True:
                m = log.recv_match()  # every kind, counted: a log of none wanted says what it holds
                if m is None:
                    break
                kind = m.get_type()
                if kind == "BAD_DATA":
                    bad += 1
                    continue
                counts[kind] = counts.get(kind, 0) + 1
                if kind not in wanted:
                    continue
                if kind in offsets:
                    offsets[kind].append(_packet_offset(log, m))
                out.setdefault(kind, []).append((float(m._timestamp), int(m.get_srcSystem()), m.to_dict()))
            log.close()
    except OSError as err:
        raise ReaderError(path, f"cannot read: {err.strerror or err}") from err
    except Exception as err:  # pymavlink raises its own and struct errors on damaged packets
        raise ReaderError(path, f"not a readable MAVLink telemetry log: {type(err).__name__}: {err}") from err
    return Telemetry(out, bad, offsets, counts)


def _packet_offset(log: Any, m: Any) -> int:
    """Where the packet `m` (just decoded) starts in the file: its bytes end where the parser's unread
    buffer begins (past damage the parser may have joined bytes across a timestamp it read: whoever
    uses the offset checks the packet is there)."""
    return int(log.f.tell() - log.mav.buf_len() - len(m.get_msgbuf()))


def _boot_us(fields: dict) -> int | None:
    if "time_boot_ms" in fields:
        return int(fields["time_boot_ms"]) * 1000
    t = int(fields.get("time_usec", 0))
    return t if 0 < t < UNIX_US_MIN else None


def _nothing_to_judge(path: Path, counts: Mapping[str, int], why: str, skipped: list[Skipped]) -> NothingToJudgeError:
    """A sound telemetry log holding nothing a detector reads, named by the messages it does hold."""
    held = sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))
    listed = ", ".join(f"{kind} x{n}" for kind, n in held[:6])
    if len(held) > 6:
        listed += f" and {len(held) - 6} more kinds"
    return NothingToJudgeError(path, f"MAVLink telemetry {why} ({listed})", "tlog", skipped)


def vehicle_of(path: Path, msgs: Mapping[str, list[tuple[float, int, dict]]]) -> int:
    """The system read: the one that sent most GPS messages, else the first vehicle heartbeat's."""
    gps_count: dict[int, int] = {}
    for kind in GPS_KINDS:
        for _, sysid, _ in msgs.get(kind, []):
            gps_count[sysid] = gps_count.get(sysid, 0) + 1
    beats = [s for _, s, f in msgs.get("HEARTBEAT", []) if f.get("type") != MAV_TYPE_GCS]
    vehicle = max(gps_count, key=lambda s: gps_count[s]) if gps_count else (beats[0] if beats else None)
    if vehicle is None:
        raise ReaderError(path, f"no vehicle GPS or heartbeat in this telemetry log (messages: {sorted(msgs)})")
    return vehicle


@dataclasses.dataclass(frozen=True)
class TlogClock:
    """The vehicle's boot clock on UTC (`offset_ns`), how it was found, and the link's latency: the ground
    station's receive times against the boot-stamped messages' own times."""

    offset_ns: int
    latency_ns: int
    description: str

    def stamp_ns(self, t_gcs: float, fields: dict) -> int:
        """A message's time: its own boot stamp on UTC, its UNIX time_usec, else its receive time."""
        b = _boot_us(fields)
        if b is not None:
            return b * 1000 + self.offset_ns
        t = int(fields.get("time_usec", 0))
        return t * 1000 if t >= UNIX_US_MIN else round(t_gcs * 1e9)


def tlog_clock(path: Path, msgs: Mapping[str, list[tuple[float, int, dict]]]) -> TlogClock:
    """The clock of one vehicle's messages: SYSTEM_TIME's offset when sent, else the receive times'."""
    # every boot-stamped message with the ground station's receive time: the clock without SYSTEM_TIME,
    # and the link's latency
    sent = [(t, b) for v in msgs.values() for t, _, f in v if (b := _boot_us(f)) is not None and t > 0]
    sys_time = [f for _, _, f in msgs.get("SYSTEM_TIME", []) if f["time_unix_usec"] > 0 and f["time_boot_ms"] > 0]
    if sys_time:
        offset_ns = int(np.median([f["time_unix_usec"] * 1000 - f["time_boot_ms"] * 1_000_000 for f in sys_time]))
        description = f"vehicle boot time + SYSTEM_TIME offset (median of {len(sys_time)})"
    else:
        if not sent:
            raise ReaderError(path, "no message carries a boot-time stamp the log can be timed by")
        offset_ns = int(np.median([t * 1e9 - b * 1000 for t, b in sent]))
        description = "vehicle boot time + median offset to the ground station's receive times (link latency included)"
    latency = int(np.median([t * 1e9 - (b * 1000 + offset_ns) for t, b in sent])) if sent else 0
    return TlogClock(offset_ns, latency, description)


def gps_rows(msgs: Mapping[str, list[tuple[float, int, dict]]], clock: TlogClock) -> pd.DataFrame:
    """One fixes row per GPS message (no-fix ones too), in the order of `msgs`, with `packet` (its index in
    `msgs[receiver_id]`), `ell` (height from alt_ellipsoid) and `unix` (placed by the receive time)."""
    fix_rows = []
    for kind in GPS_KINDS:
        rows = msgs.get(kind, [])
        gcs_ns = np.array([round(t * 1e9) for t, _, _ in rows], dtype=np.int64)
        own_ns = np.array([int(f.get("time_usec", 0)) * 1000 for _, _, f in rows], dtype=np.int64)
        # ArduPilot sends the receiver's own UNIX time: a spoofer moves it, so the row is placed by the
        # ground station's clock (less the link's latency) and the difference is `time_offset_s`
        unix = own_ns >= UNIX_US_MIN * 1000
        offsets = time_offset_s(own_ns, gcs_ns, unix)
        for i, (t_gcs, _, f) in enumerate(rows):
            fix_type = _FIX.get(int(f["fix_type"]), FixType.NO_FIX)
            ell = int(f.get("alt_ellipsoid", 0) or 0)
            vel = f["vel"] / 100.0 if f["vel"] != 65535 else np.nan
            cog = np.radians(f["cog"] / 100.0) if f["cog"] != 65535 else np.nan
            fix_rows.append(
                {
                    "t_ns": int(gcs_ns[i]) - clock.latency_ns if unix[i] else clock.stamp_ns(t_gcs, f),
                    "time_offset_s": offsets[i],
                    "receiver_id": kind,
                    "lat_deg": f["lat"] * 1e-7,
                    "lon_deg": f["lon"] * 1e-7,
                    "height_m": (ell if ell else f["alt"]) / 1000.0,
                    "ell": bool(ell),
                    "vel_e_mps": vel * np.sin(cog) if np.isfinite(cog) else (0.0 if vel == 0 else np.nan),
                    "vel_n_mps": vel * np.cos(cog) if np.isfinite(cog) else (0.0 if vel == 0 else np.nan),
                    "hdop": f["eph"] / 100.0 if f["eph"] != 65535 else np.nan,
                    "vdop": f["epv"] / 100.0 if f["epv"] != 65535 else np.nan,
                    "h_acc_m": f.get("h_acc", 0) / 1000.0 if f.get("h_acc", 0) else np.nan,
                    "v_acc_m": f.get("v_acc", 0) / 1000.0 if f.get("v_acc", 0) else np.nan,
                    "vel_acc_mps": f.get("vel_acc", 0) / 1000.0 if f.get("vel_acc", 0) else np.nan,
                    "sats_used": f["satellites_visible"] if f["satellites_visible"] != 255 else np.nan,
                    "fix_type": fix_type,
                    "packet": i,
                    "unix": bool(unix[i]),
                }
            )
    return pd.DataFrame(fix_rows)


def read_tlog(path: Path, topics: Mapping[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    path = Path(path)
    telemetry = read_telemetry(path)
    msgs = telemetry.messages
    skipped: list[Skipped] = []
    meta: dict[str, str] = {}
    if telemetry.bad:
        skipped.append(
            Skipped("<tlog>", "bytes that are no valid MAVLink packet (bad CRC, cut, garbage)", telemetry.bad, "lost")
        )
    try:
        vehicle = vehicle_of(path, msgs)
    except ReaderError:
        if telemetry.counts and not telemetry.bad:  # a ground station's own telemetry, its link to no vehicle
            why = "without a vehicle's heartbeat, GPS or IMU"
            raise _nothing_to_judge(path, telemetry.counts, why, skipped) from None
        raise
    others = sum(1 for v in msgs.values() for _, s, _ in v if s != vehicle)
    if others:
        skipped.append(Skipped("<tlog>", f"messages of other systems than vehicle {vehicle}", others))
    msgs = telemetry.of_system(vehicle).messages
    beats = [f for _, _, f in msgs.get("HEARTBEAT", []) if f.get("type") != MAV_TYPE_GCS]
    ardupilot = any(f.get("autopilot") == MAV_AUTOPILOT_ARDUPILOTMEGA for f in beats)
    meta["vehicle"] = f"system {vehicle}" + (" (ArduPilot)" if ardupilot else "")
    if not any(kind in msgs for kind in (*GPS_KINDS, *IMU_KINDS)) and not telemetry.bad:
        # a vehicle that streamed status alone (a link at its slowest rates, a bench session): nothing to time
        # or judge, though the log is sound
        raise _nothing_to_judge(path, telemetry.counts, "without a GPS or IMU message", skipped)
    clock = tlog_clock(path, msgs)
    offset_ns, stamp_ns = clock.offset_ns, clock.stamp_ns
    meta["clock"] = clock.description
    frames: dict[str, pd.DataFrame] = {}
    streams: list[StreamInfo] = []
    fixes = gps_rows(msgs, clock)
    if len(fixes):
        if fixes["unix"].any():
            meta |= log_clock("the ground station's receive time, less the link latency", False)
        no_fix = fixes["fix_type"] == FixType.NO_FIX
        for rid in fixes.loc[no_fix, "receiver_id"].unique():
            skipped.append(
                Skipped(str(rid), "fix_type 0-1 (no fix)", int((no_fix & (fixes["receiver_id"] == rid)).sum()))
            )
        fixes = fixes[~no_fix]
        meta["height"] = (
            "ellipsoidal (alt_ellipsoid)" if fixes["ell"].all() else "AMSL (alt): the vehicle sent no alt_ellipsoid"
        )
        frames["fixes"] = fixes.drop(columns=["ell", "packet", "unix"]).astype({"fix_type": np.int8})
        for rid in fixes["receiver_id"].unique():
            streams.append(
                StreamInfo("fix", str(rid), str(rid), f"mavlink/{rid}", int((fixes["receiver_id"] == rid).sum()))
            )
    if progress:
        progress(1, 2)
    imu_kinds = [k for k in IMU_KINDS[:3] if msgs.get(k)]
    if not imu_kinds and msgs.get("RAW_IMU"):
        if ardupilot:
            imu_kinds = ["RAW_IMU"]
        else:
            skipped.append(
                Skipped(
                    "RAW_IMU", "raw sensor units of an unknown autopilot (ArduPilot's are scaled)", len(msgs["RAW_IMU"])
                )
            )
    att = msgs.get("ATTITUDE", [])
    att_cols = None
    if att:
        att_cols = {
            "TimeUS": np.array([(stamp_ns(t, f) - offset_ns) // 1000 for t, _, f in att], dtype=np.int64),
            "Roll": np.degrees([f["roll"] for _, _, f in att]),
            "Pitch": np.degrees([f["pitch"] for _, _, f in att]),
            "Yaw": np.degrees([f["yaw"] for _, _, f in att]),
        }
    imu_parts = []
    for kind in imu_kinds:
        rows = msgs[kind]
        t_ns = np.array([stamp_ns(t, f) for t, _, f in rows], dtype=np.int64)
        q = attitude_at(att_cols, (t_ns - offset_ns) // 1000)
        df = pd.DataFrame(
            {
                "t_ns": t_ns,
                "imu_id": kind,
                "ax_mps2": [f["xacc"] * G0 / 1000 for _, _, f in rows],
                "ay_mps2": [f["yacc"] * G0 / 1000 for _, _, f in rows],
                "az_mps2": [f["zacc"] * G0 / 1000 for _, _, f in rows],
                "wx_radps": [f["xgyro"] / 1000 for _, _, f in rows],
                "wy_radps": [f["ygyro"] / 1000 for _, _, f in rows],
                "wz_radps": [f["zgyro"] / 1000 for _, _, f in rows],
                "qw": q[:, 0],
                "qx": q[:, 1],
                "qy": q[:, 2],
                "qz": q[:, 3],
            }
        )
        imu_parts.append(df)
        streams.append(StreamInfo("imu", kind, kind, f"mavlink/{kind}", len(df), body_frame="FRD"))
    if imu_parts:
        frames["imu"] = pd.concat(imu_parts, ignore_index=True)
    ekf_parts = []
    for kind, columns in EKF_RATIOS.items():
        rows = msgs.get(kind, [])
        if rows:
            ratios = {col: [float(f.get(name, np.nan)) for _, _, f in rows] for col, name in columns.items()}
            stamps = [stamp_ns(t, f) for t, _, f in rows]
            ekf_parts.append(pd.DataFrame({"t_ns": stamps, "source": f"autopilot ({kind})"} | ratios))
            streams.append(StreamInfo("autopilot_ekf", kind, kind, f"mavlink/{kind} (test ratios)", len(rows)))
    if ekf_parts:
        frames["autopilot_ekf"] = pd.concat(ekf_parts, ignore_index=True)
    if msgs.get("GLOBAL_POSITION_INT"):
        skipped.append(
            Skipped(
                "GLOBAL_POSITION_INT",
                "the autopilot's fused position, not a GNSS receiver",
                len(msgs["GLOBAL_POSITION_INT"]),
            )
        )
    if topics:
        skipped.append(Skipped("<tlog>", f"--topic ignored for telemetry logs ({dict(topics)})", len(topics)))
    if not frames:
        raise ReaderError(
            path, f"no GPS_RAW_INT, GPS2_RAW or IMU message in this telemetry log (messages: {sorted(msgs)})"
        )
    table = build_table(path, "tlog", "unix", frames, streams, skipped, metadata=meta)
    if progress:
        progress(2, 2)
    return table


def packet_length(head: bytes, at: int) -> int | None:
    """Length of the MAVLink packet starting at `at` (v1 0xFE or v2 0xFD), None if there is none."""
    if at + 3 > len(head):
        return None
    stx, n = head[at], head[at + 1]
    if stx == 0xFE:
        return 6 + n + 2
    if stx == 0xFD:
        return 10 + n + 2 + (13 if head[at + 2] & 1 else 0)
    return None


def _is_tlog(path: Path, head: bytes) -> bool:
    """Two consecutive records: a plausible UNIX microsecond time, then a MAVLink packet."""
    if path.is_dir() or len(head) < 16:
        return False
    at = 0
    for _ in range(2):
        if at + 8 > len(head):
            return at > 0
        (t_us,) = struct.unpack(">Q", head[at : at + 8])
        if not UNIX_US_MIN <= t_us <= 4_102_444_800_000_000:  # 2000 - 2100
            return False
        n = packet_length(head, at + 8)
        if n is None:
            return False
        at += 8 + n
    return True


FORMATS = (
    ReaderFormat(
        "tlog",
        "MAVLink telemetry log (.tlog)",
        read_tlog,
        _is_tlog,
        rewrite="spooflens.writers.tlog_rewrite:rewrite_tlog",
    ),
)
