"""RINEX text: a file as bytes with its line layout, fixed-width fields cut out with numpy.

Shared by the observation and navigation parts and by the rewriter: exact decimal parsing (a mantissa
and the digits after the point, so seconds become nanoseconds without rounding), integer fields,
calendar dates, satellite ids, and the header lines every RINEX file starts with.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray

from spooflens.errors import ReaderError

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

NS = 1_000_000_000
GPS_EPOCH = datetime(1980, 1, 6, tzinfo=UTC)
SYSTEMS = "GRESCJI"
OBSERVATION_VERSIONS = "2.10, 2.11, 3.02-3.05, 4.00-4.02"
SUPPORTED_VERSIONS = f"{OBSERVATION_VERSIONS} observation files"


@dataclass(frozen=True)
class TextLines:
    """A file's bytes with where every line starts and how long it is, for vectorised field access.

    Lines are cut at `\\n`; a `\\r` before it is not part of the line. `terminated` is False when the
    last line has no newline, i.e. the file may have been cut inside it.
    """

    path: Path
    data: bytes
    buf: NDArray[np.uint8]
    starts: IntArray
    lens: IntArray
    terminated: bool
    losses: tuple[str, ...] = ()  # what unpacking a packed file lost (a gzip stream cut short...)
    packing: tuple[str, ...] = ()  # how the file was shipped: ("gzip", "Compact RINEX (Hatanaka)")

    @classmethod
    def load(cls, path: Path) -> TextLines:
        from readers.rinex.packaging import unpack

        unpacked = unpack(path)
        data = unpacked.data
        if not data:
            raise ReaderError(path, "file is empty (0 bytes)" if not unpacked.packing else "packed file holds no text")
        buf = np.frombuffer(data, dtype=np.uint8)
        nl = np.flatnonzero(buf == 10)
        starts = np.concatenate(([0], nl + 1)).astype(np.int64)
        ends = np.concatenate((nl, [len(buf)])).astype(np.int64)
        terminated = data.endswith(b"\n")
        if terminated:
            starts, ends = starts[:-1], ends[:-1]
        cr = (ends > starts) & (buf[np.maximum(ends - 1, 0)] == 13)
        lens = ends - starts - cr.astype(np.int64)
        return cls(path, data, buf, starts, lens, terminated, tuple(unpacked.losses), tuple(unpacked.packing))

    def __len__(self) -> int:
        return len(self.starts)

    def line(self, i: int) -> str:
        s = int(self.starts[i])
        return self.data[s : s + int(self.lens[i])].decode("latin-1")

    def field(self, rows: IntArray, col: IntArray | int, width: int) -> NDArray[np.uint8]:
        """Characters [col, col + width) of each line in `rows` as an (n, width) array, blank-padded."""
        rows = np.asarray(rows, dtype=np.int64)
        cols = np.broadcast_to(np.asarray(col, dtype=np.int64), rows.shape)
        room = self.lens[rows] - cols  # characters of the field inside its line
        pos = np.where(room > 0, self.starts[rows] + cols, len(self.buf))
        out = sliding_window_view(self._padded(width), width)[pos]
        short = np.flatnonzero(room < width)
        if len(short):
            out[short] = np.where(np.arange(width) < room[short, None], out[short], 32)
        return out

    def _padded(self, width: int) -> NDArray[np.uint8]:
        """The bytes followed by `width` blanks, so a window starting anywhere in the file is in bounds."""
        cached = self.__dict__.get("_pad")
        if cached is None or len(cached) - len(self.buf) < width:
            cached = np.concatenate((self.buf, np.full(max(width, 64), 32, dtype=np.uint8)))
            object.__setattr__(self, "_pad", cached)
        return cached


def decimal_parts(chars: NDArray[np.uint8]) -> tuple[IntArray, IntArray, BoolArray, BoolArray]:
    """Fixed-width decimal numbers -> (signed integer mantissa, digits after the point, blank, bad).

    Exact integer arithmetic, so `mantissa / 10**frac` is the correctly rounded value (what float()
    of the text gives) and seconds convert to nanoseconds without rounding. Anything but one optional
    sign, digits and at most one point, with no blank inside, is `bad`. The mantissa counts trailing
    blanks as zeros (and `frac` counts them too), which keeps the weights of a column a function of
    the point's position alone: one matrix-vector product per point position (F14.3: one in all).
    """
    n, w = chars.shape
    space = chars == 32
    digit = (chars - np.uint8(48)) < 10
    point = chars == 46
    sign = (chars == 45) | (chars == 43)
    nonspace = ~space
    blank = ~nonspace.any(axis=1)
    first = np.argmax(nonspace, axis=1)
    last = w - 1 - np.argmax(nonspace[:, ::-1], axis=1)
    rows = np.arange(n)
    n_sign = np.count_nonzero(sign, axis=1)
    bad = (
        (np.count_nonzero(digit | point | sign | space, axis=1) < w)
        | (np.count_nonzero(nonspace, axis=1) != last - first + 1)
        | (n_sign > sign[rows, first])
        | (np.count_nonzero(point, axis=1) > 1)
        | ~digit.any(axis=1)
    ) & ~blank
    ppos = np.where(point.any(axis=1), np.argmax(point, axis=1), last + 1)  # no point: one after the last digit
    dv = np.where(digit, chars - np.uint8(48), np.uint8(0))
    mant = np.zeros(n, dtype=np.int64)
    for p in np.unique(ppos).tolist():
        k = np.arange(w)
        weights = _POW10[np.where(k < p, p - k - 1 + (w - 1 - p if p < w else 0), w - 1 - k)] * (k != p)
        sel = np.flatnonzero(ppos == p)
        mant[sel] = dv[sel].astype(np.int64) @ weights
    frac = np.where(ppos < w, w - 1 - ppos, 0).astype(np.int64)
    mant = np.where((chars == 45).any(axis=1), -mant, mant)
    return mant, frac, blank, bad


_POW10 = 10 ** np.arange(19, dtype=np.int64)


def parse_fixed(chars: NDArray[np.uint8]) -> tuple[FloatArray, BoolArray, BoolArray]:
    """Fixed-width decimal fields -> (values, blank, bad); NaN where blank or bad."""
    out = np.full(len(chars), np.nan)
    blank = np.zeros(len(chars), dtype=bool)
    bad = np.zeros(len(chars), dtype=bool)
    step = 1 << 16  # chunks whose temporaries stay in cache
    for a in range(0, len(chars), step):
        mant, frac, blank[a : a + step], bad[a : a + step] = decimal_parts(chars[a : a + step])
        out[a : a + step] = mant / _POW10F[frac]
    out[blank | bad] = np.nan
    return out, blank, bad


_POW10F = 10.0 ** np.arange(19)


def parse_int(chars: NDArray[np.uint8]) -> tuple[IntArray, BoolArray]:
    """Integer fields -> (values, ok); a blank or non-integer field is not ok."""
    mant, frac, blank, bad = decimal_parts(chars)
    return mant // _POW10[frac], ~(blank | bad | (chars == 46).any(axis=1))


def _days_from_civil(y: IntArray, m: IntArray, d: IntArray) -> IntArray:
    """Days since 1970-01-01 of proleptic Gregorian dates (H. Hinnant's algorithm, vectorised)."""
    y = y - (m <= 2)
    era = np.floor_divide(y, 400)
    yoe = y - era * 400
    mp = (m + 9) % 12
    doy = (153 * mp + 2) // 5 + d - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146097 + doe - 719468


def calendar_ns(
    y: IntArray, mo: IntArray, d: IntArray, h: IntArray, mi: IntArray, sec_mant: IntArray, sec_frac: IntArray
) -> tuple[IntArray, BoolArray]:
    """Calendar fields (seconds as mantissa/10**frac) -> ns since 1970 on the same scale, and validity."""
    ok = (mo >= 1) & (mo <= 12) & (d >= 1) & (d <= 31) & (h >= 0) & (h <= 24) & (mi >= 0) & (mi <= 60)
    ok &= (sec_mant >= 0) & (y >= 1980) & (y <= 2200)
    sec_ns = np.where(sec_frac <= 9, sec_mant * _POW10[np.clip(9 - sec_frac, 0, 9)], sec_mant // _POW10[sec_frac - 9])
    days = _days_from_civil(np.where(ok, y, 1980), np.where(ok, mo, 1), np.where(ok, d, 1))
    ns = (days * 86400 + h * 3600 + mi * 60) * NS + sec_ns
    return np.where(ok, ns, 0), ok


def sv_ids(tok: NDArray[np.uint8]) -> tuple[NDArray[np.str_], NDArray[np.uint8], BoolArray]:
    """3-character satellite fields ('G05', 'G 5', ' 5') -> ('G05', system letter byte, valid)."""
    sys = tok[:, 0].copy()
    sys[sys == 32] = ord("G")  # RINEX 2: a blank system letter is GPS
    d1, d2 = tok[:, 1], tok[:, 2]
    dig1 = (d1 >= 48) & (d1 <= 57)
    ok = np.isin(sys, np.frombuffer(SYSTEMS.encode(), dtype=np.uint8)) & (d2 >= 48) & (d2 <= 57) & (dig1 | (d1 == 32))
    prn = np.where(dig1, d1.astype(np.int64) - 48, 0) * 10 + (d2.astype(np.int64) - 48)
    ok &= prn > 0
    prn = np.where(ok, prn, 0)
    out = np.empty((len(tok), 3), dtype=np.uint8)
    out[:, 0] = np.where(ok, sys, ord("?"))  # any byte of a bad id (non-ASCII too) must still make a str
    out[:, 1] = 48 + prn // 10
    out[:, 2] = 48 + prn % 10
    return np.ascontiguousarray(out).view("S3").ravel().astype("U3"), sys, ok


# ---------------------------------------------------------------------------------------------------
# headers


# ---------------------------------------------------------------------------------------------------
# header lines every RINEX file has


def first_line(path: Path) -> str:
    """The RINEX VERSION / TYPE line of a file, plain or packed (gzip, zip, .Z, Compact RINEX)."""
    from readers.rinex.packaging import head_text

    return head_text(path, 4096).split(b"\n", 1)[0][:256].decode("latin-1")


def header_lines(path: Path) -> list[str]:
    """The header lines of a RINEX file, plain or packed, up to END OF HEADER (or the first 64 KiB)."""
    from readers.rinex.packaging import head_text

    lines = []
    for raw in head_text(path).split(b"\n"):
        line = raw.decode("latin-1").rstrip("\r")
        lines.append(line)
        if "END OF HEADER" in line:
            break
    return lines


def end_of_header(text: TextLines) -> int:
    pos = text.data.find(b"END OF HEADER")
    if pos < 0:
        raise ReaderError(text.path, "no END OF HEADER line (file cut inside the header, or not RINEX)")
    return int(np.searchsorted(text.starts, pos, side="right") - 1)


def _version(path: Path, first: str) -> float:
    try:
        return float(first[:9])
    except ValueError:
        raise ReaderError(
            path, f"RINEX version {first[:9].strip()!r} is not a number; supported: {SUPPORTED_VERSIONS}"
        ) from None


def checked_version(path: Path, first: str, kind: str, supported: str) -> float:
    """The version of a RINEX file from its first line; ReaderError unless it is a RINEX 2, 3 or 4 file (4's
    observation records are 3's; its navigation records are 3's behind a `> EPH` line)."""
    if "RINEX VERSION / TYPE" not in first:
        raise ReaderError(path, "first line is not RINEX VERSION / TYPE")
    version = _version(path, first)
    if not 2.0 <= version < 5.0:
        raise ReaderError(path, f"unsupported RINEX {kind}version {version:g}; supported: {supported}")
    return version
