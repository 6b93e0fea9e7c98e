"""RINEX observation files (2.10/2.11, 3.02-3.05) to an EpochTable, RINEX navigation files to GPS orbits.

A log is one observation file or a directory holding several (one receiver per file: MARKER NAME, else
the file stem; duplicates get the file name appended). Each satellite of each epoch becomes one row of
the `observations` frame, on the GPS time scale (`time_reference` "gps").

**Which observable.** One L1-band signal per satellite and epoch, the first present (not blank, not
0.0, which RINEX uses for "missing") of a priority list; phase, Doppler and C/N0 come from that same
signal (`L`, `D`, `S` with the code's band and attribute), never mixed across signals:

- RINEX 2: `C1`, then `P1`; with `L1`, `D1`, `S1` (a blank system letter is GPS).
- RINEX 3, per system (`CODE_PRIORITY`): GPS `C1C C1W C1P C1Y C1X C1S C1L C1M`; GLONASS `C1C C1P`;
  Galileo `C1C C1X C1B C1A C1Z`; QZSS `C1C C1X C1L C1S C1Z C1E C1B`; SBAS `C1C`; BeiDou B1I
  `C2I C2X C2Q` (3.03+) or `C1I C1Q` (3.02), then B1C `C1P C1X C1D`; NavIC `C5A C5X C5B C5C` (L5).

Carrier frequency: 1575.42 MHz for GPS/Galileo/QZSS/SBAS L1/E1 and BeiDou B1C, 1561.098 MHz for
B1I, 1176.45 MHz for NavIC L5; GLONASS G1 from the header's GLONASS SLOT / FRQ # (NaN without it).
`pseudorange_rate_mps = -doppler_hz * c / carrier_freq_hz`.

**Satellite states.** GPS rows get the satellite's position, velocity and clock at the signal's
transmission time (`t_rx - pr/c`, corrected once by the satellite clock), in the ECEF frame of that
instant (no Earth-rotation correction: the receiver side applies it). The navigation file is found
beside the observation file: the same name with the extension's last letter `o` -> `n`/`p`
(`07590920.05o` -> `07590920.05n`), a RINEX 3 long name `..._MO.rnx` -> `..._GN.rnx`/`..._MN.rnx`,
`.obs` -> `.nav`; else every GPS/mixed navigation file in the directory (found by content). The topic
`nav` overrides this: `read_log(path, topics={"nav": "/path/brdc0920.05n"})`, on the command line
`--topic nav=/path/brdc0920.05n`. Rows without a valid broadcast record keep NaN states and are
counted under "no ephemeris"; non-GPS satellites get no states (only GPS orbits are modelled).

**Time.** Epochs are taken in the file's time system (TIME OF FIRST OBS): GPS (and QZSS/Galileo,
aligned with GPS to nanoseconds) as they are; BeiDou time + 14 s; GLONASS time (UTC(SU) + 3 h) is
converted to GPS with the leap-second table. Other systems are refused. The receiver clock offset
field is ignored. Epoch flags 0 and 1 are data; 2-5 are events whose header records are skipped (a
flag-4 record that redefines the observation types is honoured); 6 (cycle-slip records) is skipped.

**Bad input.** A file cut mid-epoch keeps every complete epoch before the cut; a satellite row with a
field that is not a number is skipped; an epoch whose header lists more satellites than lines follow
is skipped (RINEX 2) or read from the lines present (RINEX 3); every such loss is listed in
`table.skipped`. An unknown version, a navigation file given as a log, or a file without END OF
HEADER is one ReaderError.

Parsing is vectorised: a file is read once as bytes and every fixed-width field of every line is cut
out with numpy, so a 1 Hz day (86,400 epochs, ~1M satellite rows) reads in a few seconds.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray

from readers import ReaderFormat
from spooflens.epoch_table import GPS_EPOCH_UNIX_NS, EpochTable, Skipped, StreamInfo, build_table, gps_utc_offset_ns
from spooflens.errors import ReaderError
from spooflens.gnss.ephemeris import C_MPS, SECONDS_PER_WEEK, GpsEphemerides, Klobuchar, states_at_transmission

Progress = Callable[[int, int], None]
FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

NS = 1_000_000_000
GPS_EPOCH = datetime(1980, 1, 6, tzinfo=UTC)
SYSTEMS = "GRESCJI"
SUPPORTED_VERSIONS = "2.10, 2.11 and 3.02-3.05 observation files"
# table.metadata key (+ ".<receiver id>") holding the header's APPROX POSITION XYZ, "x y z" in ECEF metres
APPROX_POSITION_KEY = "rinex.approx_position_xyz_m"
DEFAULT_TIME_SYSTEM = {"R": "GLO", "E": "GAL", "C": "BDT", "J": "QZS"}  # single-system files without one

CODE_PRIORITY_V2: tuple[str, ...] = ("C1", "P1")
CODE_PRIORITY: dict[str, tuple[str, ...]] = {
    "G": ("C1C", "C1W", "C1P", "C1Y", "C1X", "C1S", "C1L", "C1M"),
    "R": ("C1C", "C1P"),
    "E": ("C1C", "C1X", "C1B", "C1A", "C1Z"),
    "J": ("C1C", "C1X", "C1L", "C1S", "C1Z", "C1E", "C1B"),
    "S": ("C1C",),
    "C": ("C2I", "C2X", "C2Q", "C1I", "C1Q", "C1P", "C1X", "C1D"),
    "I": ("C5A", "C5X", "C5B", "C5C"),
}

# carrier frequency (Hz) per system and RINEX band digit; GLONASS FDMA bands are computed from the channel
BAND_HZ: dict[str, dict[str, float]] = {
    "G": {"1": 1575.42e6, "2": 1227.60e6, "5": 1176.45e6},
    "E": {"1": 1575.42e6, "5": 1176.45e6, "7": 1207.14e6, "8": 1191.795e6, "6": 1278.75e6},
    "J": {"1": 1575.42e6, "2": 1227.60e6, "5": 1176.45e6, "6": 1278.75e6},
    "S": {"1": 1575.42e6, "5": 1176.45e6},
    "C": {"1": 1575.42e6, "2": 1561.098e6, "5": 1176.45e6, "6": 1268.52e6, "7": 1207.14e6, "8": 1191.795e6},
    "I": {"5": 1176.45e6, "9": 2492.028e6},
    "R": {"3": 1202.025e6, "4": 1600.995e6, "6": 1248.06e6},
}
GLONASS_FDMA = {"1": (1602.0e6, 0.5625e6), "2": (1246.0e6, 0.4375e6)}  # base, channel step


# ---------------------------------------------------------------------------------------------------
# fixed-width text, vectorised


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

    @classmethod
    def load(cls, path: Path) -> TextLines:
        try:
            data = path.read_bytes()
        except OSError as err:
            raise ReaderError(path, f"cannot read: {err.strerror or err}") from err
        if not data:
            raise ReaderError(path, "file is empty (0 bytes)")
        buf = np.frombuffer(data, dtype=np.uint8)
        nl = np.flatnonzero(buf == 10)
        starts = np.concatenate(([0], nl + 1)).astype(np.int64)
        ends = np.concatenate((nl, [len(buf)])).astype(np.int64)
        terminated = data.endswith(b"\n")
        if terminated:
            starts, ends = starts[:-1], ends[:-1]
        cr = (ends > starts) & (buf[np.maximum(ends - 1, 0)] == 13)
        return cls(path, data, buf, starts, ends - starts - cr.astype(np.int64), terminated)

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


def _decimal_parts(chars: NDArray[np.uint8]) -> tuple[IntArray, IntArray, BoolArray, BoolArray]:
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
        mant, frac, blank[a : a + step], bad[a : a + step] = _decimal_parts(chars[a : a + step])
        out[a : a + step] = mant / _POW10F[frac]
    out[blank | bad] = np.nan
    return out, blank, bad


_POW10F = 10.0 ** np.arange(19)


def _parse_int(chars: NDArray[np.uint8]) -> tuple[IntArray, BoolArray]:
    """Integer fields -> (values, ok); a blank or non-integer field is not ok."""
    mant, frac, blank, bad = _decimal_parts(chars)
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


def _calendar_ns(
    y: IntArray, mo: IntArray, d: IntArray, h: IntArray, mi: IntArray, sec_mant: IntArray, sec_frac: IntArray
) -> tuple[IntArray, BoolArray]:
    """Calendar fields (seconds as mantissa/10**frac) -> ns since 1970 on the same scale, and validity."""
    ok = (mo >= 1) & (mo <= 12) & (d >= 1) & (d <= 31) & (h >= 0) & (h <= 24) & (mi >= 0) & (mi <= 60)
    ok &= (sec_mant >= 0) & (y >= 1980) & (y <= 2200)
    sec_ns = np.where(sec_frac <= 9, sec_mant * _POW10[np.clip(9 - sec_frac, 0, 9)], sec_mant // _POW10[sec_frac - 9])
    days = _days_from_civil(np.where(ok, y, 1980), np.where(ok, mo, 1), np.where(ok, d, 1))
    ns = (days * 86400 + h * 3600 + mi * 60) * NS + sec_ns
    return np.where(ok, ns, 0), ok


def _sv_ids(tok: NDArray[np.uint8]) -> tuple[NDArray[np.str_], NDArray[np.uint8], BoolArray]:
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
    out[:, 0] = sys
    out[:, 1] = 48 + prn // 10
    out[:, 2] = 48 + prn % 10
    return np.ascontiguousarray(out).view("S3").ravel().astype("U3"), sys, ok


# ---------------------------------------------------------------------------------------------------
# headers


def _first_line(path: Path) -> str:
    try:
        with path.open("rb") as f:
            return f.readline(256).decode("latin-1")
    except OSError:
        return ""


def is_rinex_obs(path: Path) -> bool:
    """True for a RINEX observation file (by content: its first line)."""
    line = _first_line(path)
    return "RINEX VERSION / TYPE" in line and "OBSERVATION DATA" in line.upper()


def is_gps_nav(path: Path) -> bool:
    """True for a RINEX navigation file that can hold GPS orbits (RINEX 2 'N', RINEX 3 GPS or mixed)."""
    line = _first_line(path)
    if "RINEX VERSION / TYPE" not in line or line[20:21].upper() != "N":
        return False
    return line[:9].strip().startswith("2") or line[40:41].upper() in ("G", "M", " ", "")


@dataclass(frozen=True)
class ObsHeader:
    """What spooflens uses from an observation file's header."""

    version: float
    system: str  # file system letter: G, R, E, C, J, S, I or M (mixed)
    marker: str
    approx_xyz: tuple[float, float, float] | None
    obs_types: dict[str, tuple[str, ...]]  # per system letter; RINEX 2: key "*" for every system
    time_system: str
    glonass_k: dict[str, int]
    end_line: int  # index of the END OF HEADER line


def _end_of_header(text: TextLines) -> int:
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


def _obs_types(lines: list[str], version: float) -> dict[str, tuple[str, ...]]:
    """Observation types declared in header (or flag-4 event) lines, per system."""
    types: dict[str, list[str]] = {}
    current = ""
    for line in lines:
        label = line[60:80].strip()
        if version < 3 and label == "# / TYPES OF OBSERV":
            types.setdefault("*", []).extend(line[6:60].split())
        elif version >= 3 and label == "SYS / # / OBS TYPES":
            if line[:1].strip():
                current = line[0].upper()
                types[current] = []
            if current:
                types[current].extend(line[7:60].split())
    return {k: tuple(v) for k, v in types.items()}


def _checked_version(path: Path, first: str, kind: str, supported: str) -> float:
    """The version of a RINEX file from its first line; ReaderError unless it is a RINEX 2 or 3 file."""
    if "RINEX VERSION / TYPE" not in first:
        raise ReaderError(path, "first line is not RINEX VERSION / TYPE")
    version = _version(path, first)
    if not 2.0 <= version < 4.0:
        raise ReaderError(path, f"unsupported RINEX {kind}version {version:g}; supported: {supported}")
    return version


def read_obs_header(text: TextLines) -> ObsHeader:
    """Parse the header of an observation file; ReaderError for what is not a supported one."""
    path = text.path
    end = _end_of_header(text)
    lines = [text.line(i) for i in range(end + 1)]
    first = lines[0]
    version = _checked_version(path, first, "", SUPPORTED_VERSIONS)
    ftype = first[20:21].upper()
    if ftype != "O":
        kind = "navigation" if ftype in "NGHLCEJI" else f"type {ftype!r}"
        raise ReaderError(
            path, f"a RINEX {kind} file, not observations: give the observation file (its nav file is found beside it)"
        )
    system = (first[40:41].strip() or "G").upper()
    marker, xyz, tsys, glo = "", None, "", {}
    for line in lines:
        label = line[60:80].strip()
        if label == "MARKER NAME":
            marker = line[:60].strip()
        elif label == "APPROX POSITION XYZ":
            try:
                x, y, z = (float(v) for v in line[:42].split()[:3])
                xyz = (x, y, z)
            except ValueError:
                xyz = None
        elif label == "TIME OF FIRST OBS":
            tsys = line[48:51].strip().upper()
        elif label == "SYS / SCALE FACTOR" and line[2:6].strip() not in ("", "1"):
            factor = line[2:6].strip()
            raise ReaderError(path, f"observations scaled by {factor} (SYS / SCALE FACTOR) are not supported")
        elif label == "GLONASS SLOT / FRQ #":
            for slot, k in re.findall(r"R\s*(\d{1,2})\s+([-+]?\d+)", line[:60]):
                glo[f"R{int(slot):02d}"] = int(k)
    tsys = tsys or DEFAULT_TIME_SYSTEM.get(system, "GPS")
    types = _obs_types(lines, version)
    if not types:
        label = "# / TYPES OF OBSERV" if version < 3 else "SYS / # / OBS TYPES"
        raise ReaderError(path, f"header declares no observation types ({label})")
    return ObsHeader(version, system, marker, xyz, types, tsys, glo, end)


def rinex_approx_position(path: Path | str) -> tuple[float, float, float] | None:
    """The header's APPROX POSITION XYZ (ECEF, m), the surveyed site for a static station; None if absent."""
    path = Path(path)
    try:
        f = path.open("rb")
    except OSError as err:
        raise ReaderError(path, f"cannot read: {err.strerror or err}") from err
    with f:
        for raw in f:
            line = raw.decode("latin-1").rstrip("\r\n")
            label = line[60:80].strip()
            if label == "APPROX POSITION XYZ":
                try:
                    x, y, z = (float(v) for v in line[:42].split()[:3])
                except ValueError:
                    return None
                return None if x == y == z == 0.0 else (x, y, z)
            if label == "END OF HEADER":
                break
    return None


# ---------------------------------------------------------------------------------------------------
# observation body: epochs and satellite rows


@dataclass
class ObsScan:
    """The layout of one observation file's body: data epochs and where each satellite's fields are.

    Shared by the reader and the rewriter (`spooflens.writers.rinex_rewrite`) so both agree on every
    epoch time and line. Arrays are in file order; `row_*` has one entry per satellite line group.
    """

    text: TextLines
    header: ObsHeader
    layouts: list[dict[str, tuple[str, ...]]]
    epoch_line: IntArray  # line index of the epoch header
    epoch_header_lines: IntArray  # 1 + continuation lines (RINEX 2, > 12 satellites)
    epoch_ns: IntArray  # GPS ns since 1980-01-06
    epoch_layout: IntArray
    row_epoch: IntArray
    row_slot: IntArray  # position in the epoch's satellite list
    row_line: IntArray  # first data line of the satellite
    row_nlines: IntArray
    row_sv: NDArray[np.str_]
    row_sys: NDArray[np.uint8]
    skipped: list[Skipped] = field(default_factory=list)

    @property
    def version(self) -> float:
        return self.header.version

    def field_at(self, rows: IntArray, type_index: IntArray | int) -> tuple[IntArray, IntArray]:
        """(line, column) of observation type number `type_index` of the given satellite rows."""
        m = np.broadcast_to(np.asarray(type_index, dtype=np.int64), np.shape(rows))
        if self.version < 3:
            return self.row_line[rows] + m // 5, 16 * (m % 5)
        return self.row_line[rows], 3 + 16 * m


def _clean_end(length: int, version: float) -> bool:
    """Whether an unterminated last data line ends on a field boundary (else it was cut inside a field)."""
    rest = length if version < 3 else length - 3
    return rest >= 0 and rest % 16 in (0, 14, 15)


def _time_shift(path: Path, tsys: str, epoch_ns: IntArray, skipped: list[Skipped]) -> IntArray:
    """Epoch times (ns on the file's clock, from the calendar) -> GPS ns since 1980-01-06."""
    gps = epoch_ns - GPS_EPOCH_UNIX_NS
    if tsys in ("", "GPS", "GAL", "QZS", "IRN"):
        if tsys in ("GAL", "QZS", "IRN"):
            skipped.append(
                Skipped(path.name, f"time system {tsys} taken as GPS time (aligned to nanoseconds)", 1, "repaired")
            )
        return gps
    if tsys == "BDT":
        skipped.append(Skipped(path.name, "BeiDou time converted to GPS time (+14 s)", len(gps), "repaired"))
        return gps + 14 * NS
    if tsys in ("GLO", "UTC"):
        utc = gps - (3 * 3600 * NS if tsys == "GLO" else 0)
        leap = gps_utc_offset_ns(utc + gps_utc_offset_ns(utc))
        skipped.append(
            Skipped(path.name, f"{tsys} time converted to GPS time (leap seconds applied)", len(gps), "repaired")
        )
        return utc + leap
    raise ReaderError(path, f"time system {tsys!r} (TIME OF FIRST OBS) is not supported; use GPS, GLO, GAL, BDT or QZS")


def _header_times(
    text: TextLines, lines: IntArray, cols: tuple[tuple[int, int], ...], two_digit_year: bool
) -> tuple[IntArray, BoolArray]:
    """Calendar ns (file clock) of epoch header lines, fields at `cols` (year, month, day, hour, min, sec)."""
    parts = []
    ok = np.ones(len(lines), dtype=bool)
    for a, b in cols[:5]:
        v, good = _parse_int(text.field(lines, a, b - a))
        parts.append(v)
        ok &= good
    sec_mant, sec_frac, blank, bad = _decimal_parts(text.field(lines, cols[5][0], cols[5][1] - cols[5][0]))
    ok &= ~blank & ~bad
    y = parts[0]
    if two_digit_year:
        y = np.where(y < 80, y + 2000, np.where(y < 100, y + 1900, y))
    ns, valid = _calendar_ns(y, parts[1], parts[2], parts[3], parts[4], sec_mant, sec_frac)
    return ns, ok & valid


class _Counts(dict[tuple[str, str], int]):
    """Skipped/repaired counts of one file by (reason, action), turned into Skipped entries at the end."""

    def add(self, reason: str, action: str, k: int = 1) -> None:
        self[(reason, action)] = self.get((reason, action), 0) + k

    def skipped(self, name: str) -> list[Skipped]:
        return [Skipped(name, reason, n, action) for (reason, action), n in self.items() if n]


def _v2_epoch_lines(c: NDArray[np.uint8]) -> BoolArray:
    """Which lines (first 32 characters) look like RINEX 2 epoch headers.

    The date fields (I3 x5, F11.7), two blanks, a flag 0-6 and a count in I3; an event record
    (flags 2-5) may leave the date blank. A data line never matches: its F14.3 fields put digits
    where the flag and the count go, and a decimal point at column 26 where the blanks are.
    """
    dig = (c >= 48) & (c <= 57)
    spc = c == 32
    head = (c[:, 28] >= 48) & (c[:, 28] <= 54) & spc[:, 26] & spc[:, 27] & dig[:, 31]
    head &= (dig[:, 29] | spc[:, 29]) & (dig[:, 30] | spc[:, 30])
    date_blank = spc[:, :26].all(axis=1)
    date_like = (c[:, 18] == 46) & (dig | spc | (c == 46))[:, :26].all(axis=1)
    date_like &= spc[:, [0, 3, 6, 9, 12, 15]].all(axis=1)
    return head & (date_blank | date_like)


def _scan_v2(text: TextLines, header: ObsHeader) -> ObsScan:
    """Walk a RINEX 2 body epoch by epoch (data lines do not name their satellite)."""
    n = len(text)
    body0 = header.end_line + 1
    lines = np.arange(body0, n, dtype=np.int64)
    c = text.field(lines, 0, 32)
    cand = _v2_epoch_lines(c)
    cand_lines = lines[cand]
    flags = (c[cand, 28].astype(np.int64) - 48).tolist()
    nsats, _ = _parse_int(c[cand, 29:32])
    nsats_l = nsats.tolist()
    cal_ns, cal_ok = _header_times(text, cand_lines, ((0, 3), (3, 6), (6, 9), (9, 12), (12, 15), (15, 26)), True)
    cidx = np.full(n + 1, -1, dtype=np.int64)
    cidx[cand_lines] = np.arange(len(cand_lines))
    cidx_l = cidx.tolist()
    cum = np.concatenate(([0], np.cumsum(cidx[:n] >= 0))).tolist()
    nxt = np.full(n + 1, n, dtype=np.int64)
    nxt[cand_lines] = cand_lines
    nxt = np.minimum.accumulate(nxt[::-1])[::-1].tolist()
    layouts = [header.obs_types]
    lps = [max(1, -(-len(header.obs_types["*"]) // 5))]
    counts = _Counts()
    count = counts.add

    ep_line, ep_hdr, ep_data0, ep_ns, ep_k, ep_layout = [], [], [], [], [], []
    i = body0
    while i < n:
        k = cidx_l[i]
        if k < 0:
            j = nxt[i]
            if j == n and not text.terminated:  # the last line, unterminated and unreadable: cut inside it
                count("file cut mid-epoch; kept every epoch before", "lost")
                j -= 1
            if j > i:
                count("lines outside any epoch (unreadable epoch header?)", "lost", j - i)
            i = nxt[i]
            continue
        f, ns = flags[k], nsats_l[k]
        if 2 <= f <= 5:
            special = [text.line(x) for x in range(i + 1, min(i + 1 + ns, n))]
            redefined = _obs_types(special, header.version)
            if redefined.get("*"):
                layouts.append(redefined)
                lps.append(max(1, -(-len(redefined["*"]) // 5)))
            count("event records (epoch flags 2-5) with their header lines", "skipped")
            i += 1 + ns
            continue
        ncont = (ns - 1) // 12 if ns > 12 else 0
        data0 = i + 1 + ncont
        end = data0 + ns * lps[-1]
        if end > n:
            count("file cut mid-epoch; kept every epoch before", "lost")
            break
        if cum[end] - cum[i + 1] > 0:
            count("epochs with fewer satellite lines than their header lists", "lost")
            i = nxt[i + 1]
            continue
        if f == 6:
            count("cycle-slip records (epoch flag 6)", "skipped")
        elif not cal_ok[k]:
            count("epochs with an unreadable date", "lost")
        else:
            ep_line.append(i)
            ep_hdr.append(1 + ncont)
            ep_data0.append(data0)
            ep_ns.append(int(cal_ns[k]))
            ep_k.append(ns)
            ep_layout.append(len(layouts) - 1)
        i = end
    ends_at_cut = bool(ep_line) and ep_data0[-1] + ep_k[-1] * lps[ep_layout[-1]] == n
    if ends_at_cut and not text.terminated and not _clean_end(int(text.lens[-1]), header.version):
        count("file cut mid-epoch; kept every epoch before", "lost")
        for arr in (ep_line, ep_hdr, ep_data0, ep_ns, ep_k, ep_layout):
            arr.pop()
    e_line = np.asarray(ep_line, dtype=np.int64)
    nsat = np.asarray(ep_k, dtype=np.int64)
    row_epoch = np.repeat(np.arange(len(e_line)), nsat)
    offsets = np.concatenate(([0], np.cumsum(nsat)[:-1])) if len(nsat) else np.zeros(0, dtype=np.int64)
    slot = np.arange(len(row_epoch)) - np.repeat(offsets, nsat)
    e_lps = np.asarray(lps, dtype=np.int64)[np.asarray(ep_layout, dtype=np.int64)]
    tok = text.field(e_line[row_epoch] + slot // 12, 32 + 3 * (slot % 12), 3)
    sv, sys, ok = _sv_ids(tok)
    if (~ok).any():
        count("satellites with an unreadable id in the epoch header", "lost", int((~ok).sum()))
    row_line = np.asarray(ep_data0, dtype=np.int64)[row_epoch] + slot * e_lps[row_epoch]
    skipped = counts.skipped(text.path.name)
    return ObsScan(
        text=text,
        header=header,
        layouts=layouts,
        epoch_line=e_line,
        epoch_header_lines=np.asarray(ep_hdr, dtype=np.int64),
        epoch_ns=_time_shift(text.path, header.time_system, np.asarray(ep_ns, dtype=np.int64), skipped),
        epoch_layout=np.asarray(ep_layout, dtype=np.int64),
        row_epoch=row_epoch[ok],
        row_slot=slot[ok],
        row_line=row_line[ok],
        row_nlines=e_lps[row_epoch][ok],
        row_sv=sv[ok],
        row_sys=sys[ok],
        skipped=skipped,
    )


def _scan_v3(text: TextLines, header: ObsHeader) -> ObsScan:
    """Split a RINEX 3 body at its '>' epoch lines (data lines name their satellite)."""
    n = len(text)
    body0 = header.end_line + 1
    lines = np.arange(body0, n, dtype=np.int64)
    lens = text.lens[lines]
    first = np.where(lens > 0, text.buf[np.minimum(text.starts[lines], len(text.buf) - 1)], 32)
    is_ep = first == ord(">")
    ep_lines = lines[is_ep]
    counts = _Counts()
    count = counts.add

    blank_line = np.zeros(len(lines), dtype=bool)
    if len(lines):
        blank_line = (text.field(lines, 0, 3) == 32).all(axis=1) & (lens <= 3)
    before = (~is_ep & ~blank_line)[: (int(np.argmax(is_ep)) if is_ep.any() else len(lines))]
    if before.any():
        count("lines outside any epoch", "lost", int(before.sum()))
    flag, flag_ok = _parse_int(text.field(ep_lines, 29, 3))
    nsat, nsat_ok = _parse_int(text.field(ep_lines, 32, 3))
    cal_ns, cal_ok = _header_times(text, ep_lines, ((1, 6), (6, 9), (9, 12), (12, 15), (15, 18), (18, 29)), False)
    next_ep = np.concatenate((ep_lines[1:], [n]))
    owned = next_ep - ep_lines - 1
    header_ok = flag_ok & nsat_ok & (flag >= 0) & (flag <= 6)
    # events: special records (flag 2-5) may redefine the observation types from the next epoch on
    layouts = [header.obs_types]
    layout_start = np.zeros(len(ep_lines), dtype=np.int64)
    for e in np.flatnonzero(header_ok & (flag >= 2) & (flag <= 5)).tolist():
        count("event records (epoch flags 2-5) with their header lines", "skipped")
        special = [
            text.line(x) for x in range(int(ep_lines[e]) + 1, int(ep_lines[e]) + 1 + min(int(nsat[e]), int(owned[e])))
        ]
        redefined = _obs_types(special, header.version)
        if redefined:
            layouts.append({**layouts[-1], **redefined})
            layout_start[e + 1 :] += 1
    if (header_ok & (flag == 6)).any():
        count("cycle-slip records (epoch flag 6)", "skipped", int((header_ok & (flag == 6)).sum()))
    unreadable = ~header_ok
    if len(ep_lines) and ep_lines[-1] == n - 1 and not text.terminated and not (header_ok[-1] and cal_ok[-1]):
        count("file cut mid-epoch; kept every epoch before", "lost")  # cut inside the last epoch line
        header_ok[-1] = unreadable[-1] = False
    data = header_ok & (flag <= 1)
    if unreadable.any():
        count("epochs with an unreadable header", "lost", int(unreadable.sum()))
    if (data & ~cal_ok).any():
        count("epochs with an unreadable date", "lost", int((data & ~cal_ok).sum()))
    data &= cal_ok
    if len(ep_lines) and data[-1]:
        last_cut = owned[-1] < nsat[-1] or (
            not text.terminated and owned[-1] > 0 and not _clean_end(int(text.lens[-1]), header.version)
        )
        if last_cut:
            count("file cut mid-epoch; kept every epoch before", "lost")
            data[-1] = False
    mismatch = data & (owned != nsat)
    if mismatch.any():
        count(
            "epoch headers whose satellite count differs from the lines that follow; read the lines present",
            "repaired",
            int(mismatch.sum()),
        )
    epochs = np.flatnonzero(data)
    row_epoch = np.repeat(np.arange(len(epochs)), owned[epochs])
    offsets = np.concatenate(([0], np.cumsum(owned[epochs])[:-1])) if len(epochs) else np.zeros(0, dtype=np.int64)
    slot = np.arange(len(row_epoch)) - np.repeat(offsets, owned[epochs])
    row_line = ep_lines[epochs][row_epoch] + 1 + slot
    sv, sys, ok = _sv_ids(text.field(row_line, 0, 3))
    blank_rows = (text.lens[row_line] == 0) | (text.field(row_line, 0, 3) == 32).all(axis=1)
    if (~ok & ~blank_rows).any():
        count("satellite lines with an unreadable satellite id", "lost", int((~ok & ~blank_rows).sum()))
    skipped = counts.skipped(text.path.name)
    ep_ns = _time_shift(text.path, header.time_system, cal_ns[epochs], skipped)
    return ObsScan(
        text=text,
        header=header,
        layouts=layouts,
        epoch_line=ep_lines[epochs],
        epoch_header_lines=np.ones(len(epochs), dtype=np.int64),
        epoch_ns=ep_ns,
        epoch_layout=layout_start[epochs],
        row_epoch=row_epoch[ok],
        row_slot=slot[ok],
        row_line=row_line[ok],
        row_nlines=np.ones(int(ok.sum()), dtype=np.int64),
        row_sv=sv[ok],
        row_sys=sys[ok],
        skipped=skipped,
    )


def scan_obs(path: Path) -> ObsScan:
    """Read and lay out one observation file (header, epochs, satellite rows)."""
    text = TextLines.load(path)
    header = read_obs_header(text)
    return _scan_v2(text, header) if header.version < 3 else _scan_v3(text, header)


# ---------------------------------------------------------------------------------------------------
# observables


def carrier_frequency_hz(system: str, obs_type: str, version: float, glonass_k: int | None = None) -> float:
    """Carrier frequency of an observation type ('L1C', 'C1', 'D5X'...) of a system; NaN if unknown.

    GLONASS G1/G2 are FDMA: they need the satellite's frequency channel `glonass_k`.
    """
    band = obs_type[1:2]
    attr = obs_type[2:3]
    if system == "R":
        if band in GLONASS_FDMA:
            if glonass_k is None:
                return float("nan")
            base, step = GLONASS_FDMA[band]
            return base + glonass_k * step
        return BAND_HZ["R"].get(band, float("nan"))
    if system == "C" and band == "1" and (attr in ("I", "Q") or (attr == "X" and version < 3.03)):
        return 1561.098e6  # RINEX 3.02 named B1I as band 1
    return BAND_HZ.get(system, {}).get(band, float("nan"))


def _same_signal(code: str, kind: str, version: float) -> str:
    """The phase/Doppler/C/N0 type of the signal a code observable belongs to."""
    return kind + ("1" if version < 3 else code[1:])


@dataclass
class _Columns:
    pr: FloatArray
    phase: FloatArray
    doppler: FloatArray
    cn0: FloatArray
    freq: FloatArray
    bad: BoolArray


def _extract(scan: ObsScan) -> _Columns:
    """Pick each row's L1 signal by the priority list and read its code, phase, Doppler and C/N0."""
    n = len(scan.row_sv)
    cols = _Columns(*(np.full(n, np.nan) for _ in range(5)), np.zeros(n, dtype=bool))
    version = scan.version
    row_layout = scan.epoch_layout[scan.row_epoch]
    glo = scan.header.glonass_k
    for lay_id, layout in enumerate(scan.layouts):
        in_layout = row_layout == lay_id
        for sys_byte in np.unique(scan.row_sys[in_layout]).tolist():
            sys = chr(sys_byte)
            types = layout.get("*") if version < 3 else layout.get(sys)
            todo = np.flatnonzero(in_layout & (scan.row_sys == sys_byte))
            if not types:
                continue
            priority = CODE_PRIORITY_V2 if version < 3 else CODE_PRIORITY.get(sys, ())
            for code in priority:
                if code not in types or not len(todo):
                    continue
                values, blank, bad = _values(scan, todo, types.index(code))
                cols.bad[todo[bad]] = True
                got = todo[~blank & ~bad]
                cols.pr[got] = values[~blank & ~bad]
                for kind, arr in (("L", cols.phase), ("D", cols.doppler), ("S", cols.cn0)):
                    t = _same_signal(code, kind, version)
                    if t in types:
                        v, _, b = _values(scan, got, types.index(t))
                        cols.bad[got[b]] = True
                        arr[got] = v
                if sys == "R":
                    k = pd.Series(scan.row_sv[got]).map(glo).to_numpy(dtype=float)
                    base, step = GLONASS_FDMA.get(code[1], (np.nan, np.nan))
                    cols.freq[got] = base + k * step
                else:
                    cols.freq[got] = carrier_frequency_hz(sys, code if version >= 3 else "C1C", version)
                todo = todo[blank]
    return cols


def _values(scan: ObsScan, rows: IntArray, type_index: int) -> tuple[FloatArray, BoolArray, BoolArray]:
    """F14.3 values of one observation type for the given rows; 0.0 counts as blank (RINEX: missing)."""
    line, col = scan.field_at(rows, type_index)
    values, blank, bad = parse_fixed(scan.text.field(line, col, 14))
    blank = blank | (values == 0.0)
    values[blank] = np.nan
    return values, blank, bad


# ---------------------------------------------------------------------------------------------------
# navigation files


@dataclass(frozen=True)
class NavFile:
    """A navigation file's GPS records, with what was skipped and why."""

    path: Path
    version: float
    ephemerides: GpsEphemerides
    records: int
    skipped: list[Skipped]


_NAV_KEYS = (  # RINEX GPS broadcast orbit lines 1-7, four fields each (None: not used)
    ("iode", "crs", "delta_n", "m0"),
    ("cuc", "e", "cus", "sqrt_a"),
    ("toe_sow", "cic", "omega0", "cis"),
    ("i0", "crc", "omega", "omega_dot"),
    ("idot", None, "week", None),
    (None, "health", "tgd", None),
    (None, "fit_hours", None, None),
)
_OPTIONAL = {"fit_hours"}


def _nav_number(text: str) -> float | None:
    s = text.strip()
    if not s:
        return None
    return float(s.replace("D", "E").replace("d", "e"))


def _nav_record(lines: list[str], version: float) -> dict[str, float | int | str]:
    """One GPS broadcast record (first line + 7 orbit lines) -> GpsEphemerides.from_records keys."""
    first = lines[0]
    if version < 3:
        sv = f"G{int(first[:2]):02d}"
        yy, mo, d, h, mi = (int(v) for v in first[2:17].split())
        sec = float(first[17:22])
        year = yy + (2000 if yy < 80 else 1900) if yy < 100 else yy
        head, col0 = first[22:79], 3
    else:
        sv = f"G{int(first[1:3]):02d}"
        year, mo, d, h, mi, isec = (int(v) for v in first[4:23].split())
        sec = float(isec)
        head, col0 = first[23:80], 4
    toc = datetime(year, mo, d, h, mi, tzinfo=UTC) + timedelta(seconds=sec)
    rec: dict[str, float | int | str] = {"sv_id": sv, "toc_s": (toc - GPS_EPOCH).total_seconds()}
    for key, k in zip(("af0", "af1", "af2"), range(3), strict=True):
        v = _nav_number(head[19 * k : 19 * k + 19])
        if v is None:
            raise ValueError(f"{key} is blank")
        rec[key] = v
    for row, keys in enumerate(_NAV_KEYS):
        line = lines[row + 1] if row + 1 < len(lines) else ""
        for k, key in enumerate(keys):
            if key is None:
                continue
            v = _nav_number(line[col0 + 19 * k : col0 + 19 * k + 19])
            if v is None and key not in _OPTIONAL:
                raise ValueError(f"{key} is blank")
            rec[key] = 0.0 if v is None else v
    fit = float(rec.pop("fit_hours"))
    if fit > 4.0:
        rec["max_age_s"] = fit * 3600.0 / 2
    week = int(rec["week"])
    toc_week = int(float(rec["toc_s"]) // SECONDS_PER_WEEK)
    while week + 512 < toc_week:  # a week written modulo 1024
        week += 1024
    rec["week"], rec["health"], rec["iode"] = week, int(rec["health"]), int(rec["iode"])
    values = [float(v) for key, v in rec.items() if key != "sv_id"]
    if not np.all(np.isfinite(values)) or not 2000.0 < float(rec["sqrt_a"]) < 10000.0 or not 0 <= float(rec["e"]) < 1:
        raise ValueError("implausible orbit (sqrt(A) or e out of range)")
    return rec


def _klobuchar(lines: list[str]) -> Klobuchar | None:
    alpha = beta = None

    def four(text: str) -> tuple[float, float, float, float] | None:
        try:
            vals = [_nav_number(text[12 * k : 12 * k + 12]) for k in range(4)]
        except ValueError:
            return None
        return None if any(v is None for v in vals) else (vals[0], vals[1], vals[2], vals[3])  # type: ignore[return-value]

    for line in lines:
        label = line[60:80].strip()
        if label == "ION ALPHA":
            alpha = four(line[2:50])
        elif label == "ION BETA":
            beta = four(line[2:50])
        elif label == "IONOSPHERIC CORR" and line[:4] == "GPSA":
            alpha = four(line[5:53])
        elif label == "IONOSPHERIC CORR" and line[:4] == "GPSB":
            beta = four(line[5:53])
    return Klobuchar(alpha, beta) if alpha and beta else None


def read_rinex_nav_file(path: Path | str) -> NavFile:
    """Read a RINEX 2 GPS or RINEX 3 (GPS or mixed) navigation file, keeping the GPS records.

    Records that are cut short or hold a field that is not a number are skipped and counted; other
    systems' records are counted as skipped. ReaderError if no GPS record is usable.
    """
    path = Path(path)
    text = TextLines.load(path)
    end = _end_of_header(text)
    lines = [text.line(i) for i in range(len(text))]
    first = lines[0]
    version = _checked_version(path, first, "navigation ", "2.x GPS, 3.x")
    ftype, fsys = first[20:21].upper(), first[40:41].upper()
    if version < 3 and ftype != "N":
        raise ReaderError(path, f"RINEX 2 navigation type {ftype!r}: only GPS navigation ('N') files carry GPS orbits")
    if version >= 3 and fsys not in ("G", "M", " ", ""):
        raise ReaderError(path, f"RINEX 3 navigation file of system {fsys!r}: no GPS records")
    body = lines[end + 1 :]
    is_start = [(ln[:2].strip() != "") if version < 3 else (ln[:1].strip() != "") for ln in body]
    starts = [i for i, s in enumerate(is_start) if s]
    records: list[dict[str, float | int | str]] = []
    bad, other = 0, 0
    first_bad: tuple[int, str] | None = None
    for a, b in zip(starts, [*starts[1:], len(body)][: len(starts)], strict=True):
        rec_lines = body[a:b]
        if version >= 3 and rec_lines[0][:1].upper() != "G":
            other += 1
            continue
        try:
            if len(rec_lines) < 7:
                raise ValueError(f"record cut short ({len(rec_lines)} of 8 lines)")
            if b == len(body) and not text.terminated and (len(rec_lines) < 8 or len(rec_lines[-1].rstrip()) < 22):
                raise ValueError("record cut short (file ends inside it)")
            records.append(_nav_record(rec_lines, version))
        except (ValueError, IndexError) as err:
            bad += 1
            first_bad = first_bad or (end + 2 + a, str(err))
    skipped = []
    if bad and first_bad:
        skipped.append(
            Skipped(
                path.name,
                f"unreadable or cut navigation records (first at line {first_bad[0]}: {first_bad[1]})",
                bad,
                "lost",
            )
        )
    if other:
        skipped.append(Skipped(path.name, "non-GPS navigation records (only GPS orbits are used)", other))
    if not records:
        where = f"; first problem at line {first_bad[0]}: {first_bad[1]}" if first_bad else ""
        raise ReaderError(path, f"no usable GPS navigation record{where}")
    unique = {(r["sv_id"], r["week"], r["toe_sow"], r["iode"]): r for r in reversed(records)}
    if len(unique) < len(records):
        skipped.append(Skipped(path.name, "duplicate navigation records", len(records) - len(unique)))
    eph = GpsEphemerides.from_records(list(unique.values()), iono=_klobuchar(lines[: end + 1]))
    return NavFile(path, version, eph, len(eph), skipped)


def read_rinex_nav(path: Path | str) -> GpsEphemerides:
    """GPS broadcast ephemerides of a RINEX navigation file (`read_rinex_nav_file` for what was skipped)."""
    return read_rinex_nav_file(path).ephemerides


def _nav_siblings(obs: Path) -> list[Path]:
    """Navigation files named after an observation file (RINEX 2 short names, RINEX 3 long names)."""
    names: list[str] = []
    suffix = obs.suffix
    if len(suffix) >= 2 and suffix[-1] in "oO":
        names += [obs.stem + suffix[:-1] + ch for ch in "nNpP"]
    m = re.match(r"(.*_)[A-Z]O(\.rnx.*)$", obs.name, flags=re.IGNORECASE)
    if m:
        names += [f"{m.group(1)}{kind}{m.group(2)}" for kind in ("GN", "MN")]
    if suffix.lower() == ".obs":
        names += [obs.stem + ".nav"]
    return [obs.with_name(n) for n in dict.fromkeys(names) if obs.with_name(n).is_file()]


def find_nav_files(obs: Path, topics: Mapping[str, str] | None = None) -> list[Path]:
    """The navigation file(s) for an observation file: `topics['nav']`, a same-named sibling, or the directory's."""
    if topics and topics.get("nav"):
        nav = Path(topics["nav"])
        if not nav.is_file():
            raise ReaderError(nav, "navigation file given with --topic nav= does not exist", "nav")
        return [nav]
    siblings = _nav_siblings(obs)
    if siblings:
        return siblings[:1]
    return sorted(p for p in obs.parent.iterdir() if p.is_file() and p != obs and is_gps_nav(p))


# ---------------------------------------------------------------------------------------------------
# the log


def obs_files(path: Path) -> list[tuple[Path, str]]:
    """The observation files of a log (a file or a directory) with their receiver ids, in a fixed order."""
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.is_file() and is_rinex_obs(p))
        if not files:
            raise ReaderError(path, "directory holds no RINEX observation file")
    else:
        files = [path]
    markers = []
    for f in files:
        marker = ""
        with f.open("rb") as fh:
            for raw in fh:
                line = raw.decode("latin-1")
                if line[60:80].strip() == "MARKER NAME":
                    marker = line[:60].strip()
                if "END OF HEADER" in line:
                    break
        markers.append(marker or f.stem)
    dup = {m for m in markers if markers.count(m) > 1}
    return [(f, f"{m}_{f.name}" if m in dup else m) for f, m in zip(files, markers, strict=True)]


@dataclass
class _FileResult:
    rows: dict[str, np.ndarray]
    stream: StreamInfo
    navs: list[NavFile]
    skipped: list[Skipped]
    approx_xyz: tuple[float, float, float] | None = None


def _observation_rows(scan: ObsScan, receiver_id: str, skipped: list[Skipped]) -> dict[str, np.ndarray]:
    """The rows of one file (t_ns instead of t_s), skipping satellites with garbage or no L1 code."""
    cols = _extract(scan)
    if cols.bad.any():
        skipped.append(
            Skipped(receiver_id, "satellite rows with a field that is not a number", int(cols.bad.sum()), "lost")
        )
    no_code = ~np.isfinite(cols.pr) & ~cols.bad
    if no_code.any():
        skipped.append(
            Skipped(receiver_id, "satellite rows without an L1 pseudorange (see the priority list)", int(no_code.sum()))
        )
    idx = np.flatnonzero(np.isfinite(cols.pr) & ~cols.bad)
    doppler, freq = cols.doppler[idx], cols.freq[idx]
    return {
        "t_ns": scan.epoch_ns[scan.row_epoch[idx]],
        "sv_id": scan.row_sv[idx],
        "pseudorange_m": cols.pr[idx],
        "pseudorange_rate_mps": -doppler * C_MPS / freq,
        "doppler_hz": doppler,
        "carrier_phase_cycles": cols.phase[idx],
        "carrier_freq_hz": freq,
        "cn0_dbhz": cols.cn0[idx],
    }


def _add_satellite_states(
    rows: dict[str, np.ndarray], navs: list[NavFile], obs_name: str, receiver_id: str, skipped: list[Skipped]
) -> None:
    """Fill the sv_* columns of GPS rows from the broadcast orbits; count every row left without."""
    sv = rows["sv_id"]
    gps = np.char.startswith(sv, "G") if len(sv) else np.zeros(0, dtype=bool)
    if navs and gps.any():
        eph = navs[0].ephemerides if len(navs) == 1 else _merge(navs)
        g = np.flatnonzero(gps)
        states = states_at_transmission(eph, sv[g], rows["t_ns"][g] / 1e9, rows["pseudorange_m"][g]).columns()
        for name, values in states.items():
            rows[name] = np.full(len(sv), np.nan)
            rows[name][g] = values
        missing = int((~np.isfinite(states["sv_x_m"])).sum())
        if missing:
            skipped.append(
                Skipped(
                    receiver_id,
                    "GPS rows without a valid broadcast ephemeris; satellite states NaN",
                    missing,
                    "no ephemeris",
                )
            )
    elif gps.any():
        reason = f"no navigation file found for {obs_name} (give one with --topic nav=FILE); no satellite states"
        skipped.append(Skipped(receiver_id, reason, int(gps.sum()), "no ephemeris"))
    if (~gps).any():
        skipped.append(
            Skipped(
                receiver_id,
                "non-GPS rows: no satellite states (only GPS orbits are modelled)",
                int((~gps).sum()),
                "no ephemeris",
            )
        )


def _navigation(
    obs: Path, topics: Mapping[str, str] | None, cache: dict[Path, NavFile | None], skipped: list[Skipped]
) -> list[NavFile]:
    """The navigation files for `obs`, each read once per log.

    A nav file the search found that cannot be read costs only the satellite states (listed as lost);
    one named with --topic nav= is the user's explicit choice, so its problem is an error.
    """
    navs = []
    for nav_path in find_nav_files(obs, topics):
        if nav_path not in cache:
            try:
                cache[nav_path] = read_rinex_nav_file(nav_path)
            except ReaderError as err:
                if topics and topics.get("nav"):
                    raise
                cache[nav_path] = None
                skipped.append(Skipped(nav_path.name, f"navigation file unusable: {err.problem}", 1, "lost"))
        nav = cache[nav_path]
        if nav is not None:
            navs.append(nav)
    return navs


def _read_obs_file(
    path: Path, receiver_id: str, topics: Mapping[str, str] | None, nav_cache: dict[Path, NavFile | None]
) -> _FileResult:
    scan = scan_obs(path)
    skipped = list(scan.skipped)
    rows = _observation_rows(scan, receiver_id, skipped)
    navs = _navigation(path, topics, nav_cache, skipped)
    _add_satellite_states(rows, navs, path.name, receiver_id, skipped)
    epochs = len(np.unique(rows["t_ns"]))
    stream = StreamInfo("observations", receiver_id, path.name, f"RINEX {scan.version:.2f} obs", epochs)
    xyz = scan.header.approx_xyz
    return _FileResult(rows, stream, navs, skipped, None if xyz is None or not any(xyz) else xyz)


def _merge(navs: list[NavFile]) -> GpsEphemerides:
    """Several navigation files as one set of records (duplicates are harmless: the nearest toe wins)."""
    eph = [n.ephemerides for n in navs]
    names = [f for f in GpsEphemerides.__dataclass_fields__ if f != "iono"]
    recs = [{k: getattr(e, k)[i].item() for k in names} for e in eph for i in range(len(e))]
    return GpsEphemerides.from_records(recs, iono=next((e.iono for e in eph if e.iono), None))


def _assemble(path: Path, parts: list[_FileResult], skipped: list[Skipped]) -> EpochTable:
    """Every receiver's rows through `build_table` (time base = first epoch, sorting, duplicates)."""
    n_rows = [len(p.rows["t_ns"]) for p in parts]
    names = sorted({k for p in parts for k in p.rows})
    cols: dict[str, np.ndarray] = {
        k: np.concatenate([p.rows.get(k, np.full(n, np.nan)) for p, n in zip(parts, n_rows, strict=True)])
        for k in names
    }
    cols["t_ns"] = cols["t_ns"].astype(np.int64)
    cols["receiver_id"] = np.repeat([p.stream.stream_id for p in parts], n_rows)
    t0 = int(cols["t_ns"].min())
    streams = [p.stream for p in parts]
    seen: set[Path] = set()
    for p in parts:
        for nav in p.navs:
            if nav.path in seen:
                continue
            seen.add(nav.path)
            toe_ns = np.round(nav.ephemerides.toe_s * 1e9).astype(np.int64)
            span = (float((toe_ns.min() - t0) / 1e9), float((toe_ns.max() - t0) / 1e9))
            streams.append(
                StreamInfo(
                    "nav", nav.path.name, nav.path.name, f"RINEX {nav.version:.2f} nav (GPS)", nav.records, *span
                )
            )
            skipped.extend(nav.skipped)
    # The header's APPROX POSITION: a static station's surveyed site (the known-station detectors decide
    # whether the receiver really stayed there; a moving receiver's header is only where it started).
    metadata = {
        f"{APPROX_POSITION_KEY}.{p.stream.stream_id}": " ".join(f"{v:.4f}" for v in p.approx_xyz)
        for p in parts
        if p.approx_xyz is not None
    }
    table = build_table(
        path, "rinex", "gps", {"observations": pd.DataFrame(cols)}, streams, skipped, t0_ns=t0, metadata=metadata
    )
    navs = list({n.path: n for p in parts for n in p.navs}.values())
    table.ephemerides = (navs[0].ephemerides if len(navs) == 1 else _merge(navs)) if navs else None
    return table


def read_rinex(path: Path, topics: Mapping[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    """Read a RINEX observation file, or a directory of them (one receiver each), into an EpochTable."""
    path = Path(path)
    files = obs_files(path)
    skipped: list[Skipped] = []
    if topics and set(topics) - {"nav"}:
        other = {k: v for k, v in topics.items() if k != "nav"}
        skipped.append(Skipped("<rinex>", f"--topic ignored for RINEX logs except nav= ({other})", len(other)))
    nav_cache: dict[Path, NavFile | None] = {}
    parts = []
    for i, (f, rid) in enumerate(files):
        part = _read_obs_file(f, rid, topics, nav_cache)
        parts.append(part)
        skipped.extend(part.skipped)
        if progress:
            progress(i + 1, len(files))
    if not any(len(p.rows["t_ns"]) for p in parts):
        reasons = "; ".join(str(s) for s in skipped) or "no epochs after the header"
        raise ReaderError(path, f"no usable observation in the file(s): {reasons}", "observations")
    return _assemble(path, parts, skipped)


def _is_rinex(path: Path, head: bytes) -> bool:
    if path.is_dir():
        # a directory with CSV files is a CSV log, even when RINEX files lie beside them
        return not any(path.glob("*.csv")) and any(p.is_file() and is_rinex_obs(p) for p in sorted(path.iterdir()))
    first = head.split(b"\n", 1)[0].decode("latin-1")
    return "RINEX VERSION / TYPE" in first


FORMATS = (
    ReaderFormat(
        "rinex",
        "RINEX observation file (2.10, 2.11, 3.02-3.05) or a directory of them, navigation file beside",
        read_rinex,
        _is_rinex,
        rewrite="spooflens.writers.rinex_rewrite:rewrite_rinex_log",
    ),
)
