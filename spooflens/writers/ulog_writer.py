"""Write an EpochTable as a PX4 ULog: sensor_combined, vehicle_attitude, one sensor_gps per receiver and its
satellite_info (per-satellite C/N0, elevation, azimuth, used) where the table has its satellites.

The layout follows the ULog specification (file header, 'B' flag bits, 'I' info, 'F' formats,
'A' add-logged, 'D' data) and PX4's habits: fields ordered by size as the uORB structs are, a trailing
`_padding0` declared in the format but not written, body frame FRD, NED velocity, microseconds since
boot, GPS time in `time_utc_usec`, attitude as `vehicle_attitude.q` (body FRD -> NED).

`sensor_gps` has the current SensorGps definition (with `authentication_state`, state codes 1 OK,
2 mitigated, 3 detected) unless the table says its codes carry the legacy meaning (1 none, 2 indicated,
3 multiple): then the PX4 v1.14 definition (int 1e-7 deg positions, no `authentication_state`) is
written, so the raw codes keep their meaning. Values the table lacks are written as PX4 does when a
driver has none: NaN floats, -1 for noise_per_ms and jamming_indicator, 65535 for the AGC, 0 for
codes; the MSL altitude is not known (NaN, or 0 in the integer definition). A FLU IMU is rotated
(y and z negated) on the way out.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pandas as pd

from readers.px4 import PX4_FIX_OF, enu_flu_to_ned_frd, legacy_meaning
from spooflens.epoch_table import EpochTable
from spooflens.schema import FixType, SpoofingFlag

_MAGIC = b"ULog\x01\x12\x35\x01"
_NUMPY = {
    "uint64_t": "<u8",
    "int32_t": "<i4",
    "uint32_t": "<u4",
    "uint16_t": "<u2",
    "uint8_t": "u1",
    "bool": "u1",
    "float": "<f4",
    "double": "<f8",
}
Fields = list[tuple[str, str]]

SENSOR_COMBINED: Fields = [
    ("uint64_t", "timestamp"),
    ("float[3]", "gyro_rad"),
    ("uint32_t", "gyro_integral_dt"),
    ("int32_t", "accelerometer_timestamp_relative"),
    ("float[3]", "accelerometer_m_s2"),
    ("uint32_t", "accelerometer_integral_dt"),
    ("uint8_t", "accelerometer_clipping"),
    ("uint8_t", "gyro_clipping"),
    ("uint8_t", "accel_calibration_count"),
    ("uint8_t", "gyro_calibration_count"),
]
VEHICLE_ATTITUDE: Fields = [
    ("uint64_t", "timestamp"),
    ("uint64_t", "timestamp_sample"),
    ("float[4]", "q"),
    ("float[4]", "delta_q_reset"),
    ("uint8_t", "quat_reset_counter"),
]
_GPS_HEAD: Fields = [("uint64_t", "timestamp"), ("uint64_t", "timestamp_sample"), ("uint64_t", "time_utc_usec")]
_GPS_MIDDLE: Fields = [
    ("float", "s_variance_m_s"),
    ("float", "c_variance_rad"),
    ("float", "eph"),
    ("float", "epv"),
    ("float", "hdop"),
    ("float", "vdop"),
    ("int32_t", "noise_per_ms"),
    ("int32_t", "jamming_indicator"),
    ("float", "vel_m_s"),
    ("float", "vel_n_m_s"),
    ("float", "vel_e_m_s"),
    ("float", "vel_d_m_s"),
    ("float", "cog_rad"),
    ("int32_t", "timestamp_time_relative"),
]
# PX4 main's SensorGps (the 2025 GNSS-integrity definition)
SENSOR_GPS: Fields = [
    *_GPS_HEAD,
    ("double", "latitude_deg"),
    ("double", "longitude_deg"),
    ("double", "altitude_msl_m"),
    ("double", "altitude_ellipsoid_m"),
    ("uint32_t", "device_id"),
    *_GPS_MIDDLE,
    ("uint32_t", "system_error"),
    ("float", "heading"),
    ("float", "heading_offset"),
    ("float", "heading_accuracy"),
    ("float", "rtcm_injection_rate"),
    ("uint16_t", "automatic_gain_control"),
    ("uint8_t", "fix_type"),
    ("uint8_t", "jamming_state"),
    ("uint8_t", "spoofing_state"),
    ("uint8_t", "authentication_state"),
    ("bool", "vel_ned_valid"),
    ("uint8_t", "satellites_used"),
    ("uint8_t", "selected_rtcm_instance"),
    ("bool", "rtcm_crc_failed"),
    ("uint8_t", "rtcm_msg_used"),
    ("uint8_t", "quality_corrections"),
    ("uint8_t", "quality_receiver"),
    ("uint8_t", "quality_gnss_signals"),
    ("uint8_t", "quality_post_processing"),
]
# PX4 v1.14's sensor_gps: positions in int 1e-7 deg and mm, legacy state codes, no authentication_state
SENSOR_GPS_V1_14: Fields = [
    *_GPS_HEAD,
    ("uint32_t", "device_id"),
    ("int32_t", "lat"),
    ("int32_t", "lon"),
    ("int32_t", "alt"),
    ("int32_t", "alt_ellipsoid"),
    *_GPS_MIDDLE,
    ("float", "heading"),
    ("float", "heading_offset"),
    ("float", "heading_accuracy"),
    ("float", "rtcm_injection_rate"),
    ("uint16_t", "automatic_gain_control"),
    ("uint8_t", "fix_type"),
    ("uint8_t", "jamming_state"),
    ("uint8_t", "spoofing_state"),
    ("bool", "vel_ned_valid"),
    ("uint8_t", "satellites_used"),
    ("uint8_t", "selected_rtcm_instance"),
]


SATELLITE_SLOTS = 40
# PX4's SatelliteInfo: up to 40 satellites, `svid` in u-blox's NAV-SVINFO numbering (as PX4's u-blox
# driver writes it), `snr` the C/N0 in dB-Hz (0: not tracked), `elevation` in degrees as an int8 cast to
# uint8, `azimuth` 0-255 for 0-360 deg
SATELLITE_INFO: Fields = [
    ("uint64_t", "timestamp"),
    ("uint8_t", "count"),
    *((f"uint8_t[{SATELLITE_SLOTS}]", name) for name in ("svid", "used", "elevation", "azimuth", "snr", "prn")),
]
# u-blox NAV-SVINFO numbers by system: (system letter, first satellite number, its svid, last number)
_SVINFO = (("G", 1, 1, 32), ("S", 20, 120, 58), ("E", 1, 211, 36), ("C", 1, 159, 5), ("C", 6, 34, 36))
_SVINFO_MORE = (("R", 1, 65, 32), ("J", 1, 193, 10))


def svinfo_number(sv_id: str) -> int:
    """u-blox NAV-SVINFO number of a RINEX-style satellite id (0: none, e.g. a GLONASS slot above 32)."""
    system, number = sv_id[:1], int(sv_id[1:]) if sv_id[1:].isdigit() else 0
    for letter, first, svid, last in (*_SVINFO, *_SVINFO_MORE):
        if letter == system and first <= number <= last:
            return svid + number - first
    return 0


def _dtype(fields: Fields) -> np.dtype:
    parts: list[tuple[str, str] | tuple[str, str, tuple[int]]] = [("msg_id", "<u2")]
    for t, name in fields:
        base, _, count = t.partition("[")
        parts.append((name, _NUMPY[base], (int(count[:-1]),)) if count else (name, _NUMPY[base]))
    return np.dtype(parts)


def _msg(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


class ULogFile:
    """A ULog being built: info messages, topics with their rows, text messages; `write` encodes it.

    `topic(name, fields, n, multi_id)` declares a topic instance and returns its rows (a numpy
    structured array named by field) for the caller to fill; data messages are written in timestamp
    order across topics, as PX4's logger interleaves them.
    """

    def __init__(self) -> None:
        self.header = bytearray(_MAGIC + struct.pack("<Q", 0))
        self.header += _msg(b"B", bytes(40))
        self.formats: dict[str, Fields] = {}
        self.subscriptions: list[tuple[str, int]] = []
        self.rows: list[np.ndarray] = []
        self.texts: list[tuple[int, bytes]] = []

    def info(self, key: str, value: str | int) -> None:
        """An 'I' message: strings as char[n], integers as uint32_t (as PX4 writes ver_sw_release)."""
        if isinstance(value, str):
            raw, type_ = value.encode(), f"char[{len(value.encode())}]"
        else:
            raw, type_ = struct.pack("<I", value), "uint32_t"
        k = f"{type_} {key}".encode()
        self.header += _msg(b"I", struct.pack("<B", len(k)) + k + raw)

    def topic(self, name: str, fields: Fields, n: int, multi_id: int = 0) -> np.ndarray:
        if self.formats.setdefault(name, fields) != fields:
            raise ValueError(f"topic {name!r} declared twice with different fields")
        rows = np.zeros(n, dtype=_dtype(fields))
        rows["msg_id"] = len(self.subscriptions)
        self.subscriptions.append((name, multi_id))
        self.rows.append(rows)
        return rows

    def text(self, timestamp_us: int, message: str, level: str = "4") -> None:
        """An 'L' logged string (level '0' emergency .. '4' warning .. '7' debug)."""
        body = level.encode()[:1] + struct.pack("<Q", timestamp_us) + message.encode()
        self.texts.append((timestamp_us, _msg(b"L", body)))

    def write(self, path: Path) -> None:
        out = bytearray(self.header)
        for name, fields in self.formats.items():
            size = _dtype(fields).itemsize - 2
            pad = (-size) % 8  # PX4 declares the struct's trailing padding and does not log it
            body = "".join(f"{t} {n};" for t, n in fields) + (f"uint8_t[{pad}] _padding0;" if pad else "")
            out += _msg(b"F", f"{name}:{body}".encode())
        for msg_id, (name, multi_id) in enumerate(self.subscriptions):
            out += _msg(b"A", struct.pack("<BH", multi_id, msg_id) + name.encode())
        payloads: list[bytes] = []
        stamps: list[np.ndarray] = []
        for rows in self.rows:
            raw = rows.view(np.uint8).reshape(len(rows), -1)
            head = struct.pack("<HB", raw.shape[1], ord("D"))
            payloads += [head + r.tobytes() for r in raw]
            stamps.append(rows["timestamp"].astype(np.int64))
        payloads += [b for _, b in self.texts]
        stamps.append(np.array([t for t, _ in self.texts], dtype=np.int64))
        order = np.argsort(np.concatenate(stamps), kind="stable")
        out += b"".join(payloads[i] for i in order)
        Path(path).write_bytes(bytes(out))


def _finite(values: np.ndarray, fill: float) -> np.ndarray:
    return np.where(np.isfinite(values), values, fill)


def _gps_rows(
    r: np.ndarray, fx: pd.DataFrame, t_us: np.ndarray, utc_us: np.ndarray, legacy: bool, device_id: int
) -> None:
    c = {name: fx[name].to_numpy(dtype=float) for name in fx.columns if fx[name].dtype.kind == "f"}
    r["timestamp"] = r["timestamp_sample"] = t_us
    r["time_utc_usec"] = utc_us
    r["device_id"] = device_id
    if legacy:
        r["lat"] = np.round(c["lat_deg"] * 1e7)
        r["lon"] = np.round(c["lon_deg"] * 1e7)
        r["alt_ellipsoid"] = np.round(c["height_m"] * 1e3)
    else:
        r["latitude_deg"], r["longitude_deg"] = c["lat_deg"], c["lon_deg"]
        r["altitude_ellipsoid_m"], r["altitude_msl_m"] = c["height_m"], np.nan
    ve, vn, vu = c["vel_e_mps"], c["vel_n_mps"], c["vel_u_mps"]
    r["vel_n_m_s"], r["vel_e_m_s"], r["vel_d_m_s"] = vn, ve, -vu
    r["vel_m_s"], r["cog_rad"] = np.hypot(ve, vn), np.arctan2(ve, vn)
    r["vel_ned_valid"] = np.isfinite(ve) & np.isfinite(vn)
    r["eph"], r["epv"], r["s_variance_m_s"] = c["h_acc_m"], c["v_acc_m"], c["vel_acc_mps"]
    r["c_variance_rad"] = np.nan
    r["hdop"], r["vdop"] = c["hdop"], c["vdop"]
    r["noise_per_ms"] = _finite(c["noise_per_ms"], -1)
    r["jamming_indicator"] = _finite(c["jamming_indicator"], -1)
    r["automatic_gain_control"] = _finite(c["agc"], 65535)
    r["satellites_used"] = _finite(c["sats_used"], 0)
    r["fix_type"] = [PX4_FIX_OF.get(FixType(int(f)), 3) for f in fx["fix_type"]]
    r["jamming_state"] = _finite(c["jamming_state"], 0)
    flag = fx["spoofing_flag"].to_numpy()
    from_flag = np.select(
        [flag == SpoofingFlag.CLEAR, flag == SpoofingFlag.INDICATED], [1, 2 if legacy else 3], default=0
    )
    r["spoofing_state"] = np.where(np.isfinite(c["spoofing_state"]), c["spoofing_state"], from_flag)
    if not legacy:
        r["authentication_state"] = _finite(c["authentication_state"], 0)
    r["heading"] = r["heading_offset"] = r["heading_accuracy"] = np.nan


def write_ulog(table: EpochTable, path: Path, boot_offset_s: float = 10.0) -> None:
    """One IMU, every receiver; times as µs since a boot `boot_offset_s` before the log start."""
    boot_us = int(table.t0_ns // 1000) - int(boot_offset_s * 1e6)
    clock = table.unix_ns(np.zeros(1)) is not None
    legacy = legacy_meaning(table.metadata)
    log = ULogFile()
    # the firmware's info messages as the source log had them (readers.ulog keeps them as px4.<key>)
    log.info("sys_name", table.metadata.get("px4.sys_name", "PX4"))
    for key in ("ver_sw_release", "ver_sw", "ver_sw_branch", "ver_hw"):
        value = table.metadata.get(f"px4.{key}")
        if value:
            log.info(key, int(value, 16) if key == "ver_sw_release" else value)
    if len(table.imu):
        imu = table.imu_of(table.imus()[0])
        flu = next((s.body_frame for s in table.streams if s.role == "imu"), "FLU") != "FRD"
        sign = np.array([1.0, -1.0, -1.0]) if flu else np.ones(3)
        t_us = (table.absolute_ns(imu["t_s"].to_numpy()) // 1000 - boot_us).astype(np.int64)
        r = log.topic("sensor_combined", SENSOR_COMBINED, len(imu))
        r["timestamp"] = t_us
        r["gyro_rad"] = imu[["wx_radps", "wy_radps", "wz_radps"]].to_numpy() * sign
        r["accelerometer_m_s2"] = imu[["ax_mps2", "ay_mps2", "az_mps2"]].to_numpy() * sign
        r["gyro_integral_dt"] = r["accelerometer_integral_dt"] = int(np.median(np.diff(t_us))) if len(t_us) > 1 else 0
        q = imu[["qw", "qx", "qy", "qz"]].to_numpy(dtype=float)
        with_q = np.isfinite(q).all(axis=1)
        if with_q.any():
            a = log.topic("vehicle_attitude", VEHICLE_ATTITUDE, int(with_q.sum()))
            a["timestamp"] = a["timestamp_sample"] = t_us[with_q]
            a["q"] = enu_flu_to_ned_frd(q[with_q])
            a["delta_q_reset"] = [1.0, 0.0, 0.0, 0.0]
    for k, rid in enumerate(table.receivers() if len(table.fixes) else []):
        fx = table.fixes_of(rid)
        t_us = (table.absolute_ns(fx["t_s"].to_numpy()) // 1000 - boot_us).astype(np.int64)
        utc = table.unix_ns(fx["t_s"].to_numpy())
        utc_us = (utc // 1000).astype(np.int64) if clock and utc is not None else np.zeros(len(fx), np.int64)
        if clock and "time_offset_s" in fx:  # the receiver's own time, as it stood against the log's clock
            utc_us += np.round(np.nan_to_num(fx["time_offset_s"].to_numpy(dtype=float)) * 1e6).astype(np.int64)
        device_id = int(table.metadata.get(f"px4.device_id.{rid}", "0"))
        g = log.topic("sensor_gps", SENSOR_GPS_V1_14 if legacy else SENSOR_GPS, len(fx), multi_id=k)
        _gps_rows(g, fx, t_us, utc_us, legacy, device_id)
        sky = table.satellites[table.satellites["receiver_id"].astype(str) == rid] if len(table.satellites) else None
        if sky is not None and len(sky):
            _satellite_info(log, sky, table, boot_us, k)
    log.write(path)


def _satellite_info(log: ULogFile, sky: pd.DataFrame, table: EpochTable, boot_us: int, multi_id: int) -> None:
    """One satellite_info message per epoch of the receiver's sky (the first 40 satellites of each)."""
    svid = np.array([svinfo_number(s) for s in sky["sv_id"].astype(str)], dtype=np.int64)
    sky = sky.assign(_svid=svid)[svid > 0]
    epochs = np.unique(sky["t_s"].to_numpy(float))
    r = log.topic("satellite_info", SATELLITE_INFO, len(epochs), multi_id=multi_id)
    r["timestamp"] = (table.absolute_ns(epochs) // 1000 - boot_us).astype(np.int64)
    epoch = np.searchsorted(epochs, sky["t_s"].to_numpy(float))
    slot = sky.groupby(epoch).cumcount().to_numpy()
    keep = slot < SATELLITE_SLOTS
    e, k = epoch[keep], slot[keep]
    r["count"] = np.minimum(np.bincount(epoch, minlength=len(epochs)), SATELLITE_SLOTS)
    cn0 = sky["cn0_dbhz"].to_numpy(float)[keep]
    el = sky["elevation_deg"].to_numpy(float)[keep]
    az = sky["azimuth_deg"].to_numpy(float)[keep]
    used = sky["used"].to_numpy(float)[keep]
    r["svid"][e, k] = sky["_svid"].to_numpy()[keep]
    r["prn"][e, k] = sky["_svid"].to_numpy()[keep]
    r["snr"][e, k] = np.clip(np.round(np.nan_to_num(cn0, nan=0.0)), 0, 255)
    r["elevation"][e, k] = np.where(np.isfinite(el), np.round(el), -91).astype(np.int64) % 256
    r["azimuth"][e, k] = np.clip(np.round(np.nan_to_num(az) * 255.0 / 360.0), 0, 255)
    r["used"][e, k] = np.nan_to_num(used, nan=0.0) > 0
