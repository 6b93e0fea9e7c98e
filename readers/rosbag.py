"""ROS1 .bag files and ROS2 bag directories (sqlite3 or MCAP storage), through rosbags' AnyReader.

A ROS1 bag whose index is missing (recording cut short, file truncated) is read by a sequential scan
of its chunks instead, keeping every message before the damage.
"""

from __future__ import annotations

import bz2
import struct
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import lz4.frame
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from readers import ReaderFormat
from readers.streams import StreamCollector, ros_topic
from spooflens.epoch_table import EpochTable, Skipped
from spooflens.errors import ReaderError

Progress = Callable[[int, int], None]
_PROGRESS_EVERY = 20000


def read_rosbag(path: Path, topics: dict[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    path = Path(path)
    is_ros1 = path.is_file()
    fmt = "ros1bag" if is_ros1 else "ros2bag"
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
    collector.add_topics({c.topic: ros_topic(c.msgtype, encoding, reader.deserialize) for c in reader.connections})
    total = reader.message_count
    n = 0
    try:
        for conn, t_ns, raw in reader.messages():
            collector.add(conn.topic, t_ns, raw)
            n += 1
            if progress and n % _PROGRESS_EVERY == 0:
                progress(n, total)
    except Exception as err:  # noqa: BLE001 - keep what was read before the damage
        collector.skipped.append(
            Skipped("<file>", f"reading stopped after {n} of {total} messages: {err}", total - n, "lost")
        )
    if progress:
        progress(n, total)
    if n == 0 and total:
        raise ReaderError(path, f"no message could be read ({collector.skipped[-1].reason})")
    return collector.finish("unix")


# --- sequential ROS1 scan for bags without a usable index -------------------------------------------

_OP_MSG, _OP_CHUNK, _OP_CONN = 0x02, 0x05, 0x07


def _fields(header: bytes) -> dict[str, bytes]:
    out, pos = {}, 0
    while pos + 4 <= len(header):
        (n,) = struct.unpack_from("<I", header, pos)
        name, _, value = header[pos + 4 : pos + 4 + n].partition(b"=")
        out[name.decode("latin-1")] = value
        pos += 4 + n
    return out


def _records(data: bytes | memoryview) -> Iterator[tuple[dict[str, bytes], memoryview]]:
    """Records of a ROS1 bag body; stops (raising ValueError) at a record cut short."""
    view, pos = memoryview(data), 0
    while pos < len(view):
        if pos + 4 > len(view):
            raise ValueError("record header length cut short")
        (hlen,) = struct.unpack_from("<I", view, pos)
        if pos + 8 + hlen > len(view):
            raise ValueError("record header cut short")
        header = _fields(bytes(view[pos + 4 : pos + 4 + hlen]))
        (dlen,) = struct.unpack_from("<I", view, pos + 4 + hlen)
        start = pos + 8 + hlen
        if start + dlen > len(view):
            raise ValueError("record data cut short")
        yield header, view[start : start + dlen]
        pos = start + dlen


def _decompress(kind: bytes, data: memoryview, size: int) -> bytes:
    if kind == b"none":
        return bytes(data)
    if kind == b"bz2":
        return bz2.decompress(data)
    if kind == b"lz4":
        return lz4.frame.decompress(bytes(data))
    raise ValueError(f"unknown chunk compression {kind!r}")


def _read_ros1_sequential(path: Path, topics: dict[str, str] | None, progress: Progress | None, why: str) -> EpochTable:
    raw = path.read_bytes()
    if not raw.startswith(b"#ROSBAG V2.0\n"):
        raise ReaderError(path, f"not a readable ROS1 bag ({why})")
    conns: dict[int, tuple[str, str, str]] = {}  # id -> topic, type, definition
    messages: list[tuple[int, int, bytes]] = []
    problem = ""

    def take(header: dict[str, bytes], data: memoryview) -> None:
        op = header.get("op", b"\0")[0]
        if op == _OP_CONN:
            c = _fields(bytes(data))
            conns[struct.unpack("<I", header["conn"])[0]] = (
                header["topic"].decode(),
                c["type"].decode(),
                c.get("message_definition", b"").decode(),
            )
        elif op == _OP_MSG:
            sec, nsec = struct.unpack("<II", header["time"])
            messages.append((struct.unpack("<I", header["conn"])[0], sec * 1_000_000_000 + nsec, bytes(data)))

    try:
        for header, data in _records(memoryview(raw)[13:]):
            if header.get("op", b"\0")[0] == _OP_CHUNK:
                size = struct.unpack("<I", header["size"])[0]
                for inner, inner_data in _records(_decompress(header["compression"], data, size)):
                    take(inner, inner_data)
            else:
                take(header, data)
            if progress:
                progress(len(messages), 0)
    except (ValueError, KeyError, struct.error, OSError) as err:
        problem = str(err)
    if not messages:
        raise ReaderError(path, f"no message could be read ({why}; scan: {problem or 'no messages'})")
    store = get_typestore(Stores.EMPTY)
    for _, msgtype, definition in conns.values():
        if definition:
            store.register(get_types_from_msg(definition, msgtype))

    def deserialize(data: bytes | memoryview, msgtype: str) -> object:
        return store.deserialize_ros1(bytes(data), msgtype)

    collector = StreamCollector(path, "ros1bag", topics)
    collector.add_topics({topic: ros_topic(msgtype, "ros1", deserialize) for topic, msgtype, _ in conns.values()})
    collector.skipped.append(
        Skipped(
            "<file>",
            f"bag index unusable ({why}); read sequentially" + (f", stopped at damage: {problem}" if problem else ""),
            1,
            "lost" if problem else "repaired",
        )
    )
    for conn, t_ns, data in sorted(messages, key=lambda m: m[1]):
        if conn in conns:
            collector.add(conns[conn][0], t_ns, data)
    return collector.finish("unix")


ROS1_MAGIC = b"#ROSBAG V2.0\n"


def _is_ros1_bag(path: Path, head: bytes) -> bool:
    return head.startswith(ROS1_MAGIC)


def _is_ros2_bag(path: Path, head: bytes) -> bool:
    return path.is_dir() and ((path / "metadata.yaml").exists() or any(path.glob("*.db3")) or any(path.glob("*.mcap")))


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
