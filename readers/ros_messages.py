"""ROS message types <-> epoch-table columns: the one place each type's mapping is written, both ways.

Every container that carries ROS messages (MCAP with ROS1 or ROS2 channels, ROS1 bags, ROS2 bags)
reads through here, and every writer and the `inject` rewriter write through here, so a NavSatFix is a
NavSatFix whatever file holds it and whichever way it goes. Each supported type has a *kind*
(`KINDS`): its ROS type names, its role, a fixed tuple of raw values per message, and the functions
that take a message apart (`extract`), build one from a table row (`build`), and put spoofed fix
values into one (`edit`). Reading: messages become raw rows either by the fast path (fixed-layout Imu
and NavSatFix decoded straight from their bytes) or from a deserialised message, both giving identical
rows, and the fixed layouts (`RosKind.layout`: Imu, NavSatFix, the twists, Odometry) of many messages at
once with numpy (`batch_decoder`, `readers.ros_batch`); raw rows become schema columns in vectorised
`*_columns` functions. Writing: Imu and NavSatFix
are encoded straight to bytes (the mirror of the fast path), the other kinds built as typestore
messages and serialised.
"""

from __future__ import annotations

import dataclasses
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from readers.ros_batch import Field, Pick, decode_batch
from spooflens.schema import FixType

FloatArray = NDArray[np.float64]
RawRows = Mapping[str, FloatArray]  # a stream's raw columns by name (`RowBuffer.arrays`)

Row = Callable[[str], float]  # a table row: column name -> value
FixValues = tuple[float, float, float, float, float, float]  # lat, lon, h, ve, vn, vu


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
        a.x,
        a.y,
        a.z,
        w.x,
        w.y,
        w.z,
        o.w,
        o.x,
        o.y,
        o.z,
        m.orientation_covariance[0],
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


def _time_reference(m: Any) -> tuple[float, ...]:
    return (float(m.time_ref.sec), float(m.time_ref.nanosec))


def extract(kind: str, msg: Any) -> tuple[int, tuple[float, ...]]:
    """(header stamp ns, raw values) of a deserialised message of `kind`."""
    return stamp_ns(msg.header), KINDS[kind].extract(msg)


# --- fast path: fixed layouts straight from bytes ----------------------------------------------------
# After the header's frame_id string both types have a fixed layout. CDR aligns each primitive to its
# size relative to the payload start (after the 4-byte encapsulation header); ROS1 packs them.

_U32 = struct.Struct("<I")
_CDR_STAMP = struct.Struct("<iI")
_ROS1_STAMP = struct.Struct("<II")
_IMU_BODY = struct.Struct("<37d")
_FIX_BODY = struct.Struct("<3d9dB")
_ROS1_FIX_STATUS = struct.Struct("<bH")
# linear_acceleration, angular_velocity, orientation (w, x, y, z), orientation_covariance[0] of the 37
# doubles: the schema's column order, so the table's columns are the decoded rows themselves
_IMU_PICK = (25, 26, 27, 13, 14, 15, 3, 0, 1, 2, 4)


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


def fix_columns(kind: str, v: RawRows) -> dict[str, np.ndarray]:
    """Schema `fixes` columns (without t_s/receiver_id) from raw NavSatFix or GPSFix rows."""
    c = v.__getitem__

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


def imu_columns(v: RawRows) -> dict[str, np.ndarray]:
    """Schema `imu` columns from raw Imu rows; orientation NaN where the message says it has none.

    The columns are `v`'s own (its orientation cleared in place): a day of 100 Hz IMU is 0.7 GB, which
    a copy would hold twice while the frame is made."""
    c = v.__getitem__
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
        out[q] = c(q)
        out[q][no_orientation] = np.nan
    return out


def velocity_columns(v: RawRows) -> dict[str, np.ndarray]:
    """ENU velocity and its 1-sigma accuracy from raw twist rows (GNSS drivers publish ENU)."""
    var = np.column_stack([v["cov_ve"], v["cov_vn"], v["cov_vu"]])
    acc = np.sqrt(np.abs(np.mean(var, axis=1)))
    acc[~(np.all(var > 0, axis=1))] = np.nan
    return {"vel_e_mps": v["ve"], "vel_n_mps": v["vn"], "vel_u_mps": v["vu"], "vel_acc_mps": acc}


def odometry_columns(v: RawRows) -> dict[str, np.ndarray]:
    names = ("x_m", "y_m", "z_m", "vx_mps", "vy_mps", "vz_mps", "wz_radps")
    return dict(zip(names, v.values(), strict=True))


# --- the reverse direction, for writers: table rows -> messages ---------------------------------------

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


def imu_parts(row: Row) -> tuple[tuple[float, float, float, float] | None, tuple[float, ...], tuple[float, ...]]:
    """(orientation (x, y, z, w) or None when the row has none, angular rate, specific force) of an IMU row."""
    q = (row("qx"), row("qy"), row("qz"), row("qw"))
    w = (row("wx_radps"), row("wy_radps"), row("wz_radps"))
    a = (row("ax_mps2"), row("ay_mps2"), row("az_mps2"))
    return (q if np.all(np.isfinite(q)) else None), w, a


def _build_twist_cov(T: Any, header: Any, row: Row) -> Any:
    V = T["geometry_msgs/msg/Vector3"]
    cov6 = np.zeros(36)
    acc = row("vel_acc_mps")
    cov6[[0, 7, 14]] = acc**2 if np.isfinite(acc) else 0.0
    twist = T["geometry_msgs/msg/Twist"](
        linear=V(x=row("vel_e_mps"), y=row("vel_n_mps"), z=row("vel_u_mps")),
        angular=V(x=0.0, y=0.0, z=0.0),
    )
    return T["geometry_msgs/msg/TwistWithCovarianceStamped"](
        header=header, twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov6)
    )


def _build_odometry(T: Any, header: Any, row: Row) -> Any:
    V = T["geometry_msgs/msg/Vector3"]
    pose = T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=row("x_m"), y=row("y_m"), z=row("z_m")),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
    )
    twist = T["geometry_msgs/msg/Twist"](
        linear=V(x=row("vx_mps"), y=row("vy_mps"), z=row("vz_mps")),
        angular=V(x=0.0, y=0.0, z=row("wz_radps")),
    )
    return T["nav_msgs/msg/Odometry"](
        header=header,
        child_frame_id="base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
    )


def _header(T: Any, stamp: int, frame_id: str, seq: int | None) -> Any:
    """A std_msgs/Header; `seq` only for ROS1 (ROS2 headers have none)."""
    time = T["builtin_interfaces/msg/Time"](sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000)
    extra = {"seq": seq} if seq is not None else {}
    return T["std_msgs/msg/Header"](**extra, stamp=time, frame_id=frame_id)


def encode(kind: str, store: Any, ros_version: int, stamp: int, frame_id: str, row: Row, seq: int) -> bytes:
    """One message of `kind` from a table row, serialised for ROS `ros_version` (1: ROS1, 2: CDR).

    Imu and NavSatFix are packed straight to bytes (the mirror of the fast decode path); the other kinds
    are built as `store` (a rosbags typestore) messages and serialised. `seq` is the ROS1 header seq.
    """
    encoding = "cdr" if ros_version == 2 else "ros1"
    if kind == "imu":
        q, w, a = imu_parts(row)
        return encode_imu(stamp, frame_id, q, w, a, encoding, seq=seq)
    if kind == "navsatfix":
        cov, cov_type = navsat_covariance(row("h_acc_m"), row("v_acc_m"))
        return encode_navsatfix(
            stamp,
            frame_id,
            navsat_status(int(row("fix_type"))),
            row("lat_deg"),
            row("lon_deg"),
            row("height_m"),
            cov,
            cov_type,
            encoding,
            seq=seq,
        )
    spec = KINDS[kind]
    if spec.build is None:
        raise KeyError(f"no ROS encoder for {kind!r}; writable kinds are {sorted(writable_kinds())}")
    msg = spec.build(store.types, _header(store.types, stamp, frame_id, seq if ros_version == 1 else None), row)
    serialize = store.serialize_cdr if ros_version == 2 else store.serialize_ros1
    return bytes(serialize(msg, spec.msgtypes[0]))


# --- spoofed values into decoded messages (inject) ---------------------------------------------------


def _edit_fix(msg: Any, values: FixValues, velocity: bool) -> Any:
    lat, lon, h, *_ = values
    return dataclasses.replace(msg, latitude=lat, longitude=lon, altitude=h)


def _edit_gpsfix(msg: Any, values: FixValues, velocity: bool) -> Any:
    lat, lon, h, ve, vn, vu = values
    changes: dict[str, Any] = {"latitude": lat, "longitude": lon, "altitude": h}
    if velocity and np.isfinite(ve):
        changes |= {"speed": float(np.hypot(ve, vn)), "track": float(np.degrees(np.arctan2(ve, vn)) % 360), "climb": vu}
    return dataclasses.replace(msg, **changes)


def _edit_twist_cov(msg: Any, values: FixValues, velocity: bool) -> Any:
    _, _, _, ve, vn, vu = values
    lin = dataclasses.replace(msg.twist.twist.linear, x=ve, y=vn, z=vu)
    inner = dataclasses.replace(msg.twist.twist, linear=lin)
    return dataclasses.replace(msg, twist=dataclasses.replace(msg.twist, twist=inner))


def _edit_twist(msg: Any, values: FixValues, velocity: bool) -> Any:
    _, _, _, ve, vn, vu = values
    lin = dataclasses.replace(msg.twist.linear, x=ve, y=vn, z=vu)
    return dataclasses.replace(msg, twist=dataclasses.replace(msg.twist, linear=lin))


def edit(kind: str, msg: Any, values: FixValues, velocity: bool) -> Any:
    """A copy of a decoded fix or velocity message carrying spoofed (lat, lon, h, ve, vn, vu).

    A GPSFix gets the velocity too when `velocity` is set (and the values have one); velocity messages
    always get it.
    """
    spec = KINDS[kind]
    if spec.edit is None:
        raise KeyError(f"{kind!r} messages carry no fix or velocity to edit")
    return spec.edit(msg, values, velocity)


# --- fixed layouts (after std_msgs/Header), for decoding many messages at once ------------------------

_IMU_LAYOUT = (
    Field("orientation", "f8", 4),
    Field("orientation_covariance", "f8", 9),
    Field("angular_velocity", "f8", 3),
    Field("angular_velocity_covariance", "f8", 9),
    Field("linear_acceleration", "f8", 3),
    Field("linear_acceleration_covariance", "f8", 9),
)
_IMU_PICKS: tuple[Pick, ...] = (  # the order of _IMU_PICK
    *(("linear_acceleration", i) for i in range(3)),
    *(("angular_velocity", i) for i in range(3)),
    *(("orientation", i) for i in (3, 0, 1, 2)),
    ("orientation_covariance", 0),
)
_NAVSATFIX_LAYOUT = (
    Field("status", "i1"),
    Field("service", "u2"),
    Field("position", "f8", 3),  # latitude, longitude, altitude
    Field("position_covariance", "f8", 9),
    Field("position_covariance_type", "u1"),
)
_NAVSATFIX_PICKS: tuple[Pick, ...] = (
    ("status", 0),
    *(("position", i) for i in range(3)),
    *(("position_covariance", i) for i in (0, 4, 8)),
    ("position_covariance_type", 0),
)
_TWIST = (Field("linear", "f8", 3), Field("angular", "f8", 3))
_TWIST_COV_LAYOUT = (*_TWIST, Field("covariance", "f8", 36))
_TWIST_PICKS: tuple[Pick, ...] = (*(("linear", i) for i in range(3)), None, None, None)
_TWIST_COV_PICKS: tuple[Pick, ...] = (*(("linear", i) for i in range(3)), *(("covariance", i) for i in (0, 7, 14)))
_ODOMETRY_LAYOUT = (
    Field("child_frame_id", "string"),
    Field("position", "f8", 3),
    Field("orientation", "f8", 4),
    Field("pose_covariance", "f8", 36),
    Field("linear", "f8", 3),
    Field("angular", "f8", 3),
    Field("twist_covariance", "f8", 36),
)
_ODOMETRY_PICKS: tuple[Pick, ...] = (
    *(("position", i) for i in range(3)),
    *(("linear", i) for i in range(3)),
    ("angular", 2),
)

BatchDecoder = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


def batch_decoder(kind: str, encoding: str) -> BatchDecoder | None:
    """(buf, starts, lengths) -> (stamps, raw rows, ok) for messages of `kind` ('cdr' or 'ros1' encoded),
    or None when the kind has no fixed layout. Rows agree with `extract` of the deserialised message."""
    spec = KINDS[kind]
    if spec.layout is None or encoding not in ("cdr", "ros1"):
        return None
    layout, picks = spec.layout, spec.picks

    def decode(buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return decode_batch(layout, picks, encoding, buf, starts, lengths)

    return decode


# --- the kinds --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RosKind:
    """One kind of ROS message and its mapping both ways.

    `msgtypes`: ROS2-style names this kind reads (ROS1 names are normalised); writers emit the first.
    `raw_columns`: the tuple `extract` returns per message (the fast path returns the same).
    `build`: (typestore types, header, row) -> message, for kinds written as typestore messages
    (Imu and NavSatFix are packed straight to bytes by `encode`). `edit`: spoofed values in.
    `layout`: the fields after the header when the type has a fixed layout (strings may vary), and
    `picks`: where each raw column lies in it ((field, index), None for a value the type lacks), for
    decoding a whole chunk of messages at once; None for types with arrays (GPSFix), decoded one by one.
    """

    msgtypes: tuple[str, ...]
    role: str
    raw_columns: tuple[str, ...]
    extract: Callable[[Any], tuple[float, ...]]
    build: Callable[[Any, Any, Row], Any] | None = None
    edit: Callable[[Any, FixValues, bool], Any] | None = None
    layout: tuple[Field, ...] | None = None
    picks: tuple[Pick, ...] = ()


KINDS: dict[str, RosKind] = {
    "navsatfix": RosKind(
        ("sensor_msgs/msg/NavSatFix",),
        "fix",
        ("status", "lat", "lon", "alt", "cov_e", "cov_n", "cov_u", "cov_type"),
        _navsatfix,
        edit=_edit_fix,
        layout=_NAVSATFIX_LAYOUT,
        picks=_NAVSATFIX_PICKS,
    ),
    "gpsfix": RosKind(
        ("gps_msgs/msg/GPSFix", "gps_common/msg/GPSFix"),
        "fix",
        (
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
        _gpsfix,
        edit=_edit_gpsfix,
    ),
    "imu": RosKind(
        ("sensor_msgs/msg/Imu",),
        "imu",
        ("ax", "ay", "az", "wx", "wy", "wz", "qw", "qx", "qy", "qz", "ocov0"),
        _imu,
        layout=_IMU_LAYOUT,
        picks=_IMU_PICKS,
    ),
    "twist_cov": RosKind(
        ("geometry_msgs/msg/TwistWithCovarianceStamped",),
        "vel",
        ("ve", "vn", "vu", "cov_ve", "cov_vn", "cov_vu"),
        _twist_cov,
        build=_build_twist_cov,
        edit=_edit_twist_cov,
        layout=_TWIST_COV_LAYOUT,
        picks=_TWIST_COV_PICKS,
    ),
    "twist": RosKind(
        ("geometry_msgs/msg/TwistStamped",),
        "vel",
        ("ve", "vn", "vu", "cov_ve", "cov_vn", "cov_vu"),
        _twist,
        edit=_edit_twist,
        layout=_TWIST,
        picks=_TWIST_PICKS,
    ),
    "odometry": RosKind(
        ("nav_msgs/msg/Odometry",),
        "odom",
        ("x", "y", "z", "vx", "vy", "vz", "wz"),
        _odometry,
        build=_build_odometry,
        layout=_ODOMETRY_LAYOUT,
        picks=_ODOMETRY_PICKS,
    ),
    # nmea_navsat_driver and others: the receiver's time of a sentence (`time_ref`) beside the host's
    # time it came at (the header stamp)
    "time_reference": RosKind(("sensor_msgs/msg/TimeReference",), "timeref", ("ref_sec", "ref_nsec"), _time_reference),
}
KIND_BY_TYPE = {t: kind for kind, spec in KINDS.items() for t in spec.msgtypes}
ROLE_BY_KIND = {kind: spec.role for kind, spec in KINDS.items()}
RAW_COLUMNS = {kind: spec.raw_columns for kind, spec in KINDS.items()}


def writable_kinds() -> set[str]:
    """Kinds `encode` can write."""
    return {"imu", "navsatfix"} | {k for k, spec in KINDS.items() if spec.build is not None}


def msgtype_of(kind: str) -> str:
    """The ROS type a writer emits for `kind`."""
    return KINDS[kind].msgtypes[0]
