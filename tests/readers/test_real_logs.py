"""The real husky bag (ROS1, recorded by others) reads correctly in every container."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from readers import read_log
from readers.ros_messages import decode_ros1, extract
from spooflens.epoch_table import EpochTable


@pytest.fixture(scope="module")
def husky(husky_bag: Path) -> EpochTable:
    return read_log(husky_bag)


@pytest.fixture(scope="module")
def converted(husky_bag: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The bag converted by rosbags-convert into ROS2 sqlite3, ROS2 MCAP storage and a bare .mcap."""
    tool = Path(sys.executable).with_name("rosbags-convert")
    out = tmp_path_factory.mktemp("husky")
    paths = {}
    for storage in ("sqlite3", "mcap"):
        dst = out / f"husky_{storage}"
        subprocess.run(
            [str(tool), "--src", str(husky_bag), "--dst", str(dst), "--dst-storage", storage],
            check=True,
            capture_output=True,
        )
        paths[f"ros2bag-{storage}"] = dst
    bare = out / "bare.mcap"
    shutil.copy(next(paths["ros2bag-mcap"].glob("*.mcap")), bare)
    paths["bare-mcap"] = bare
    return paths


def test_husky_streams_counts_rates_and_span(husky: EpochTable) -> None:
    by_role = {s.role: s for s in husky.streams}
    fix, imu, odom = by_role["fix"], by_role["imu"], by_role["odometry"]
    assert (fix.topic, fix.count) == ("/fix", 989) and fix.rate_hz == pytest.approx(2.5, abs=0.05)
    assert (imu.topic, imu.count) == ("/imu/data", 11865) and imu.rate_hz == pytest.approx(30.0, abs=0.2)
    assert odom.count == 3952 and odom.rate_hz == pytest.approx(10.0, abs=0.1)
    assert husky.duration_s == pytest.approx(395.3, abs=0.5)
    assert husky.time_reference == "unix" and husky.absolute_iso(0.0).startswith("2015-05-21")
    assert husky.skipped == []


def test_husky_values_positions_and_rotated_imu_mount(husky: EpochTable) -> None:
    assert husky.fixes["lat_deg"].mean() == pytest.approx(42.376, abs=0.002)
    assert husky.fixes["lon_deg"].mean() == pytest.approx(-71.147, abs=0.002)
    assert set(husky.fixes["fix_type"]) == {3}  # SBAS fix
    mean_f = husky.imu[["ax_mps2", "ay_mps2", "az_mps2"]].mean().to_numpy()
    assert mean_f[1] == pytest.approx(9.8, abs=0.2) and abs(mean_f[0]) < 0.5 and abs(mean_f[2]) < 0.5
    q = husky.imu[["qw", "qx", "qy", "qz"]].to_numpy()
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-3)


@pytest.mark.parametrize("container", ["ros2bag-sqlite3", "ros2bag-mcap", "bare-mcap"])
def test_every_container_gives_the_same_table(husky: EpochTable, converted: dict[str, Path], container: str) -> None:
    other = read_log(converted[container])
    for frame in ("imu", "fixes", "odometry"):
        pd.testing.assert_frame_equal(other.frame(frame), husky.frame(frame))
    assert [(s.role, s.topic, s.msgtype, s.count) for s in other.streams] == [
        (s.role, s.topic, s.msgtype, s.count) for s in husky.streams
    ]
    assert other.t0_ns == husky.t0_ns


def test_fast_path_equals_the_deserialiser_on_real_messages(husky_bag: Path) -> None:
    from rosbags.highlevel import AnyReader

    checked = 0
    with AnyReader([husky_bag]) as reader:
        for conn, _, raw in reader.messages():
            kind = {"sensor_msgs/msg/Imu": "imu", "sensor_msgs/msg/NavSatFix": "navsatfix"}.get(conn.msgtype)
            if kind:
                fast = decode_ros1(kind, raw)
                slow = extract(kind, reader.deserialize(raw, conn.msgtype))
                assert fast is not None and fast[0] == slow[0]
                np.testing.assert_array_equal(np.array(fast[1], float), np.array(slow[1], float))
                checked += 1
            if checked >= 3000:
                break
    assert checked == 3000
