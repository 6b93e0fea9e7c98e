"""MCAP files with ROS2 (CDR), ROS1, JSON and protobuf channels.

Read as a stream of records, so memory holds only the decoded columns. Chunks are decompressed and
their CRC checked one at a time: a corrupt chunk costs its own messages, not the rest of the file; a
file cut short keeps everything before the cut. A chunk's message records are found from the message
index records after it (checked to tile the chunk exactly, else the records are walked), and each
channel's messages of a group of chunks are decoded together: fixed-layout ROS types straight into
numpy (`readers.ros_batch`), others one by one. Decompression runs a few chunks ahead, decoding a group
behind, each in a thread of its own, so reading, decompressing and decoding overlap. Without a summary
section (a recording that was never closed) the channels are learnt while reading, and the messages are
buffered until the end.
"""

from __future__ import annotations

import io
import json
import os
import struct
import zlib
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from functools import partial
from pathlib import Path
from typing import Any, BinaryIO

import lz4.frame
import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Schema
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

from readers import ReaderFormat, foxglove_messages
from readers.ros_batch import gather
from readers.streams import StreamCollector, TopicDecl, ros_topic
from spooflens.epoch_table import EpochTable, Skipped
from spooflens.errors import ReaderError, one_line
from spooflens.threads import thread_count

Progress = Callable[[int, int], None]
_RECORD_SIZE_LIMIT = 1 << 30  # a corrupt length field must not make us allocate more than this
_OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK, _OP_MESSAGE_INDEX, _OP_DATA_END = (
    0x02,
    0x03,
    0x04,
    0x05,
    0x06,
    0x07,
    0x0F,
)
_RECORD_HEAD = struct.Struct("<BQ")  # opcode, length
_MSG_FIELDS = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time (then the payload)
_PROGRESS_EVERY = 20000
_GROUP_BYTES = 16 << 20  # decompressed chunk bytes decoded together


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


MAX_CHUNK_BYTES = 1 << 30  # writers make chunks of a few MB; a larger declared size is a corrupt field


def _decompress(chunk: Chunk) -> bytes:
    if not 0 <= chunk.uncompressed_size <= MAX_CHUNK_BYTES:
        raise ValueError(f"chunk declares {chunk.uncompressed_size} bytes uncompressed (corrupt length)")
    if chunk.compression == "zstd":
        declared = zstandard.frame_content_size(chunk.data)  # -1: the frame does not say
        if declared > chunk.uncompressed_size:  # zstandard would allocate what the frame header says
            raise ValueError(f"zstd frame declares {declared} bytes in a chunk of {chunk.uncompressed_size}")
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


class _DecompressingAhead:
    """Chunks decompressed (and their CRC checked) a few ahead, in a thread of its own, while the reader
    decodes the ones before: zstd, lz4 and crc32 release the GIL, so the two overlap. `push` a chunk and
    get back, in file order, the chunks whose turn has come, each with a call giving its bytes (or
    raising what decompressing it raised); `drain` gives the rest. With one thread allowed
    (`SPOOFLENS_THREADS=1`, a batch worker) each chunk is decompressed when its turn comes."""

    def __init__(self, ahead: int = 4) -> None:
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="spooflens-mcap") if thread_count() >= 2 else None
        self._ahead = ahead
        self._queue: deque[tuple[Chunk, list[bytes], Callable[[], bytes]]] = deque()

    def push(self, chunk: Chunk, indexes: list[bytes]) -> Iterator[tuple[Chunk, list[bytes], Callable[[], bytes]]]:
        if self._pool is None:
            yield chunk, indexes, lambda: _decompress(chunk)
            return
        future: Future[bytes] = self._pool.submit(_decompress, chunk)
        self._queue.append((chunk, indexes, future.result))
        while len(self._queue) > self._ahead:
            yield self._queue.popleft()

    def drain(self) -> Iterator[tuple[Chunk, list[bytes], Callable[[], bytes]]]:
        while self._queue:
            yield self._queue.popleft()

    def close(self) -> None:
        self._queue.clear()
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)


class _DecodingBehind:
    """Groups of chunks decoded into the streams on a thread of their own, in file order, while the
    reader reads and indexes the next group (numpy's gathers release the GIL). One group at a time, so
    at most two groups' bytes are held; whatever else touches the streams waits for it first (`wait`).
    With one thread allowed each group is decoded when handed over."""

    def __init__(self) -> None:
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="spooflens-decode") if thread_count() >= 2 else None
        self._busy: Future[None] | None = None

    def submit(self, call: Callable[[], None]) -> None:
        self.wait()
        if self._pool is None:
            call()
        else:
            self._busy = self._pool.submit(call)

    def wait(self) -> None:
        """Until the group handed over last is decoded (raising what decoding it raised)."""
        busy, self._busy = self._busy, None
        if busy is not None:
            busy.result()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)


def _decode_group(
    collector: StreamCollector, channels: dict[int, Channel], buf: np.ndarray, offsets: np.ndarray
) -> None:
    """The message records at `offsets` of `buf` into the collector, each channel's decoded together."""
    lengths = np.maximum(gather(buf, offsets + 1, "u8").astype(np.int64) - 22, 0)
    channel_ids = gather(buf, offsets + 9, "u2").astype(np.int64)
    log_times = gather(buf, offsets + 15, "u8").astype(np.int64)
    starts = offsets + 31
    for cid in np.unique(channel_ids):
        ch = channels.get(int(cid))
        if ch is not None:
            sel = channel_ids == cid
            collector.add_batch(ch.topic, log_times[sel], buf, starts[sel], lengths[sel])


def _walk_chunk(data: bytes) -> tuple[list[int], list[Schema | Channel]]:
    """Offsets of the message records of a chunk, plus any schema/channel records, by walking its records."""
    offsets: list[int] = []
    other: list[Schema | Channel] = []
    pos, end = 0, len(data)
    head = _RECORD_HEAD.unpack_from
    while pos + 9 <= end:
        op, length = head(data, pos)
        if pos + 9 + length > end:
            raise ValueError("record in chunk cut short")
        if op == _OP_MESSAGE:
            offsets.append(pos)
        elif op in (_OP_SCHEMA, _OP_CHANNEL):  # schema, channel inside the chunk
            stream = ReadDataStream(io.BytesIO(data[pos + 9 : pos + 9 + length]))
            other.append(Schema.read(stream) if op == _OP_SCHEMA else Channel.read(stream))
        pos += 9 + length
    return offsets, other


def _indexed_offsets(buf: np.ndarray, indexes: list[bytes]) -> np.ndarray | None:
    """Offsets of a chunk's message records from the message index records after it, if each is a whole
    message record inside the chunk and none overlaps the next (else None: walk the chunk). Saves walking
    records in Python. Only for files with a summary: records between messages (a chunk may repeat its
    schemas and channels) are not looked at."""
    parts = []
    for body in indexes:
        if len(body) < 6:
            return None
        (n_bytes,) = struct.unpack_from("<I", body, 2)
        if n_bytes % 16 or 6 + n_bytes > len(body):
            return None
        parts.append(np.frombuffer(body, dtype="<u8", count=n_bytes // 8, offset=6)[1::2])  # (log time, offset)
    if not parts:
        return None
    offsets = np.sort(np.concatenate(parts).astype(np.int64))
    if not len(offsets) or offsets[0] < 0 or offsets[-1] + 31 > len(buf):  # < 0: a u8 beyond int64
        return None
    if np.any(buf[offsets] != _OP_MESSAGE):
        return None
    lengths = gather(buf, offsets + 1, "u8").astype(np.uint64)
    if np.any(lengths > len(buf)):
        return None
    ends = offsets + 9 + lengths.astype(np.int64)
    if np.any(ends[:-1] > offsets[1:]) or ends[-1] > len(buf):
        return None
    return offsets


def _top_level_records(f: BinaryIO) -> Iterator[tuple[int, bytes]]:
    """(opcode, body) of the data section's schema, channel, message, chunk and message index records;
    other records, and the summary section, are skipped unread. ValueError where the file is cut."""
    size = os.fstat(f.fileno()).st_size
    if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
        raise ValueError("no MCAP magic at the start")
    in_data = True
    while True:
        head = f.read(9)
        if len(head) < 9:
            raise ValueError("file cut short: no footer")
        op, length = _RECORD_HEAD.unpack(head)
        if length > _RECORD_SIZE_LIMIT:
            raise ValueError(f"record length {length} over the {_RECORD_SIZE_LIMIT}-byte limit (corrupt length)")
        if op == _OP_FOOTER:
            return
        if op == _OP_DATA_END:
            in_data = False  # the summary section repeats what was read; skipped, but a cut in it is damage
        if in_data and op in (_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK, _OP_MESSAGE_INDEX):
            body = f.read(length)
            if len(body) < length:
                raise ValueError("record cut short")
            yield op, body
        elif f.seek(length, io.SEEK_CUR) > size:
            raise ValueError("record cut short")


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
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        collector.add_topics(
            _declarations(decoders, schemas, channels),
            ((channels[cid].topic, n) for cid, n in counts.items() if cid in channels),
        )
    n_read = 0
    problem = ""

    def handle(channel_id: int, log_time: int, data: bytes | memoryview) -> None:
        nonlocal n_read
        n_read += 1
        if declared:
            ch = channels.get(channel_id)
            if ch is not None:
                decoding.wait()
                collector.add(ch.topic, log_time, data)
        else:
            pending.append((channel_id, log_time, bytes(data)))
        if progress and n_read % _PROGRESS_EVERY == 0:
            progress(n_read, total)

    group: list[tuple[np.ndarray, np.ndarray]] = []  # (chunk bytes, message record offsets) not decoded yet

    def chunk_messages(chunk: Chunk, indexes: list[bytes], decompressed: Callable[[], bytes]) -> None:
        """A chunk's message records, queued for `decode_group` (without a summary: kept per message)."""
        nonlocal n_read
        try:
            data = decompressed()
            buf = np.frombuffer(data, dtype=np.uint8)
            offsets = _indexed_offsets(buf, indexes) if declared else None
            if offsets is None:
                walked, other = _walk_chunk(data)
                for rec in other:
                    if isinstance(rec, Schema):
                        schemas[rec.id] = rec
                    else:
                        channels[rec.id] = rec
                offsets = np.asarray(walked, dtype=np.int64)
        except (ValueError, OverflowError, zstandard.ZstdError, RuntimeError, struct.error) as err:
            decoding.wait()
            collector.skipped.append(
                Skipped(
                    "<file>",
                    f"chunk starting at log time {chunk.message_start_time} unreadable ({err}); its "
                    "messages were skipped",
                    0,
                    "lost",
                )
            )
            return
        if not len(offsets):
            return
        if not declared:
            lengths = np.maximum(gather(buf, offsets + 1, "u8").astype(np.int64) - 22, 0)
            channel_ids = gather(buf, offsets + 9, "u2").astype(np.int64)
            log_times = gather(buf, offsets + 15, "u8").astype(np.int64)
            for cid, t, s0, n in zip(channel_ids, log_times, offsets + 31, lengths, strict=True):
                pending.append((int(cid), int(t), data[s0 : s0 + n]))
            n_read += len(offsets)
            return
        group.append((buf, offsets))
        if sum(len(b) for b, _ in group) >= _GROUP_BYTES:
            decode_group()

    def decode_group() -> None:
        """The messages of the chunks read so far, each channel's decoded together: numpy's per-call cost
        is paid once per group of chunks, not once per chunk."""
        nonlocal n_read
        if not group:
            return
        shifts = np.cumsum([0] + [len(b) for b, _ in group[:-1]])
        buf = np.concatenate([b for b, _ in group]) if len(group) > 1 else group[0][0]
        offsets = np.concatenate([o + shift for (_, o), shift in zip(group, shifts, strict=True)])
        group.clear()
        decoding.submit(partial(_decode_group, collector, dict(channels), buf, offsets))
        n_read += len(offsets)
        if progress:
            progress(n_read, total)

    chunk: Chunk | None = None
    indexes: list[bytes] = []
    ahead = _DecompressingAhead()
    decoding = _DecodingBehind()
    try:
        with path.open("rb") as f:
            for op, body in _top_level_records(f):
                if op == _OP_MESSAGE_INDEX:
                    indexes.append(body)
                    continue
                if chunk is not None:
                    for queued in ahead.push(chunk, indexes):
                        chunk_messages(*queued)
                    chunk, indexes = None, []
                if op != _OP_CHUNK:  # a record outside the chunks: every chunk before it first, in order
                    for queued in ahead.drain():
                        chunk_messages(*queued)
                if op == _OP_SCHEMA:
                    schema = Schema.read(ReadDataStream(io.BytesIO(body)))
                    schemas[schema.id] = schema
                elif op == _OP_CHANNEL:
                    channel = Channel.read(ReadDataStream(io.BytesIO(body)))
                    channels[channel.id] = channel
                elif op == _OP_MESSAGE:
                    channel_id, _, log_time, _ = _MSG_FIELDS.unpack_from(body)
                    handle(channel_id, log_time, body[_MSG_FIELDS.size :])
                elif op == _OP_CHUNK:
                    chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
    except (McapError, ValueError, OverflowError, struct.error, EOFError, OSError, MemoryError) as err:
        problem = f"{type(err).__name__}: {err}" if str(err) else type(err).__name__
    try:
        if chunk is not None:  # the last chunk, complete even when what follows it is not
            for queued in ahead.push(chunk, indexes):
                chunk_messages(*queued)
        for queued in ahead.drain():
            chunk_messages(*queued)
        decode_group()
        decoding.wait()
    finally:
        ahead.close()
        decoding.close()
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
