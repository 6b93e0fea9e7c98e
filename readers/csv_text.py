"""CSV text as every CSV reader here meets it: header comments, the clock comment, and the rows.

Shared by the spooflens CSV log, the PX4 CSV dialect and the truth file beside a log. The rows are read
in two passes that both stream (a file of millions of rows never sits in memory as text or as Python
objects): a byte scan counts each line's fields, so a row cut short, a garbage line, a row with
extra fields or a file cut in the middle of its last row is found and counted as lost instead of being
padded with NaN or silently dropped; then pandas parses the good lines in chunks, each column turned
into numbers (a value that is not a number becomes NaN, counted by the caller) unless it is a text
column.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from spooflens.epoch_table import Skipped
from spooflens.errors import ReaderError

SCAN_BLOCK = 1 << 24  # bytes scanned at a time
CHUNK_ROWS = 250_000  # rows parsed at a time
# the latest absolute start a `# t0_ns:` may give: 2100-01-01 in UNIX (or GPS) nanoseconds
MAX_T0_NS = 4_102_444_800_000_000_000
_INT = re.compile(r"[+]?\d+")


def header_comments(path: Path) -> dict[str, str]:
    """`# key: value` lines before the header row, keys lower-cased."""
    meta: dict[str, str] = {}
    with path.open(encoding="utf-8", errors="replace") as f:
        for line in f:
            if not line.startswith("#"):
                break
            key, sep, value = line[1:].partition(":")
            if sep:
                meta[key.strip().lower()] = value.strip()
    return meta


def parse_t0_ns(path: Path, text: str, stream: str | None = None) -> int:
    """The value of a `# t0_ns:` comment: whole nanoseconds from 0 to 2100-01-01, else ReaderError."""
    value = text.strip()
    if not _INT.fullmatch(value) or int(value) > MAX_T0_NS:
        raise ReaderError(
            path,
            f"# t0_ns: {value[:40]!r} is not a whole number of nanoseconds from 0 to {MAX_T0_NS} (2100-01-01)",
            stream,
        )
    return int(value)


@dataclass
class Layout:
    """What the byte scan found: where the header is and which lines to leave out."""

    header_line: int = -1  # 0-based line number of the header row
    names: list[str] = field(default_factory=list)
    skip: set[int] = field(default_factory=set)  # comments, blank lines, bad rows (0-based line numbers)
    bad_fields: int = 0  # rows whose field count is not the header's (garbage, rows cut short)
    cut_last_row: bool = False  # the file ends in the middle of a row
    rows: int = 0  # good data rows


def scan(path: Path) -> Layout:
    """Count the fields of every line, in blocks of bytes (no line is ever a Python object)."""
    out = Layout()
    fields = 0
    line_no = 0  # line number of the first line starting in the current block
    carry = b""  # a line that started in the previous block
    recent = np.zeros(0, dtype=np.int64)  # lengths of the last good rows
    with path.open("rb") as f:
        while True:
            block = f.read(SCAN_BLOCK)
            data = carry + block
            if not data:
                break
            arr = np.frombuffer(data, dtype=np.uint8)
            ends = np.flatnonzero(arr == 10)
            last_block = not block
            if last_block and (not len(ends) or ends[-1] != len(arr) - 1):
                ends = np.append(ends, len(arr))  # the last line, without its newline
                out.cut_last_row = True
            if not len(ends):
                carry = data
                continue
            starts = np.concatenate(([0], ends[:-1] + 1))
            commas = np.flatnonzero(arr == 44)
            n_commas = np.searchsorted(commas, ends) - np.searchsorted(commas, starts)
            lengths = ends - starts
            nonempty = lengths > 0
            lengths[nonempty] -= arr[ends[nonempty] - 1] == 13  # a CRLF line's CR
            first = np.zeros(len(ends), dtype=np.uint8)
            first[nonempty] = arr[starts[nonempty]]
            comment = first == ord("#")
            blank = lengths <= 0
            numbers = line_no + np.arange(len(ends))
            out.skip.update(numbers[comment | blank].tolist())
            after = np.ones(len(ends), dtype=bool)
            if out.header_line < 0:
                candidates = np.flatnonzero(~comment & ~blank)
                after[:] = False
                if len(candidates):
                    h = int(candidates[0])
                    out.header_line = int(numbers[h])
                    raw = bytes(data[starts[h] : starts[h] + lengths[h]])
                    out.names = [n.strip() for n in raw.decode("utf-8", "replace").split(",")]
                    fields = len(out.names)
                    after[h + 1 :] = True
            rows = after & ~comment & ~blank
            wrong = rows & (n_commas != fields - 1)
            out.skip.update(numbers[wrong].tolist())
            out.bad_fields += int(wrong.sum())
            out.rows += int((rows & ~wrong).sum())
            if out.cut_last_row and not wrong[-1]:
                # all fields there and no final newline: a hand-made file, unless the row is clearly
                # shorter than its neighbours (cut inside its last field)
                others = np.concatenate((recent, lengths[rows & ~wrong][:-1]))[-100:]
                if len(others) and lengths[-1] < 0.9 * float(np.median(others)):
                    out.skip.add(int(numbers[-1]))
                    out.bad_fields += 1
                    out.rows -= 1
                else:
                    out.cut_last_row = False
            recent = np.concatenate((recent, lengths[rows & ~wrong]))[-100:]
            line_no += len(ends)
            carry = b"" if last_block else bytes(data[ends[-1] + 1 :])
            if last_block:
                break
    return out


def read_rows(
    path: Path,
    skipped: list[Skipped],
    keep: Callable[[str], bool] = lambda name: True,
    text_columns: Iterable[str] = (),
    stream: str | None = None,
) -> pd.DataFrame:
    """The data rows of a CSV: the columns `keep` accepts, numbers (NaN where a cell is not one) except
    `text_columns` (stripped strings). Rows with the wrong number of fields and a last row cut short are
    left out and listed in `skipped` as lost; an unreadable file raises ReaderError."""
    label = stream or path.name
    try:
        layout = scan(path)
    except OSError as err:
        raise ReaderError(path, f"cannot read: {err}", stream) from err
    if layout.header_line < 0:
        raise ReaderError(path, "no header row (the file holds only comments or blank lines)", stream)
    if layout.bad_fields:
        what = f"rows whose number of fields is not the header's {len(layout.names)} (garbage or cut short)"
        if layout.cut_last_row:
            what += "; the file ends in the middle of its last row"
        skipped.append(Skipped(label, what, layout.bad_fields, "lost"))
    if not layout.rows:
        raise ReaderError(path, "CSV has a header but no rows", stream)
    text = set(text_columns)
    wanted = [n for n in dict.fromkeys(layout.names) if keep(n)]
    # numbers go straight into arrays of the final length (the scan counted the rows); text stays in
    # pandas' Arrow-backed strings, a few bytes a value
    numbers = {n: np.full(layout.rows, np.nan) for n in wanted if n not in text}
    strings: dict[str, list[pd.Series]] = {n: [] for n in wanted if n in text}
    filled = 0
    try:
        chunks = pd.read_csv(
            path,
            skiprows=layout.skip | set(range(layout.header_line)),
            header=0,
            usecols=lambda n: str(n).strip() in wanted,
            skipinitialspace=True,
            dtype={n: str for n in strings},
            chunksize=CHUNK_ROWS,
            encoding_errors="replace",
            on_bad_lines="skip",
            skip_blank_lines=False,
            engine="c",
        )
        for chunk in chunks:
            chunk.columns = [str(c).strip() for c in chunk.columns]
            chunk = chunk.loc[:, ~chunk.columns.duplicated()]
            m = min(len(chunk), layout.rows - filled)
            for name, out in numbers.items():
                if name in chunk.columns:
                    out[filled : filled + m] = _numbers(chunk[name])[:m]
            for name, parts in strings.items():
                col = chunk[name] if name in chunk.columns else pd.Series("", index=chunk.index)
                parts.append(col.astype("string").str.strip().fillna("").iloc[:m])
            filled += m
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, ValueError, OverflowError) as err:
        raise ReaderError(path, f"not a readable CSV: {err}", stream) from err
    columns: dict[str, object] = {n: v[:filled] for n, v in numbers.items()}
    columns |= {n: pd.concat(v, ignore_index=True) if v else pd.Series([], dtype="string") for n, v in strings.items()}
    return pd.DataFrame({n: columns[n] for n in wanted}, copy=False)


def _numbers(col: pd.Series) -> np.ndarray:
    """A column as float64: true/false as 1/0, anything that is not a number as NaN."""
    if pd.api.types.is_numeric_dtype(col.dtype) and not pd.api.types.is_bool_dtype(col.dtype):
        return col.to_numpy(dtype=np.float64, na_value=np.nan)
    s = col.astype("string").str.strip()
    low = s.str.lower()
    s = s.mask(low == "true", "1").mask(low == "false", "0")
    return np.asarray(pd.to_numeric(s, errors="coerce"), dtype=np.float64)
