"""MAVLink telemetry written with pymavlink's own encoder (no real .tlog with a clear licence exists)."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np


def write_tlog(
    path: Path, seconds: float = 30.0, gps_hz: int = 5, imu_hz: int = 50, gps_unix_from_s: float | None = None
) -> tuple[int, int]:
    """A vehicle flying north at 2 m/s, level, nose east: GPS_RAW_INT, SCALED_IMU, ATTITUDE, SYSTEM_TIME.
    With `gps_unix_from_s` GPS_RAW_INT carries the receiver's UNIX time (ArduPilot), 7.5 s ahead from
    that time on (a spoofer's clock)."""
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    t0_unix_us, boot0_ms = 1_700_000_000_000_000, 60_000
    recs = []
    for k in range(int(seconds * imu_hz)):
        t_ms = boot0_ms + k * 1000 // imu_hz
        recs.append((t_ms, mav.scaled_imu_encode(t_ms, 0, 0, -1000, 1, 2, 3, 0, 0, 0)))
        recs.append((t_ms, mav.attitude_encode(t_ms, 0.0, 0.0, np.radians(90), 0, 0, 0)))
    for k in range(int(seconds * gps_hz)):
        t_ms = boot0_ms + k * 1000 // gps_hz
        lat = 52.0 + 2.0 * k / gps_hz / 111_250.0
        recs.append(
            (
                t_ms,
                mav.gps_raw_int_encode(
                    t_ms * 1000
                    if gps_unix_from_s is None
                    else t0_unix_us
                    + (t_ms - boot0_ms) * 1000
                    + (7_500_000 if (t_ms - boot0_ms) / 1000 >= gps_unix_from_s else 0),
                    3,
                    round(lat * 1e7),
                    100_000_000,
                    100_000,
                    90,
                    120,
                    200,
                    0,
                    12,
                    alt_ellipsoid=145_000,
                    h_acc=800,
                    v_acc=1500,
                    vel_acc=300,
                ),
            )
        )
        if k % gps_hz == 0:
            recs.append((t_ms, mav.system_time_encode(t0_unix_us + (t_ms - boot0_ms) * 1000, t_ms)))
            recs.append((t_ms, mav.heartbeat_encode(2, 3, 0, 0, 4)))
    recs.sort(key=lambda r: r[0])
    with path.open("wb") as f:
        for t_ms, msg in recs:
            f.write(struct.pack(">Q", t0_unix_us + (t_ms - boot0_ms) * 1000 + 150_000))  # 150 ms link latency
            f.write(msg.pack(mav))
    return t0_unix_us, boot0_ms
