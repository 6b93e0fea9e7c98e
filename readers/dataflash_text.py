"""ArduPilot DataFlash logs as text (Mission Planner / APM Planner `.log`), decoded column-wise.

Mission Planner and APM Planner save a DataFlash log as text, one message a line: `NAME, v1, v2, ...`
(some files `NAME,v1,v2`), the FMT lines first defining each message's fields (`FMT, 130, 45, GPS,
BIHBcLLeeEefI, Status,TimeMS,...`). Values are written as the log shows them: scaled fields already
scaled (`L` in degrees, `c`/`C`/`e`/`E` divided by 100), strings as text.

The lines are grouped by message name and each type's fields converted a column at a time with numpy,
into the same arrays, dtypes and units the binary reader (`readers.dataflash`) produces; a `DataFlash`
over them (`TextDataFlash`) then does everything else the binary path does (today's names of every
revision, boot time of untimed messages from the message logged before them, plausibility). Each row's
`_ofs` is the byte offset of its line in the file, so file order is kept and `inject` can rewrite the line.

Damaged lines (too few or too many fields, text where a number belongs, a type no FMT defines, binary
junk, a last line cut without its newline) are skipped and counted per message type; the rest is read.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from pymavlink.DFReader import FORMAT_TO_STRUCT, DFFormat

from readers.dataflash import Columns, DataFlash, open_dataflash
from spooflens.epoch_table import Skipped
from spooflens.errors import ReaderError

BOM = b"\xef\xbb\xbf"
STREAM = "<ardupilot_text>"
FMT_COLUMNS = "Type,Length,Name,Format,Columns"
_NAME = re.compile(rb"[A-Za-z0-9_]{1,4}")
_FMT_OF_FMT = re.compile(rb"^[ \t]*FMT,\s?128\s*,", re.MULTILINE)
# Mission Planner writes what the board's CLI printed before the log when it downloads one over the
# console (APM 2.x, 2012-2014): `1`, `ArduCopter V3.0.1 (5c6503e2)`, `Free RAM: 1331`, `ArduPilot 2`
_BANNER_LINE = re.compile(rb"[ -~\t\r]{0,120}")
MAX_BANNER_LINES = 16
STRING_LETTERS = "nNZ"


def log_start(head: bytes) -> int | None:
    """Offset of the FMT of FMT (`FMT, 128, ...`) that opens a text DataFlash log in `head` (its first
    bytes), after a BOM and at most `MAX_BANNER_LINES` short lines of plain text; None when it does not."""
    start = len(BOM) if head.startswith(BOM) else 0
    found = _FMT_OF_FMT.search(head[start:])
    if found is None:
        return None
    banner = head[start : start + found.start()].split(b"\n")[:-1]
    if len(banner) > MAX_BANNER_LINES or not all(_BANNER_LINE.fullmatch(line) for line in banner):
        return None
    return start + found.start()


def is_dataflash_text(head: bytes) -> bool:
    """The log opens with the FMT of FMT, `FMT, 128, ...` (after a BOM, blank lines or a download banner)."""
    return log_start(head) is not None


@dataclass
class TextIndex:
    """What `DataFlash` asks of pymavlink's index, for a text log: the formats by type id, and per type
    the offsets (line starts) of its well-formed lines."""

    formats: dict[int, DFFormat] = field(default_factory=dict)
    name_to_id: dict[str, int] = field(default_factory=dict)
    counts: dict[int, int] = field(default_factory=dict)
    offsets: dict[int, list[int]] = field(default_factory=dict)


@dataclass
class TextDataFlash(DataFlash):
    """A text DataFlash log: `data` is the file, `fields[name]` each well-formed line's values (bytes)."""

    fields: dict[str, list[list[bytes]]] = field(default_factory=dict)
    delimiter: str = ", "

    def logged(self, name: str) -> tuple[NDArray[np.int64], Columns] | None:
        layout = self.usable_dtype(name)
        if layout is None:
            return None
        dt, scale = layout
        ofs = self.offsets(name)
        rows = self.fields[name]
        table = np.array(rows, dtype=object).reshape(len(rows), len(dt.names or ()))
        good = np.ones(len(rows), dtype=bool)
        converted: Columns = {}
        for k, col in enumerate(dt.names or ()):
            values, ok = _column(table[:, k], dt.fields[col][0] if dt.fields else None, col in scale)  # type: ignore[index]
            converted[col] = values
            good &= ok
        if not good.all():
            reason = "a field that is not a number where the format has one"
            self.skipped.append(Skipped(name, reason, int((~good).sum()), "lost"))
            converted = {k: v[good] for k, v in converted.items()}
            ofs = ofs[good]
        return ofs, converted


def _column(raw: NDArray, dtype: np.dtype | None, scaled: bool) -> tuple[NDArray, NDArray[np.bool_]]:
    """One column's text values as the binary reader's array (scaled fields float64, already in the log's
    units), and which rows held a value of that type."""
    n = len(raw)
    ok = np.ones(n, dtype=bool)
    if dtype is None or dtype.subdtype is not None:  # `a` (int16[32]): read as its text, not used by spooflens
        return np.array([v.strip() for v in raw], dtype=object), ok
    if dtype.kind == "S":
        return np.array([v.strip() for v in raw], dtype=dtype), ok
    target = np.dtype(np.float64) if scaled else dtype
    try:
        return np.array(raw.tolist(), dtype=bytes).astype(target), ok
    except (ValueError, OverflowError):
        pass
    out = np.zeros(n, dtype=target)
    for i, v in enumerate(raw):
        try:
            out[i] = np.array([v]).astype(target)[0]
        except (ValueError, OverflowError):
            ok[i] = False
    return out, ok


def _fmt_of(fields: list[bytes]) -> tuple[str, DFFormat] | str:
    """(name, format) of an FMT line's fields (Type, Length, Name, Format, Columns...), or why it is unusable."""
    if len(fields) < 4:
        return "FMT line with too few fields"
    try:
        ftype = int(fields[0])
        name = fields[2].strip().decode("ascii")
        letters = fields[3].strip().decode("ascii")
        columns = ",".join(c.strip().decode("ascii") for c in fields[4:])
    except (ValueError, UnicodeDecodeError):
        return "FMT line with an unreadable type, name, format or columns"
    if name == "FMT" and columns == "Type,Length,Name,Format":  # some text logs drop FMT's last column name
        columns = FMT_COLUMNS
    if not _NAME.fullmatch(name.encode()) or any(c not in FORMAT_TO_STRUCT for c in letters):
        return f"FMT line with an unusable name or format letters ({name!r}, {letters!r})"
    names = columns.split(",") if columns else []  # a message with no fields (STRT in 2015) has none
    if len(names) != len(letters):
        return f"FMT of {name} names {len(names)} columns for {len(letters)} format letters"
    size = 3 + struct.calcsize("<" + "".join(FORMAT_TO_STRUCT[c][0] for c in letters))
    return name, DFFormat(ftype, name, size, letters, columns)


def open_text_dataflash(path: Path) -> TextDataFlash:
    """Read and index a text DataFlash log; refuses a file with no FMT line in one line (ReaderError)."""
    try:
        data = path.read_bytes()
    except OSError as err:
        raise ReaderError(path, f"cannot read: {err.strerror or err}") from err
    opening = log_start(data[:4096])
    start = opening if opening is not None else len(BOM) if data.startswith(BOM) else 0
    banner = [
        line.strip().decode("ascii", "replace") for line in data[:start].removeprefix(BOM).split(b"\n") if line.strip()
    ]
    lines = data[start:].split(b"\n")
    cut = lines.pop() if lines else b""  # what follows the last newline: a line cut short, or nothing
    grouped: dict[bytes, tuple[list[int], list[list[bytes]]]] = {}
    junk = 0
    ofs = start
    for line in lines:
        here = ofs
        ofs += len(line) + 1
        parts = line.rstrip(b"\r").split(b",")
        tag = parts[0].strip()
        if not tag and len(parts) == 1:  # a blank line: nothing lost
            continue
        if not _NAME.fullmatch(tag):
            junk += 1
            continue
        entry = grouped.setdefault(tag, ([], []))
        entry[0].append(here)
        entry[1].append(parts[1:])
    if not grouped.get(b"FMT"):
        raise ReaderError(path, "no FMT line: not an ArduPilot DataFlash text log")
    skipped: list[Skipped] = []
    if banner:
        what = f"line of text before the log's first FMT (a ground station's download banner: {' / '.join(banner[:4])})"
        skipped.append(Skipped(STREAM, what, len(banner), "skipped"))
    if junk:
        skipped.append(Skipped(STREAM, "line that is not a message (binary junk or damaged text)", junk, "lost"))
    if cut.strip(b"\r\n\t \0"):
        cut_name = cut.split(b",", 1)[0].strip()
        stream = cut_name.decode("ascii") if _NAME.fullmatch(cut_name) else STREAM
        skipped.append(Skipped(stream, "line cut off at the end of the file (no newline)", 1, "lost"))
    formats: dict[str, DFFormat] = {"FMT": DFFormat(128, "FMT", 89, "BBnNZ", FMT_COLUMNS)}
    bad_fmt = 0
    for fields in grouped[b"FMT"][1]:
        found = _fmt_of(fields)
        if isinstance(found, str):
            bad_fmt += 1
        elif found[0] not in formats:
            formats[found[0]] = found[1]
    if bad_fmt:
        skipped.append(Skipped("FMT", "unusable message format definition", bad_fmt, "lost"))
    index = TextIndex()
    used: set[int] = set()
    per_name: dict[str, list[list[bytes]]] = {}
    for raw_name, (offsets, rows) in grouped.items():
        name = raw_name.decode("ascii")
        fmt = formats.get(name)
        if fmt is None:
            skipped.append(Skipped(name, "no FMT line defines this message type", len(rows), "lost"))
            continue
        width = len(fmt.format)
        kept_ofs, kept = [], []
        short = long = 0
        for o, r in zip(offsets, rows, strict=True):
            if width == 0 and not b"".join(r).strip():  # a message with no fields: `STRT` or `STRT, `
                r = []
            elif len(r) > width and fmt.format[-1] in STRING_LETTERS:  # a string last: its commas are text
                r = [*r[: width - 1], b",".join(r[width - 1 :])]
            if len(r) == width:
                kept_ofs.append(o)
                kept.append(r)
            elif len(r) < width:
                short += 1
            else:
                long += 1
        for n, what in ((short, "too few"), (long, "too many")):
            if n:
                skipped.append(Skipped(name, f"line with {what} fields for its FMT ({width})", n, "lost"))
        t = fmt.type if 0 <= fmt.type < 256 and fmt.type not in used else 256 + len(index.formats)
        used.add(t)
        index.formats[t] = fmt
        index.name_to_id[name] = t
        index.counts[t] = len(kept)
        index.offsets[t] = kept_ofs
        per_name[name] = kept
    delimiter = ", " if b", " in data[start : start + 200] else ","
    return TextDataFlash(  # type: ignore[arg-type]
        path, data, index, skipped=skipped, fields=per_name, delimiter=delimiter, banner=banner
    )


def open_any_dataflash(path: Path) -> DataFlash:
    """A DataFlash log, binary or text, by its content."""
    with Path(path).open("rb") as f:
        head = f.read(4096)
    return open_text_dataflash(path) if is_dataflash_text(head) else open_dataflash(path)
