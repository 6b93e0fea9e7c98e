"""MCAP files with ROS2 (CDR), ROS1, JSON and protobuf channels.

Read as a stream of records, so memory holds only the decoded columns. Chunks are decompressed and
their CRC checked one at a time: a corrupt chunk costs its own messages, not the rest of the file; a
file cut short keeps everything before the cut. Without a summary section (a recording that was
never closed) the channels are learnt while reading, and the messages are buffered until the end.
"""

from __future__ import annotations

import io
import json
import struct
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Footer, Message, Schema
from mcap.stream_reader import StreamReader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

from readers import ReaderFormat, foxglove_messages
from readers.streams import StreamCollector, TopicDecl, ros_topic
from spooflens.epoch_table import EpochTable, Skipped
from spooflens.errors import ReaderError, one_line

Progress = Callable[[int, int], None]
_RECORD_SIZE_LIMIT = 1 << 30  # a corrupt length field must not make us allocate more than this
_OP_MESSAGE = 0x05
_MSG_HEAD = struct.Struct("<BQHIQQ")  # opcode, length, channel id, sequence, log time, publish time
_PROGRESS_EVERY = 20000


class _Decoders:
    """Per-encoding decoders built from the file's own schemas (nothing from the file is executed)."""

    def __init__(self) -> None:
        self.ros2 = get_typestore(Stores.EMPTY)
        self.ros1 = get_typestore(Stores.EMPTY)
        self.protobuf = ProtobufDecoderFactory()

    def declare(self, schema: Schema | None, channel: Channel) -> TopicDecl:
        """The decoder of a channel, built from its schema; a schema the libraries cannot build a type
        from (damaged text, a broken protobuf descriptor, a type clashing with another schema's) costs
        that channel's messages, counted as lost, and nothing else."""
        try:
            return self._declare(schema, channel)
        except Exception as err:  # noqa: BLE001 - rosbags, protobuf and UTF-8 errors alike: the schema is damaged
            name = schema.name if schema else "<no schema>"
            return TopicDecl(name, None, problem=f"schema unreadable ({one_line(err, 160)})")

    def _declare(self, schema: Schema | None, channel: Channel) -> TopicDecl:
        name = schema.name if schema else "<no schema>"
        enc = channel.message_encoding
        if schema is not None and enc == "cdr" and schema.encoding in ("ros2msg", "ros2idl"):
            text = schema.data.decode()
            types = get_types_from_msg(text, name) if schema.encoding == "ros2msg" else get_types_from_idl(text)
            self.ros2.register(types)
            return ros_topic(name, "cdr", lambda raw, t: self.ros2.deserialize_cdr(bytes(raw), t))
        if schema is not None and enc == "ros1" and schema.encoding == "ros1msg":
            self.ros1.register(get_types_from_msg(schema.data.decode(), name))
            return ros_topic(name, "ros1", lambda raw, t: self.ros1.deserialize_ros1(bytes(raw), t))
        kind = foxglove_messages.KIND_BY_SCHEMA.get(name)
        if kind and enc == "json":
            return TopicDecl(name, kind, _foxglove_decoder(kind, lambda raw: json.loads(bytes(raw))))
        if kind and enc == "protobuf" and schema is not None:
            decode = self.protobuf.decoder_for("protobuf", schema)
            if decode is not None:
                return TopicDecl(name, kind, _foxglove_decoder(kind, lambda raw: decode(bytes(raw))))
        return TopicDecl(f"{name} ({enc})", None)


def _foxglove_decoder(kind: str, parse: Callable[[bytes | memoryview], Any]) -> Callable[..., Any]:
    def decode(raw: bytes | memoryview) -> tuple[tuple[int, tuple[float, ...]], str]:
        msg = parse(raw)
        return foxglove_messages.extract(kind, msg), foxglove_messages.frame_id(msg)

    return decode


def _decompress(chunk: Chunk) -> bytes:
    if chunk.compression == "zstd":
        data = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
    elif chunk.compression == "lz4":
        data = lz4.frame.decompress(chunk.data)
    elif chunk.compression == "":
        data = chunk.data
    else:
        raise ValueError(f"unsupported chunk compression {chunk.compression!r}")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise ValueError("chunk CRC mismatch")
    return data


def _chunk_messages(data: bytes) -> tuple[list[tuple[int, int, memoryview]], list[Schema | Channel]]:
    """(channel id, log time, payload) of every message in a chunk, plus any schema/channel records."""
    view = memoryview(data)
    out: list[tuple[int, int, memoryview]] = []
    other: list[Schema | Channel] = []
    pos, end = 0, len(data)
    unpack = _MSG_HEAD.unpack_from
    while pos + 9 <= end:
        op = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        if pos + 9 + length > end:
            raise ValueError("record in chunk cut short")
        if op == _OP_MESSAGE:
            _, _, channel_id, _, log_time, _ = unpack(data, pos)
            out.append((channel_id, log_time, view[pos + 31 : pos + 9 + length]))
        elif op in (0x03, 0x04):  # schema, channel inside the chunk
            stream = ReadDataStream(io.BytesIO(data[pos + 9 : pos + 9 + length]))
            other.append(Schema.read(stream) if op == 0x03 else Channel.read(stream))
        pos += 9 + length
    return out, other


def read_mcap(path: Path, topics: dict[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    path = Path(path)
    summary = None
    try:
        with path.open("rb") as f:
            summary = make_reader(f).get_summary()
    except Exception:  # noqa: BLE001 - no or damaged summary: fall back to learning channels on the way
        summary = None
    collector = StreamCollector(path, "mcap", topics)
    decoders = _Decoders()
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    pending: list[tuple[int, int, bytes]] = []
    declared = summary is not None and bool(summary.channels)
    total = summary.statistics.message_count if summary and summary.statistics else 0
    if declared:
        assert summary is not None
        schemas, channels = dict(summary.schemas), dict(summary.channels)
        collector.add_topics(_declarations(decoders, schemas, channels))
    n_read = 0
    problem = ""

    def handle(channel_id: int, log_time: int, data: bytes | memoryview) -> None:
        nonlocal n_read
        n_read += 1
        if declared:
            ch = channels.get(channel_id)
            if ch is not None:
                collector.add(ch.topic, log_time, data)
        else:
            pending.append((channel_id, log_time, bytes(data)))
        if progress and n_read % _PROGRESS_EVERY == 0:
            progress(n_read, total)

    try:
        with path.open("rb") as f:
            reader = StreamReader(f, emit_chunks=True, record_size_limit=_RECORD_SIZE_LIMIT)
            for record in reader.records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    handle(record.channel_id, record.log_time, record.data)
                elif isinstance(record, Chunk):
                    try:
                        msgs, other = _chunk_messages(_decompress(record))
                    except (ValueError, zstandard.ZstdError, RuntimeError) as err:
                        collector.skipped.append(
                            Skipped(
                                "<file>",
                                f"chunk starting at log time "
                                f"{record.message_start_time} unreadable ({err}); its "
                                "messages were skipped",
                                0,
                                "lost",
                            )
                        )
                        continue
                    for rec in other:
                        if isinstance(rec, Schema):
                            schemas[rec.id] = rec
                        else:
                            channels[rec.id] = rec
                    for channel_id, log_time, data in msgs:
                        handle(channel_id, log_time, data)
                elif isinstance(record, Footer):
                    break
    except (McapError, ValueError, struct.error, EOFError, OSError, MemoryError) as err:
        problem = f"{type(err).__name__}: {err}" if str(err) else type(err).__name__
    if problem:
        if n_read == 0 and not channels:
            raise ReaderError(path, f"not a readable MCAP file ({problem})")
        collector.skipped.append(
            Skipped(
                "<file>",
                f"file damaged or cut short after {n_read} messages ({problem})",
                max(total - n_read, 0),
                "lost",
            )
        )
    if not declared:
        collector.add_topics(_declarations(decoders, schemas, channels))
        for channel_id, log_time, payload in pending:
            ch = channels.get(channel_id)
            if ch is not None:
                collector.add(ch.topic, log_time, payload)
    if progress:
        progress(n_read, max(total, n_read))
    return collector.finish("unix")


def _declarations(
    decoders: _Decoders, schemas: dict[int, Schema], channels: dict[int, Channel]
) -> dict[str, TopicDecl]:
    return {ch.topic: decoders.declare(schemas.get(ch.schema_id), ch) for ch in channels.values()}


MCAP_MAGIC = b"\x89MCAP0\r\n"


def _is_mcap(path: Path, head: bytes) -> bool:
    return head.startswith(MCAP_MAGIC)


FORMATS = (
    ReaderFormat(
        "mcap",
        "MCAP (.mcap) with ROS2 (CDR), ROS1, JSON or protobuf channels",
        read_mcap,  # type: ignore[arg-type]
        _is_mcap,
        rewrite="spooflens.writers.rewrite:rewrite_container",
    ),
)
