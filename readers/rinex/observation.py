"""RINEX observation files: the header, the body's epochs and satellite rows, and the L1 observables.

`scan_obs` lays a file out (every data epoch, where each satellite's fields are) once, shared by the
reader and the rewriter (`spooflens.writers.rinex_rewrite`); `extract_l1` then reads each satellite's
L1-band code, phase, Doppler and C/N0 by the priority lists below.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from readers.rinex.text import (
    NS,
    SUPPORTED_VERSIONS,
    BoolArray,
    FloatArray,
    IntArray,
    TextLines,
    calendar_ns,
    checked_version,
    decimal_parts,
    end_of_header,
    first_line,
    header_lines,
    parse_fixed,
    parse_int,
    sv_ids,
)
from spooflens.epoch_table import GPS_EPOCH_UNIX_NS, Skipped, utc_gps_offset_ns
from spooflens.errors import ReaderError

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
# header


def is_rinex_obs(path: Path) -> bool:
    """True for a RINEX observation file (by content: its first line)."""
    line = first_line(path)
    return "RINEX VERSION / TYPE" in line and "OBSERVATION DATA" in line.upper()


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


def obs_types(lines: list[str], version: float) -> dict[str, tuple[str, ...]]:
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


def read_obs_header(text: TextLines) -> ObsHeader:
    """Parse the header of an observation file; ReaderError for what is not a supported one."""
    path = text.path
    end = end_of_header(text)
    lines = [text.line(i) for i in range(end + 1)]
    first = lines[0]
    version = checked_version(path, first, "", SUPPORTED_VERSIONS)
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
            # the word after the seconds, at columns 49-51 by the format; some writers (a Hatanaka sample file)
            # widen the seconds by a character and push it right
            word = re.search(r"[A-Za-z]{3}", line[30:60])
            tsys = word.group(0).upper() if word else ""
        elif label == "SYS / SCALE FACTOR" and line[2:6].strip() not in ("", "1"):
            factor = line[2:6].strip()
            raise ReaderError(path, f"observations scaled by {factor} (SYS / SCALE FACTOR) are not supported")
        elif label == "GLONASS SLOT / FRQ #":
            for slot, k in re.findall(r"R\s*(\d{1,2})\s+([-+]?\d+)", line[:60]):
                glo[f"R{int(slot):02d}"] = int(k)
    tsys = tsys or DEFAULT_TIME_SYSTEM.get(system, "GPS")
    types = obs_types(lines, version)
    if not types:
        label = "# / TYPES OF OBSERV" if version < 3 else "SYS / # / OBS TYPES"
        raise ReaderError(path, f"header declares no observation types ({label})")
    return ObsHeader(version, system, marker, xyz, types, tsys, glo, end)


def rinex_approx_position(path: Path | str) -> tuple[float, float, float] | None:
    """The header's APPROX POSITION XYZ (ECEF, m), the surveyed site for a static station; None if absent."""
    path = Path(path)
    if not path.is_file():
        raise ReaderError(path, "cannot read: no such file")
    for line in header_lines(path):
        if line[60:80].strip() == "APPROX POSITION XYZ":
            try:
                x, y, z = (float(v) for v in line[:42].split()[:3])
            except ValueError:
                return None
            return None if x == y == z == 0.0 else (x, y, z)
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
    # epoch flag 1: power failure between the previous epoch and this one (every carrier restarts)
    epoch_power_failure: BoolArray
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
        leap = utc_gps_offset_ns(utc)
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
        v, good = parse_int(text.field(lines, a, b - a))
        parts.append(v)
        ok &= good
    sec_mant, sec_frac, blank, bad = decimal_parts(text.field(lines, cols[5][0], cols[5][1] - cols[5][0]))
    ok &= ~blank & ~bad
    y = parts[0]
    if two_digit_year:
        y = np.where(y < 80, y + 2000, np.where(y < 100, y + 1900, y))
    ns, valid = calendar_ns(y, parts[1], parts[2], parts[3], parts[4], sec_mant, sec_frac)
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
    nsats, _ = parse_int(c[cand, 29:32])
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

    ep_line, ep_hdr, ep_data0, ep_ns, ep_k, ep_layout, ep_flag = [], [], [], [], [], [], []
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
            redefined = obs_types(special, header.version)
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
            ep_flag.append(f)
        i = end
    ends_at_cut = bool(ep_line) and ep_data0[-1] + ep_k[-1] * lps[ep_layout[-1]] == n
    if ends_at_cut and not text.terminated and not _clean_end(int(text.lens[-1]), header.version):
        count("file cut mid-epoch; kept every epoch before", "lost")
        for arr in (ep_line, ep_hdr, ep_data0, ep_ns, ep_k, ep_layout, ep_flag):
            arr.pop()
    e_line = np.asarray(ep_line, dtype=np.int64)
    nsat = np.asarray(ep_k, dtype=np.int64)
    row_epoch = np.repeat(np.arange(len(e_line)), nsat)
    offsets = np.concatenate(([0], np.cumsum(nsat)[:-1])) if len(nsat) else np.zeros(0, dtype=np.int64)
    slot = np.arange(len(row_epoch)) - np.repeat(offsets, nsat)
    e_lps = np.asarray(lps, dtype=np.int64)[np.asarray(ep_layout, dtype=np.int64)]
    tok = text.field(e_line[row_epoch] + slot // 12, 32 + 3 * (slot % 12), 3)
    sv, sys, ok = sv_ids(tok)
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
        epoch_power_failure=np.asarray(ep_flag, dtype=np.int64) == 1,
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
    flag, flag_ok = parse_int(text.field(ep_lines, 29, 3))
    nsat, nsat_ok = parse_int(text.field(ep_lines, 32, 3))
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
        redefined = obs_types(special, header.version)
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
    sv, sys, ok = sv_ids(text.field(row_line, 0, 3))
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
        epoch_power_failure=flag[epochs] == 1,
        skipped=skipped,
    )


def scan_obs(path: Path) -> ObsScan:
    """Read and lay out one observation file (header, epochs, satellite rows)."""
    text = TextLines.load(path)
    header = read_obs_header(text)
    scan = _scan_v2(text, header) if header.version < 3 else _scan_v3(text, header)
    scan.skipped.extend(Skipped(path.name, loss, 1, "lost") for loss in text.losses)
    if text.packing:
        how = " inside ".join(reversed(text.packing))
        scan.skipped.append(Skipped(path.name, f"read as shipped: {how}, unpacked in memory", 1, "unpacked"))
    return scan


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
    lli: IntArray  # the phase's loss-of-lock indicator (0 where blank or no phase)


def extract_l1(scan: ObsScan) -> _Columns:
    """Pick each row's L1 signal by the priority list and read its code, phase, Doppler and C/N0."""
    n = len(scan.row_sv)
    nan = np.full(n, np.nan)
    cols = _Columns(
        nan.copy(), nan.copy(), nan.copy(), nan.copy(), nan.copy(), np.zeros(n, dtype=bool), np.zeros(n, np.int64)
    )
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
                        if kind == "L":
                            cols.lli[got] = _lli(scan, got, types.index(t))
                if sys == "R":
                    k = pd.Series(scan.row_sv[got]).map(glo).to_numpy(dtype=float)
                    base, step = GLONASS_FDMA.get(code[1], (np.nan, np.nan))
                    cols.freq[got] = base + k * step
                else:
                    cols.freq[got] = carrier_frequency_hz(sys, code if version >= 3 else "C1C", version)
                todo = todo[blank]
    return cols


def _lli(scan: ObsScan, rows: IntArray, type_index: int) -> IntArray:
    """The loss-of-lock indicator digit after an observation's F14.3 (column 15 of its field); 0 if blank."""
    line, col = scan.field_at(rows, type_index)
    c = scan.text.field(line, col + 14, 1)[:, 0].astype(np.int64)
    return np.where((c >= 48) & (c <= 57), c - 48, 0)


def _values(scan: ObsScan, rows: IntArray, type_index: int) -> tuple[FloatArray, BoolArray, BoolArray]:
    """F14.3 values of one observation type for the given rows; 0.0 counts as blank (RINEX: missing)."""
    line, col = scan.field_at(rows, type_index)
    values, blank, bad = parse_fixed(scan.text.field(line, col, 14))
    blank = blank | (values == 0.0)
    values[blank] = np.nan
    return values, blank, bad


# ---------------------------------------------------------------------------------------------------
# navigation files
