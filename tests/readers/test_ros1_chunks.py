"""A cleanly indexed ROS1 bag is read from its own index, a group of chunks at a time
(`readers.rosbag1_chunks`): the same table as rosbags' reader gives message by message, whatever the
compression, the chunking or the publishers sharing a topic; a bag whose index disagrees with its chunks
is left to rosbags' reader."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

import readers.rosbag
from readers import read_log
from readers.rosbag1_chunks import read_indexed
from spooflens.epoch_table import EpochTable
from spooflens.simulation.simulate import SCENARIOS, simulate
from spooflens.writers import write_log

FRAMES = ("imu", "fixes", "odometry", "headings", "truth")


def _by_rosbags(path: Path, monkeypatch: pytest.MonkeyPatch) -> EpochTable:
    with monkeypatch.context() as m:
        m.setattr(readers.rosbag, "read_indexed", lambda *args: None)
        return read_log(path)


def _assert_same(a: EpochTable, b: EpochTable) -> None:
    for name in FRAMES:
        pd.testing.assert_frame_equal(getattr(a, name), getattr(b, name))
    assert a.streams == b.streams
    assert a.skipped == b.skipped
    assert a.segments == b.segments


def test_the_real_husky_bag_is_read_from_its_index_as_rosbags_reads_it(
    husky_bag: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert read_indexed(husky_bag, None, None) is not None
    _assert_same(read_log(husky_bag), _by_rosbags(husky_bag, monkeypatch))


@pytest.mark.parametrize("compression", [None, Writer.CompressionFormat.LZ4, Writer.CompressionFormat.BZ2])
def test_two_publishers_on_one_topic_in_many_small_chunks_come_in_rosbags_order(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, compression: Writer.CompressionFormat | None
) -> None:
    """Two connections on /imu/data, their stamps interleaved with ties, and a fix topic; chunks of a
    few messages each, so every group holds many chunks and a topic's messages many groups."""
    ts = get_typestore(Stores.ROS1_NOETIC)
    Imu, Header, Time = (
        ts.types[n] for n in ("sensor_msgs/msg/Imu", "std_msgs/msg/Header", "builtin_interfaces/msg/Time")
    )
    Quaternion, Vector3 = ts.types["geometry_msgs/msg/Quaternion"], ts.types["geometry_msgs/msg/Vector3"]
    NavSatFix, NavSatStatus = ts.types["sensor_msgs/msg/NavSatFix"], ts.types["sensor_msgs/msg/NavSatStatus"]
    cov = np.zeros(9)
    t0 = 1_700_000_000
    path = tmp_path / "two_publishers.bag"
    monkeypatch.setattr(readers.rosbag1_chunks, "_GROUP_BYTES", 4096)
    w = Writer(path)
    if compression is not None:
        w.set_compression(compression)
    w.chunk_threshold = 2048
    with w:
        imu = [w.add_connection("/imu/data", Imu.__msgtype__, typestore=ts, callerid=f"/node{k}") for k in (0, 1)]
        fix = w.add_connection("/gps/fix", NavSatFix.__msgtype__, typestore=ts)
        for k in range(400):
            t_ns = (t0 * 10**9) + (k // 2) * 10_000_000  # two messages per stamp: ties across the publishers
            stamp = Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9)
            msg = Imu(
                Header(seq=k, stamp=stamp, frame_id="imu"),
                Quaternion(0.0, 0.0, 0.0, 1.0),
                cov,
                Vector3(0.01 * k, 0.0, 0.0),
                cov,
                Vector3(0.0, 0.0, 9.81 + 0.001 * k),
                cov,
            )
            w.write(imu[k % 2], t_ns, ts.serialize_ros1(msg, Imu.__msgtype__))
            if k % 20 == 0:
                status = NavSatStatus(status=0, service=1)
                fixmsg = NavSatFix(
                    Header(seq=k, stamp=stamp, frame_id="gps"), status, 47.0 + 1e-6 * k, 8.0, 400.0, cov, 2
                )
                w.write(fix, t_ns, ts.serialize_ros1(fixmsg, NavSatFix.__msgtype__))
    table = read_indexed(path, None, None)
    # one row per IMU stamp (the table keeps one of two samples at the same time: which one, the order says)
    assert table is not None and len(table.imu) == 200 and len(table.fixes) == 20
    _assert_same(table, _by_rosbags(path, monkeypatch))


def test_a_bag_whose_index_disagrees_with_its_chunks_is_left_to_rosbags(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An index entry's time changed: no longer the time of the message record it points at."""
    src = tmp_path / "ground.bag"
    write_log(simulate(SCENARIOS["ground"], seed=0, duration_s=20.0).table, src, "ros1bag")
    clean = read_log(src)
    data = bytearray(src.read_bytes())
    at = data.index(b"op=\x04")  # the first index data record: its entries after its header and length
    (hlen,) = struct.unpack_from("<I", data, at - 4)
    entries = at - 4 + 4 + hlen + 4
    data[entries : entries + 4] = struct.pack("<I", struct.unpack_from("<I", data, entries)[0] + 1)
    bad = tmp_path / "bad.bag"
    bad.write_bytes(bytes(data))
    assert read_indexed(src, None, None) is not None
    assert read_indexed(bad, None, None) is None
    table = read_log(bad)  # rosbags' reader: what it can read, and what it could not, counted
    assert 0 < len(table.imu) <= len(clean.imu)
    _assert_same(table, _by_rosbags(bad, monkeypatch))


def test_a_bag_whose_index_lists_a_damaged_connection_is_left_to_rosbags(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The index section's copy of a connection record with its message definition's field length
    damaged: rosbags' reader refuses the index and the bag is read by the sequential scan, as before."""
    src = tmp_path / "ground.bag"
    write_log(simulate(SCENARIOS["ground"], seed=0, duration_s=20.0).table, src, "ros1bag")
    data = bytearray(src.read_bytes())
    at = data.rindex(b"message_definition=") - 4  # the last connection record: the index section's
    data[at : at + 4] = struct.pack("<I", 0xFFFF)
    bad = tmp_path / "bad.bag"
    bad.write_bytes(bytes(data))
    assert read_indexed(bad, None, None) is None
    table = read_log(bad)
    assert any("bag index unusable" in s.reason for s in table.skipped)
    _assert_same(table, _by_rosbags(bad, monkeypatch))


def test_a_topic_whose_messages_lie_in_chunks_out_of_time_order_is_left_to_rosbags(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Fixes written late (the second half of the log's first, then the first half): rosbags' reader
    yields them by time across the chunks, which a group of chunks at a time cannot."""
    ts = get_typestore(Stores.ROS1_NOETIC)
    NavSatFix, NavSatStatus = ts.types["sensor_msgs/msg/NavSatFix"], ts.types["sensor_msgs/msg/NavSatStatus"]
    Header, Time = ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    path = tmp_path / "late.bag"
    w = Writer(path)
    w.chunk_threshold = 1024
    t0 = 1_700_000_000
    with w:
        fix = w.add_connection("/gps/fix", NavSatFix.__msgtype__, typestore=ts)
        for k in [*range(30, 60), *range(30)]:
            t_ns = (t0 + k) * 10**9
            msg = NavSatFix(
                Header(seq=k, stamp=Time(sec=t0 + k, nanosec=0), frame_id="gps"),
                NavSatStatus(status=0, service=1),
                47.0 + 1e-5 * k,
                8.0,
                400.0,
                np.zeros(9),
                0,
            )
            w.write(fix, t_ns, ts.serialize_ros1(msg, NavSatFix.__msgtype__))
    assert read_indexed(path, None, None) is None
    table = read_log(path)
    assert len(table.fixes) == 60 and np.all(np.diff(table.fixes["t_s"].to_numpy()) > 0)
    _assert_same(table, _by_rosbags(path, monkeypatch))
