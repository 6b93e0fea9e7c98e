"""Message encoders per wire format: ROS2 CDR, ROS1, JSON and protobuf (Foxglove conventions).

What each message holds is mapped where its type is read: ROS types in `readers.ros_messages`, the
JSON/protobuf schemas in `readers.foxglove_messages`. Here only the wire format: schemas, headers' seq
numbers, serialisation.
"""

from __future__ import annotations

import contextlib
import json
from functools import cached_property
from typing import Any

import numpy as np
from google.protobuf import descriptor_pool, message_factory
from rosbags.typesys import Stores, get_typestore

from readers import foxglove_messages, ros_messages
from spooflens.writers.messages import OutStream

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

    def row(self, s: OutStream, i: int) -> ros_messages.Row:
        """Row `i` of stream `s` as a column name -> float lookup."""
        c = self(s)
        return lambda name: float(c[name][i])


class RosEncoder:
    """ROS1 or ROS2 (CDR) messages, each kind mapped by `readers.ros_messages` (the one ROS mapping)."""

    def __init__(self, ros_version: int) -> None:
        self.ros_version = ros_version
        self.encoding = "cdr" if ros_version == 2 else "ros1"
        self.store = get_typestore(Stores.ROS2_HUMBLE if ros_version == 2 else Stores.ROS1_NOETIC)
        self.columns = _Columns()
        self._seq: dict[str, int] = {}

    def msgtype(self, kind: str) -> str:
        return ros_messages.msgtype_of(kind)

    def msgdef(self, kind: str) -> str:
        return self.store.generate_msgdef(self.msgtype(kind), ros_version=self.ros_version)[0]

    def _next_seq(self, topic: str) -> int:
        self._seq[topic] = self._seq.get(topic, -1) + 1
        return self._seq[topic]

    def encode(self, s: OutStream, i: int, t: int) -> bytes:
        row = self.columns.row(s, i)
        return ros_messages.encode(s.kind, self.store, self.ros_version, t, s.frame_id, row, self._next_seq(s.topic))


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
        return json.dumps(foxglove_messages.fields(s.kind, self.columns.row(s, i), t, s.frame_id)).encode()


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
        fields = foxglove_messages.fields(s.kind, self.columns.row(s, i), t, s.frame_id)
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
