"""PX4 ULog through pyulog: sensor_combined (IMU) and sensor_gps / vehicle_gps_position (fixes).

PX4 conventions: IMU body frame FRD; velocities NED (turned into ENU here); timestamps in
microseconds since boot. When the GPS topic carries `time_utc_usec`, the log is put on the UNIX clock
(median offset between the two clocks); otherwise the time reference is "boot".
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np
import pandas as pd
from pyulog import ULog

from readers import ReaderFormat
from spooflens.epoch_table import EpochTable, Skipped, StreamInfo, build_table
from spooflens.errors import ReaderError
from spooflens.schema import FixType, SpoofingFlag

Progress = Callable[[int, int], None]
GPS_TOPICS = ("sensor_gps", "vehicle_gps_position")
IMU_TOPIC = "sensor_combined"
# PX4 fix_type: 0-1 none, 2 2D, 3 3D, 4 DGPS/SBAS, 5 RTK float, 6 RTK fixed
_FIX = {
    0: FixType.NO_FIX,
    1: FixType.NO_FIX,
    2: FixType.FIX_2D,
    3: FixType.FIX_3D,
    4: FixType.DGNSS,
    5: FixType.RTK_FLOAT,
    6: FixType.RTK_FIXED,
}
# PX4 spoofing_state: 0 unknown, 1 none, 2 indicated, 3 multiple indications
_SPOOF = {0: SpoofingFlag.UNKNOWN, 1: SpoofingFlag.CLEAR, 2: SpoofingFlag.INDICATED, 3: SpoofingFlag.INDICATED}


def _field(d: dict[str, np.ndarray], *names: str, scale: float = 1.0) -> np.ndarray | None:
    for n in names:
        if n in d:
            return d[n].astype(float) * scale
    return None


def _codes(values: np.ndarray | None, table: dict[int, int], default: int, n: int) -> np.ndarray:
    out = np.full(n, default, dtype=np.int8)
    if values is not None:
        for code, mapped in table.items():
            out[values == code] = mapped
    return out


def read_ulog(path: Path, topics: Mapping[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    path = Path(path)
    try:
        ulog = ULog(str(path), [IMU_TOPIC, *GPS_TOPICS], disable_str_exceptions=True)
    except Exception as err:
        raise ReaderError(path, f"not a readable ULog: {type(err).__name__}: {err}") from err
    skipped: list[Skipped] = []
    if ulog.file_corruption:
        skipped.append(
            Skipped("<file>", "pyulog found corrupt data and re-synchronised; some messages lost", 0, "lost")
        )
    data = {(d.name, d.multi_id): d.data for d in ulog.data_list}
    gps_key = next(((n, m) for n in GPS_TOPICS for (dn, m) in data if dn == n and m == 0), None)
    streams: list[StreamInfo] = []
    frames: dict[str, pd.DataFrame] = {}
    offset_us = 0
    reference = "boot"
    if gps_key is not None:
        g = data[gps_key]
        utc = _field(g, "time_utc_usec")
        ts = g["timestamp"].astype(np.int64)
        if utc is not None and np.any(utc > 0):
            offset_us = int(np.median(utc[utc > 0].astype(np.int64) - ts[utc > 0]))
            reference = "unix"
        lat = _field(g, "latitude_deg")
        lat = lat if lat is not None else _field(g, "lat", scale=1e-7)
        lon = _field(g, "longitude_deg")
        lon = lon if lon is not None else _field(g, "lon", scale=1e-7)
        alt = _field(g, "altitude_ellipsoid_m")
        alt = alt if alt is not None else _field(g, "alt_ellipsoid", scale=1e-3)
        if lat is None or lon is None or alt is None:
            raise ReaderError(path, f"{gps_key[0]} has no latitude/longitude/ellipsoid height fields", gps_key[0])
        n = len(ts)
        vn, ve, vd = (_field(g, f"vel_{a}_m_s") for a in "ned")
        cols: dict[str, object] = {
            "t_ns": (ts + offset_us) * 1000,
            "receiver_id": gps_key[0],
            "lat_deg": lat,
            "lon_deg": lon,
            "height_m": alt,
            "h_acc_m": _field(g, "eph"),
            "v_acc_m": _field(g, "epv"),
            "vel_acc_mps": _field(g, "s_variance_m_s"),
            "sats_used": _field(g, "satellites_used"),
            "jamming_indicator": _field(g, "jamming_indicator"),
            "fix_type": _codes(g.get("fix_type"), _FIX, FixType.FIX_3D, n),
            "spoofing_flag": _codes(g.get("spoofing_state"), _SPOOF, SpoofingFlag.UNKNOWN, n),
        }
        if vn is not None and ve is not None and vd is not None:
            cols |= {"vel_e_mps": ve, "vel_n_mps": vn, "vel_u_mps": -vd}
        fixes = pd.DataFrame({k: v for k, v in cols.items() if v is not None})
        no_fix = fixes["fix_type"].to_numpy() == FixType.NO_FIX
        if no_fix.any():
            skipped.append(Skipped(gps_key[0], "fix_type no fix", int(no_fix.sum())))
            fixes = fixes[~no_fix]
        frames["fixes"] = fixes
        streams.append(StreamInfo("fix", gps_key[0], gps_key[0], f"px4/{gps_key[0]}", len(fixes)))
    if (IMU_TOPIC, 0) in data:
        d = data[(IMU_TOPIC, 0)]
        t = (d["timestamp"].astype(np.int64) + offset_us) * 1000
        cols = {"t_ns": t, "imu_id": IMU_TOPIC}
        for i, axis in enumerate("xyz"):
            cols[f"a{axis}_mps2"] = d[f"accelerometer_m_s2[{i}]"].astype(float)
            cols[f"w{axis}_radps"] = d[f"gyro_rad[{i}]"].astype(float)
        frames["imu"] = pd.DataFrame(cols)
        streams.append(StreamInfo("imu", IMU_TOPIC, IMU_TOPIC, "px4/sensor_combined", len(t), body_frame="FRD"))
    others = sorted({d.name for d in ulog.data_list} - {IMU_TOPIC, *GPS_TOPICS})
    if others:
        skipped.append(Skipped("<ulog>", f"topics not used: {others}", len(others)))
    if topics:
        skipped.append(Skipped("<ulog>", f"--topic ignored for ULog ({dict(topics)})", len(topics)))
    if progress:
        progress(1, 1)
    if not frames:
        raise ReaderError(path, f"no {IMU_TOPIC} or GPS topic ({', '.join(GPS_TOPICS)}) in this ULog")
    return build_table(path, "ulog", reference, frames, streams, skipped)


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
