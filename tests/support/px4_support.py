"""PX4 logs as the firmware writes them, built with the project's ULog encoder (no real PX4 log is at hand).

Message layouts are PX4's own, per release: v1.12's vehicle_gps_position (int 1e-7 deg, jamming_state,
no spoofing_state), v1.14's sensor_gps (device_id, spoofing_state with the legacy meaning; the writer's
SENSOR_GPS_V1_14), and the current SensorGps (authentication_state; the writer's SENSOR_GPS). A flight is
a multirotor moving north-east at 2.2 m/s; from `attack_s` on, the receiver reports what an SDR spoofer
does to an M8N (accuracy and DOP inflated, noise and jamming indicator up, satellites lost, AGC down,
its own spoofing and jamming states raised).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from spooflens.writers.ulog_writer import (
    SENSOR_COMBINED,
    SENSOR_GPS,
    SENSOR_GPS_V1_14,
    VEHICLE_ATTITUDE,
    Fields,
    ULogFile,
)

LAT0, LON0, H0 = 47.3977419, 8.5455939, 488.25
BOOT_UTC_US = 1_700_000_000_000_000  # UNIX time of boot, µs
M8N_SERIAL2 = 0xA8 << 16 | 2 << 3 | 5  # u-blox 8 on serial bus 2 (device_id bit fields)
M9N_SERIAL4 = 0xA9 << 16 | 4 << 3 | 5
V1_12_3 = 0x010C03FF  # ver_sw_release v1.12.3 (release)
V1_14_0 = 0x010E00FF

V1_12_VEHICLE_GPS_POSITION: Fields = [
    ("uint64_t", "timestamp"),
    ("uint64_t", "time_utc_usec"),
    ("int32_t", "lat"),
    ("int32_t", "lon"),
    ("int32_t", "alt"),
    ("int32_t", "alt_ellipsoid"),
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
    ("float", "heading"),
    ("float", "heading_offset"),
    ("uint8_t", "fix_type"),
    ("uint8_t", "jamming_state"),
    ("bool", "vel_ned_valid"),
    ("uint8_t", "satellites_used"),
    ("uint8_t", "selected"),
]
VEHICLE_AIR_DATA: Fields = [("uint64_t", "timestamp"), ("float", "baro_alt_meter"), ("float", "baro_pressure_pa")]
BATTERY_STATUS: Fields = [("uint64_t", "timestamp"), ("float", "voltage_v")]
VEHICLE_GLOBAL_POSITION: Fields = [
    ("uint64_t", "timestamp"),
    ("double", "lat"),
    ("double", "lon"),
    ("float", "alt"),
    ("float", "eph"),
    ("float", "epv"),
]
SATELLITE_INFO: Fields = [  # PX4's SatelliteInfo (v1.14 on: 40 satellites)
    ("uint64_t", "timestamp"),
    ("uint8_t", "count"),
    ("uint8_t[40]", "svid"),
    ("uint8_t[40]", "used"),
    ("uint8_t[40]", "elevation"),
    ("uint8_t[40]", "azimuth"),
    ("uint8_t[40]", "snr"),
    ("uint8_t[40]", "prn"),
]
# 12 satellites in the u-blox NAV-SVINFO numbering PX4's driver writes: G02..G24, R03, R05 (65 + n - 1),
# E11, E12 (211 + n - 1); the clean sky spreads over 12 dB around 38 dB-Hz (mean 38)
SKY_SVID = np.array([2, 5, 7, 9, 13, 15, 20, 24, 67, 69, 221, 222])
SKY_OFFSET_DB = np.array([-6, -5, -4, -3, -2, -1, 1, 2, 3, 4, 5, 6])
SKY_ELEVATION = np.array([12, 25, 33, 41, 58, 77, 64, 47, 29, 18, 52, 255])  # 255: -1 deg, as the driver wraps it


def flight(t_s: np.ndarray, attack_s: float | None = None) -> dict[str, np.ndarray]:
    """What the receiver reports at boot times `t_s`, in schema units (degrees, metres, m/s ENU)."""
    after = np.zeros(len(t_s), bool) if attack_s is None else t_s >= attack_s
    ve, vn, vu = 2.0, 1.0, 0.5
    return {
        "t_s": t_s,
        "lat_deg": LAT0 + vn * t_s / 111_194.9,
        "lon_deg": LON0 + ve * t_s / (111_194.9 * np.cos(np.radians(LAT0))),
        "height_m": H0 + vu * t_s,
        "vel_e_mps": np.full(len(t_s), ve),
        "vel_n_mps": np.full(len(t_s), vn),
        "vel_u_mps": np.full(len(t_s), vu),
        "h_acc_m": np.where(after, 6.0, 1.6),
        "v_acc_m": np.where(after, 9.5, 2.5),
        "vel_acc_mps": np.where(after, 4.0, 0.35),
        "hdop": np.where(after, 2.1, 0.9),
        "vdop": np.where(after, 3.0, 1.3),
        "noise_per_ms": np.where(after, 141.0, 95.0),
        "jamming_indicator": np.where(after, 83.0, 21.0),
        "agc": np.where(after, 1500.0, 3100.0),
        "sats_used": np.where(after, 8.0, 14.0),
        "jamming_state": np.where(after, 2.0, 1.0),
        "spoofing_state": np.where(after, 2.0, 1.0),
    }


def fill_gps(rows: np.ndarray, f: dict[str, np.ndarray], device_id: int = 0, auth: float | np.ndarray = 3.0) -> None:
    """Set every field of a PX4 GPS message layout from `flight` values, in that layout's units."""
    names = set(rows.dtype.names or ())
    t_us = np.round(f["t_s"] * 1e6).astype(np.int64)
    put = {
        "timestamp": t_us,
        "timestamp_sample": t_us,
        "time_utc_usec": BOOT_UTC_US + t_us,
        "device_id": device_id,
        "lat": np.round(f["lat_deg"] * 1e7),
        "lon": np.round(f["lon_deg"] * 1e7),
        "alt": np.round((f["height_m"] - 47.0) * 1e3),  # MSL: geoid 47 m above the ellipsoid in Zurich
        "alt_ellipsoid": np.round(f["height_m"] * 1e3),
        "latitude_deg": f["lat_deg"],
        "longitude_deg": f["lon_deg"],
        "altitude_msl_m": f["height_m"] - 47.0,
        "altitude_ellipsoid_m": f["height_m"],
        "s_variance_m_s": f["vel_acc_mps"],
        "eph": f["h_acc_m"],
        "epv": f["v_acc_m"],
        "hdop": f["hdop"],
        "vdop": f["vdop"],
        "noise_per_ms": f["noise_per_ms"],
        "jamming_indicator": f["jamming_indicator"],
        "automatic_gain_control": f["agc"],
        "vel_n_m_s": f["vel_n_mps"],
        "vel_e_m_s": f["vel_e_mps"],
        "vel_d_m_s": -f["vel_u_mps"],
        "vel_m_s": np.hypot(f["vel_e_mps"], f["vel_n_mps"]),
        "vel_ned_valid": 1,
        "satellites_used": f["sats_used"],
        "fix_type": 3,
        "jamming_state": f["jamming_state"],
        "spoofing_state": f["spoofing_state"],
        "authentication_state": auth,
    }
    for name, value in put.items():
        if name in names:
            rows[name] = value


def fill_imu(rows: np.ndarray, t_s: np.ndarray) -> None:
    """A hovering multirotor's sensor_combined (body FRD: gravity reads -9.81 on z)."""
    rows["timestamp"] = np.round(t_s * 1e6).astype(np.int64)
    rows["accelerometer_m_s2"] = [0.0, 0.0, -9.81]
    rows["gyro_rad"] = [0.0, 0.0, 0.0]


def v1_12_log(path: Path) -> dict[str, np.ndarray]:
    """PX4 v1.12.3: vehicle_gps_position at 5 Hz; the first two messages have no fix, one is dead
    reckoned (fix_type 8), one has vel_ned_valid false. Returns the flight it logged."""
    log = ULogFile()
    log.info("sys_name", "PX4")
    log.info("ver_sw_release", V1_12_3)
    log.info("ver_sw", "1c0f2a7b4d9e3f5a6b7c8d9e0f1a2b3c4d5e6f70")
    log.info("ver_hw", "PX4_FMU_V5")
    t_imu = np.round(np.arange(1.0, 31.0, 0.02), 6)
    fill_imu(log.topic("sensor_combined", SENSOR_COMBINED, len(t_imu)), t_imu)
    t = np.round(np.arange(1.0, 31.0, 0.2), 6)
    f = flight(t, attack_s=20.0)
    rows = log.topic("vehicle_gps_position", V1_12_VEHICLE_GPS_POSITION, len(t))
    fill_gps(rows, f)
    rows["fix_type"][:2] = 1
    rows["lat"][:2] = rows["lon"][:2] = rows["alt_ellipsoid"][:2] = 0
    rows["fix_type"][10] = 8
    rows["vel_ned_valid"][12] = 0
    air = log.topic("vehicle_air_data", VEHICLE_AIR_DATA, 30)
    air["timestamp"] = np.round(np.arange(30), 6) * 1_000_000 + 1_000_000
    log.write(path)
    return f


def v1_14_two_receivers(
    path: Path, attack_s: float | None = 20.0, attitude: bool = True, seconds: float = 30.0
) -> dict[str, Any]:
    """PX4 v1.14.0 with two receivers: sensor_gps 0 (M8N) and 1 (M9N) at the logger's default 1 Hz,
    vehicle_gps_position at 5 Hz from receiver 0 except three blended messages (device_id 0); the
    driver's 'GPS spoofing detected!' warning; vehicle_attitude at 10 Hz; satellite_info of receiver 0;
    vehicle_air_data, vehicle_global_position and battery_status, which spooflens does not use."""
    log = ULogFile()
    log.info("sys_name", "PX4")
    log.info("ver_sw_release", V1_14_0)
    log.info("ver_sw", "b1a4c0de00000000000000000000000000000000")
    t_imu = np.round(np.arange(1.0, 1.0 + seconds, 0.02), 6)
    fill_imu(log.topic("sensor_combined", SENSOR_COMBINED, len(t_imu)), t_imu)
    t_att = np.round(np.arange(1.0, 1.0 + seconds, 0.1), 6)
    if attitude:
        att = log.topic("vehicle_attitude", VEHICLE_ATTITUDE, len(t_att))
        att["timestamp"] = att["timestamp_sample"] = np.round(t_att * 1e6).astype(np.int64)
        att["q"] = [np.cos(np.radians(15)), 0.0, 0.0, np.sin(np.radians(15))]  # level, heading 30 deg
    t1 = np.round(np.arange(1.0, 1.0 + seconds, 1.0), 6)
    fill_gps(log.topic("sensor_gps", SENSOR_GPS_V1_14, len(t1), 0), flight(t1, attack_s), M8N_SERIAL2)
    t1b = t1 + 0.05
    fill_gps(log.topic("sensor_gps", SENSOR_GPS_V1_14, len(t1b), 1), flight(t1b, attack_s), M9N_SERIAL4)
    t5 = np.round(np.arange(1.0, 1.0 + seconds, 0.2), 6)
    f5 = flight(t5, attack_s)
    sel = log.topic("vehicle_gps_position", SENSOR_GPS_V1_14, len(t5))
    fill_gps(sel, f5, M8N_SERIAL2)
    sel["device_id"][[40, 41, 42]] = 0
    sats = log.topic("satellite_info", SATELLITE_INFO, len(t1))
    sats["timestamp"] = np.round(t1 * 1e6).astype(np.int64)
    sats["count"] = 12
    under = flight(t1, attack_s)["spoofing_state"] > 1
    wobble = np.where(np.arange(len(t1))[:, None] % 2 == 0, 0, np.sign(SKY_OFFSET_DB))  # the sky is never still
    # under attack every channel locks onto the one transmitter: 47 dB-Hz all
    sats["snr"][:, :12] = np.where(
        under[:, None], 47, 38 + SKY_OFFSET_DB[None, :] + wobble - wobble.mean(axis=1)[:, None]
    )
    sats["snr"][:, 12:14] = 30  # beyond `count`: not satellites of this message
    sats["svid"][:, :12] = SKY_SVID
    sats["svid"][:, 12:14] = 3
    sats["used"][:, :12] = 1
    sats["elevation"][:, :12] = SKY_ELEVATION
    sats["azimuth"][:, :12] = np.arange(12) * 20
    for name, fields in (
        ("vehicle_air_data", VEHICLE_AIR_DATA),
        ("battery_status", BATTERY_STATUS),
        ("vehicle_global_position", VEHICLE_GLOBAL_POSITION),
    ):
        r = log.topic(name, fields, int(seconds))
        r["timestamp"] = np.round(np.arange(int(seconds)), 6) * 1_000_000 + 1_000_000
        if name == "vehicle_global_position":
            r["lat"], r["lon"], r["eph"] = LAT0, LON0, 1.0
    if attack_s is not None:
        log.text(int((attack_s + 0.4) * 1e6), "GPS spoofing detected! (state: 2)")
    log.write(path)
    return {"t1": t1, "t5": t5, "f5": f5, "f1b": flight(t1b, attack_s), "t_att": t_att}


def current_log(path: Path, attack_s: float | None = 20.0) -> dict[str, np.ndarray]:
    """The current SensorGps (with authentication_state): one receiver at 5 Hz, codes 2 mitigated
    and 3 detected after the attack, authentication 3 OK before and 2 error after."""
    log = ULogFile()
    log.info("sys_name", "PX4")
    t = np.round(np.arange(1.0, 31.0, 0.2), 6)
    f = flight(t, attack_s)
    if attack_s is not None:
        late = t >= attack_s + 5
        f["spoofing_state"] = np.where(late, 3.0, f["spoofing_state"])
        f["jamming_state"] = np.where(late, 3.0, f["jamming_state"])
    auth = np.where(f["spoofing_state"] > 1, 2.0, 3.0)
    fill_gps(log.topic("sensor_gps", SENSOR_GPS, len(t)), f, M8N_SERIAL2, auth)
    log.write(path)
    return f | {"authentication_state": auth}
