"""Logs as they are shipped, archived or mailed: any log of another format inside gzip, bzip2, xz, Unix
compress (.Z), a zip or a tar archive (`flight.ulg.gz`, `track.nmea.bz2`, a zip of a ROS2 bag folder,
`capture.tar.gz`).

The packing is recognised by content, never by name, and taken off into a temporary folder, streamed,
with a ceiling on what it may unpack to (an archive that would fill the disk is refused, not unpacked);
what is inside is then read as if it had been given unpacked. A stream cut short or damaged keeps what
came before the damage, the loss listed, as a cut plain log does. Archive members are written by their
names with every path part that could leave the folder (absolute paths, '..', links, devices) dropped:
nothing in an input file decides where a byte lands outside it. Packed RINEX is its reader's own
(`readers.rinex.packaging`: it also expands Hatanaka's Compact RINEX and reads the navigation file beside
the observations in a zip).
"""

from __future__ import annotations

import lzma
import shutil
import tarfile
import tempfile
import threading
import zipfile
import zlib
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import IO

from readers import Progress, ReaderFormat
from readers.compression import CHUNK, LZW_PACKING, expand_lzw, inflate, packing_of, zip_members
from spooflens.epoch_table import EpochTable, Skipped
from spooflens.errors import ReaderError

MAX_UNPACKED_BYTES = 16 * 2**30  # a day-long multi-gigabyte ULog or bag fits; a decompression bomb does not
SPARE_BYTES = 2**30  # left free on the temporary folder's disk
CUT_ZIP_IN_MEMORY = 512 * 2**20  # a zip without its directory is read whole, from its members' own headers
MAX_DEPTH = 3  # a tar in a gzip in a zip; a zip that unpacks to itself does not go on for ever
SUFFIXES = (".gz", ".gzip", ".bz2", ".xz", ".Z", ".tgz", ".tbz2", ".txz")  # what a compressed stream's name ends in
JUNK = ("__MACOSX", ".DS_Store", "Thumbs.db")  # what archivers add beside the files


def _sniff(path: Path, head: bytes) -> bool:
    return path.is_file() and packing_of(head) is not None


_nesting = threading.local()


def _ceiling(folder: Path) -> int:
    """What a file may unpack to: the ceiling, or less when the disk has less to spare."""
    return max(0, min(MAX_UNPACKED_BYTES, shutil.disk_usage(folder).free - SPARE_BYTES))


def _too_big(path: Path, packing: str, limit: int) -> ReaderError:
    return ReaderError(
        path, f"{packing} unpacks to more than {limit / 2**30:.1f} GiB (the ceiling, or what the disk spares): refused"
    )


def _copy(
    path: Path, packing: str, source: IO[bytes], target: IO[bytes], limit: int, written: int = 0
) -> tuple[int, str | None]:
    """Copy a stream, its total held under `limit`; (bytes written, the damage that stopped it or None)."""
    try:
        while piece := source.read(CHUNK):
            written += len(piece)
            if written > limit:
                raise _too_big(path, packing, limit)
            target.write(piece)
    except EOFError:
        return written, f"{packing} stream cut short: what came after the cut is lost"
    except (OSError, zlib.error, lzma.LZMAError, ValueError) as err:
        return written, f"{packing} stream damaged ({err}): what came after the damage is lost"
    return written, None


def _unpack_stream(path: Path, packing: str, folder: Path) -> tuple[Path, list[str]]:
    """A compressed stream's content as one file in `folder`, named as `path` without its suffix."""
    name = path.name
    for suffix in SUFFIXES:
        if name.endswith(suffix) and len(name) > len(suffix):
            name = name[: -len(suffix)] + (".tar" if suffix in (".tgz", ".tbz2", ".txz") else "")
            break
    inner = folder / (name if name != path.name else f"{name}.unpacked")
    losses: list[str] = []
    limit = _ceiling(folder)
    with inner.open("wb") as target:
        if packing == LZW_PACKING:
            data = expand_lzw(path, path.read_bytes(), limit, _too_big)
            target.write(data)
            written = len(data)
        else:
            with path.open("rb") as source:
                written, damage = inflate(path, packing, source, target, limit, _too_big)
            if damage:
                losses.append(damage)
    if not written:
        raise ReaderError(path, f"{packing} stream holds nothing" + (f" readable: {losses[0]}" if losses else ""))
    return inner, losses


def _safe_parts(name: str) -> tuple[str, ...] | None:
    """A member's path inside the folder, or None for one that would leave it or is an archiver's junk."""
    parts = tuple(p for p in PurePosixPath(name.replace("\\", "/")).parts if p not in ("", ".", "/"))
    if "\0" in name or not parts or ".." in parts or any(":" in p for p in parts) or any(p in JUNK for p in parts):
        return None
    return parts


def _member_target(folder: Path, packing: str, name: str, losses: list[str]) -> Path | None:
    """Where archive member `name` is written in `folder`, or None (the drop listed in `losses`) for a
    name that would leave it or is an archiver's own."""
    parts = _safe_parts(name)
    if parts is None:
        leaves = "its path would leave the archive's folder (or is an archiver's own)"
        losses.append(f"{packing} member {name!r} not unpacked: {leaves}")
        return None
    return folder.joinpath(*parts)


def _unpack_zip(path: Path, folder: Path) -> list[str]:
    losses: list[str] = []
    written, limit = 0, _ceiling(folder)
    try:
        archive = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as err:
        return _unpack_cut_zip(path, folder, f"{err}")
    with archive:
        for info in archive.infolist():
            if info.is_dir() or (target := _member_target(folder, "zip", info.filename, losses)) is None:
                continue
            try:
                target.parent.mkdir(parents=True, exist_ok=True)
                with archive.open(info) as source, target.open("wb") as out:
                    written, damage = _copy(path, "zip", source, out, limit, written)
            except (zipfile.BadZipFile, NotImplementedError, RuntimeError, OSError, EOFError, ValueError) as err:
                damage = f"zip member {info.filename!r} not read ({err})"  # damaged, encrypted, a name no file can have
            if damage:
                losses.append(damage)
    return losses


def _unpack_cut_zip(path: Path, folder: Path, why: str) -> list[str]:
    """A zip whose directory at its end is lost (cut short): its members read from their own headers."""
    if path.stat().st_size > CUT_ZIP_IN_MEMORY:
        raise ReaderError(path, f"zip archive damaged or cut short, its directory unreadable ({why})")
    found: list[str] = []
    losses: list[str] = []
    limit = min(CUT_ZIP_IN_MEMORY, _ceiling(folder))
    for name, body in zip_members(path, path.read_bytes(), limit, found, _too_big).items():
        if (target := _member_target(folder, "zip", name, losses)) is None:
            continue
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(body)
        except OSError as err:  # a name this file system cannot hold
            losses.append(f"zip member {name!r} not unpacked ({err})")
    return [*found, *losses]


def _unpack_tar(path: Path, folder: Path) -> list[str]:
    losses: list[str] = []
    written, limit = 0, _ceiling(folder)
    try:
        with tarfile.open(path, "r:") as archive:
            for member in archive:
                if member.isdir():
                    continue
                if (target := _member_target(folder, "tar", member.name, losses)) is None:
                    continue
                if not member.isfile():
                    losses.append(f"tar member {member.name!r} not unpacked (a link or a device: never made)")
                    continue
                source = archive.extractfile(member)
                if source is None:
                    continue
                try:
                    target.parent.mkdir(parents=True, exist_ok=True)
                    with target.open("wb") as out:
                        written, damage = _copy(path, "tar", source, out, limit, written)
                except OSError as err:  # a name this file system cannot hold, or a folder a member made a file
                    damage = f"tar member {member.name!r} not unpacked ({err})"
                if damage:
                    losses.append(damage)
    except (tarfile.TarError, OSError, EOFError, ValueError) as err:
        losses.append(f"tar archive damaged or cut short ({err}): the members after the damage are lost")
    return losses


def _what_to_read(path: Path, packing: str, folder: Path, losses: list[str]) -> Path:
    """The one log an archive holds: its only file or folder, else the folder it unpacked to as one log
    (a ROS2 bag's files, a folder of NMEA files); refused naming what it holds when it is none."""
    entries = sorted(folder.iterdir())
    if not entries:
        raise ReaderError(
            path, f"{packing} archive holds no file" + (f" readable: {'; '.join(losses)}" if losses else "")
        )
    if len(entries) == 1:
        return entries[0]
    return folder


def _unpacked(path: Path, folder: Path) -> tuple[str, Path, list[str]]:
    with path.open("rb") as f:
        packing = packing_of(f.read(512))
    if packing is None:  # changed since it was sniffed
        raise ReaderError(path, "no longer a packed file")
    if packing == "zip":
        losses = _unpack_zip(path, folder)
    elif packing == "tar":
        losses = _unpack_tar(path, folder)
    else:
        inner, losses = _unpack_stream(path, packing, folder)
        return packing, inner, losses
    return packing, _what_to_read(path, packing, folder, losses), losses


def _several(packing: str, folder: Path, problem: str) -> str:
    """Why an archive of several files is no one log: the logs it holds, else the reader's reason."""
    from readers import separate_logs

    logs = separate_logs(folder, None)
    if not logs:
        return f"{packing} of several files: {problem}"
    listed = ", ".join(f"{p.name} ({fmt})" for p, fmt in logs[:4]) + (" ..." if len(logs) > 4 else "")
    return f"{packing} of {len(logs)} separate logs, not one: {listed}; unpack it and analyse each"


@dataclass(frozen=True)
class Unpacked:
    """A packed file's content laid out in a temporary folder: the one log to read (the folder itself for
    an archive of several files), its packing, what unpacking lost."""

    log: Path
    packing: str
    losses: tuple[str, ...]
    folder: Path

    @property
    def label(self) -> str:
        """How it was packed, and the log inside when that is one file or folder: "zip (logs/r4.log)"."""
        return (
            self.packing
            if self.log == self.folder
            else f"{self.packing} ({self.log.relative_to(self.folder).as_posix()})"
        )


@contextmanager
def unpacked(path: Path) -> Iterator[Unpacked]:
    """`path` unpacked (see the module) for the block's length; the folder is removed after it."""
    depth = getattr(_nesting, "depth", 0)
    if depth >= MAX_DEPTH:
        raise ReaderError(path, f"packed {depth + 1} times over (an archive that holds itself?): not unpacked further")
    folder = Path(tempfile.mkdtemp(prefix="spooflens-unpacked-"))
    _nesting.depth = depth + 1
    try:
        packing, inner, losses = _unpacked(path, folder)
        yield Unpacked(inner, packing, tuple(losses), folder)
    finally:
        _nesting.depth = depth
        shutil.rmtree(folder, ignore_errors=True)


def read_packed(path: Path, topics: Mapping[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    """Read the log inside a packed file (see the module), as its own format's reader reads it."""
    from readers import read_log

    path = Path(path)
    with unpacked(path) as content:
        try:
            table = read_log(content.log, topics, progress)
        except ReaderError as err:
            problem = err.problem.replace(str(content.folder), path.name)
            where = (
                f"{content.label}: {problem}"
                if content.log != content.folder
                else _several(content.packing, content.folder, problem)
            )
            if content.losses:
                where += f" ({'; '.join(content.losses)})"
            raise type(err)(path, where, err.stream) from err
    table.source = path
    table.metadata = {**table.metadata, "packing": content.label}
    note = f"read as shipped: {content.label}, unpacked to a temporary folder"
    lost = [Skipped(path.name, loss, 1, "lost") for loss in content.losses]
    table.skipped = [*table.skipped, Skipped(path.name, note, 1, "unpacked"), *lost]
    return table


FORMATS = (
    ReaderFormat(
        "packed",
        "every format here inside gzip, bzip2, xz, Unix compress (.Z), zip or tar (flight.ulg.gz, a zipped ROS2 bag)",
        read_packed,
        _sniff,
        rewrite="spooflens.writers.rewrite:rewrite_packed",
    ),
)
