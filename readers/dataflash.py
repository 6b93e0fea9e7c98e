"""ArduPilot DataFlash binary logs, decoded column-wise.

pymavlink's `DFReader_binary` finds the messages (its indexer re-synchronises on the A3 95 header
after damage) and parses the FMT/FMTU records; the rows of each message type are then cut out of the
file's bytes and viewed through a numpy structured dtype built from the FMT format string, so a long
log decodes at numpy speed, not one Python object per message. Format letters carry pymavlink's
multipliers (`c`/`C`/`e`/`E` x 0.01, `L` x 1e-7). Nothing in the file is executed: only FMT strings
are interpreted, through pymavlink's fixed table of format letters.
"""

from __future__ import annotations

import contextlib
import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from pymavlink.DFReader import FORMAT_TO_STRUCT, DFReader_binary

from spooflens.epoch_table import Skipped
from spooflens.errors import ReaderError

HEADER = b"\xa3\x95\x80"  # every DataFlash binary log starts with the FMT of FMT
Columns = dict[str, NDArray]


@dataclass
class DataFlash:
    """The decodable content of one log: message name -> column arrays, plus what was lost."""

    path: Path
    data: bytes
    reader: DFReader_binary
    skipped: list[Skipped] = field(default_factory=list)
    _cache: dict[str, Columns | None] = field(default_factory=dict)

    def names(self) -> set[str]:
        return {n for n, t in self.reader.name_to_id.items() if self.reader.counts[t] > 0}

    def count(self, name: str) -> int:
        t = self.reader.name_to_id.get(name)
        return 0 if t is None else int(self.reader.counts[t])

    def offsets(self, name: str) -> NDArray[np.int64]:
        t = self.reader.name_to_id[name]
        return np.asarray(self.reader.offsets[t], dtype=np.int64)

    def columns(self, name: str) -> Columns | None:
        """Every row of message `name` as arrays (strings as bytes), or None if the log has none."""
        if name not in self._cache:
            self._cache[name] = self._decode(name)
        return self._cache[name]

    def dtype(self, name: str) -> tuple[np.dtype, dict[str, float]]:
        """The structured dtype of a message body and the multiplier of each scaled column."""
        fmt = self.reader.formats[self.reader.name_to_id[name]]
        if len(fmt.columns) != len(fmt.format):
            raise ValueError(f"FMT of {name} has {len(fmt.columns)} columns for {len(fmt.format)} format letters")
        names, formats, scale = [], [], {}
        for col, letter in zip(fmt.columns, fmt.format, strict=True):
            code, mult, _ = FORMAT_TO_STRUCT[letter]
            if letter == "a":
                np_type: object = ("<i2", (32,))
            elif code.endswith("s"):
                np_type = f"S{code[:-1]}"
            else:
                np_type = "<" + code
            names.append(col)
            formats.append(np_type)
            if mult is not None:
                scale[col] = mult
        dt = np.dtype({"names": names, "formats": formats})  # packed, as struct "<..." is
        if dt.itemsize != fmt.len - 3:
            raise ValueError(f"FMT of {name} says {fmt.len - 3} bytes, its format string {dt.itemsize}")
        return dt, scale

    def _decode(self, name: str) -> Columns | None:
        if self.count(name) == 0:
            return None
        try:
            dt, scale = self.dtype(name)
        except (KeyError, ValueError) as err:
            self.skipped.append(Skipped(name, f"message format unusable: {err}", self.count(name), "lost"))
            return None
        ofs = self.offsets(name)
        whole = ofs + 3 + dt.itemsize <= len(self.data)
        if not whole.all():
            self.skipped.append(Skipped(name, "message cut off at the end of the file", int((~whole).sum()), "lost"))
            ofs = ofs[whole]
        buf = np.frombuffer(self.data, dtype=np.uint8)
        rows = buf[ofs[:, None] + 3 + np.arange(dt.itemsize)].view(dt).ravel()
        out: Columns = {}
        for col in dt.names or ():
            values = rows[col]
            if col in scale:
                # dividing by 100 or 1e7 rounds like pymavlink (and like the autopilot's own tools)
                values = values.astype(np.float64) / round(1.0 / scale[col])
            out[col] = values
        return out

    def strings(self, name: str, column: str) -> list[str]:
        cols = self.columns(name)
        if cols is None or column not in cols:
            return []
        return [v.split(b"\0", 1)[0].decode("utf-8", errors="replace") for v in cols[column]]


_BAD = re.compile(r"bad header|Skipped (\d+) bad bytes|unknown msg type")


def open_dataflash(path: Path) -> DataFlash:
    """Index a DataFlash log with pymavlink (its console chatter captured and counted, never printed)."""
    chatter = io.StringIO()
    try:
        data = path.read_bytes()
        with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
            reader = DFReader_binary(str(path))
    except OSError as err:
        raise ReaderError(path, f"cannot read: {err.strerror or err}") from err
    except Exception as err:  # pymavlink raises bare Exception for an unknown format letter
        raise ReaderError(path, f"not a readable DataFlash log: {type(err).__name__}: {err}") from err
    log = DataFlash(path, data, reader)
    bad = [m for m in _BAD.finditer(chatter.getvalue())]
    if bad:
        log.skipped.append(
            Skipped(
                "<dataflash>", "corrupt bytes between messages; re-synchronised on the next header", len(bad), "lost"
            )
        )
    if "unknown msg type" in chatter.getvalue():
        log.skipped.append(
            Skipped("<dataflash>", "a message of undefined type: pymavlink's index stops there", 1, "lost")
        )
    return log


def is_dataflash(head: bytes) -> bool:
    return head.startswith(HEADER)
