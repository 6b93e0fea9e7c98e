"""Write an EpochTable as a ROS1 .bag or a ROS2 bag directory (sqlite3 or MCAP storage)."""

from __future__ import annotations

import shutil
from pathlib import Path

from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2

from spooflens.epoch_table import EpochTable
from spooflens.writers.encoders import RosEncoder
from spooflens.writers.messages import in_time_order, out_streams


def write_ros1_bag(table: EpochTable, path: Path) -> None:
    enc = RosEncoder(1)
    streams = out_streams(table)
    path = Path(path)
    path.unlink(missing_ok=True)
    with Writer1(path) as w:
        conns = {s.topic: w.add_connection(s.topic, enc.msgtype(s.kind), typestore=enc.store) for s in streams}
        for s, i, t in in_time_order(streams):
            w.write(conns[s.topic], t, enc.encode(s, i, t))


def write_ros2_bag(table: EpochTable, path: Path, storage: str = "sqlite3") -> None:
    enc = RosEncoder(2)
    streams = out_streams(table)
    path = Path(path)
    if path.exists():
        shutil.rmtree(path)
    plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
    with Writer2(path, version=9, storage_plugin=plugin) as w:
        conns = {s.topic: w.add_connection(s.topic, enc.msgtype(s.kind), typestore=enc.store) for s in streams}
        for s, i, t in in_time_order(streams):
            w.write(conns[s.topic], t, enc.encode(s, i, t))
