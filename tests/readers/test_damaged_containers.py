"""Damaged containers, each built here: MCAP schemas overwritten, ROS2 bags with messages deleted or
another serialization format, ROS1 bags and ULogs cut short or with corrupt sizes, a ULog format of
huge arrays, a RINEX epoch with a non-ASCII byte, a pipe. What is lost is counted and named, never an
internal error."""

from __future__ import annotations

import os
import random
import re
import shutil
import sqlite3
import struct
from pathlib import Path

import pandas as pd
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer
from paths import REAL, ROOT
from pipeline_support import circling_table

from readers import read_log
from spooflens.bench.mutations import ulog_messages
from spooflens.cli import main
from spooflens.errors import ReaderError
from spooflens.simulation.simulate import SCENARIOS, simulate
from spooflens.writers import write_log

GSI = REAL / "rinex_gsi_pair"


def _with_schema(src: Path, dst: Path, name: str, edit) -> None:
    """A copy of an MCAP with one schema's data replaced by edit(data)."""
    with src.open("rb") as f, dst.open("wb") as out:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        w = Writer(out)
        w.start(profile=reader.get_header().profile, library="test")
        ids = {
            sid: w.register_schema(s.name, s.encoding, edit(s.data) if s.name == name else s.data)
            for sid, s in summary.schemas.items()
        }
        chans = {
            cid: w.register_channel(c.topic, c.message_encoding, ids[c.schema_id], dict(c.metadata))
            for cid, c in summary.channels.items()
        }
        for _, channel, message in reader.iter_messages(log_time_order=False):
            w.add_message(chans[channel.id], message.log_time, message.data, message.publish_time)
        w.finish()


@pytest.mark.parametrize(
    ("fmt", "edit"),
    [
        ("mcap-ros2", lambda d: d.replace(b"float64 x", b"flaot64 x")),  # an unknown type
        ("mcap-ros2", lambda d: d.replace(b"geometry_msgs/Vector3", b"geometry_msgs/Vec#or3")),  # a bad name
        ("mcap-ros2", lambda d: d[: len(d) // 2] + b"\xff\xfe" + d[len(d) // 2 :]),  # not UTF-8
        ("mcap-ros1", lambda d: d.replace(b"\n", b"\n]][[\n", 1)),  # garbage line: a multi-line library error
        ("mcap-protobuf", lambda d: d[:20] + bytes(b ^ 0x5A for b in d[20:60]) + d[60:]),  # descriptor set
    ],
)
def test_an_overwritten_schema_costs_its_topic_counted_as_lost(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], fmt: str, edit
) -> None:
    src, bad = tmp_path / "src.mcap", tmp_path / "bad.mcap"
    write_log(circling_table(seconds=60.0), src, fmt)
    with src.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    name = next(s.name for s in summary.schemas.values() if "Imu" in s.name)
    _with_schema(src, bad, name, edit)
    table = read_log(bad)
    lost = [s for s in table.skipped if s.action == "lost"]
    # the damaged schema costs its channel's messages (or, when it clashes with another schema's type of
    # the same name, the channel registered second: which of two disagreeing schemas is right is unknown)
    assert lost and all("schema unreadable" in s.reason and "\n" not in s.reason for s in lost)
    assert sum(s.count for s in lost) in (3000, 60) and len(table.fixes) + len(table.imu) >= 60
    code = main(["analyze", str(bad), "-o", str(tmp_path / "x.rrd"), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code in (2, 3) and len(err) == 1 and "schema unreadable" in err[0]


@pytest.fixture(scope="module")
def sqlite_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("bag") / "bag"
    write_log(circling_table(seconds=60.0), path, "ros2bag-sqlite3")
    return path


def _bag_copy(src: Path, dst: Path, *sql: str) -> Path:
    shutil.copytree(src, dst)
    con = sqlite3.connect(next(dst.glob("*.db3")))
    for statement in sql:
        con.execute(statement)
    con.commit()
    con.close()
    return dst


def test_ros2_bag_with_its_messages_deleted(sqlite_bag: Path, tmp_path: Path) -> None:
    empty = _bag_copy(sqlite_bag, tmp_path / "empty", "DELETE FROM messages")
    with pytest.raises(ReaderError, match=r"the bag lists \d+ messages, none is readable .*holds 0 messages"):
        read_log(empty)
    full = read_log(sqlite_bag)
    half = read_log(_bag_copy(sqlite_bag, tmp_path / "half", "DELETE FROM messages WHERE id % 2 = 0"))
    lost = {s.stream: s.count for s in half.skipped if s.action == "lost"}
    assert lost["/imu"] + len(half.imu) == len(full.imu)
    assert lost["/gps/fix"] + len(half.fixes) == len(full.fixes)
    assert all("the bag lists" in s.reason for s in half.skipped if s.action == "lost")


def test_ros2_bag_with_another_serialization_format(sqlite_bag: Path, tmp_path: Path) -> None:
    moved = _bag_copy(sqlite_bag, tmp_path / "fmt", "UPDATE topics SET serialization_format = 'ros1'")
    with pytest.raises(ReaderError, match=r"topics serialised as \['ros1'\] \(readable: \['cdr'\]\)"):
        read_log(moved)
    meta = tmp_path / "meta"
    shutil.copytree(sqlite_bag, meta)
    text = (meta / "metadata.yaml").read_text()
    (meta / "metadata.yaml").write_text(re.sub(r"serialization_format: \w+", "serialization_format: ros1", text))
    with pytest.raises(ReaderError, match="cannot open ROS2 bag"):
        read_log(meta)


def test_a_cut_ros1_bag_counts_and_names_what_was_lost(husky_bag: Path, tmp_path: Path) -> None:
    full = read_log(husky_bag)
    cut = tmp_path / "cut.bag"
    cut.write_bytes(husky_bag.read_bytes()[:700_000])
    table = read_log(cut)
    assert len(table.odometry) > 1000 and not [s for s in table.skipped if "could not be decoded" in s.reason]
    lost = {s.stream: s.count for s in table.skipped if s.action == "lost" and s.stream != "<file>"}
    for stream, read, whole in (
        ("/imu/data", len(table.imu), len(full.imu)),
        ("/fix", len(table.fixes), len(full.fixes)),
        ("/husky_velocity_controller/odom", len(table.odometry), len(full.odometry)),
    ):
        assert read + lost[stream] == pytest.approx(whole, rel=0.02), stream


def test_a_ros2_bag_metadata_with_nan_message_counts(tmp_path: Path) -> None:
    """The 10^4 fuzz run wrote NaN into metadata.yaml's message counts (TypeError summing them before):
    the bag is read, the unreadable counts are noted."""
    src = tmp_path / "src"
    write_log(circling_table(seconds=30.0), src, "ros2bag-mcap")
    full = read_log(src)
    meta = src / "metadata.yaml"
    meta.write_text(re.sub(r"message_count: \d+", "message_count: NaN", meta.read_text()))
    table = read_log(src)
    assert len(table.imu) == len(full.imu) and len(table.fixes) == len(full.fixes)
    assert any("message count in the bag's metadata unreadable" in s.reason for s in table.skipped)


def _mcap_records(data: bytes, opcode: int) -> list[int]:
    """Offsets of the top-level records of one opcode in an MCAP file."""
    out, pos = [], 8
    while pos + 9 <= len(data):
        op, length = struct.unpack_from("<BQ", data, pos)
        if op == opcode:
            out.append(pos)
        if op == 0x02:  # footer
            break
        pos += 9 + length
    return out


@pytest.mark.parametrize(
    ("opcode", "field_at", "value"),
    [
        (0x06, 9 + 16, 0x7FFF_FFFF_FFFF_FFFF),  # a chunk's uncompressed size
        (0x07, 9 + 2 + 4 + 8, 0xFFFF_FFFF_FFFF_FFFF),  # a message index's first offset (-1 as int64)
        (0x07, 9 + 2 + 4 + 8, 0x8000_0000_0000_0000),
    ],
)
def test_an_mcap_length_or_offset_beyond_int64_is_damage_not_an_overflow(
    tmp_path: Path, opcode: int, field_at: int, value: int
) -> None:
    """The fuzz run overwrote MCAP integers with 2^63-scale values: zstandard refused the declared size
    (OverflowError) and a message index offset became a huge negative index (IndexError)."""
    src = tmp_path / "src.mcap"
    write_log(circling_table(seconds=30.0), src, "mcap-ros2")
    data = bytearray(src.read_bytes())
    at = _mcap_records(bytes(data), opcode)
    assert at, "the writer made no such record"
    struct.pack_into("<Q", data, at[0] + field_at, value)
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    table = read_log(bad)  # the damaged chunk is lost and counted; an index is walked past
    full = read_log(src)
    if opcode == 0x06:
        assert any("corrupt length" in s.reason and s.action == "lost" for s in table.skipped)
    else:
        assert len(table.imu) == len(full.imu) and len(table.fixes) == len(full.fixes)
    assert main(["inspect", str(bad)]) in (0, 3)


def test_an_mcap_zstd_frame_declaring_gigabytes_is_damage_not_a_memory_error(tmp_path: Path) -> None:
    """The second 10^4 fuzz run set a chunk's zstd frame content size to 4 GB: zstandard allocated what
    the frame said and ran out of memory (MemoryError under the 4 GB cap). A frame declaring more than
    the chunk holds is damage: the chunk's messages are lost and counted, the rest is read."""
    src = ROOT / "sample_logs" / "dual_receiver.mcap"
    data = bytearray(src.read_bytes())
    chunk = _mcap_records(bytes(data), 0x06)[0]
    frame = data.index(b"\x28\xb5\x2f\xfd", chunk)  # the zstd magic of the chunk's records
    descriptor = data[frame + 4]
    single = (descriptor >> 5) & 1
    start = frame + 5 + (0 if single else 1) + (0, 1, 2, 4)[descriptor & 3]
    size = {0: 1 if single else 0, 1: 2, 2: 4, 3: 8}[descriptor >> 6]
    assert size >= 4, "the writer's frame has no content size to overwrite"
    data[start : start + size] = b"\xff" * size
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    table = read_log(bad)
    assert any("zstd frame declares" in s.reason and s.action == "lost" for s in table.skipped)
    assert main(["inspect", str(bad)]) == 3


@pytest.mark.parametrize("threads", [1, 2])
def test_mcap_chunks_decompressed_ahead_are_decoded_in_file_order_and_a_damaged_one_is_lost_alone(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, threads: int
) -> None:
    """Chunks are decompressed a few ahead in a thread of their own and decoded, a group of chunks at a
    time, in another (one thread: each when its turn comes). Either way the table is the same, row for
    row, and a chunk whose data is damaged in the middle of the file loses its own messages only,
    counted. Every chunk a group of its own here: many groups decoded behind the reading."""
    import readers.mcap_file

    monkeypatch.setattr(readers.mcap_file, "_GROUP_BYTES", 1)

    src = ROOT / "sample_logs" / "spoofed_flight.mcap"
    data = bytearray(src.read_bytes())
    chunks = _mcap_records(bytes(data), 0x06)
    assert len(chunks) > 4, "too few chunks to read any ahead (four are)"
    middle = chunks[len(chunks) // 2]
    frame = data.index(b"\x28\xb5\x2f\xfd", middle)
    data[frame + 40 : frame + 48] = bytes(b ^ 0xFF for b in data[frame + 40 : frame + 48])
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    monkeypatch.setattr(readers.mcap_file, "thread_count", lambda: threads)
    full, table = read_log(src), read_log(bad)
    lost = [s for s in table.skipped if "unreadable" in s.reason and s.action == "lost"]
    assert len(lost) == 1 and "chunk starting at log time" in lost[0].reason
    assert 0 < len(full.imu) - len(table.imu) < len(full.imu) / 3
    t = table.imu["t_s"].to_numpy()
    assert (t[1:] >= t[:-1]).all()
    monkeypatch.setattr(readers.mcap_file, "thread_count", lambda: 3 - threads)
    other = read_log(bad)
    pd.testing.assert_frame_equal(other.imu, table.imu)
    pd.testing.assert_frame_equal(other.fixes, table.fixes)


@pytest.fixture(scope="module")
def ulog(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("ulog") / "sim.ulg"
    write_log(simulate(SCENARIOS["ground"], seed=0, duration_s=60.0).table, path, "ulog")
    return path


def test_a_ulog_cut_short_says_so(ulog: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = ulog.read_bytes()
    for k, cut in enumerate((0.4, 0.9)):
        path = tmp_path / f"cut{k}.ulg"
        path.write_bytes(data[: int(len(data) * cut)])
        table = read_log(path)
        assert any(s.action == "lost" and "cut short" in s.reason for s in table.skipped)
        code = main(["analyze", str(path), "-o", str(tmp_path / "x.rrd"), "--quiet"])
        assert code == 3 and "cut short" in capsys.readouterr().err


def test_corrupt_ulog_message_sizes_count_the_samples_they_cost(ulog: Path, tmp_path: Path) -> None:
    data = ulog.read_bytes()
    full = read_log(ulog)
    messages = ulog_messages(data)
    rng = random.Random(1)
    for trial in range(4):
        bad = bytearray(data)
        for _ in range(3):
            pos, _, _ = rng.choice(messages[len(messages) // 10 :])
            bad[pos : pos + 2] = struct.pack("<H", rng.choice([0, 65535, rng.randrange(65536)]))
        path = tmp_path / f"bad{trial}.ulg"
        path.write_bytes(bytes(bad))
        table = read_log(path)
        lost = {s.stream: s.count for s in table.skipped if s.action == "lost"}
        assert lost, trial
        for stream, read, whole in (
            ("sensor_gps/0", len(table.fixes), len(full.fixes)),
            ("sensor_combined", len(table.imu), len(full.imu)),
        ):
            assert read + lost.get(stream, 0) == pytest.approx(whole, rel=0.03), (trial, stream)


def test_a_ulog_format_declaring_a_huge_first_array(ulog: Path, tmp_path: Path) -> None:
    data = bytearray(ulog.read_bytes())
    for pos, size, kind in ulog_messages(bytes(data)):
        if kind == ord("F") and data[pos + 3 : pos + 3 + size].startswith(b"sensor_gps:"):
            text = bytes(data[pos + 3 : pos + 3 + size])
            new = re.sub(rb"^sensor_gps:uint64_t timestamp", b"sensor_gps:uint64_t[99999999] timestamp", text)
            data[pos : pos + 3 + size] = struct.pack("<HB", len(new), ord("F")) + new
            break
    path = tmp_path / "huge.ulg"
    path.write_bytes(bytes(data))
    table = read_log(path)
    assert not len(table.fixes) and len(table.imu) == len(read_log(ulog).imu)
    lost = {s.stream: s.count for s in table.skipped if s.action == "lost"}
    assert lost["sensor_gps/0"] == 601  # every GPS message of the minute, counted by walking the file


def test_a_non_ascii_byte_in_a_rinex_epoch_satellite_list(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    lines = (GSI / "07590920.05o").read_bytes().split(b"\n")
    end = next(i for i, line in enumerate(lines) if b"END OF HEADER" in line)
    epochs = [i for i in range(end + 1, len(lines)) if lines[i].startswith(b" 05  4  2")]
    for k, byte in enumerate((b"\xe9", b"\xff", b"\xc3")):
        i = epochs[10 + k]
        lines[i] = lines[i][:35] + byte + lines[i][36:]  # inside the second satellite id
    (tmp_path / "x.05o").write_bytes(b"\n".join(lines))
    shutil.copy(GSI / "07590920.05n", tmp_path / "x.05n")
    table = read_log(tmp_path / "x.05o")
    lost = {s.reason: s.count for s in table.skipped if s.action == "lost"}
    assert lost == {"satellites with an unreadable id in the epoch header": 3}
    code = main(["analyze", str(tmp_path / "x.05o"), "-o", str(tmp_path / "x.rrd"), "--quiet"])
    assert code == 3 and "unreadable id" in capsys.readouterr().err


def test_a_pipe_named_like_a_log_is_refused_at_once(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    fifo = tmp_path / "x.mcap"
    os.mkfifo(fifo)
    assert main(["inspect", str(fifo)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a regular file or a directory" in err[0]
