"""Readers: one module per log format, each turning a file into an EpochTable.

`read_log` sniffs the format from the content (not the extension) and dispatches through `READERS`,
a plain mapping a test can patch. Readers know nothing of detectors.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from pathlib import Path

from spooflens.epoch_table import EpochTable
from spooflens.errors import ReaderError, UnsupportedFormatError

Progress = Callable[[int, int], None]
ReaderFn = Callable[[Path, Mapping[str, str] | None, Progress | None], EpochTable]

MCAP_MAGIC = b"\x89MCAP0\r\n"
ROS1_MAGIC = b"#ROSBAG V2.0\n"
ULOG_MAGIC = b"ULog\x01\x12\x35"
SQLITE_MAGIC = b"SQLite format 3\x00"

# format name -> "module:function", imported on first use so a format's dependencies load only when needed
READER_PATHS: dict[str, str] = {
    "mcap": "readers.mcap_file:read_mcap",
    "ros1bag": "readers.rosbag:read_rosbag",
    "ros2bag": "readers.rosbag:read_rosbag",
    "csv": "readers.csv_log:read_csv",
    "ulog": "readers.ulog:read_ulog",
    "rinex": "readers.rinex:read_rinex",
}
SUPPORTED = (
    "MCAP (.mcap), ROS1 bag (.bag), ROS2 bag directory, spooflens CSV (.csv), PX4 ULog (.ulg), "
    "RINEX obs (a file or a directory of them)"
)


def _load(spec: str) -> ReaderFn:
    module, _, func = spec.partition(":")
    fn: ReaderFn = getattr(importlib.import_module(module), func)
    return fn


class _Registry(dict[str, ReaderFn]):
    """format -> reader function, imported lazily from READER_PATHS unless a test set one."""

    def __missing__(self, fmt: str) -> ReaderFn:
        fn = _load(READER_PATHS[fmt])
        self[fmt] = fn
        return fn


READERS: dict[str, ReaderFn] = _Registry()


def _holds_rinex_obs(directory: Path) -> bool:
    """A directory with at least one RINEX observation file (by content), read as one multi-receiver log."""
    from readers.rinex import is_rinex_obs

    return any(p.is_file() and is_rinex_obs(p) for p in sorted(directory.iterdir()))


def sniff_format(path: Path) -> str:
    """Format name of `path` from its content; raises ReaderError for what no reader knows."""
    if not path.exists():
        raise ReaderError(path, "no such file or directory")
    if path.is_dir():
        if (path / "metadata.yaml").exists() or any(path.glob("*.db3")) or any(path.glob("*.mcap")):
            return "ros2bag"
        if any(path.glob("*.csv")):
            return "csv"
        if _holds_rinex_obs(path):
            return "rinex"
        raise UnsupportedFormatError(
            path, f"directory is neither a ROS2 bag, a CSV log nor RINEX observations; supported: {SUPPORTED}"
        )
    with path.open("rb") as f:
        head = f.read(512)
    if not head:
        raise ReaderError(path, "file is empty (0 bytes)")
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    if head.startswith(ROS1_MAGIC):
        return "ros1bag"
    if head.startswith(ULOG_MAGIC):
        return "ulog"
    if head.startswith(SQLITE_MAGIC):
        raise UnsupportedFormatError(path, "a bare sqlite3 file: give the ROS2 bag directory (with metadata.yaml)")
    text = head.decode("utf-8", errors="replace")
    if "RINEX VERSION / TYPE" in text.splitlines()[0] if text else False:
        return "rinex"
    if "\ufffd" not in text and ("," in text) and text.lstrip().startswith(("#", *"abcdefghijklmnopqrstuvwxyz")):
        return "csv"
    raise UnsupportedFormatError(path, f"unknown format (starts with {head[:12]!r}); supported: {SUPPORTED}")


def read_log(path: Path | str, topics: Mapping[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    """Read any supported log into an EpochTable (what could be read, with what was skipped listed)."""
    path = Path(path)
    fmt = sniff_format(path)
    table = READERS[fmt](path, topics, progress)
    table.validate()
    return table
