"""PX4 ULog through pyulog: sensor_combined (IMU), vehicle_attitude (its orientation) and the GPS topics.

PX4 conventions (`readers.px4`): IMU body frame FRD; velocities NED (turned into ENU here); timestamps
in microseconds since boot. When a GPS topic carries `time_utc_usec`, the log is put on the UNIX clock
(median offset between the two clocks); otherwise the time reference is "boot". Every receiver
indicator the GPS topic defines is read (accuracies, DOPs, satellites, noise, AGC, jamming indicator and
state, spoofing and authentication state); the meaning of the state codes is taken from the message
definition written in the log and recorded in the table's metadata with the firmware version.
"""

from __future__ import annotations

import contextlib
import io
import mmap
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd
from pyulog import ULog

from readers import NothingToJudgeError, ReaderFormat
from readers.px4 import (
    ATTITUDE_TOPIC,
    BARO_TOPIC,
    EKF_TOPICS,
    GPS_TOPICS,
    IMU_TOPIC,
    PX4_LOG_CLOCK,
    SATELLITE_TOPIC,
    GpsSource,
    Record,
    autopilot_ekf_frame,
    canonical_record,
    cn0_mean,
    enum_metadata,
    firmware_description,
    gps_columns,
    interpolate_attitude,
    nearest_values,
    ned_frd_to_enu_flu,
    position_units,
    receiver_metadata,
    satellites_frame,
    select_receivers,
    utc_offset_us,
)
from readers.ros_batch import gather
from spooflens.epoch_table import EpochTable, Skipped, StreamInfo, build_table, gap_losses
from spooflens.errors import ReaderError, one_line
from spooflens.schema import FixType

Progress = Callable[[int, int], None]
# ULog info messages kept in the table's metadata as `px4.<key>`
INFO_KEYS = ("sys_name", "ver_sw_release", "ver_sw", "ver_sw_branch", "ver_hw")
# a fix takes the mean C/N0 of the satellite_info message nearest in time within this
SATELLITE_MAX_DT_US = 1_000_000
# attitude samples further apart than this are not interpolated across (PX4 logs it at 20-250 Hz)
ATTITUDE_MAX_GAP_US = 500_000


def _topics_defined(ulog: ULog) -> set[str]:
    """Topic names with a definition in the log (format names that are not only nested types)."""
    formats = ulog.message_formats
    nested = {t for f in formats.values() for (t, _, _) in f.fields if t in formats}
    return set(formats) - nested


class _MappedFile:
    """A ULog read through a memory map, as the file object pyulog takes. After damage pyulog looks for the
    next message one byte at a time, seeking back for each; on a file every seek is a system call (a 5 MB
    damaged stretch took 33 s, 12 s mapped). mmap's seek returns None where pyulog needs the position."""

    def __init__(self, mapped: mmap.mmap) -> None:
        self._mapped = mapped

    def read(self, n: int | None = -1) -> bytes:
        return self._mapped.read(n if n is not None and n >= 0 else None)

    def seek(self, pos: int, whence: Literal[0, 1, 2] = 0) -> int:
        self._mapped.seek(pos, whence)
        return self._mapped.tell()

    def tell(self) -> int:
        return self._mapped.tell()

    def close(self) -> None:
        """The map is closed by whoever opened it."""


def read_ulog(path: Path, topics: Mapping[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    path = Path(path)
    said = io.StringIO()  # pyulog prints its warnings; they belong in the damage note, not on stdout
    try:
        with (
            path.open("rb") as f,
            mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mapped,
            contextlib.redirect_stdout(said),
        ):
            ulog = ULog(
                _MappedFile(mapped),
                [IMU_TOPIC, ATTITUDE_TOPIC, SATELLITE_TOPIC, *GPS_TOPICS, *EKF_TOPICS],
                disable_str_exceptions=True,
            )
    except Exception as err:
        raise ReaderError(path, f"not a readable ULog: {one_line(err)}") from err
    skipped: list[Skipped] = []
    damage = _damage(path, ulog.file_corruption, one_line(said.getvalue()))
    decoded = {(d.name, d.multi_id) for d in ulog.data_list if len(d.data.get("timestamp", ()))}
    for (name, multi), count in damage.listed.items():
        if name in (IMU_TOPIC, *GPS_TOPICS) and (name, multi) not in decoded:
            skipped.append(Skipped(f"{name}/{multi}", "every message undecodable (its format damaged)", count, "lost"))
    data: dict[tuple[str, int], dict[str, np.ndarray]] = {}
    for d in ulog.data_list:
        if "timestamp" not in d.data:  # a damaged format message: the rows cannot be placed in time
            skipped.append(Skipped(d.name, "format damaged (no timestamp field): messages lost", 1, "lost"))
        elif d.name == IMU_TOPIC and not all(f in d.data for f in _IMU_FIELDS):
            missing = [f for f in _IMU_FIELDS if f not in d.data]
            skipped.append(
                Skipped(d.name, f"format damaged (no {missing}): messages lost", len(d.data["timestamp"]), "lost")
            )
        else:
            data[(d.name, d.multi_id)] = d.data
    info = ulog.msg_info_dict
    firmware = firmware_description(info)
    metadata: dict[str, str] = {"firmware": firmware}
    # the info messages behind it, as logged (a ULog written from this table carries them again)
    for key in INFO_KEYS:
        if isinstance(info.get(key), int):
            metadata[f"px4.{key}"] = f"0x{info[key]:08X}"
        elif isinstance(info.get(key), str) and info[key]:
            metadata[f"px4.{key}"] = info[key]
    gps_records: dict[tuple[str, int], Record] = {
        k: canonical_record(v) for k, v in data.items() if k[0] in GPS_TOPICS and len(v["timestamp"])
    }
    sources, notes = select_receivers(gps_records)
    skipped += notes
    offset = utc_offset_us([gps_records[(s.topic, s.multi_id)] for s in sources])
    offset_us, reference = (offset, "unix") if offset is not None else (0, "boot")
    frames: dict[str, pd.DataFrame] = {}
    streams: list[StreamInfo] = []
    fixes = [
        _fixes(path, s, gps_records[(s.topic, s.multi_id)], data.get((SATELLITE_TOPIC, k)), offset_us, skipped)
        for k, s in enumerate(sources)
    ]
    if fixes:
        frames["fixes"] = pd.concat([f for f, _ in fixes], ignore_index=True)
        streams += [info_ for _, info_ in fixes]
        used_topics = {s.topic for s in sources}
        definition = next(t for t in GPS_TOPICS if t in used_topics)
        metadata |= enum_metadata(
            {c for s in sources for c in gps_records[(s.topic, s.multi_id)]},
            f"the log's {definition} definition",
            firmware if "ver_sw_release" in info else "",
        )
        metadata["px4.gps_source"] = "; ".join(f"{s.receiver_id}: {s.description}" for s in sources)
        if any("time_utc_usec" in gps_records[(s.topic, s.multi_id)] for s in sources):
            metadata |= PX4_LOG_CLOCK
        metadata |= receiver_metadata([(s, gps_records[(s.topic, s.multi_id)]) for s in sources])
    skies = [
        sky
        for k, s in enumerate(sources)
        if (SATELLITE_TOPIC, k) in data
        and (sky := satellites_frame(data[(SATELLITE_TOPIC, k)], s.receiver_id, SATELLITE_TOPIC, offset_us, skipped))
    ]
    if skies:
        frames["satellites"] = pd.concat([frame for frame, _ in skies], ignore_index=True)
        streams += [sky_info for _, sky_info in skies]
    if (IMU_TOPIC, 0) in data:
        imu, info_ = _imu(data[(IMU_TOPIC, 0)], data.get((ATTITUDE_TOPIC, 0)), offset_us, skipped)
        frames["imu"] = imu
        streams.append(info_)
    elif (ATTITUDE_TOPIC, 0) in data:
        skipped.append(
            Skipped(ATTITUDE_TOPIC, "no sensor_combined to attach the orientation to", len(data[(ATTITUDE_TOPIC, 0)]))
        )
    ekf = autopilot_ekf_frame(data, offset_us)
    if ekf is not None:
        frames["autopilot_ekf"] = ekf[0]
        streams += ekf[1]
    defined = _topics_defined(ulog)
    if BARO_TOPIC in defined:
        skipped.append(Skipped(BARO_TOPIC, "barometric altitude not used (no schema column for it yet)", 1))
    used = {IMU_TOPIC, ATTITUDE_TOPIC, SATELLITE_TOPIC, *GPS_TOPICS, BARO_TOPIC, *EKF_TOPICS}
    others = sorted(defined - used)
    if others:
        skipped.append(Skipped("<ulog>", f"topics not used: {others}", len(others)))
    warnings = _gnss_log_messages(ulog)
    if warnings:
        metadata["px4.gnss_log_messages"] = warnings
    if topics:
        skipped.append(Skipped("<ulog>", f"--topic ignored for ULog ({dict(topics)})", len(topics)))
    if progress:
        progress(1, 1)
    if not frames:
        lacking = f"no {IMU_TOPIC} or GPS topic ({', '.join(GPS_TOPICS)})"
        if damage.what:
            raise ReaderError(path, f"{lacking} in this ULog ({damage.what})")
        # sound, and logged with a profile or on a bench that recorded none of them
        listed = ", ".join(sorted(defined)[:8]) + (f" and {len(defined) - 8} more" if len(defined) > 8 else "")
        raise NothingToJudgeError(path, f"PX4 ULog with {lacking} (topics: {listed or 'none'})", "ulog", skipped)
    if damage.what:
        skipped += _damage_losses(damage, frames, offset_us)
    return build_table(path, "ulog", reference, frames, streams, skipped, metadata=metadata)


# ULog message types (the spec's): a header with another type means the walk lost the message boundaries
_MESSAGE_TYPES = frozenset(b"BFIMPQARDLCSO")
_IMU_FIELDS = tuple(f"{name}[{i}]" for name in ("accelerometer_m_s2", "gyro_rad") for i in range(3))


@dataclass(frozen=True)
class _Damage:
    what: str  # "" for an undamaged file
    end_us: int | None  # the last data message's timestamp found anywhere in the file (boot µs)
    listed: dict[tuple[str, int], int]  # (topic, instance) -> data messages the walk found


def _chain(data: bytes, pos: int, links: int = 6) -> bool:
    """Do `links` message headers follow each other from `pos` (a place to re-synchronise)?"""
    for _ in range(links):
        if pos < 0 or pos + 3 > len(data) or data[pos + 2] not in _MESSAGE_TYPES:
            return False
        pos += 3 + (data[pos] | data[pos + 1] << 8)
    return pos <= len(data)


def _damage(path: Path, pyulog_corruption: bool, pyulog_said: str = "") -> _Damage:
    """How the file is damaged, and the time its last data message carries.

    pyulog re-synchronises after corrupt bytes (and may stop at a corrupt size without saying so), so the
    message boundaries are walked here too: a header of no ULog type, or a size running past the end, is
    damage; the walk then re-synchronises on the next run of headers that follow each other, so the time
    the file really ends at is known and what the reader missed at the end can be counted.
    """
    data = path.read_bytes()
    pos, n = 16, len(data)
    what = ""
    end_us: int | None = None
    subscribed: dict[int, tuple[str, int]] = {}  # msg_id -> (topic, instance), from the 'A' messages
    data_at: list[int] = []  # where each data message's msg_id and timestamp lie: read after the walk
    kind_d, kind_a = ord("D"), ord("A")
    while pos + 3 <= n:
        size, kind = data[pos] | data[pos + 1] << 8, data[pos + 2]
        if kind not in _MESSAGE_TYPES or pos + 3 + size > n:
            nxt = data.find(b"D", pos + 3)
            while nxt != -1 and not _chain(data, nxt - 2):
                nxt = data.find(b"D", nxt + 1)
            if nxt == -1:
                what = what or f"file cut short in the middle of a message at byte {pos} of {n}; what followed is lost"
                break
            what = what or f"corrupt message header at byte {pos} of {n}"
            pos = nxt - 2
            continue
        if kind == kind_d and size >= 10:
            data_at.append(pos + 3)
        elif kind == kind_a and size > 3:
            multi, msg_id = struct.unpack_from("<BH", data, pos + 3)
            subscribed[msg_id] = (data[pos + 6 : pos + 3 + size].decode("ascii", "replace"), multi)
        pos += 3 + size
    raw = np.frombuffer(data, dtype=np.uint8)
    at = np.asarray(data_at, dtype=np.int64)
    msg_ids = gather(raw, at, "u2").astype(np.int64)
    stamps = gather(raw, at + 2, "u8")
    ids, first, n_of = np.unique(msg_ids, return_index=True, return_counts=True)
    in_order = np.argsort(first)  # by first appearance, as the walk met them
    counts = dict(zip(ids[in_order].tolist(), n_of[in_order].tolist(), strict=True))
    if 0 < n - pos < 3 and not what:
        what = f"file cut short at byte {n} (a message header cut in half); what followed is lost"
    if pyulog_corruption:
        what = f"{what}; pyulog re-synchronised" if what else "pyulog found corrupt data and re-synchronised"
        what += f" ({pyulog_said})" if pyulog_said else ""
    if len(stamps):  # the data's end: a corrupt stamp among a few resynchronised messages must not set it
        t = np.sort(stamps.astype(np.uint64))
        top = int(t[int(0.999 * (len(t) - 1))])
        end_us = int(t[t <= top + 60_000_000][-1]) if top < 2**53 else None
    listed: dict[tuple[str, int], int] = {}
    for msg_id, count in counts.items():
        if msg_id in subscribed:
            listed[subscribed[msg_id]] = listed.get(subscribed[msg_id], 0) + count
    return _Damage(what, end_us, listed)


def _damage_losses(damage: _Damage, frames: Mapping[str, pd.DataFrame], offset_us: int) -> list[Skipped]:
    """The damage, and per stream the samples missing in the gaps it left and after the last sample
    the reader got, up to the last data message in the file (a damaged stretch of a file is a stretch
    of time without rows: the stream's own rate says how many went with it)."""
    out = [Skipped("<file>", damage.what, 0, "lost")]
    for frame, key in (("fixes", "receiver_id"), ("imu", "imu_id")):
        df = frames.get(frame)
        if df is None or not len(df):
            continue
        for sid, rows in df.groupby(key, sort=False):
            t = np.sort(rows["t_ns"].to_numpy(dtype=np.int64))
            end = None if damage.end_us is None else (damage.end_us + offset_us) * 1000
            missing = gap_losses(t, end_ns=end)
            if missing:
                out.append(
                    Skipped(str(sid), f"about {missing} samples missing where the file is damaged", missing, "lost")
                )
    return out


def _fixes(
    path: Path,
    source: GpsSource,
    rec: Record,
    satellites: Mapping[str, np.ndarray] | None,
    offset_us: int,
    skipped: list[Skipped],
) -> tuple[pd.DataFrame, StreamInfo]:
    rid = source.receiver_id
    units = position_units(rec, by_magnitude=False)
    if units is None:
        raise ReaderError(path, f"{source.topic} has no latitude/longitude/altitude fields", source.topic)
    rows = {k: np.asarray(v)[source.rows] for k, v in rec.items()}
    mapped = gps_columns(rows, units)
    skipped += [Skipped(rid, what, n, "repaired") for what, n in mapped.notes]
    ts = rows["timestamp"].astype(np.int64)
    description = source.description
    cn0 = cn0_mean(satellites) if satellites is not None and len(satellites["timestamp"]) else None
    if satellites is not None and cn0 is not None:
        t_sat = satellites["timestamp"].astype(np.int64)
        mapped.columns["cn0_mean_dbhz"] = nearest_values(ts, t_sat, cn0, SATELLITE_MAX_DT_US)
        description += f" + {SATELLITE_TOPIC} (mean C/N0)"
    fixes = pd.DataFrame({"t_ns": (ts + offset_us) * 1000, "receiver_id": rid} | mapped.columns)
    no_fix = fixes["fix_type"].to_numpy() == FixType.NO_FIX
    if no_fix.any():
        skipped.append(Skipped(rid, "fix_type 0-1 (no fix)", int(no_fix.sum())))
        fixes = fixes[~no_fix]
    return fixes, StreamInfo("fix", rid, source.topic, description, len(fixes))


def _imu(
    d: Mapping[str, np.ndarray], att: Mapping[str, np.ndarray] | None, offset_us: int, skipped: list[Skipped]
) -> tuple[pd.DataFrame, StreamInfo]:
    ts = d["timestamp"].astype(np.int64)
    cols: dict[str, object] = {"t_ns": (ts + offset_us) * 1000, "imu_id": IMU_TOPIC}
    for i, axis in enumerate("xyz"):
        cols[f"a{axis}_mps2"] = d[f"accelerometer_m_s2[{i}]"].astype(float)
        cols[f"w{axis}_radps"] = d[f"gyro_rad[{i}]"].astype(float)
    msgtype = f"px4/{IMU_TOPIC}"
    if att is not None and all(f"q[{i}]" in att for i in range(4)):
        q = ned_frd_to_enu_flu(np.stack([att[f"q[{i}]"].astype(float) for i in range(4)], axis=1))
        t_att = att["timestamp"].astype(np.int64)
        q_imu = interpolate_attitude(ts, t_att, q, ATTITUDE_MAX_GAP_US)
        cols |= {"qw": q_imu[:, 0], "qx": q_imu[:, 1], "qy": q_imu[:, 2], "qz": q_imu[:, 3]}
        msgtype += f" + {ATTITUDE_TOPIC} (PX4's estimate, body FLU -> ENU, slerped onto the IMU times)"
        lost = int(np.isnan(q_imu[:, 0]).sum())
        if lost:
            skipped.append(
                Skipped(
                    ATTITUDE_TOPIC,
                    f"IMU samples outside the attitude's span or in a gap over {ATTITUDE_MAX_GAP_US / 1e6:g} s: "
                    "no orientation",
                    lost,
                    "repaired",
                )
            )
    return pd.DataFrame(cols), StreamInfo("imu", IMU_TOPIC, IMU_TOPIC, msgtype, len(ts), body_frame="FRD")


def _gnss_log_messages(ulog: ULog, limit: int = 20) -> str:
    """The log's own text messages about GPS spoofing or jamming (PX4 v1.14-v1.15 GPS drivers print them)."""
    hits = [
        m
        for m in ulog.logged_messages
        if ("spoof" in m.message.lower() or "jamm" in m.message.lower()) and "gps" in m.message.lower()
    ]
    if not hits:
        return ""
    shown = "; ".join(f"boot {m.timestamp / 1e6:.3f} s [{m.log_level_str()}] {m.message}" for m in hits[:limit])
    more = f"; ... {len(hits) - limit} more" if len(hits) > limit else ""
    return f"{len(hits)} message(s): {shown}{more}"


ULOG_MAGIC = b"ULog\x01\x12\x35"


def _is_ulog(path: Path, head: bytes) -> bool:
    return head.startswith(ULOG_MAGIC)


FORMATS = (
    ReaderFormat(
        "ulog",
        "PX4 ULog (.ulg)",
        read_ulog,
        _is_ulog,
        rewrite="spooflens.writers.rewrite:rewrite_with_writer",
    ),
)
