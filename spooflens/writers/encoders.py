"""Message encoders per wire format: ROS2 CDR, ROS1, JSON and protobuf (Foxglove conventions)."""

from __future__ import annotations

import contextlib
import json
from functools import cached_property
from typing import Any

import numpy as np
from google.protobuf import descriptor_pool, message_factory
from rosbags.typesys import Stores, get_typestore

from readers import foxglove_messages
from readers.ros_messages import encode_imu, encode_navsatfix, navsat_covariance, navsat_status
from spooflens.writers.messages import OutStream

ROS_TYPES = {
    "imu": "sensor_msgs/msg/Imu",
    "navsatfix": "sensor_msgs/msg/NavSatFix",
    "twist_cov": "geometry_msgs/msg/TwistWithCovarianceStamped",
    "odometry": "nav_msgs/msg/Odometry",
}
FOXGLOVE_SCHEMAS = {"imu": "spooflens.Imu", "navsatfix": "foxglove.LocationFix"}


class _Columns:
    """Numpy columns of each stream, extracted once (row access on DataFrames is slow)."""

    def __init__(self) -> None:
        self._cache: dict[int, dict[str, np.ndarray]] = {}

    def __call__(self, s: OutStream) -> dict[str, np.ndarray]:
        key = id(s)
        if key not in self._cache:
            self._cache[key] = {c: s.rows[c].to_numpy() for c in s.rows.columns}
        return self._cache[key]


def _imu_parts(c: dict[str, np.ndarray], i: int) -> tuple[Any, tuple[float, ...], tuple[float, ...]]:
    q = (c["qx"][i], c["qy"][i], c["qz"][i], c["qw"][i])
    q = None if not np.all(np.isfinite(q)) else tuple(float(x) for x in q)
    w = (float(c["wx_radps"][i]), float(c["wy_radps"][i]), float(c["wz_radps"][i]))
    a = (float(c["ax_mps2"][i]), float(c["ay_mps2"][i]), float(c["az_mps2"][i]))
    return q, w, a


class RosEncoder:
    """ROS1 or ROS2 (CDR) messages; Imu and NavSatFix through the fixed-layout encoders."""

    def __init__(self, ros_version: int) -> None:
        self.ros_version = ros_version
        self.encoding = "cdr" if ros_version == 2 else "ros1"
        self.store = get_typestore(Stores.ROS2_HUMBLE if ros_version == 2 else Stores.ROS1_NOETIC)
        self.columns = _Columns()
        self._seq: dict[str, int] = {}

    def msgtype(self, kind: str) -> str:
        return ROS_TYPES[kind]

    def msgdef(self, kind: str) -> str:
        return self.store.generate_msgdef(ROS_TYPES[kind], ros_version=self.ros_version)[0]

    def _header(self, t: int, frame_id: str, topic: str) -> Any:
        T = self.store.types
        stamp = T["builtin_interfaces/msg/Time"](sec=t // 1_000_000_000, nanosec=t % 1_000_000_000)
        extra = {"seq": self._next_seq(topic)} if self.ros_version == 1 else {}
        return T["std_msgs/msg/Header"](**extra, stamp=stamp, frame_id=frame_id)

    def _next_seq(self, topic: str) -> int:
        self._seq[topic] = self._seq.get(topic, -1) + 1
        return self._seq[topic]

    def encode(self, s: OutStream, i: int, t: int) -> bytes:
        c = self.columns(s)
        if s.kind == "imu":
            q, w, a = _imu_parts(c, i)
            return encode_imu(t, s.frame_id, q, w, a, self.encoding, seq=self._next_seq(s.topic))
        if s.kind == "navsatfix":
            cov, cov_type = navsat_covariance(float(c["h_acc_m"][i]), float(c["v_acc_m"][i]))
            return encode_navsatfix(
                t,
                s.frame_id,
                navsat_status(int(c["fix_type"][i])),
                float(c["lat_deg"][i]),
                float(c["lon_deg"][i]),
                float(c["height_m"][i]),
                cov,
                cov_type,
                self.encoding,
                seq=self._next_seq(s.topic),
            )
        T = self.store.types
        V = T["geometry_msgs/msg/Vector3"]
        cov6 = np.zeros(36)
        if s.kind == "twist_cov":
            acc = float(c["vel_acc_mps"][i])
            cov6[[0, 7, 14]] = acc**2 if np.isfinite(acc) else 0.0
            twist = T["geometry_msgs/msg/Twist"](
                linear=V(x=float(c["vel_e_mps"][i]), y=float(c["vel_n_mps"][i]), z=float(c["vel_u_mps"][i])),
                angular=V(x=0.0, y=0.0, z=0.0),
            )
            msg = T["geometry_msgs/msg/TwistWithCovarianceStamped"](
                header=self._header(t, s.frame_id, s.topic),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov6),
            )
        else:
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=float(c["x_m"][i]), y=float(c["y_m"][i]), z=float(c["z_m"][i])),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            )
            twist = T["geometry_msgs/msg/Twist"](
                linear=V(x=float(c["vx_mps"][i]), y=float(c["vy_mps"][i]), z=float(c["vz_mps"][i])),
                angular=V(x=0.0, y=0.0, z=float(c["wz_radps"][i])),
            )
            msg = T["nav_msgs/msg/Odometry"](
                header=self._header(t, s.frame_id, s.topic),
                child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
            )
        ser = self.store.serialize_cdr if self.ros_version == 2 else self.store.serialize_ros1
        return bytes(ser(msg, ROS_TYPES[s.kind]))


def _foxglove_fields(c: dict[str, np.ndarray], kind: str, i: int, t: int, frame_id: str) -> dict[str, Any]:
    stamp = {"sec": t // 1_000_000_000, "nsec": t % 1_000_000_000}
    if kind == "imu":
        q, w, a = _imu_parts(c, i)
        out: dict[str, Any] = {
            "timestamp": stamp,
            "frame_id": frame_id,
            "angular_velocity": dict(zip("xyz", w, strict=True)),
            "linear_acceleration": dict(zip("xyz", a, strict=True)),
        }
        if q is not None:
            out["orientation"] = dict(zip("xyzw", q, strict=True))
        return out
    cov, cov_type = navsat_covariance(float(c["h_acc_m"][i]), float(c["v_acc_m"][i]))
    return {
        "timestamp": stamp,
        "frame_id": frame_id,
        "latitude": float(c["lat_deg"][i]),
        "longitude": float(c["lon_deg"][i]),
        "altitude": float(c["height_m"][i]),
        "position_covariance": cov,
        "position_covariance_type": cov_type,
    }


class JsonEncoder:
    encoding = "json"
    schema_encoding = "jsonschema"

    def __init__(self) -> None:
        self.columns = _Columns()

    def supports(self, kind: str) -> bool:
        return kind in FOXGLOVE_SCHEMAS

    def schema(self, kind: str) -> tuple[str, bytes]:
        name = FOXGLOVE_SCHEMAS[kind]
        return name, foxglove_messages.JSON_SCHEMAS[name]

    def encode(self, s: OutStream, i: int, t: int) -> bytes:
        return json.dumps(_foxglove_fields(self.columns(s), s.kind, i, t, s.frame_id)).encode()


class ProtobufEncoder:
    encoding = "protobuf"
    schema_encoding = "protobuf"

    def __init__(self) -> None:
        self.columns = _Columns()

    def supports(self, kind: str) -> bool:
        return kind in FOXGLOVE_SCHEMAS

    def schema(self, kind: str) -> tuple[str, bytes]:
        name = FOXGLOVE_SCHEMAS[kind]
        return name, foxglove_messages.protobuf_file_descriptor_set(name)

    @cached_property
    def _classes(self) -> dict[str, Any]:
        from google.protobuf import descriptor_pb2

        pool = descriptor_pool.DescriptorPool()
        classes = {}
        for kind, name in FOXGLOVE_SCHEMAS.items():
            fds = descriptor_pb2.FileDescriptorSet.FromString(foxglove_messages.protobuf_file_descriptor_set(name))
            for f in fds.file:
                with contextlib.suppress(TypeError):  # google/protobuf/timestamp.proto is in every set
                    pool.Add(f)
            classes[kind] = message_factory.GetMessageClass(pool.FindMessageTypeByName(name))
        return classes

    def encode(self, s: OutStream, i: int, t: int) -> bytes:
        fields = _foxglove_fields(self.columns(s), s.kind, i, t, s.frame_id)
        msg = self._classes[s.kind]()
        stamp = fields.pop("timestamp")
        msg.timestamp.seconds, msg.timestamp.nanos = stamp["sec"], stamp["nsec"]
        for key, value in fields.items():
            if isinstance(value, dict):
                sub = getattr(msg, key)
                for k, v in value.items():
                    setattr(sub, k, v)
            elif isinstance(value, list):
                getattr(msg, key).extend(value)
            else:
                setattr(msg, key, value)
        return bytes(msg.SerializeToString())
