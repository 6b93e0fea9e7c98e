"""Write an EpochTable as a PX4 ULog (sensor_combined + sensor_gps), the subset our reader maps.

The layout follows the ULog specification (file header, 'B' flag bits, 'F' formats, 'A' add-logged,
'D' data); PX4 conventions: body frame FRD, NED velocity, microseconds since boot, GPS time in
`time_utc_usec`. The IMU must already be in FRD (PX4's frame) when the table says so; a FLU IMU is
rotated (y and z negated) on the way out.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from spooflens.epoch_table import EpochTable
from spooflens.schema import FixType, SpoofingFlag

_MAGIC = b"ULog\x01\x12\x35\x01"
SENSOR_COMBINED = (
    "sensor_combined",
    [("uint64_t", "timestamp"), ("float[3]", "gyro_rad"), ("float[3]", "accelerometer_m_s2")],
)
SENSOR_GPS = (
    "sensor_gps",
    [
        ("uint64_t", "timestamp"),
        ("uint64_t", "time_utc_usec"),
        ("double", "latitude_deg"),
        ("double", "longitude_deg"),
        ("double", "altitude_ellipsoid_m"),
        ("float", "eph"),
        ("float", "epv"),
        ("float", "s_variance_m_s"),
        ("float", "vel_n_m_s"),
        ("float", "vel_e_m_s"),
        ("float", "vel_d_m_s"),
        ("int32_t", "noise_per_ms"),
        ("int32_t", "jamming_indicator"),
        ("uint8_t", "fix_type"),
        ("uint8_t", "satellites_used"),
        ("uint8_t", "spoofing_state"),
    ],
)
_PACK = {"uint64_t": "Q", "double": "d", "float": "f", "float[3]": "3f", "int32_t": "i", "uint8_t": "B"}
_PX4_FIX = {
    FixType.NO_FIX: 1,
    FixType.FIX_2D: 2,
    FixType.FIX_3D: 3,
    FixType.SBAS: 4,
    FixType.DGNSS: 4,
    FixType.RTK_FLOAT: 5,
    FixType.RTK_FIXED: 6,
}
_PX4_SPOOF = {SpoofingFlag.UNKNOWN: 0, SpoofingFlag.CLEAR: 1, SpoofingFlag.INDICATED: 2}


def _msg(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


def write_ulog(table: EpochTable, path: Path, boot_offset_s: float = 10.0) -> None:
    """One IMU and one receiver; times as µs since a boot `boot_offset_s` before the log start."""
    boot_us = int(table.t0_ns // 1000) - int(boot_offset_s * 1e6)
    unix = table.unix_ns(np.zeros(1))
    out = bytearray(_MAGIC + struct.pack("<Q", 0))
    out += _msg(b"B", bytes(40))
    for name, fields in (SENSOR_COMBINED, SENSOR_GPS):
        out += _msg(b"F", f"{name}:{''.join(f'{t} {n};' for t, n in fields)}".encode())
    out += _msg(b"A", struct.pack("<BH", 0, 0) + b"sensor_combined")
    out += _msg(b"A", struct.pack("<BH", 0, 1) + b"sensor_gps")
    records: list[tuple[int, bytes]] = []
    if len(table.imu):
        imu = table.imu_of(table.imus()[0])
        flu = next((s.body_frame for s in table.streams if s.role == "imu"), "FLU") != "FRD"
        sign = np.array([1.0, -1.0, -1.0]) if flu else np.ones(3)
        t_us = (table.absolute_ns(imu["t_s"].to_numpy()) // 1000 - boot_us).astype(np.int64)
        g = imu[["wx_radps", "wy_radps", "wz_radps"]].to_numpy() * sign
        a = imu[["ax_mps2", "ay_mps2", "az_mps2"]].to_numpy() * sign
        fmt = struct.Struct("<HQ3f3f")
        records += [(int(t), fmt.pack(0, int(t), *gi, *ai)) for t, gi, ai in zip(t_us, g, a, strict=True)]
    if len(table.fixes):
        fx = table.fixes_of(table.receivers()[0])
        t_abs = table.absolute_ns(fx["t_s"].to_numpy())
        t_us = (t_abs // 1000 - boot_us).astype(np.int64)
        utc = (table.unix_ns(fx["t_s"].to_numpy()) // 1000) if unix is not None else np.zeros(len(fx), np.int64)
        fmt = struct.Struct("<HQQdddffffffiiBBB")
        v = np.nan_to_num(fx[["vel_n_mps", "vel_e_mps", "vel_u_mps"]].to_numpy(), nan=0.0)
        for k in range(len(fx)):
            r = fx.iloc[k]
            records.append(
                (
                    int(t_us[k]),
                    fmt.pack(
                        1,
                        int(t_us[k]),
                        int(utc[k]),
                        r.lat_deg,
                        r.lon_deg,
                        r.height_m,
                        np.nan_to_num(r.h_acc_m, nan=99.0),
                        np.nan_to_num(r.v_acc_m, nan=99.0),
                        np.nan_to_num(r.vel_acc_mps, nan=9.0),
                        v[k, 0],
                        v[k, 1],
                        -v[k, 2],
                        0,
                        int(np.nan_to_num(r.jamming_indicator, nan=0)),
                        _PX4_FIX.get(FixType(int(r.fix_type)), 3),
                        int(np.nan_to_num(r.sats_used, nan=0)),
                        _PX4_SPOOF[SpoofingFlag(int(r.spoofing_flag))],
                    ),
                )
            )
    for _, payload in sorted(records, key=lambda r: r[0]):
        out += _msg(b"D", payload)
    Path(path).write_bytes(bytes(out))
