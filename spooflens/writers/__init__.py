"""Writers: an EpochTable to any format the readers read (sample logs, simulations, attacked copies).

Format names: mcap-ros2, mcap-ros1, mcap-json, mcap-protobuf, ros1bag, ros2bag-sqlite3, ros2bag-mcap, csv, ulog,
rinex (observations only, with a navigation file).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from spooflens.epoch_table import EpochTable
from spooflens.errors import WriterError
from spooflens.writers.bag_writer import write_ros1_bag, write_ros2_bag
from spooflens.writers.csv_writer import write_csv
from spooflens.writers.mcap_writer import write_mcap
from spooflens.writers.rinex_writer import write_rinex
from spooflens.writers.ulog_writer import write_ulog

WRITERS: dict[str, Callable[[EpochTable, Path], object]] = {
    "mcap-ros2": lambda t, p: write_mcap(t, p, "ros2"),
    "mcap-ros1": lambda t, p: write_mcap(t, p, "ros1"),
    "mcap-json": lambda t, p: write_mcap(t, p, "json"),
    "mcap-protobuf": lambda t, p: write_mcap(t, p, "protobuf"),
    "ros1bag": write_ros1_bag,
    "ros2bag-sqlite3": lambda t, p: write_ros2_bag(t, p, "sqlite3"),
    "ros2bag-mcap": lambda t, p: write_ros2_bag(t, p, "mcap"),
    "csv": write_csv,
    "ulog": write_ulog,
    "rinex": write_rinex,
}
SUFFIX = {
    "mcap-ros2": ".mcap",
    "mcap-ros1": ".mcap",
    "mcap-json": ".mcap",
    "mcap-protobuf": ".mcap",
    "ros1bag": ".bag",
    "ros2bag-sqlite3": "",
    "ros2bag-mcap": "",
    "csv": "",
    "ulog": ".ulg",
    "rinex": "",
}


def write_log(table: EpochTable, path: Path | str, fmt: str) -> None:
    """Write `table` to `path` in format `fmt` (see WRITERS)."""
    if fmt not in WRITERS:
        raise WriterError(f"{path}: unknown output format {fmt!r}; formats are {sorted(WRITERS)}")
    try:
        WRITERS[fmt](table, Path(path))
    except OSError as err:
        raise WriterError(f"{path}: cannot write {fmt}: {err}") from err
