"""MAVLink telemetry written with pymavlink's own encoder (no real .tlog with a clear licence exists)."""

from __future__ import annotations

import os
import struct
from pathlib import Path
from typing import Any

import numpy as np

GPS_RAW_INT_V1_LENGTH = 30  # its payload without the MAVLink 2 extension fields (alt_ellipsoid on)


def mavlink1(msg: Any, mav: Any, length: int | None = None) -> bytes:
    """`msg` as a MAVLink1 sender packs it: v1 framing, and its payload cut to `length` (a MAVLink1 sender
    has no extension fields; pymavlink's own v1 packing includes them)."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    full = msg.pack(mav, force_mavlink1=True)
    if length is None:
        return bytes(full)
    header = bytes([full[0], length]) + bytes(full[2:6])
    crc = mavlink.x25crc(header[1:] + full[6 : 6 + length])
    crc.accumulate(bytes([msg.crc_extra]))
    return header + bytes(full[6 : 6 + length]) + struct.pack("<H", crc.crc)


def tlog_records(data: bytes) -> list[tuple[bytes, bytes]]:
    """(8-byte receive time, MAVLink packet) of each record of a tlog without damage."""
    from readers.tlog import packet_length

    out = []
    at = 0
    while at < len(data):
        n = packet_length(data, at + 8)
        assert n is not None, f"no MAVLink packet at byte {at + 8}"
        out.append((data[at : at + 8], data[at + 8 : at + 8 + n]))
        at += 8 + n
    return out


def msgid(packet: bytes) -> int:
    """The message id of a v1 or v2 packet."""
    return packet[5] if packet[0] == 0xFE else int.from_bytes(packet[7:10], "little")


def write_tlog(
    path: Path,
    seconds: float = 30.0,
    gps_hz: int = 5,
    imu_hz: int = 50,
    gps_unix_from_s: float | None = None,
    v1: bool = False,
    gps2: bool = False,
) -> tuple[int, int]:
    """A vehicle flying north at 2 m/s, level, nose east: GPS_RAW_INT, SCALED_IMU, ATTITUDE, SYSTEM_TIME.
    With `gps_unix_from_s` GPS_RAW_INT carries the receiver's UNIX time (ArduPilot), 7.5 s ahead from
    that time on (a spoofer's clock). `v1`: every packet MAVLink1, GPS_RAW_INT without its extension fields
    (so without alt_ellipsoid and the accuracies). `gps2`: a second receiver's GPS2_RAW beside each fix."""
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
        if gps2:  # a second receiver 1 m east, boot-stamped, without alt_ellipsoid
            lon2 = round((10.0 + 1.0 / (111_320.0 * np.cos(np.radians(52.0)))) * 1e7)
            fix2 = mav.gps2_raw_encode(t_ms * 1000, 3, round(lat * 1e7), lon2, 100_000, 110, 150, 200, 0, 10, 0, 0)
            recs.append((t_ms, fix2))
        if k % gps_hz == 0:
            recs.append((t_ms, mav.system_time_encode(t0_unix_us + (t_ms - boot0_ms) * 1000, t_ms)))
            recs.append((t_ms, mav.heartbeat_encode(2, 3, 0, 0, 4)))
    recs.sort(key=lambda r: r[0])
    with path.open("wb") as f:
        for t_ms, msg in recs:
            f.write(struct.pack(">Q", t0_unix_us + (t_ms - boot0_ms) * 1000 + 150_000))  # 150 ms link latency
            if not v1:
                f.write(msg.pack(mav))
            else:
                f.write(mavlink1(msg, mav, GPS_RAW_INT_V1_LENGTH if msg.get_type() == "GPS_RAW_INT" else None))
            mav.seq = (mav.seq + 1) % 256
    return t0_unix_us, boot0_ms
