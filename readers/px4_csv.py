"""The PX4 CSV dialect: GPS, IMU and attitude tables with PX4's own field names and units.

Investigators often receive PX4 data as tables, most often `ulog2csv` output: a directory of
`<log>_<topic>_<instance>.csv` files, one per topic instance, each with the message's fields as
columns (`timestamp` first, in microseconds since boot; arrays as `q[0]`, `gyro_rad[0]`, ...). A single
GPS table with those column names is accepted too. A file is taken as PX4 by its columns, not its name:

- GPS: `timestamp`, a position (`lat`/`lon` or `latitude_deg`/`longitude_deg`), a field only a GPS
  message has (`fix_type`, `satellites_used`, `vel_n_m_s`, `noise_per_ms`, `jamming_indicator`, ...)
  and a sign of PX4 rather than a spooflens CSV: a PX4-only name (`vel_n_m_s`, `time_utc_usec`,
  `alt_ellipsoid`, `vel_ned_valid`, `s_variance_m_s`, ...) or latitudes in 1e-7 degrees.
- IMU: `timestamp`, `gyro_rad[0..2]`, `accelerometer_m_s2[0..2]` (sensor_combined, body FRD).
- Attitude: `timestamp`, `q[0..3]` and `delta_q_reset[0]` (vehicle_attitude, body FRD -> NED), or a
  `vehicle_attitude` file name with `q[0..3]`.
- Satellites: `timestamp`, `count`, `snr[0]` (satellite_info: the mean C/N0 of each fix).

In a directory holding any such file, every other file with a `timestamp` column is another PX4 topic
and is listed as unused. Where a name allows two units the values decide (`readers.px4.position_units`),
and a repaired-row note says which was chosen.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from readers.csv_text import read_rows
from readers.px4 import (
    ATTITUDE_TOPIC,
    BARO_TOPIC,
    EKF_TOPICS,
    GPS_TOPICS,
    IMU_TOPIC,
    INNOVATION_TOPICS,
    PX4_LOG_CLOCK,
    RATIO_TOPICS,
    RAW_GPS_TOPICS,
    SATELLITE_TOPIC,
    GpsSource,
    Record,
    autopilot_ekf_frame,
    canonical_record,
    cn0_mean,
    enum_metadata,
    gps_columns,
    interpolate_attitude,
    nearest_values,
    ned_frd_to_enu_flu,
    position_units,
    receiver_metadata,
    satellites_frame,
    select_receivers,
)
from spooflens.epoch_table import Skipped, StreamInfo
from spooflens.errors import ReaderError
from spooflens.schema import FixType

GPS_ONLY = {
    "fix_type",
    "satellites_used",
    "vel_n_m_s",
    "vel_e_m_s",
    "vel_north",
    "vel_east",
    "s_variance_m_s",
    "speed_accuracy",
    "noise_per_ms",
    "noise",
    "jamming_indicator",
    "jamming_state",
    "spoofing_state",
    "time_utc_usec",
    "hdop",
    "vdop",
    "vel_ned_valid",
    "cog_rad",
}
PX4_ONLY = {
    "vel_n_m_s",
    "vel_e_m_s",
    "vel_d_m_s",
    "vel_north",
    "vel_east",
    "s_variance_m_s",
    "time_utc_usec",
    "alt_ellipsoid",
    "vel_ned_valid",
    "latitude_deg",
    "longitude_deg",
    "altitude_ellipsoid_m",
    "altitude_msl_m",
    "c_variance_rad",
    "cog_rad",
    "timestamp_time_relative",
    "timestamp_sample",
    "device_id",
    "vel_m_s",
}
IMU_COLUMNS = {f"{n}[{i}]" for n in ("gyro_rad", "accelerometer_m_s2") for i in range(3)}
Q_COLUMNS = [f"q[{i}]" for i in range(4)]
KNOWN_TOPICS = (*GPS_TOPICS, IMU_TOPIC, ATTITUDE_TOPIC, SATELLITE_TOPIC, BARO_TOPIC, *EKF_TOPICS)
SAMPLE_ROWS = 200
ATTITUDE_MAX_GAP_US = 500_000
SATELLITE_MAX_DT_US = 1_000_000


def topic_of(path: Path) -> tuple[str | None, int]:
    """(topic, instance) from a ulog2csv file name `<log>_<topic>_<instance>.csv`, (None, 0) otherwise."""
    for topic in sorted(KNOWN_TOPICS, key=len, reverse=True):
        m = re.fullmatch(rf"(?:.*_)?{topic}_(\d+)", path.stem)
        if m:
            return topic, int(m.group(1))
    return None, 0


MAX_HEADER_BYTES = 1 << 16  # PX4's widest topic header is a few kB; a longer one is no PX4 table


def _header_line(path: Path) -> bytes | None:
    """The first line that is not a comment, if it ends within MAX_HEADER_BYTES of its start."""
    try:
        with path.open("rb") as f:
            for line in iter(lambda: f.readline(MAX_HEADER_BYTES + 1), b""):
                if len(line) > MAX_HEADER_BYTES:
                    return None
                if line.strip() and not line.startswith(b"#"):
                    return line
    except OSError:
        return None
    return None


def _sample(path: Path) -> pd.DataFrame | None:
    if _header_line(path) is None:  # pandas names a million-field header's columns in quadratic time
        return None
    try:
        df = pd.read_csv(path, comment="#", skipinitialspace=True, nrows=SAMPLE_ROWS, on_bad_lines="skip")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, ValueError):
        return None
    df.columns = [str(c).strip() for c in df.columns]
    return df


def _ekf_fields(topic: str) -> set[str]:
    ratios = RATIO_TOPICS.get(topic, {}).values()
    return set(INNOVATION_TOPICS.get(topic, {})) | {name for names in ratios for name in names}


def kind_of(path: Path, df: pd.DataFrame) -> str | None:
    """'gps', 'imu', 'attitude', 'satellites' for a PX4 table, 'topic' for another PX4-like table with a
    `timestamp` column (unused unless beside a PX4 file), None when it is no PX4 table."""
    cols = set(df.columns)
    if "timestamp" not in cols:
        return None
    topic, _ = topic_of(path)
    has_position = (
        {"lat", "lon"} <= cols
        or {"latitude_deg", "longitude_deg"} <= cols
        or {
            "latitude",
            "longitude",
        }
        <= cols
    )
    if has_position and cols & GPS_ONLY and (topic in GPS_TOPICS or topic is None):
        lat = pd.to_numeric(df["lat"], errors="coerce").abs().max() if "lat" in cols else 0.0
        if cols & PX4_ONLY or topic in GPS_TOPICS or (np.isfinite(lat) and lat > 90):
            return "gps"
    if cols >= IMU_COLUMNS and topic in (IMU_TOPIC, None):
        return "imu"
    if set(Q_COLUMNS) <= cols and (topic == ATTITUDE_TOPIC or (topic is None and "delta_q_reset[0]" in cols)):
        return "attitude"
    if {"count", "snr[0]"} <= cols and topic in (SATELLITE_TOPIC, None):
        return "satellites"
    if topic in EKF_TOPICS and cols & _ekf_fields(topic):  # innovations and ratios share layouts: by name
        return "ekf"
    return "topic"


def split(files: list[Path]) -> tuple[dict[Path, str], list[Path]]:
    """Files of the PX4 dialect with their kind, and the others (read as spooflens CSV)."""
    kinds: dict[Path, str | None] = {}
    for f in files:
        df = _sample(f)
        kinds[f] = kind_of(f, df) if df is not None else None
    px4 = {f: k for f, k in kinds.items() if k is not None and k != "topic"}
    if not px4:
        return {}, files
    # beside a PX4 table, every other table with a `timestamp` column is another PX4 topic
    px4 |= {f: "topic" for f, k in kinds.items() if k == "topic"}
    return px4, [f for f in files if f not in px4]


@dataclass
class Px4Part:
    """What the PX4 files of a CSV log hold, in absolute nanoseconds (`t_ns`), ready for build_table."""

    frames: dict[str, pd.DataFrame] = field(default_factory=dict)
    streams: list[StreamInfo] = field(default_factory=list)
    reference: str = "boot"
    metadata: dict[str, str] = field(default_factory=dict)


def _record(path: Path, skipped: list[Skipped]) -> Record:
    """Every column as numbers (true/false as 1/0); rows without a finite, non-negative timestamp dropped."""
    df = read_rows(path, skipped)
    rec: Record = {str(c): df[c].to_numpy() for c in df.columns}
    t = rec["timestamp"]
    keep = np.isfinite(t) & (t >= 0) & (t < 1e17)
    if not keep.all():
        skipped.append(Skipped(path.name, "rows without a usable timestamp", int((~keep).sum())))
    return {k: v[keep] for k, v in rec.items()}


def _timestamp_us(path: Path, rec: Record, notes: list[str]) -> np.ndarray:
    """PX4 `timestamp` in µs; a table in seconds (steps under 100, i.e. faster than 10 kHz in µs) is scaled."""
    t = rec["timestamp"].astype(float)
    step = float(np.median(np.diff(np.sort(t)))) if len(t) > 1 else 1e6
    if 0 < step < 100:
        notes.append("timestamp in seconds (sample spacing under 100): scaled to µs")
        return np.round(t * 1e6).astype(np.int64)
    return np.round(t).astype(np.int64)


def read_px4(files: dict[Path, str], skipped: list[Skipped]) -> Px4Part:
    """Read the PX4 tables of a CSV log (their kinds from `split`)."""
    part = Px4Part()
    unused = sorted(f.name for f, k in files.items() if k == "topic")
    baro = [f.name for f in files if topic_of(f)[0] == BARO_TOPIC]
    if baro:
        skipped.append(Skipped(baro[0], "barometric altitude not used (no schema column for it yet)", 1))
    unused = [u for u in unused if u not in baro]
    if unused:
        skipped.append(Skipped("<csv>", f"PX4 topics not used: {unused}", len(unused)))
    notes: dict[Path, list[str]] = {f: [] for f in files}
    records = {f: _record(f, skipped) for f, k in files.items() if k != "topic"}
    times = {f: _timestamp_us(f, rec, notes[f]) for f, rec in records.items()}
    gps_files = [f for f, k in files.items() if k == "gps"]
    named: dict[tuple[str, int], Record] = {}
    origin: dict[tuple[str, int], Path] = {}
    sources: list[tuple[GpsSource, Record, Path]] = []
    for f in gps_files:
        rec = canonical_record(records[f]) | {"timestamp": times[f]}
        topic, instance = topic_of(f)
        if topic is not None:
            named[(topic, instance)] = rec
            origin[(topic, instance)] = f
        else:
            rows = np.ones(len(times[f]), dtype=bool)
            raw = RAW_GPS_TOPICS[0]
            sources.append((GpsSource(f.stem, raw, 0, rows, f"PX4 GPS table {f.name}"), rec, f))
    chosen, notes_sel = select_receivers(named)
    skipped += notes_sel
    sources += [(s, named[(s.topic, s.multi_id)], origin[(s.topic, s.multi_id)]) for s in chosen]
    utc = _utc_offset(sources)
    offset_us = utc if utc is not None else 0
    if utc is not None:
        part.reference = "unix"
        clock = f"clock UNIX from time_utc_usec (boot + {utc / 1e6:.3f} s)"
    elif any(np.median(times[f]) > 1e15 for f in records if len(times[f])):
        part.reference = "unix"
        clock = "clock UNIX (timestamp values are UNIX microseconds)"
    else:
        clock = "clock: seconds since boot (no time_utc_usec)"
    sats = [f for f, k in files.items() if k == "satellites"]
    fixes: list[pd.DataFrame] = []
    skies: list[tuple[pd.DataFrame, StreamInfo]] = []
    for k, (src, rec, f) in enumerate(sources):
        df, info = _fixes(f, src, rec, offset_us, notes[f], skipped)
        sat = next((s for s in sats if topic_of(s)[1] == k), sats[0] if len(sats) == 1 and k == 0 else None)
        if sat is not None:
            per_satellite = satellites_frame(records[sat], info.stream_id, sat.name, offset_us, skipped)
            if per_satellite is not None:
                skies.append(per_satellite)
            cn0 = cn0_mean(records[sat])
            if cn0 is not None:
                t_fix = df["t_ns"].to_numpy() // 1000 - offset_us
                df["cn0_mean_dbhz"] = nearest_values(t_fix, times[sat], cn0, SATELLITE_MAX_DT_US)
                info = StreamInfo(
                    "fix", info.stream_id, info.topic, info.msgtype + f" + {sat.name} (mean C/N0)", info.count
                )
        fixes.append(df)
        part.streams.append(info)
    if fixes:
        part.frames["fixes"] = pd.concat(fixes, ignore_index=True)
        columns = {c for _, rec, _ in sources for c in rec}
        basis = "the columns of " + ", ".join(sorted({f.name for _, _, f in sources}))
        part.metadata |= enum_metadata(columns, basis)
        part.metadata |= receiver_metadata([(s, rec) for s, rec, _ in sources])
        part.metadata["px4.gps_source"] = "; ".join(f"{s.receiver_id}: {s.description}" for s, _, _ in sources)
        if any("time_utc_usec" in rec for _, rec, _ in sources):
            part.metadata |= PX4_LOG_CLOCK
    if skies:
        part.frames["satellites"] = pd.concat([frame for frame, _ in skies], ignore_index=True)
        part.streams += [sky_info for _, sky_info in skies]
    imu_files = [f for f, k in files.items() if k == "imu"]
    att_files = [f for f, k in files.items() if k == "attitude"]
    if imu_files:
        f = imu_files[0]
        part.frames["imu"], info = _imu(f, records[f], times[f], offset_us, att_files, records, times, skipped)
        part.streams.append(info)
        notes[f].append("gyro_rad/accelerometer_m_s2 in body FRD")
        if len(imu_files) > 1:
            skipped.append(Skipped("<csv>", f"more than one sensor_combined table; read {f.name}", len(imu_files) - 1))
    elif att_files:
        skipped.append(Skipped(att_files[0].name, "no sensor_combined table to attach the orientation to", 1))
    ekf_files = [f for f, k in files.items() if k == "ekf"]
    ekf_records = {}
    for f in ekf_files:
        topic, instance = topic_of(f)
        ekf_records[(str(topic), instance)] = records[f] | {"timestamp": times[f]}
    ekf = autopilot_ekf_frame(ekf_records, offset_us)
    if ekf is not None:
        part.frames["autopilot_ekf"] = ekf[0]
        part.streams += ekf[1]
    read = {f for _, _, f in sources} | set(imu_files[:1]) | set(att_files[:1] if imu_files else []) | set(sats)
    read |= set(ekf_files)
    for f, what in notes.items():
        if f in read:
            unit = [] if any(w.startswith("timestamp") for w in what) else ["timestamp µs since boot"]
            text = "; ".join(["PX4 CSV dialect", *unit, *what, clock])
            skipped.append(Skipped(f.name, text, len(records[f]["timestamp"]), "repaired"))
    return part


def _utc_offset(sources: list[tuple[GpsSource, Record, Path]]) -> int | None:
    diffs = []
    for _, rec, _ in sources:
        if "time_utc_usec" in rec:
            utc = np.nan_to_num(rec["time_utc_usec"].astype(float)).astype(np.int64)
            ok = utc > 0
            diffs.append(utc[ok] - rec["timestamp"][ok])
    alld = np.concatenate(diffs) if diffs else np.array([], dtype=np.int64)
    return int(np.median(alld)) if len(alld) else None


def _fixes(
    path: Path, src: GpsSource, rec: Record, offset_us: int, notes: list[str], skipped: list[Skipped]
) -> tuple[pd.DataFrame, StreamInfo]:
    units = position_units(rec, by_magnitude=True)
    if units is None:
        raise ReaderError(path, "PX4 GPS table without latitude/longitude/altitude columns", src.receiver_id)
    notes += list(units.notes)
    if "vel_n_m_s" in rec:
        notes.append("velocity NED -> ENU")
    rows = {k: np.asarray(v)[src.rows] for k, v in rec.items()}
    mapped = gps_columns(rows, units)
    skipped += [Skipped(src.receiver_id, what, n, "repaired") for what, n in mapped.notes]
    ts = rows["timestamp"].astype(np.int64)
    df = pd.DataFrame({"t_ns": (ts + offset_us) * 1000, "receiver_id": src.receiver_id} | mapped.columns)
    no_fix = df["fix_type"].to_numpy() == FixType.NO_FIX
    if no_fix.any():
        skipped.append(Skipped(src.receiver_id, "fix_type 0-1 (no fix)", int(no_fix.sum())))
        df = df[~no_fix].reset_index(drop=True)
    return df, StreamInfo("fix", src.receiver_id, path.name, src.description, len(df))


def _imu(
    path: Path,
    rec: Record,
    ts: np.ndarray,
    offset_us: int,
    att_files: list[Path],
    records: dict[Path, Record],
    times: dict[Path, np.ndarray],
    skipped: list[Skipped],
) -> tuple[pd.DataFrame, StreamInfo]:
    cols: dict[str, object] = {"t_ns": (ts + offset_us) * 1000, "imu_id": IMU_TOPIC}
    for i, axis in enumerate("xyz"):
        cols[f"a{axis}_mps2"] = rec[f"accelerometer_m_s2[{i}]"].astype(float)
        cols[f"w{axis}_radps"] = rec[f"gyro_rad[{i}]"].astype(float)
    msgtype = f"PX4 {IMU_TOPIC} table"
    if att_files:
        a = att_files[0]
        q = ned_frd_to_enu_flu(np.stack([records[a][c].astype(float) for c in Q_COLUMNS], axis=1))
        q_imu = interpolate_attitude(ts, times[a], q, ATTITUDE_MAX_GAP_US)
        cols |= {"qw": q_imu[:, 0], "qx": q_imu[:, 1], "qy": q_imu[:, 2], "qz": q_imu[:, 3]}
        msgtype += f" + {a.name} (PX4's attitude estimate, body FLU -> ENU, slerped onto the IMU times)"
        lost = int(np.isnan(q_imu[:, 0]).sum())
        if lost:
            skipped.append(
                Skipped(
                    a.name,
                    "IMU samples outside the attitude's span or in a gap over 0.5 s: no orientation",
                    lost,
                    "repaired",
                )
            )
    return pd.DataFrame(cols), StreamInfo("imu", IMU_TOPIC, path.name, msgtype, len(ts), body_frame="FRD")
