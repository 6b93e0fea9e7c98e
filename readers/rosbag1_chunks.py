"""A cleanly indexed ROS1 bag read a group of chunks at a time, its messages found from the bag's own
index and decoded in batches (`readers.ros_batch`), with no Python per message.

rosbags yields a bag's messages one by one (a heap merge over the connections, a record header parsed
per message): an hour of 200 Hz IMU took 4 s to read that way, the same hour in an MCAP 0.6 s. Here the
index section (connections, chunk infos) and the index data records after each chunk give every
message's connection, time and offset in its chunk; the message records' header and data lengths are
then read for all messages of a group of chunks at once.

Only a bag whose index is whole and agrees with its chunks is read this way: every message record where
the index says, of the connection and time it says, each chunk info's counts those of its index data
records, every message definition readable, and each topic's messages, in time order, lying in chunks in
file order. Anything else (`read_indexed` returns None) is left to rosbags' reader and its damage
accounting, so what a damaged bag loses is counted exactly as before. Each topic's messages come in
rosbags' order (each connection's by time, ties in file order; a topic's connections merged by time,
ties to the one listed first), so the table is the same; a message that cannot be deserialised is
counted with the type library's error (SerdeError) where rosbags' reader names its own wrapper of it.
"""

from __future__ import annotations

import bz2
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import lz4.frame
import numpy as np
from numpy.typing import NDArray
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from readers.ros_batch import gather
from readers.ros_messages import normalise_type
from readers.streams import StreamCollector, TopicDecl, ros_topic
from spooflens.epoch_table import EpochTable

Progress = Callable[[int, int], None]
IntArray = NDArray[np.int64]
MAGIC = b"#ROSBAG V2.0\n"
OP_MSG, OP_BAG_HEADER, OP_INDEX_DATA, OP_CHUNK, OP_CHUNK_INFO, OP_CONN = 0x02, 0x03, 0x04, 0x05, 0x06, 0x07
_GROUP_BYTES = 16 << 20  # decompressed chunk bytes decoded together
_MAX_RECORD = 1 << 30  # a larger length is a corrupt field
# a message data record's header as ROS1 writers make it: the fields op (1 byte), conn (4) and time (8),
# each as a 4-byte length, the name, '=' and the value
_MSG_FIELDS = {"op": 1, "conn": 4, "time": 8}
_MSG_HEADER_BYTES = sum(4 + len(name) + 1 + size for name, size in _MSG_FIELDS.items())
_INDEX_ENTRY = np.dtype([("sec", "<u4"), ("nsec", "<u4"), ("offset", "<u4")])


class _NotClean(Exception):
    """The bag is not one this path reads: left to rosbags' reader."""


def fields(header: bytes, strict: bool = False) -> dict[str, bytes]:
    """A ROS1 record header's fields (name=value, each after its 4-byte length). `strict`: each whole, a
    field running past the header or without '=' is damage (`_NotClean`); else what can be read is."""
    out, pos = {}, 0
    while pos < len(header):
        if pos + 4 > len(header):
            if strict:
                raise _NotClean("record header cut in a field's length")
            break
        (n,) = struct.unpack_from("<I", header, pos)
        name, eq, value = header[pos + 4 : pos + 4 + n].partition(b"=")
        if strict and (pos + 4 + n > len(header) or not eq):
            raise _NotClean("record header field damaged")
        out[name.decode("latin-1")] = value
        pos += 4 + n
    return out


def _text(value: bytes | None, what: str) -> str:
    if value is not None:
        try:
            return value.decode("utf-8")
        except UnicodeDecodeError:
            pass
    raise _NotClean(f"connection record's {what} missing or not UTF-8")


def decompress(kind: bytes, data: memoryview, size: int) -> bytes:
    """A chunk's data uncompressed (`size`: the uncompressed size its header gives)."""
    if kind == b"none":
        return bytes(data)
    if kind == b"bz2":
        return bz2.decompress(data)
    if kind == b"lz4":
        return lz4.frame.decompress(bytes(data))
    raise ValueError(f"unknown chunk compression {kind!r}")


@dataclass(frozen=True)
class _Connection:
    id: int
    topic: str
    msgtype: str
    definition: str


@dataclass(frozen=True)
class _Chunk:
    data_pos: int  # where its (compressed) data lies in the file
    data_len: int
    compression: bytes
    size: int  # uncompressed
    conn: IntArray  # its messages, in the order of its index data records: connection, time (ns), offset
    t_ns: IntArray
    offset: IntArray


def _record(f: BinaryIO, op: int) -> tuple[dict[str, bytes], int]:
    """(header fields, data length) of the record at the file's position, which must be of opcode `op`;
    the file is left at the record's data."""
    head = f.read(4)
    if len(head) < 4:
        raise _NotClean("record cut short")
    (hlen,) = struct.unpack("<I", head)
    if hlen > _MAX_RECORD:
        raise _NotClean("record header length implausible")
    header = fields(f.read(hlen), strict=True)
    size = f.read(4)
    if len(size) < 4:
        raise _NotClean("record cut short")
    (dlen,) = struct.unpack("<I", size)
    if dlen > _MAX_RECORD or header.get("op", b"") != bytes([op]):
        raise _NotClean(f"not the record expected (opcode {op})")
    return header, dlen


def _data(f: BinaryIO, dlen: int) -> bytes:
    data = f.read(dlen)
    if len(data) < dlen:
        raise _NotClean("record cut short")
    return data


def _number(header: dict[str, bytes], name: str, fmt: str) -> int:
    value = header.get(name, b"")
    if len(value) != struct.calcsize(fmt):
        raise _NotClean(f"record header field {name} missing or of the wrong size")
    return int(struct.unpack(fmt, value)[0])


def _index(f: BinaryIO) -> tuple[list[_Connection], list[_Chunk]]:
    """The connections and chunks the bag's index section and index data records list."""
    if f.read(len(MAGIC)) != MAGIC:
        raise _NotClean("no ROS1 bag magic")
    header, _ = _record(f, OP_BAG_HEADER)
    index_pos = _number(header, "index_pos", "<Q")
    n_conns, n_chunks = _number(header, "conn_count", "<I"), _number(header, "chunk_count", "<I")
    if index_pos == 0 or n_chunks == 0:
        raise _NotClean("bag not indexed, or without chunks")
    f.seek(index_pos)
    conns = []
    for _ in range(n_conns):
        header, dlen = _record(f, OP_CONN)
        # as whole as rosbags' reader wants it: a connection it could not read is left to its accounting
        info = fields(_data(f, dlen), strict=True)
        _text(info.get("md5sum"), "md5sum")
        conns.append(
            _Connection(
                _number(header, "conn", "<I"),
                _text(header.get("topic"), "topic"),
                _text(info.get("type"), "type"),
                _text(info.get("message_definition"), "message_definition"),
            )
        )
    infos = []
    for _ in range(n_chunks):
        header, dlen = _record(f, OP_CHUNK_INFO)
        data, count = _data(f, dlen), _number(header, "count", "<I")
        if _number(header, "ver", "<I") != 1 or len(data) != 8 * count:
            raise _NotClean("chunk info of an unknown version or size")
        pairs = np.frombuffer(data, dtype="<u4").reshape(count, 2)
        infos.append((_number(header, "chunk_pos", "<Q"), {int(c): int(n) for c, n in pairs}))
    return conns, [_chunk(f, pos, counts) for pos, counts in infos]


def _chunk(f: BinaryIO, pos: int, counts: dict[int, int]) -> _Chunk:
    """The chunk record at `pos` and the index data records after it (one per connection in it)."""
    f.seek(pos)
    header, data_len = _record(f, OP_CHUNK)
    data_pos = f.tell()
    f.seek(data_len, 1)
    conn, t_ns, offset = [], [], []
    for _ in counts:
        index_header, dlen = _record(f, OP_INDEX_DATA)
        entries = _data(f, dlen)
        cid, n = _number(index_header, "conn", "<I"), _number(index_header, "count", "<I")
        if _number(index_header, "ver", "<I") != 1 or len(entries) != 12 * n or counts.get(cid) != n:
            raise _NotClean("index data disagrees with its chunk info")
        e = np.frombuffer(entries, dtype=_INDEX_ENTRY)
        conn.append(np.full(n, cid, dtype=np.int64))
        t_ns.append(e["sec"].astype(np.int64) * 1_000_000_000 + e["nsec"].astype(np.int64))
        offset.append(e["offset"].astype(np.int64))
    none = [np.zeros(0, dtype=np.int64)]
    return _Chunk(
        data_pos,
        data_len,
        header.get("compression", b""),
        _number(header, "size", "<I"),
        np.concatenate(conn or none),
        np.concatenate(t_ns or none),
        np.concatenate(offset or none),
    )


def _declarations(conns: list[_Connection]) -> dict[str, TopicDecl]:
    store = get_typestore(Stores.EMPTY)
    for c in conns:
        if not c.definition:
            raise _NotClean("a connection without its message definition")
        try:
            store.register(get_types_from_msg(c.definition, normalise_type(c.msgtype)))
        except Exception as err:  # any library error: rosbags' reader says what is wrong with it
            raise _NotClean("a message definition unreadable") from err

    def deserialize(data: bytes | memoryview, msgtype: str) -> object:
        return store.deserialize_ros1(bytes(data), normalise_type(msgtype))

    return {c.topic: ros_topic(c.msgtype, "ros1", deserialize) for c in conns}


def _topic_orders(conns: list[_Connection], chunks: list[_Chunk]) -> dict[str, tuple[IntArray, IntArray]]:
    """Per topic: its messages (places in the bag's index, chunk after chunk) in rosbags' order, and the
    chunk of each."""
    conn = np.concatenate([c.conn for c in chunks])
    t = np.concatenate([c.t_ns for c in chunks])
    chunk_of = np.repeat(np.arange(len(chunks)), [len(c.conn) for c in chunks])
    if not set(np.unique(conn).tolist()) <= {c.id for c in conns} or len({c.id for c in conns}) != len(conns):
        raise _NotClean("index data of a connection the index does not list once")
    out = {}
    for topic in dict.fromkeys(c.topic for c in conns):
        # each connection's messages by time (ties in file order), the topic's connections merged by
        # time (ties to the one listed first): one stable sort of them listed connection by connection
        rows = np.concatenate([np.flatnonzero(conn == c.id) for c in conns if c.topic == topic])
        order = rows[np.argsort(t[rows], kind="stable")]
        if np.any(np.diff(chunk_of[order]) < 0):
            raise _NotClean(f"{topic}'s messages lie in chunks out of time order")
        out[topic] = (order, chunk_of[order])
    return out


def read_indexed(path: Path, topics: dict[str, str] | None, progress: Progress | None) -> EpochTable | None:
    """The bag's table, or None when the bag is not cleanly indexed (see the module docstring)."""
    try:
        with path.open("rb") as f:
            conns, chunks = _index(f)
            orders = _topic_orders(conns, chunks)
            collector = StreamCollector(path, "ros1bag", topics)
            collector.add_topics(_declarations(conns), ((topic, len(order)) for topic, (order, _) in orders.items()))
            _read_chunks(f, chunks, orders, collector, progress)
    except (_NotClean, OSError, ValueError, RuntimeError, struct.error, MemoryError):
        return None
    return collector.finish("unix")


def _read_chunks(
    f: BinaryIO,
    chunks: list[_Chunk],
    orders: dict[str, tuple[IntArray, IntArray]],
    collector: StreamCollector,
    progress: Progress | None,
) -> None:
    """Every message into the collector, a group of chunks at a time, each topic's in its order."""
    first_of_chunk = np.r_[0, np.cumsum([len(c.conn) for c in chunks])]
    lo = 0
    while lo < len(chunks):
        hi, size = lo + 1, chunks[lo].size
        while hi < len(chunks) and size + chunks[hi].size <= _GROUP_BYTES:
            size += chunks[hi].size
            hi += 1
        group = chunks[lo:hi]
        parts, shifts = [], [0]
        for c in group:
            f.seek(c.data_pos)
            data = decompress(c.compression, memoryview(_data(f, c.data_len)), c.size)
            if len(data) != c.size:
                raise _NotClean("a chunk of another size than its header says")
            parts.append(data)
            shifts.append(shifts[-1] + len(data))
        buf = np.frombuffer(b"".join(parts), dtype=np.uint8)
        starts, lengths = _message_data(buf, group, shifts)
        t = np.concatenate([c.t_ns for c in group])
        for topic, (order, chunk_of) in orders.items():
            a, b = np.searchsorted(chunk_of, [lo, hi])
            rows = order[a:b] - first_of_chunk[lo]
            if len(rows):
                collector.add_batch(topic, t[rows], buf, starts[rows], lengths[rows])
        if progress:
            progress(int(first_of_chunk[hi]), int(first_of_chunk[-1]))
        lo = hi


def _message_data(buf: np.ndarray, group: list[_Chunk], shifts: list[int]) -> tuple[IntArray, IntArray]:
    """(data start, data length) in `buf` of each message of the group, checked against the index: a
    message data record of the connection and time its index entry gives, inside its chunk."""
    offsets = np.concatenate([c.offset + s for c, s in zip(group, shifts, strict=False)])
    ends = np.concatenate([np.full(len(c.offset), s + c.size) for c, s in zip(group, shifts, strict=False)])
    if not len(offsets):
        return offsets, offsets
    data_at = offsets + 4 + _MSG_HEADER_BYTES
    if np.any(offsets < 0) or np.any(data_at + 4 > ends):
        raise _NotClean("a message record past its chunk")
    if np.any(gather(buf, offsets, "u4") != _MSG_HEADER_BYTES):
        raise _NotClean("a message record header not as ROS1 writers make it")
    head = buf[offsets[:, None] + 4 + np.arange(_MSG_HEADER_BYTES)]
    layout = _header_layout(bytes(head[0]))
    fixed = np.ones(_MSG_HEADER_BYTES, dtype=np.bool_)  # every byte but the conn and time values
    for name in ("conn", "time"):
        fixed[layout[name] : layout[name] + _MSG_FIELDS[name]] = False
    if head[0, layout["op"]] != OP_MSG or np.any(head[:, fixed] != head[0, fixed]):
        raise _NotClean("an index entry not at a message record of the first one's layout")
    conn = gather(buf, offsets + 4 + layout["conn"], "u4").astype(np.int64)
    sec = gather(buf, offsets + 4 + layout["time"], "u4").astype(np.int64)
    nsec = gather(buf, offsets + 4 + layout["time"] + 4, "u4").astype(np.int64)
    if np.any(conn != np.concatenate([c.conn for c in group])) or np.any(
        sec * 1_000_000_000 + nsec != np.concatenate([c.t_ns for c in group])
    ):
        raise _NotClean("a message record of another connection or time than its index entry")
    lengths = gather(buf, data_at, "u4").astype(np.int64)
    starts = data_at + 4
    if np.any(starts + lengths > ends):
        raise _NotClean("a message's data past its chunk")
    return starts, lengths


def _header_layout(header: bytes) -> dict[str, int]:
    """Where each field's value lies in a message record header (op, conn and time, in any order)."""
    at, sizes, pos = {}, {}, 0
    while pos + 4 <= len(header):
        (n,) = struct.unpack_from("<I", header, pos)
        name, _, value = header[pos + 4 : pos + 4 + n].partition(b"=")
        at[name.decode("latin-1")] = pos + 4 + len(name) + 1
        sizes[name.decode("latin-1")] = len(value)
        pos += 4 + n
    if sizes != _MSG_FIELDS or pos != len(header):
        raise _NotClean("a message record header of other fields")
    return at
