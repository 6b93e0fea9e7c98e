"""JSON and protobuf messages (Foxglove conventions) -> the same raw rows as the ROS mapping.

Supported schemas, in either encoding:
- `foxglove.LocationFix`: a GNSS fix (latitude, longitude, altitude, position_covariance (ENU, m^2),
  position_covariance_type, timestamp, frame_id).
- `spooflens.Imu`: an IMU sample (timestamp, frame_id, angular_velocity {x,y,z} rad/s,
  linear_acceleration {x,y,z} m/s^2 in a FLU body frame, optional orientation {x,y,z,w} body->ENU).
JSON timestamps are `{"sec": int, "nsec": int}` (Foxglove's JSON convention); protobuf ones are
google.protobuf.Timestamp. The writers' schemas and the row -> message mapping live here too, so each
layout is defined once, both ways.
"""

from __future__ import annotations

import json
from typing import Any

from google.protobuf import descriptor_pb2, timestamp_pb2

from readers.ros_messages import RAW_COLUMNS, Row, imu_parts, navsat_covariance

KIND_BY_SCHEMA = {"foxglove.LocationFix": "navsatfix", "spooflens.Imu": "imu"}


def _get(m: Any, name: str) -> Any:
    return m[name] if isinstance(m, dict) else getattr(m, name)


def _has(m: Any, name: str) -> bool:
    if isinstance(m, dict):
        return name in m and m[name] is not None
    if not hasattr(m, "HasField"):
        return hasattr(m, name)
    try:
        return bool(m.HasField(name))
    except ValueError:  # proto3 scalars and repeated fields have no presence: they are always there
        return True


def _stamp_ns(m: Any) -> int:
    ts = _get(m, "timestamp")
    if isinstance(ts, dict):
        return int(ts["sec"]) * 1_000_000_000 + int(ts.get("nsec", 0))
    return int(ts.seconds) * 1_000_000_000 + int(ts.nanos)


def _location_fix(m: Any) -> tuple[float, ...]:
    cov = list(_get(m, "position_covariance")) if _has(m, "position_covariance") else []
    cov = cov if len(cov) == 9 else [0.0] * 9
    cov_type = _get(m, "position_covariance_type") if _has(m, "position_covariance_type") else 0
    return (0, _get(m, "latitude"), _get(m, "longitude"), _get(m, "altitude"), cov[0], cov[4], cov[8], float(cov_type))


def _vec(m: Any, name: str, keys: str = "xyz") -> list[float]:
    v = _get(m, name)
    return [float(_get(v, k)) for k in keys]


def _imu(m: Any) -> tuple[float, ...]:
    has_q = _has(m, "orientation")
    q = _vec(m, "orientation", "wxyz") if has_q else [0.0, 0.0, 0.0, 0.0]
    w, a = _vec(m, "angular_velocity"), _vec(m, "linear_acceleration")
    return (*a, *w, *q, 0.0 if has_q else -1.0)  # RAW_COLUMNS["imu"]


_EXTRACT = {"navsatfix": _location_fix, "imu": _imu}
assert all(len(RAW_COLUMNS[k]) for k in _EXTRACT)


def extract(kind: str, msg: Any) -> tuple[int, tuple[float, ...]]:
    """(stamp ns, raw values) of a decoded JSON dict or protobuf message of a supported schema."""
    return _stamp_ns(msg), _EXTRACT[kind](msg)


def frame_id(msg: Any) -> str:
    return str(_get(msg, "frame_id")) if _has(msg, "frame_id") else ""


# --- the reverse direction: a table row -> the fields of a message (JSON dict; protobuf fills from it) --


def fields(kind: str, row: Row, t: int, frame_id: str) -> dict[str, Any]:
    """The message of `kind` (imu, navsatfix) for a table row stamped `t` ns, as nested fields."""
    stamp = {"sec": t // 1_000_000_000, "nsec": t % 1_000_000_000}
    if kind == "imu":
        q, w, a = imu_parts(row)
        out: dict[str, Any] = {
            "timestamp": stamp,
            "frame_id": frame_id,
            "angular_velocity": dict(zip("xyz", w, strict=True)),
            "linear_acceleration": dict(zip("xyz", a, strict=True)),
        }
        if q is not None:
            out["orientation"] = dict(zip("xyzw", q, strict=True))
        return out
    cov, cov_type = navsat_covariance(row("h_acc_m"), row("v_acc_m"))
    return {
        "timestamp": stamp,
        "frame_id": frame_id,
        "latitude": row("lat_deg"),
        "longitude": row("lon_deg"),
        "altitude": row("height_m"),
        "position_covariance": cov,
        "position_covariance_type": cov_type,
    }


# --- schemas for writers -----------------------------------------------------------------------------

_STAMP_JSON = {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}}
_VEC_JSON = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
JSON_SCHEMAS: dict[str, bytes] = {
    "foxglove.LocationFix": json.dumps(
        {
            "title": "foxglove.LocationFix",
            "type": "object",
            "properties": {
                "timestamp": _STAMP_JSON,
                "frame_id": {"type": "string"},
                "latitude": {"type": "number"},
                "longitude": {"type": "number"},
                "altitude": {"type": "number"},
                "position_covariance": {"type": "array", "items": {"type": "number"}},
                "position_covariance_type": {"type": "integer"},
            },
        }
    ).encode(),
    "spooflens.Imu": json.dumps(
        {
            "title": "spooflens.Imu",
            "type": "object",
            "properties": {
                "timestamp": _STAMP_JSON,
                "frame_id": {"type": "string"},
                "angular_velocity": _VEC_JSON,
                "linear_acceleration": _VEC_JSON,
                "orientation": {"type": "object", "properties": {k: {"type": "number"} for k in "xyzw"}},
            },
        }
    ).encode(),
}

_D = descriptor_pb2.FieldDescriptorProto


def _field(name: str, number: int, ftype: _D.Type.ValueType, type_name: str = "", repeated: bool = False) -> _D:
    field = _D(name=name, number=number, type=ftype, label=_D.LABEL_REPEATED if repeated else _D.LABEL_OPTIONAL)
    if type_name:  # an empty type_name still counts as set, and protobuf rejects it on scalar fields
        field.type_name = type_name
    return field


def protobuf_file_descriptor_set(schema_name: str) -> bytes:
    """A FileDescriptorSet (with its google.protobuf.Timestamp dependency) for one supported schema."""
    ts_file = descriptor_pb2.FileDescriptorProto()
    timestamp_pb2.DESCRIPTOR.CopyToProto(ts_file)
    f = descriptor_pb2.FileDescriptorProto(syntax="proto3", dependency=["google/protobuf/timestamp.proto"])
    if schema_name == "foxglove.LocationFix":
        f.name, f.package = "foxglove/LocationFix.proto", "foxglove"
        msg = f.message_type.add(name="LocationFix")
        enum = msg.enum_type.add(name="PositionCovarianceType")
        for i, n in enumerate(("UNKNOWN", "APPROXIMATED", "DIAGONAL_KNOWN", "KNOWN")):
            enum.value.add(name=n, number=i)
        msg.field.extend(
            [
                _field("timestamp", 6, _D.TYPE_MESSAGE, ".google.protobuf.Timestamp"),
                _field("frame_id", 7, _D.TYPE_STRING),
                _field("latitude", 1, _D.TYPE_DOUBLE),
                _field("longitude", 2, _D.TYPE_DOUBLE),
                _field("altitude", 3, _D.TYPE_DOUBLE),
                _field("position_covariance", 4, _D.TYPE_DOUBLE, repeated=True),
                _field("position_covariance_type", 5, _D.TYPE_ENUM, ".foxglove.LocationFix.PositionCovarianceType"),
            ]
        )
    elif schema_name == "spooflens.Imu":
        f.name, f.package = "spooflens/Imu.proto", "spooflens"
        vec = f.message_type.add(name="Vector3")
        vec.field.extend([_field(k, i + 1, _D.TYPE_DOUBLE) for i, k in enumerate("xyz")])
        quat = f.message_type.add(name="Quaternion")
        quat.field.extend([_field(k, i + 1, _D.TYPE_DOUBLE) for i, k in enumerate("xyzw")])
        msg = f.message_type.add(name="Imu")
        msg.field.extend(
            [
                _field("timestamp", 1, _D.TYPE_MESSAGE, ".google.protobuf.Timestamp"),
                _field("frame_id", 2, _D.TYPE_STRING),
                _field("angular_velocity", 3, _D.TYPE_MESSAGE, ".spooflens.Vector3"),
                _field("linear_acceleration", 4, _D.TYPE_MESSAGE, ".spooflens.Vector3"),
                _field("orientation", 5, _D.TYPE_MESSAGE, ".spooflens.Quaternion"),
            ]
        )
    else:
        raise KeyError(f"no protobuf schema for {schema_name!r}; have {sorted(KIND_BY_SCHEMA)}")
    return descriptor_pb2.FileDescriptorSet(file=[ts_file, f]).SerializeToString()
