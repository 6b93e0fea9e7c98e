"""Write an EpochTable as MCAP with ROS2, ROS1, JSON or protobuf channels."""

from __future__ import annotations

from pathlib import Path

from mcap.writer import CompressionType, Writer

from spooflens.epoch_table import EpochTable
from spooflens.writers.encoders import JsonEncoder, ProtobufEncoder, RosEncoder
from spooflens.writers.messages import in_time_order, out_streams

ENCODINGS = ("ros2", "ros1", "json", "protobuf")


def write_mcap(table: EpochTable, path: Path, encoding: str = "ros2", compression: str = "zstd") -> list[str]:
    """Write `table`; returns the streams that this encoding cannot carry (written nowhere)."""
    streams = out_streams(table)
    encoder: RosEncoder | JsonEncoder | ProtobufEncoder
    if encoding in ("ros2", "ros1"):
        ros = RosEncoder(2 if encoding == "ros2" else 1)
        schema_encoding = "ros2msg" if encoding == "ros2" else "ros1msg"

        def schema(kind: str) -> tuple[str, bytes]:
            return ros.msgtype(kind), ros.msgdef(kind).encode()

        encoder, msg_encoding, supports = ros, ros.encoding, lambda kind: True
    else:
        fox = JsonEncoder() if encoding == "json" else ProtobufEncoder()
        schema, encoder, msg_encoding, supports = fox.schema, fox, fox.encoding, fox.supports
        schema_encoding = fox.schema_encoding
    dropped = [f"{s.topic} ({s.kind})" for s in streams if not supports(s.kind)]
    streams = [s for s in streams if supports(s.kind)]
    with Path(path).open("wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD if compression == "zstd" else CompressionType.NONE)
        w.start(profile=encoding if encoding in ("ros1", "ros2") else "", library="spooflens")
        schema_ids: dict[str, int] = {}
        channel_ids: dict[str, int] = {}
        for s in streams:
            if s.kind not in schema_ids:
                name, data = schema(s.kind)
                schema_ids[s.kind] = w.register_schema(name, schema_encoding, data)
            channel_ids[s.topic] = w.register_channel(s.topic, msg_encoding, schema_ids[s.kind])
        seq: dict[str, int] = {}
        for s, i, t in in_time_order(streams):
            seq[s.topic] = seq.get(s.topic, -1) + 1
            w.add_message(
                channel_ids[s.topic], log_time=t, data=encoder.encode(s, i, t), publish_time=t, sequence=seq[s.topic]
            )
        w.finish()
    return dropped
