"""ROS1 .bag files and ROS2 bag directories (sqlite3 or MCAP storage), through rosbags' AnyReader.

A cleanly indexed ROS1 bag is read a group of chunks at a time from its own index
(`readers.rosbag1_chunks`); one whose index is damaged or disagrees with its chunks through rosbags'
reader and its damage accounting. A ROS1 bag whose index is missing (recording cut short, file
truncated) is read by a sequential scan of its chunks instead, keeping every message before the damage.
"""

from __future__ import annotations

import sqlite3
import struct
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from readers import ReaderFormat
from readers.ros_messages import normalise_type
from readers.rosbag1_chunks import MAGIC as ROS1_MAGIC
from readers.rosbag1_chunks import OP_BAG_HEADER, OP_CHUNK, OP_CONN, OP_MSG, decompress, fields, read_indexed
from readers.streams import StreamCollector, TopicDecl, ros_topic
from spooflens.epoch_table import EpochTable, Skipped
from spooflens.errors import ReaderError, one_line

Progress = Callable[[int, int], None]
_PROGRESS_EVERY = 20000
_BATCH = 8192  # messages of a topic joined and decoded together


def read_rosbag(path: Path, topics: dict[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    path = Path(path)
    is_ros1 = path.is_file()
    fmt = "ros1bag" if is_ros1 else "ros2bag"
    if is_ros1:
        table = read_indexed(path, topics, progress)  # a cleanly indexed bag: a group of chunks at a time
        if table is not None:
            return table
    with tempfile.TemporaryDirectory() as tmp:
        bag_path = path
        if is_ros1 and path.suffix != ".bag":  # AnyReader tells ROS1 from ROS2 by the .bag suffix
            bag_path = Path(tmp) / (path.name + ".bag")
            bag_path.symlink_to(path.resolve())
        try:
            reader = AnyReader([bag_path])
            reader.open()
        except Exception as err:
            if is_ros1:
                return _read_ros1_sequential(path, topics, progress, f"{type(err).__name__}: {err}")
            raise ReaderError(path, f"cannot open ROS2 bag: {err}") from err
        try:
            return _read_open_bag(path, fmt, reader, topics, progress)
        finally:
            reader.close()


def _read_open_bag(
    path: Path, fmt: str, reader: AnyReader, topics: dict[str, str] | None, progress: Progress | None
) -> EpochTable:
    encoding = "cdr" if reader.is2 else "ros1"
    collector = StreamCollector(path, fmt, topics)

    def deserialize(raw: bytes | memoryview, msgtype: str) -> object:
        return reader.deserialize(bytes(raw), msgtype)

    counts = [(c.topic, max(_listed_count(c.msgcount), 0)) for c in reader.connections]  # metadata may be damaged
    collector.add_topics({c.topic: ros_topic(c.msgtype, encoding, deserialize) for c in reader.connections}, counts)
    total = sum(n for _, n in counts)
    n = 0
    # each topic's messages gathered and decoded _BATCH at a time: rosbags yields them one by one
    pending: dict[str, tuple[list[int], list[bytes]]] = {}
    stopped: Exception | None = None
    try:
        for conn, t_ns, raw in reader.messages():
            times, raws = pending.setdefault(conn.topic, ([], []))
            times.append(t_ns)
            raws.append(raw)
            if len(raws) >= _BATCH:
                collector.add_many(conn.topic, *pending.pop(conn.topic))
            n += 1
            if progress and n % _PROGRESS_EVERY == 0:
                progress(n, total)
    except Exception as err:  # noqa: BLE001 - keep what was read before the damage
        stopped = err
    for topic, (times, raws) in pending.items():
        collector.add_many(topic, times, raws)
    if stopped is not None:
        collector.skipped.append(
            Skipped("<file>", f"reading stopped after {n} of {total} messages: {one_line(stopped)}", total - n, "lost")
        )
    else:
        collector.skipped += _missing_messages(reader, collector)
    if progress:
        progress(n, total)
    if n == 0 and total:
        facts = _sqlite_facts(path) if reader.is2 else ""
        raise ReaderError(path, f"no message could be read: the bag lists {total} messages, none is readable{facts}")
    return collector.finish("unix")


def _listed_count(msgcount: object) -> int:
    """A topic's message count as the bag's index or metadata lists it; -1 where that is no count (a
    damaged metadata.yaml can hold NaN, a string or a negative number there)."""
    try:
        count = int(msgcount)  # type: ignore[call-overload]
    except (TypeError, ValueError, OverflowError):
        return -1
    return count if count >= 0 else -1


def _missing_messages(reader: AnyReader, collector: StreamCollector) -> list[Skipped]:
    """Messages the bag's index or metadata counts per topic that its storage did not give."""
    listed: dict[str, int] = {}
    out = []
    for c in reader.connections:
        count = _listed_count(c.msgcount)
        if count < 0:  # the metadata is damaged: nothing to compare with
            out.append(
                Skipped(c.topic, f"message count in the bag's metadata unreadable ({c.msgcount!r})", 0, "repaired")
            )
            listed[c.topic] = -(2**62)
            continue
        listed[c.topic] = listed.get(c.topic, 0) + count
    for topic, count in listed.items():
        seen = collector.streams[topic].seen if topic in collector.streams else 0
        if count > seen:
            out.append(
                Skipped(
                    topic,
                    f"the bag lists {count} messages, its storage holds {seen} (deleted or damaged)",
                    count - seen,
                    "lost",
                )
            )
    return out


def _sqlite_facts(path: Path) -> str:
    """What a ROS2 sqlite3 bag's database really holds, to say why nothing was read."""
    facts = []
    for db in sorted(path.glob("*.db3")):
        try:
            con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
            try:
                (count,) = con.execute("SELECT count(*) FROM messages").fetchone()
                formats = sorted({str(f) for (f,) in con.execute("SELECT serialization_format FROM topics")})
            finally:
                con.close()
        except sqlite3.Error as err:
            facts.append(f"{db.name}: {one_line(err)}")
            continue
        facts.append(f"{db.name} holds {count} messages, topics serialised as {formats} (readable: ['cdr'])")
    return f" ({'; '.join(facts)})" if facts else ""


# --- sequential ROS1 scan for bags without a usable index -------------------------------------------


def _records(data: bytes | memoryview) -> Iterator[tuple[dict[str, bytes], memoryview, int]]:
    """(header fields, data, end offset) of each record of a ROS1 bag body; stops (raising ValueError)
    at a record cut short."""
    view, pos = memoryview(data), 0
    while pos < len(view):
        if pos + 4 > len(view):
            raise ValueError("record header length cut short")
        (hlen,) = struct.unpack_from("<I", view, pos)
        if pos + 8 + hlen > len(view):
            raise ValueError("record header cut short")
        header = fields(bytes(view[pos + 4 : pos + 4 + hlen]))
        (dlen,) = struct.unpack_from("<I", view, pos + 4 + hlen)
        start = pos + 8 + hlen
        if start + dlen > len(view):
            raise ValueError("record data cut short")
        pos = start + dlen
        yield header, view[start:pos], pos


def _read_ros1_sequential(path: Path, topics: dict[str, str] | None, progress: Progress | None, why: str) -> EpochTable:
    raw = path.read_bytes()
    if not raw.startswith(ROS1_MAGIC):
        raise ReaderError(path, f"not a readable ROS1 bag ({why})")
    body = memoryview(raw)[len(ROS1_MAGIC) :]
    conns: dict[int, tuple[str, str, str]] = {}  # id -> topic, type, definition
    messages: list[tuple[int, int, bytes]] = []
    problem = ""
    index_pos = 0  # where the chunks end and the index begins, from the bag header record
    scanned = 0  # bytes of the body read whole

    def take(header: dict[str, bytes], data: memoryview) -> None:
        nonlocal index_pos
        op = header.get("op", b"\0")[0]
        if op == OP_CONN:
            c = fields(bytes(data))
            conns[struct.unpack("<I", header["conn"])[0]] = (
                header["topic"].decode("utf-8", "replace"),
                c["type"].decode("utf-8", "replace"),
                c.get("message_definition", b"").decode("utf-8", "replace"),
            )
        elif op == OP_MSG:
            sec, nsec = struct.unpack("<II", header["time"])
            messages.append((struct.unpack("<I", header["conn"])[0], sec * 1_000_000_000 + nsec, bytes(data)))
        elif op == OP_BAG_HEADER and "index_pos" in header:
            (index_pos,) = struct.unpack("<Q", header["index_pos"])

    try:
        for header, data, end in _records(body):
            if header.get("op", b"\0")[0] == OP_CHUNK:
                size = struct.unpack("<I", header["size"])[0]
                for inner, inner_data, _ in _records(decompress(header["compression"], data, size)):
                    take(inner, inner_data)
            else:
                take(header, data)
            scanned = end
            if progress:
                progress(len(messages), 0)
    except (ValueError, KeyError, struct.error, OSError, EOFError) as err:
        problem = one_line(err)
    if not messages:
        raise ReaderError(path, f"no message could be read ({why}; scan: {problem or 'no messages'})")
    store = get_typestore(Stores.EMPTY)
    unreadable: dict[str, str] = {}  # message type -> why its definition could not be registered
    for _, msgtype, definition in conns.values():
        if definition and msgtype not in unreadable:
            try:
                store.register(get_types_from_msg(definition, normalise_type(msgtype)))
            except Exception as err:  # noqa: BLE001 - a damaged definition costs its topic
                unreadable[msgtype] = one_line(err, 160)

    def deserialize(data: bytes | memoryview, msgtype: str) -> object:
        return store.deserialize_ros1(bytes(data), normalise_type(msgtype))

    collector = StreamCollector(path, "ros1bag", topics)
    collector.add_topics(
        {
            topic: ros_topic(msgtype, "ros1", deserialize)
            if msgtype not in unreadable
            else TopicDecl(
                normalise_type(msgtype), None, problem=f"message definition unreadable ({unreadable[msgtype]})"
            )
            for topic, msgtype, _ in conns.values()
        }
    )
    per_topic: dict[str, int] = {}
    for conn, t_ns, payload in sorted(messages, key=lambda m: m[1]):
        if conn in conns:
            collector.add(conns[conn][0], t_ns, payload)
            per_topic[conns[conn][0]] = per_topic.get(conns[conn][0], 0) + 1
    if problem:
        collector.skipped += _cut_losses(per_topic, scanned, index_pos, problem, why)
    else:
        collector.skipped.append(Skipped("<file>", f"bag index unusable ({why}); read sequentially", 0, "repaired"))
    return collector.finish("unix")


def _cut_losses(per_topic: dict[str, int], scanned: int, index_pos: int, problem: str, why: str) -> list[Skipped]:
    """What a bag cut short lost, per topic: the messages its missing bytes held, estimated from each
    topic's rate over the bytes read (the index that counted them is what was cut away)."""
    body_end = index_pos - len(ROS1_MAGIC)  # the bag header's index_pos counts from the file start
    missing = body_end - scanned if body_end > scanned else 0
    note = f"bag index unusable ({why}); read sequentially up to byte {scanned + len(ROS1_MAGIC)}"
    note += f", stopped at damage: {problem}"
    if not missing or not scanned:
        return [Skipped("<file>", note + "; how much followed is unknown", 0, "lost")]
    out = [Skipped("<file>", note + f"; {missing} bytes of messages after it lost", 0, "lost")]
    for topic, count in per_topic.items():
        lost = round(count * missing / scanned)
        if lost:
            out.append(
                Skipped(
                    topic, f"about {lost} messages after the damage (estimated from the topic's rate)", lost, "lost"
                )
            )
    return out


def _is_ros1_bag(path: Path, head: bytes) -> bool:
    return head.startswith(ROS1_MAGIC)


def _is_ros2_bag(path: Path, head: bytes) -> bool:
    """A ROS2 bag is a folder with its metadata.yaml, or with an sqlite3 database (its storage alone,
    which the bag reader explains when the metadata is missing). A folder of .mcap files without the
    metadata is not one bag: each MCAP file is a log by itself (`sniff_format` says so)."""
    return path.is_dir() and ((path / "metadata.yaml").exists() or any(path.glob("*.db3")))


FORMATS = (
    ReaderFormat(
        "ros1bag",
        "ROS1 bag (.bag), also one whose index is missing",
        read_rosbag,  # type: ignore[arg-type]
        _is_ros1_bag,
        rewrite="spooflens.writers.rewrite:rewrite_container",
    ),
    ReaderFormat(
        "ros2bag",
        "ROS2 bag directory (sqlite3 or MCAP storage)",
        read_rosbag,  # type: ignore[arg-type]
        _is_ros2_bag,
        rewrite="spooflens.writers.rewrite:rewrite_container",
    ),
)
