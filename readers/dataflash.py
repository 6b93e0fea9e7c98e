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
import os
import re
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from pymavlink.DFReader import FORMAT_TO_STRUCT, DFReader_binary

from readers.dataflash_eras import is_gps_message, with_todays_names
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
    _incomplete: set[str] = field(default_factory=set)
    notes: dict[str, str] = field(default_factory=dict)  # how a revision's fields were read, for the metadata
    on_receiver_clock: set[str] = field(default_factory=set)  # GPS messages timed by their own time of week
    banner: list[str] = field(default_factory=list)  # text before a text log's first FMT (the board's banner)

    @property
    def sdlog2(self) -> bool:
        """A PX4 sdlog2 log (`.px4log`): the same container, PX4's messages, timed by `TIME.StartTime`."""
        t = self.reader.name_to_id.get("TIME")
        return t is not None and "StartTime" in self.reader.formats[t].columns

    def names(self) -> set[str]:
        return {n for n, t in self.reader.name_to_id.items() if self.reader.counts[t] > 0}

    def count(self, name: str) -> int:
        t = self.reader.name_to_id.get(name)
        return 0 if t is None else int(self.reader.counts[t])

    def offsets(self, name: str) -> NDArray[np.int64]:
        t = self.reader.name_to_id[name]
        return np.asarray(self.reader.offsets[t], dtype=np.int64)

    def plausible(self, name: str, time_us: NDArray[np.int64]) -> NDArray[np.bool_]:
        """Rows whose TimeUS fits the rest of the type's rows (a flipped byte can make it years off)."""
        if len(time_us) < 3:
            return np.ones(len(time_us), dtype=bool)
        lo, hi = np.percentile(time_us, [5, 95])
        margin = (hi - lo) + 600e6
        ok = (time_us >= lo - margin) & (time_us <= hi + margin)
        if not ok.all():
            self.skipped.append(Skipped(name, "implausible TimeUS (corrupt message)", int((~ok).sum()), "lost"))
        return np.asarray(ok)

    def columns(self, name: str, required: tuple[str, ...] = ()) -> Columns | None:
        """Every row of message `name` as arrays (strings as bytes), or None if the log has none; `_ofs` is
        each row's offset in the file. A message whose FMT lacks a `required` field (a damaged FMT text
        renames columns) is lost, counted once, rather than read without it."""
        if name not in self._cache:
            self._cache[name] = self._decode(name)
        cols = self._cache[name]
        missing = [f for f in required if cols is not None and f not in cols]
        if missing:
            if name not in self._incomplete:
                self._incomplete.add(name)
                reason = f"message format lacks field(s) {', '.join(missing)} (damaged FMT)"
                if missing == ["TimeUS"]:
                    reason = "this revision's message carries no time, and nothing in the log places it"
                self.skipped.append(Skipped(name, reason, self.count(name), "lost"))
            return None
        return cols

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
                # by size ('<u8', not '<Q'): numpy's long long is a type of its own beside its uint64, which
                # pandas cannot join on
                np_type = np.dtype("<" + code).str
            names.append(col)
            formats.append(np_type)
            if mult is not None:
                scale[col] = mult
        dt = np.dtype({"names": names, "formats": formats})  # packed, as struct "<..." is
        if dt.itemsize != fmt.len - 3:
            raise ValueError(f"FMT of {name} says {fmt.len - 3} bytes, its format string {dt.itemsize}")
        return dt, scale

    def usable_dtype(self, name: str) -> tuple[np.dtype, dict[str, float]] | None:
        """`dtype(name)`, or None with the message's rows counted as lost when its format is unusable."""
        try:
            return self.dtype(name)
        except (KeyError, ValueError) as err:
            self.skipped.append(Skipped(name, f"message format unusable: {err}", self.count(name), "lost"))
            return None

    def logged(self, name: str) -> tuple[NDArray[np.int64], Columns] | None:
        """(offset of each row, its fields as logged: the FMT's column names, scaled fields in the units the
        log shows, e.g. degrees for `L`) of every readable row of message `name`, in file order; None when
        its format is unusable (counted). The only part of the decoding that depends on the container."""
        layout = self.usable_dtype(name)
        if layout is None:
            return None
        dt, scale = layout
        ofs = self.offsets(name)
        whole = ofs + 3 + dt.itemsize <= len(self.data)
        if not whole.all():
            self.skipped.append(Skipped(name, "message cut off at the end of the file", int((~whole).sum()), "lost"))
            ofs = ofs[whole]
        buf = np.frombuffer(self.data, dtype=np.uint8)
        rows = buf[ofs[:, None] + 3 + np.arange(dt.itemsize)].view(dt).ravel()
        logged: Columns = {}
        for col in dt.names or ():
            values = rows[col]
            if col in scale:
                # dividing by 100 or 1e7 rounds like pymavlink (and like the autopilot's own tools)
                values = values.astype(np.float64) / round(1.0 / scale[col])
            logged[col] = values
        return ofs, logged

    def _decode(self, name: str) -> Columns | None:
        if self.count(name) == 0:
            return None
        found = self.logged(name)
        if found is None:
            return None
        ofs, logged = found
        sdlog2 = self.sdlog2
        cols, timed = with_todays_names(logged, sdlog2)
        if not timed and len(ofs):
            board = self.board_time_before(ofs, exclude=name)
            if board is not None:
                cols["TimeUS"] = board
                self.notes[f"{name}.TimeUS"] = (
                    "PX4 sdlog2: the StartTime of the TIME message logged before each"
                    if sdlog2
                    else "no boot time in this revision's message: the boot time of the message logged before each"
                )
            elif "GMS" in cols:  # nothing in the log has a boot clock: the receiver's time of week is the clock
                cols["TimeUS"] = cols["GMS"].astype(np.int64) * 1000
                self.on_receiver_clock.add(name)
                self.notes[f"{name}.TimeUS"] = "no boot clock in this revision's log: the receiver's time of week"
        out: Columns = {"_ofs": ofs}  # where each row sits in the file
        keep = self.plausible(name, cols["TimeUS"].astype(np.int64)) if "TimeUS" in cols else None
        for col, values in cols.items():
            out[col] = values
        if keep is not None and not keep.all():
            out = {k: v[keep] for k, v in out.items()}
        return out

    def board_time_before(self, ofs: NDArray[np.int64], exclude: str) -> NDArray[np.int64] | None:
        """Boot time (us) of the timed message written last before each offset in `ofs`: the clock of
        messages that carry none (a 2013 GPS message), within the logging loop's period. The timed type
        logged most often is the reference (the IMU in every revision; TIME, the only timed one, in sdlog2)."""
        clocks = {"TimeUS", "TimeMS", "StartTime"}
        timed = [
            n
            for n in self.names()
            if n != exclude and clocks & set(self.reader.formats[self.reader.name_to_id[n]].columns)
        ]
        for ref in sorted(timed, key=self.count, reverse=True):
            cols = self.columns(ref)
            if cols is None or "TimeUS" not in cols or not len(cols["TimeUS"]) or is_gps_message(cols):
                continue
            order = np.argsort(cols["_ofs"], kind="stable")
            k = np.searchsorted(cols["_ofs"][order], ofs) - 1
            t = cols["TimeUS"][order].astype(np.int64)
            return np.where(k >= 0, t[np.clip(k, 0, None)], t[0])
        return None

    def strings(self, name: str, column: str) -> list[str]:
        cols = self.columns(name)
        if cols is None or column not in cols:
            return []
        return [v.split(b"\0", 1)[0].decode("utf-8", errors="replace") for v in cols[column]]


@contextlib.contextmanager
def _captured_output() -> Iterator[list[str]]:
    """Capture what pymavlink prints, from Python and from its compiled indexer (file descriptors 1, 2)."""
    out: list[str] = []
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        try:
            os.dup2(tmp.fileno(), 1)
            os.dup2(tmp.fileno(), 2)
            yield out
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
            tmp.seek(0)
            out.append(tmp.read().decode("utf-8", errors="replace"))


def _resume_index(log: DataFlash, start: int) -> int:
    """Index the messages after `start`, where pymavlink's indexer stopped at a message of undefined type.

    Walks message by message with the lengths of the formats the log defined, skipping to the next
    A3 95 + known type after anything else. Returns how many messages it found.
    """
    r, data = log.reader, log.data
    buf = np.frombuffer(data, dtype=np.uint8)
    lengths = {t: f.len for t, f in r.formats.items() if f.len > 3}
    known = np.zeros(256, dtype=bool)
    known[list(lengths)] = True
    head = buf[start:]
    cand = np.flatnonzero((head[:-2] == 0xA3) & (head[1:-1] == 0x95) & known[head[2:]]) + start
    found = 0
    pos = int(cand[0]) if len(cand) else len(data)
    while pos + 3 <= len(data):
        t = data[pos + 2]
        if data[pos] == 0xA3 and data[pos + 1] == 0x95 and t in lengths and pos + lengths[t] <= len(data):
            r.offsets[t].append(pos)
            r.counts[t] += 1
            found += 1
            pos += lengths[t]
            continue
        k = int(np.searchsorted(cand, pos + 1))
        if k >= len(cand):
            break
        pos = int(cand[k])
    return found


def open_dataflash(path: Path) -> DataFlash:
    """Index a DataFlash log with pymavlink (its console chatter captured and counted, never printed)."""
    try:
        data = path.read_bytes()
        with _captured_output() as chatter:
            reader = DFReader_binary(str(path))
    except OSError as err:
        raise ReaderError(path, f"cannot read: {err.strerror or err}") from err
    except Exception as err:  # pymavlink raises bare Exception for an unknown format letter
        raise ReaderError(path, f"not a readable DataFlash log: {type(err).__name__}: {err}") from err
    text = "".join(chatter)
    log = DataFlash(path, data, reader)
    bad = len(re.findall(r"bad header", text))
    if bad:
        log.skipped.append(
            Skipped("<dataflash>", "corrupt bytes between messages; re-synchronised on the next header", bad, "lost")
        )
    stop = re.search(r"unknown msg type 0x[0-9a-f]+ \(\d+\) at (\d+)", text)
    if stop:
        found = _resume_index(log, int(stop.group(1)) + 1)
        log.skipped.append(
            Skipped(
                "<dataflash>",
                f"a message of undefined type at byte {stop.group(1)}; "
                f"{found} messages after it found by re-synchronising",
                1,
                "lost",
            )
        )
    return log


def is_dataflash(head: bytes) -> bool:
    return head.startswith(HEADER)
