"""ROS message types -> epoch-table columns: the one place this mapping is written.

Every container that carries ROS messages (MCAP with ROS1 or ROS2 channels, ROS1 bags, ROS2 bags)
goes through here, so a NavSatFix is a NavSatFix whatever file holds it. Each supported type has a
*kind* with a fixed tuple of raw values per message. Messages are turned into raw rows either by the
fast path (fixed-layout Imu and NavSatFix decoded straight from their bytes) or from a deserialised
message; both give identical rows. Raw rows become schema columns in vectorised `*_columns` functions.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spooflens.schema import FixType

FloatArray = NDArray[np.float64]

KIND_BY_TYPE = {
    "sensor_msgs/msg/NavSatFix": "navsatfix",
    "sensor_msgs/msg/Imu": "imu",
    "geometry_msgs/msg/TwistWithCovarianceStamped": "twist_cov",
    "geometry_msgs/msg/TwistStamped": "twist",
    "nav_msgs/msg/Odometry": "odometry",
    "gps_msgs/msg/GPSFix": "gpsfix",
    "gps_common/msg/GPSFix": "gpsfix",
}
ROLE_BY_KIND = {
    "navsatfix": "fix",
    "gpsfix": "fix",
    "imu": "imu",
    "twist_cov": "vel",
    "twist": "vel",
    "odometry": "odom",
}

RAW_COLUMNS: dict[str, tuple[str, ...]] = {
    "navsatfix": ("status", "lat", "lon", "alt", "cov_e", "cov_n", "cov_u", "cov_type"),
    "gpsfix": (
        "status",
        "sats_used",
        "lat",
        "lon",
        "alt",
        "track_deg",
        "speed",
        "climb",
        "err_horz",
        "err_vert",
        "err_speed",
        "hdop",
        "vdop",
        "cn0_mean",
    ),
    "imu": ("qx", "qy", "qz", "qw", "ocov0", "wx", "wy", "wz", "wcov0", "ax", "ay", "az", "acov0"),
    "twist_cov": ("ve", "vn", "vu", "cov_ve", "cov_vn", "cov_vu"),
    "twist": ("ve", "vn", "vu", "cov_ve", "cov_vn", "cov_vu"),
    "odometry": ("x", "y", "z", "vx", "vy", "vz", "wz"),
}


def normalise_type(name: str) -> str:
    """'sensor_msgs/NavSatFix' (ROS1) and 'sensor_msgs/msg/NavSatFix' (ROS2) are the same type."""
    parts = name.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return name


def kind_of(msgtype: str) -> str | None:
    return KIND_BY_TYPE.get(normalise_type(msgtype))


def stamp_ns(header: Any) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


# --- generic path: from deserialised messages (rosbags objects, attribute access) -------------------


def _navsatfix(m: Any) -> tuple[float, ...]:
    c = m.position_covariance
    return (m.status.status, m.latitude, m.longitude, m.altitude, c[0], c[4], c[8], m.position_covariance_type)


def _gpsfix(m: Any) -> tuple[float, ...]:
    s = m.status
    snr = np.asarray(s.satellite_visible_snr, dtype=float)
    tracked = snr[snr > 0]  # gpsd's per-satellite signal strength, dB-Hz; 0 for a satellite not tracked
    return (
        s.status,
        s.satellites_used,
        m.latitude,
        m.longitude,
        m.altitude,
        m.track,
        m.speed,
        m.climb,
        m.err_horz,
        m.err_vert,
        m.err_speed,
        m.hdop,
        m.vdop,
        float(tracked.mean()) if len(tracked) else np.nan,
    )


def _imu(m: Any) -> tuple[float, ...]:
    o, w, a = m.orientation, m.angular_velocity, m.linear_acceleration
    return (
        o.x,
        o.y,
        o.z,
        o.w,
        m.orientation_covariance[0],
        w.x,
        w.y,
        w.z,
        m.angular_velocity_covariance[0],
        a.x,
        a.y,
        a.z,
        m.linear_acceleration_covariance[0],
    )


def _twist_cov(m: Any) -> tuple[float, ...]:
    v, c = m.twist.twist.linear, m.twist.covariance
    return (v.x, v.y, v.z, c[0], c[7], c[14])


def _twist(m: Any) -> tuple[float, ...]:
    v = m.twist.linear
    return (v.x, v.y, v.z, np.nan, np.nan, np.nan)


def _odometry(m: Any) -> tuple[float, ...]:
    p, v, w = m.pose.pose.position, m.twist.twist.linear, m.twist.twist.angular
    return (p.x, p.y, p.z, v.x, v.y, v.z, w.z)


EXTRACT: dict[str, Callable[[Any], tuple[float, ...]]] = {
    "navsatfix": _navsatfix,
    "gpsfix": _gpsfix,
    "imu": _imu,
    "twist_cov": _twist_cov,
    "twist": _twist,
    "odometry": _odometry,
}


def extract(kind: str, msg: Any) -> tuple[int, tuple[float, ...]]:
    """(header stamp ns, raw values) of a deserialised message of `kind`."""
    return stamp_ns(msg.header), EXTRACT[kind](msg)


# --- fast path: fixed layouts straight from bytes ----------------------------------------------------
# After the header's frame_id string both types have a fixed layout. CDR aligns each primitive to its
# size relative to the payload start (after the 4-byte encapsulation header); ROS1 packs them.

_U32 = struct.Struct("<I")
_CDR_STAMP = struct.Struct("<iI")
_ROS1_STAMP = struct.Struct("<II")
_IMU_BODY = struct.Struct("<37d")
_FIX_BODY = struct.Struct("<3d9dB")
_ROS1_FIX_STATUS = struct.Struct("<bH")
_IMU_PICK = (0, 1, 2, 3, 4, 13, 14, 15, 16, 25, 26, 27, 28)


def _imu_values(v: tuple[float, ...]) -> tuple[float, ...]:
    return tuple(v[i] for i in _IMU_PICK)


def decode_cdr(kind: str, raw: bytes | memoryview) -> tuple[int, tuple[float, ...]] | None:
    """Fast decode of a little-endian CDR Imu or NavSatFix; None for other kinds or layouts."""
    if kind not in ("imu", "navsatfix") or raw[1] != 1:  # byte 1 == 1: CDR little endian
        return None
    sec, nsec = _CDR_STAMP.unpack_from(raw, 4)
    n = _U32.unpack_from(raw, 12)[0]
    pos = 16 + n
    if kind == "imu":
        pos = 4 + ((pos - 4 + 7) & ~7)
        return sec * 1_000_000_000 + nsec, _imu_values(_IMU_BODY.unpack_from(raw, pos))
    status = struct.unpack_from("<b", raw, pos)[0]
    pos = 4 + ((pos + 1 - 4 + 1) & ~1) + 2  # int8 status, then uint16 service aligned to 2
    pos = 4 + ((pos - 4 + 7) & ~7)
    lat, lon, alt, *cov, cov_type = _FIX_BODY.unpack_from(raw, pos)
    return sec * 1_000_000_000 + nsec, (status, lat, lon, alt, cov[0], cov[4], cov[8], cov_type)


def decode_ros1(kind: str, raw: bytes | memoryview) -> tuple[int, tuple[float, ...]] | None:
    """Fast decode of a ROS1-serialised Imu or NavSatFix; None for other kinds."""
    if kind not in ("imu", "navsatfix"):
        return None
    sec, nsec = _ROS1_STAMP.unpack_from(raw, 4)
    pos = 16 + _U32.unpack_from(raw, 12)[0]
    if kind == "imu":
        return sec * 1_000_000_000 + nsec, _imu_values(_IMU_BODY.unpack_from(raw, pos))
    status, _service = _ROS1_FIX_STATUS.unpack_from(raw, pos)
    lat, lon, alt, *cov, cov_type = _FIX_BODY.unpack_from(raw, pos + 3)
    return sec * 1_000_000_000 + nsec, (status, lat, lon, alt, cov[0], cov[4], cov[8], cov_type)


# --- raw rows -> schema columns (vectorised) --------------------------------------------------------

# NavSatStatus: -1 no fix, 0 fix, 1 SBAS, 2 GBAS. gps_msgs/GPSStatus (gps_umd) keeps those and adds
# 18 DGPS, 19 RTK fixed integers, 20 RTK float, 33 WAAS; other codes count as a plain fix.
_NAVSAT_FIX_TYPE = {-1: FixType.NO_FIX, 0: FixType.FIX_3D, 1: FixType.SBAS, 2: FixType.DGNSS}
_GPSFIX_FIX_TYPE = {
    -1: FixType.NO_FIX,
    0: FixType.FIX_3D,
    1: FixType.SBAS,
    2: FixType.DGNSS,
    18: FixType.DGNSS,
    19: FixType.RTK_FIXED,
    20: FixType.RTK_FLOAT,
    33: FixType.SBAS,
}
# gps_msgs/GPSFix errors are 95 % bounds: 1 sigma is err / 2.45 in 2-D, err / 1.96 in 1-D.
_CHI_95_2D, _CHI_95_1D = 2.4477, 1.96


def _map_codes(codes: FloatArray, table: dict[int, FixType]) -> NDArray[np.int8]:
    out = np.full(len(codes), FixType.FIX_3D, dtype=np.int8)
    for code, fix_type in table.items():
        out[codes == code] = fix_type
    return out


def fix_columns(kind: str, v: FloatArray) -> dict[str, np.ndarray]:
    """Schema `fixes` columns (without t_s/receiver_id) from raw NavSatFix or GPSFix rows."""
    cols = RAW_COLUMNS[kind]

    def c(name: str) -> FloatArray:
        return v[:, cols.index(name)]

    out: dict[str, np.ndarray] = {"lat_deg": c("lat"), "lon_deg": c("lon"), "height_m": c("alt")}
    if kind == "navsatfix":
        known = c("cov_type") > 0  # COVARIANCE_TYPE_UNKNOWN = 0
        out["h_acc_m"] = np.where(known, np.sqrt(np.abs(0.5 * (c("cov_e") + c("cov_n")))), np.nan)
        out["v_acc_m"] = np.where(known, np.sqrt(np.abs(c("cov_u"))), np.nan)
        out["fix_type"] = _map_codes(c("status"), _NAVSAT_FIX_TYPE)
    else:
        track, speed = np.radians(c("track_deg")), c("speed")
        out |= {
            "vel_e_mps": speed * np.sin(track),
            "vel_n_mps": speed * np.cos(track),
            "vel_u_mps": c("climb"),
            "h_acc_m": c("err_horz") / _CHI_95_2D,
            "v_acc_m": c("err_vert") / _CHI_95_1D,
            "vel_acc_mps": c("err_speed") / _CHI_95_1D,
            "sats_used": c("sats_used"),
            # gpsd leaves a DOP it does not know at 0 (or NaN); a real DOP is positive
            "hdop": np.where(c("hdop") > 0, c("hdop"), np.nan),
            "vdop": np.where(c("vdop") > 0, c("vdop"), np.nan),
            "cn0_mean_dbhz": c("cn0_mean"),
            "fix_type": _map_codes(c("status"), _GPSFIX_FIX_TYPE),
        }
    return out


def imu_columns(v: FloatArray) -> dict[str, np.ndarray]:
    """Schema `imu` columns from raw Imu rows; orientation NaN where the message says it has none."""
    cols = RAW_COLUMNS["imu"]

    def c(name: str) -> FloatArray:
        return v[:, cols.index(name)]

    no_orientation = (c("ocov0") == -1) | ((c("qx") == 0) & (c("qy") == 0) & (c("qz") == 0) & (c("qw") == 0))
    out = {
        "ax_mps2": c("ax"),
        "ay_mps2": c("ay"),
        "az_mps2": c("az"),
        "wx_radps": c("wx"),
        "wy_radps": c("wy"),
        "wz_radps": c("wz"),
    }
    for q in ("qw", "qx", "qy", "qz"):
        out[q] = np.where(no_orientation, np.nan, c(q))
    return out


def velocity_columns(kind: str, v: FloatArray) -> dict[str, np.ndarray]:
    """ENU velocity and its 1-sigma accuracy from raw twist rows (GNSS drivers publish ENU)."""
    cols = RAW_COLUMNS[kind]
    var = v[:, [cols.index("cov_ve"), cols.index("cov_vn"), cols.index("cov_vu")]]
    acc = np.sqrt(np.abs(np.mean(var, axis=1)))
    acc[~(np.all(var > 0, axis=1))] = np.nan
    return {
        "vel_e_mps": v[:, cols.index("ve")],
        "vel_n_mps": v[:, cols.index("vn")],
        "vel_u_mps": v[:, cols.index("vu")],
        "vel_acc_mps": acc,
    }


def odometry_columns(v: FloatArray) -> dict[str, np.ndarray]:
    names = ("x_m", "y_m", "z_m", "vx_mps", "vy_mps", "vz_mps", "wz_radps")
    return {n: v[:, i] for i, n in enumerate(names)}


# --- the reverse direction, for writers: schema columns -> fixed-layout message bytes ----------------

_FIX_TYPE_TO_NAVSAT = {
    FixType.NO_FIX: -1,
    FixType.SBAS: 1,
    FixType.DGNSS: 2,
    FixType.RTK_FLOAT: 2,
    FixType.RTK_FIXED: 2,
}


def navsat_status(fix_type: int) -> int:
    """NavSatStatus code for a FixType."""
    return _FIX_TYPE_TO_NAVSAT.get(FixType(int(fix_type)), 0)


def navsat_covariance(h_acc: float, v_acc: float) -> tuple[list[float], int]:
    """Diagonal ENU covariance and its type (2 = DIAGONAL_KNOWN, 0 = UNKNOWN) from 1-sigma accuracies."""
    if np.isfinite(h_acc) and np.isfinite(v_acc):
        return [h_acc**2, 0.0, 0.0, 0.0, h_acc**2, 0.0, 0.0, 0.0, v_acc**2], 2
    return [0.0] * 9, 0


def _cdr_header(stamp: int, frame_id: str) -> bytes:
    fid = frame_id.encode() + b"\0"
    return b"\x00\x01\x00\x00" + struct.pack("<iII", stamp // 1_000_000_000, stamp % 1_000_000_000, len(fid)) + fid


def _ros1_header(stamp: int, frame_id: str, seq: int) -> bytes:
    fid = frame_id.encode()
    return struct.pack("<IIII", seq, stamp // 1_000_000_000, stamp % 1_000_000_000, len(fid)) + fid


def _pad_to(buf: bytes, align: int) -> bytes:
    rel = len(buf) - 4
    return buf + b"\0" * ((-rel) % align)


def encode_imu(
    stamp: int,
    frame_id: str,
    q: tuple[float, float, float, float] | None,
    w: tuple[float, ...],
    a: tuple[float, ...],
    encoding: str,
    seq: int = 0,
) -> bytes:
    """A sensor_msgs/Imu (CDR or ROS1), orientation (x, y, z, w) or None (covariance[0] = -1)."""
    ocov = [0.0] * 9 if q is not None else [-1.0] + [0.0] * 8
    body = _IMU_BODY.pack(*(q if q is not None else (0.0, 0.0, 0.0, 0.0)), *ocov, *w, *([0.0] * 9), *a, *([0.0] * 9))
    if encoding == "cdr":
        return _pad_to(_cdr_header(stamp, frame_id), 8) + body
    return _ros1_header(stamp, frame_id, seq) + body


def encode_navsatfix(
    stamp: int,
    frame_id: str,
    status: int,
    lat: float,
    lon: float,
    alt: float,
    cov: list[float],
    cov_type: int,
    encoding: str,
    seq: int = 0,
    service: int = 1,
) -> bytes:
    """A sensor_msgs/NavSatFix (CDR or ROS1)."""
    body = _FIX_BODY.pack(lat, lon, alt, *cov, cov_type)
    if encoding == "cdr":
        head = _pad_to(_cdr_header(stamp, frame_id) + struct.pack("<b", status), 2) + struct.pack("<H", service)
        return _pad_to(head, 8) + body
    return _ros1_header(stamp, frame_id, seq) + _ROS1_FIX_STATUS.pack(status, service) + body
