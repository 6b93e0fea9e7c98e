"""Readers: one module per log format, each turning a file into an EpochTable.

Each reader module declares its formats (`FORMATS`, a tuple of `ReaderFormat`): how to recognise the
format from content, the function that reads it, and whether `inject` can write a spoofed copy back
(`rewrite`, "module:function"). The registry below is built from those declarations, in the order of
`READER_MODULES` (binary formats with a magic number first, then text formats from the most specific
to the least, the spooflens CSV last). Adding a format is one module plus one line there. Readers
know nothing of detectors.
"""

from __future__ import annotations

import importlib
import stat
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

from readers.buffers import release_freed_memory
from spooflens.epoch_table import EpochTable, Skipped, holding_nothing
from spooflens.errors import ReaderError, UnsupportedFormatError

Progress = Callable[[int, int], None]
ReaderFn = Callable[[Path, Mapping[str, str] | None, Progress | None], EpochTable]
HEAD_BYTES = 4096

# Sniffed in this order; a module may declare several formats.
READER_MODULES: tuple[str, ...] = (
    "readers.mcap_file",
    "readers.rosbag",
    "readers.ulog",
    "readers.rinex",
    "readers.packed",  # any format packed (after RINEX, which unpacks its own; before text, which a tar holds)
    "readers.ubx",
    "readers.nmea",
    "readers.gpsd_json",  # after NMEA: a gpspipe -w -r log of mostly NMEA stays NMEA
    "readers.n2k",
    "readers.ardupilot",
    "readers.tlog",
    "readers.gnss_tables",
    "readers.gnsslogger",
    "readers.csv_log",
)


@dataclass(frozen=True)
class ReaderFormat:
    """One format a reader module reads.

    `sniff(path, head)` gets the first HEAD_BYTES of a file (b"" for a directory) and says whether this
    format is it; it must be cheap and must not raise. `rewrite` names the function that writes a spoofed
    copy in this format ("module:function", signature of `spooflens.writers.rewrite.rewrite_log`), or
    None when `inject` cannot write it back. `folder_of_files`: a directory in this format is a set of
    files each in this format (NMEA, RINEX, CSV), not a container with a layout of its own (a ROS2 bag,
    whose storage files are logs by themselves); such a directory that also holds logs of other formats
    is a folder of separate logs, not one log (`sniff_format` says so). `companion(path)`: a file of this
    format that is not a log by itself but data a log reads (a RINEX navigation file beside its
    observations, a log's `LOG.truth.csv`): `batch` counts it among the paths that are not logs, not
    among the failed logs, and it makes no folder a folder of separate logs. `damaged(head)`: why a file
    that looks like this format, and that `sniff` still refused, cannot be read (standard NMEA sentences
    whose checksums all fail), said in place of "unknown format"; None when it is no such file.
    """

    name: str
    description: str
    read: ReaderFn
    sniff: Callable[[Path, bytes], bool]
    rewrite: str | None = None
    folder_of_files: bool = False
    companion: Callable[[Path], bool] | None = None
    damaged: Callable[[bytes], str | None] | None = None


def formats() -> dict[str, ReaderFormat]:
    """name -> ReaderFormat of every registered format, in sniffing order."""
    out: dict[str, ReaderFormat] = {}
    for fmt in _declared():
        if fmt.name in out:
            raise ValueError(f"reader format {fmt.name!r} declared twice")
        out[fmt.name] = fmt
    return out


def _declared() -> Iterator[ReaderFormat]:
    """Every declared format in sniffing order, importing each reader module only when reached (an MCAP
    file, sniffed first, never imports the readers of a dozen other formats and their libraries)."""
    for module in READER_MODULES:
        yield from importlib.import_module(module).FORMATS


def supported() -> str:
    return "; ".join(f.description for f in formats().values())


class NothingToJudgeError(ReaderError):
    """The log is sound and was read whole, but holds nothing any detector reads (other stations' AIS
    reports, a receiver's configuration replies, navigation messages alone). `read_log` turns it into an
    empty table that says what the log holds: analysed, it gets a NO VERDICT saying so, not a refusal;
    `inject` refuses it (nothing to spoof). `skipped`: what the reader skipped or lost on the way."""

    def __init__(
        self, path: Path | str, problem: str, stream: str | None = None, skipped: list[Skipped] | None = None
    ) -> None:
        super().__init__(path, problem, stream)
        self.skipped = list(skipped or [])


class _Registry(dict[str, ReaderFn]):
    """format name -> reader function from the declarations, unless a test put another one in."""

    def __missing__(self, name: str) -> ReaderFn:
        fmt = next((f for f in _declared() if f.name == name), None)
        if fmt is None:
            raise KeyError(name)
        self[name] = fmt.read
        return fmt.read


READERS: dict[str, ReaderFn] = _Registry()


def sniff_format(path: Path) -> str:
    """Format name of `path` from its content; raises ReaderError for what no reader knows (for a folder
    that is no log but holds logs, naming them)."""
    path = Path(path)
    name, head = _sniffed(path)
    if name is not None:
        return name
    if path.is_dir():
        _refuse_a_folder_of_separate_logs(path, None)
    if path.is_dir():
        what = "directory holds no log this tool reads"
    else:
        from readers.protocols import identify

        for fmt in formats().values():
            why = fmt.damaged(head) if fmt.damaged is not None else None
            if why is not None:
                raise ReaderError(path, why, fmt.name)
        protocol = identify(path, head)
        what = f"{protocol}: not supported" if protocol else f"unknown format (starts with {head[:12]!r})"
    raise UnsupportedFormatError(path, f"{what}; supported: {supported()}")


def recognised_format(path: Path) -> str | None:
    """Format name of `path`, None when no reader knows it, without listing what a folder that is no log
    holds (`batch` asks this of every folder it matches); raises ReaderError for what cannot be read at
    all, and for a folder in a format of files that also holds logs of another."""
    return _sniffed(Path(path))[0]


def _sniffed(path: Path) -> tuple[str | None, bytes]:
    """(format name or None, the head read) of `path`."""
    if not path.exists():
        raise ReaderError(path, "no such file or directory")
    mode = path.stat().st_mode
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        raise ReaderError(path, "not a regular file or a directory (a pipe, socket or device cannot be analysed)")
    head = b""
    if path.is_file():
        with path.open("rb") as f:
            head = f.read(HEAD_BYTES)
        if not head:
            raise ReaderError(path, "file is empty (0 bytes)")
    for fmt in _declared():
        if fmt.sniff(path, head):
            if fmt.folder_of_files and path.is_dir():
                _refuse_a_folder_of_separate_logs(path, fmt.name)
            return fmt.name, head
    return None, head


def is_companion(path: Path, name: str) -> bool:
    """Whether `path`, sniffed as format `name`, is data for a log rather than a log (ReaderFormat.companion)."""
    fmt = formats()[name]
    return fmt.companion is not None and fmt.companion(path)


def separate_logs(folder: Path, name: str | None) -> list[tuple[Path, str]]:
    """(file, format) of each file directly in `folder` that is a log in a format other than `name`
    (None: in any format); data for a log (a RINEX navigation file) is no log."""
    found = []
    for path in sorted(p for p in folder.iterdir() if p.is_file()):
        try:
            fmt = sniff_format(path)
        except ReaderError:
            continue
        if fmt != name and not is_companion(path, fmt):
            found.append((path, fmt))
    return found


def _refuse_a_folder_of_separate_logs(folder: Path, name: str | None) -> None:
    """A folder read as one log (format `name`) must hold nothing but that log's files: the reader of one
    format never reads the others, so u-blox captures beside NMEA files (an NMEA reader finds sentences in
    both), or a phone's GnssLogger and NMEA files beside its RINEX, would be dropped or merged without a
    word. A folder that is no log itself (`name` None) but holds logs (a folder of MCAP files, of bags)
    is refused the same way, naming them."""
    others = separate_logs(folder, name)
    if others:
        listed = ", ".join(f"{p.name} ({fmt})" for p, fmt in others[:4]) + (" ..." if len(others) > 4 else "")
        what = f"not one {name} log: it also holds" if name is not None else "it holds"
        raise UnsupportedFormatError(
            folder,
            f"a folder of separate logs, {what} {listed}; analyse each file, or all of them with "
            f"spooflens batch '{folder}/*'",
        )


def read_log(path: Path | str, topics: Mapping[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    """Read any supported log into an EpochTable (what could be read, with what was skipped listed)."""
    path = Path(path)
    fmt = sniff_format(path)
    try:
        table = READERS[fmt](path, topics, progress)
    except NothingToJudgeError as err:
        return holding_nothing(path, fmt, err.problem, err.skipped)
    table.validate()
    release_freed_memory()
    return table
