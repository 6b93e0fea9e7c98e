"""RINEX navigation files: GPS, Galileo and BeiDou broadcast orbits (and the Klobuchar ionosphere), and
where to find them. A BeiDou record's times are BDT (toc's calendar, toe's week and time of week): they
are put on the GPS scale (+14 s, week + 1356) as `spooflens.gnss.ephemeris` keeps them.

A Galileo record has the GPS layout with other meanings in three fields (RINEX 3.04 A8): line 5's
second field is the data sources (bit 0 I/NAV E1-B, bit 1 F/NAV E5a-I, bit 2 I/NAV E5b-I; bit 8 clock
for E5a/E1, bit 9 for E5b/E1), line 6 holds SISA, the health bits and the two group delays
BGD(E1, E5a), BGD(E1, E5b), and the week is GPS's continuous week. An E1 pseudorange is corrected with
the BGD of the clock the record carries; only the E1-B health bits (0-2) speak for E1, and only an
I/NAV record sends them, so F/NAV records (the same orbit, re-broadcast on E5a) are counted and left out.
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

from readers.orbits import ORBIT_SYSTEMS as MODELLED
from readers.rinex.text import GPS_EPOCH, TextLines, checked_version, end_of_header, first_line
from spooflens.epoch_table import Skipped
from spooflens.errors import ReaderError
from spooflens.gnss.ephemeris import BDT_OFFSET_S, BDT_WEEK_OFFSET, SECONDS_PER_WEEK, GpsEphemerides, Klobuchar

ORBIT_SYSTEMS = tuple(MODELLED)  # RINEX 3 systems whose records are read
_RINEX3_SYSTEMS = (*ORBIT_SYSTEMS, "M", " ", "")
GALILEO_INAV = 0b101  # data sources: I/NAV E1-B or E5b-I
GALILEO_E5A_CLOCK = 1 << 8
E1B_HEALTH = 0b111  # E1-B data validity and signal health


def is_broadcast_nav(path: Path) -> bool:
    """True for a RINEX navigation file that can hold orbits this tool models (RINEX 2 'N', RINEX 3 GPS,
    Galileo, BeiDou or mixed)."""
    line = first_line(path)
    if "RINEX VERSION / TYPE" not in line or line[20:21].upper() != "N":
        return False
    return line[:9].strip().startswith("2") or line[40:41].upper() in _RINEX3_SYSTEMS


@dataclass(frozen=True)
class NavFile:
    """A navigation file's GPS, Galileo and BeiDou records, with what was skipped and why."""

    path: Path
    version: float
    ephemerides: GpsEphemerides
    records: int
    skipped: list[Skipped]

    @property
    def label(self) -> str:
        """What the file is, for its stream: 'RINEX 3.04 nav (GPS, Galileo)'."""
        present = {s[:1] for s in self.ephemerides.satellites()}
        return f"RINEX {self.version:.2f} nav ({', '.join(n for k, n in MODELLED.items() if k in present)})"


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
# BeiDou (Table A14): line 6 holds SatH1 and TGD1 (B1/B3) where GPS has health and TGD; line 7 no fit
_BEIDOU_KEYS = _NAV_KEYS[:6]
# Galileo (RINEX 3.04 Table A8): lines 5-7 carry data sources, SISA, health, BGDs and the transmission time
_GALILEO_KEYS = (
    *_NAV_KEYS[:4],
    ("idot", "data_sources", "week", None),
    (None, "health", "bgd_e5a", "bgd_e5b"),
)


def _nav_number(text: str) -> float | None:
    s = text.strip()
    if not s:
        return None
    return float(s.replace("D", "E").replace("d", "e"))


# a number as some writers put it, narrower than the format's 19 columns (goGPS: `4.800000000000D+1`, a
# one-digit exponent, so the fields of a line shift)
_NUMBER = re.compile(r"[+-]?(?:\d+\.\d*|\.\d+)(?:[DdEe][+-]?\d+)?")


def _row(text: str, count: int) -> list[float | None]:
    """The `count` numbers of one record line's data part: in the format's 19-column fields, else (a writer
    with narrower fields) split at the numbers themselves when they are exactly `count` (blanks then not
    allowed, as nothing says which field is blank)."""
    try:
        return [_nav_number(text[19 * k : 19 * k + 19]) for k in range(count)]
    except ValueError:
        found = _NUMBER.findall(text)
        if len(found) != count or "".join(found) != "".join(text.split()):
            raise
        return [float(v.replace("D", "E").replace("d", "e")) for v in found]


def _nav_record(lines: list[str], version: float) -> dict[str, float | int | str]:
    """One GPS, Galileo or BeiDou broadcast record (first line + 7 orbit lines) -> GpsEphemerides.from_records
    keys."""
    first = lines[0]
    system = "G" if version < 3 else first[:1].upper()
    if version < 3:
        sv = f"G{int(first[:2]):02d}"
        yy, mo, d, h, mi = (int(v) for v in first[2:17].split())
        sec = float(first[17:22])
        year = yy + (2000 if yy < 80 else 1900) if yy < 100 else yy
        head, col0 = first[22:79], 3
    else:
        sv = f"{system}{int(first[1:3]):02d}"
        year, mo, d, h, mi, isec = (int(v) for v in first[4:23].split())
        sec = float(isec)
        head, col0 = first[23:80], 4
    toc = datetime(year, mo, d, h, mi, tzinfo=UTC) + timedelta(seconds=sec)
    rec: dict[str, float | int | str] = {"sv_id": sv, "toc_s": (toc - GPS_EPOCH).total_seconds()}
    for key, v in zip(("af0", "af1", "af2"), _row(head, 3), strict=True):
        if v is None:
            raise ValueError(f"{key} is blank")
        rec[key] = v
    for row, keys in enumerate({"E": _GALILEO_KEYS, "C": _BEIDOU_KEYS}.get(system, _NAV_KEYS)):
        line = lines[row + 1] if row + 1 < len(lines) else ""
        for name, v in zip(keys, _row(line[col0:], len(keys)), strict=True):
            if name is None:
                continue
            if v is None and name not in _OPTIONAL:
                raise ValueError(f"{name} is blank")
            rec[name] = 0.0 if v is None else v
    if system == "C":  # BeiDou time is 14 s behind GPS time; its week 0 is GPS week 1356
        rec["toc_s"] = float(rec["toc_s"]) + BDT_OFFSET_S
        rec["toe_sow"] = float(rec["toe_sow"]) + BDT_OFFSET_S
        rec["week"] = float(rec["week"]) + BDT_WEEK_OFFSET
    if system == "E":
        sources = int(float(rec.pop("data_sources")))
        if not sources & GALILEO_INAV:
            raise _FNavRecord
        bgd_e5a, bgd_e5b = float(rec.pop("bgd_e5a")), float(rec.pop("bgd_e5b"))
        rec["tgd"] = bgd_e5a if sources & GALILEO_E5A_CLOCK else bgd_e5b
        rec["health"] = int(float(rec["health"])) & E1B_HEALTH
    fit = float(rec.pop("fit_hours", 0.0))
    if fit > 4.0:
        rec["max_age_s"] = fit * 3600.0 / 2
    for key in ("week", "health", "iode"):  # integers a receiver writes: anything beyond 32 bits is damage
        if not abs(float(rec[key])) < 2**31:
            raise ValueError(f"{key} {rec[key]} out of range")
    week = int(rec["week"])
    toc_week = int(float(rec["toc_s"]) // SECONDS_PER_WEEK)
    while week + 512 < toc_week:  # a week written modulo 1024
        week += 1024
    rec["week"], rec["health"], rec["iode"] = week, int(rec["health"]), int(rec["iode"])
    values = [float(v) for key, v in rec.items() if key != "sv_id"]
    if not np.all(np.isfinite(values)) or not 2000.0 < float(rec["sqrt_a"]) < 10000.0 or not 0 <= float(rec["e"]) < 1:
        raise ValueError("implausible orbit (sqrt(A) or e out of range)")
    return rec


class _FNavRecord(Exception):
    """A Galileo F/NAV record: its orbit is the I/NAV one's, without the E1 health."""


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


# RINEX 4 message types whose records carry RINEX 3's layout for the systems read (GPS LNAV, Galileo I/NAV and
# F/NAV, BeiDou D1/D2); CNAV, CNV1-3 and the others have more lines and other fields
V4_READ = {"G": ("LNAV",), "E": ("INAV", "FNAV"), "C": ("D1", "D2")}


def _v4_records(path: Path, body: list[str]) -> tuple[list[str], Klobuchar | None, list[Skipped]]:
    """RINEX 4's navigation body as RINEX 3's: the lines of each `> EPH` record of a message type read (each
    opens with its satellite's line, as in 3.x), the GPS Klobuchar terms from its first `> ION G.. LNAV`
    record (4.x moved them out of the header), and what was passed over, counted."""
    kept: list[str] = []
    passed: Counter[str] = Counter()
    iono: Klobuchar | None = None
    block: list[str] = []
    marker: list[str] = []

    def close() -> None:
        nonlocal iono
        if not marker:
            return
        kind, sv, message = (*marker, "", "", "")[:3]  # `> EPH G01 LNAV`
        if kind == "EPH" and message in V4_READ.get(sv[:1], ()):
            kept.extend(block)
        elif kind == "ION" and sv[:1] == "G" and message == "LNAV" and iono is None:
            iono = _v4_klobuchar(block)
        else:
            passed[f"{kind} {sv[:1]} {message}".strip()] += 1

    for line in body:
        if line.startswith(">"):
            close()
            marker, block = line[1:].split(), []
        elif marker:
            block.append(line)
    close()
    skipped = [
        Skipped(path.name, f"RINEX 4 records not read ({what}: other message types, or not orbits)", n)
        for what, n in sorted(passed.items())
    ]
    return kept, iono, skipped


def _v4_klobuchar(block: list[str]) -> Klobuchar | None:
    """alpha0-3, beta0-3 of a RINEX 4 `> ION G.. LNAV` record: 3 numbers after its epoch, then 4 a line."""
    fields = [block[0][23 + 19 * k : 42 + 19 * k] for k in range(3)] if block else []
    fields += [line[4 + 19 * k : 23 + 19 * k] for line in block[1:3] for k in range(4)]
    try:
        values = [_nav_number(f) for f in fields]
    except ValueError:
        return None
    if len(values) < 8 or any(v is None for v in values[:8]):
        return None
    alpha, beta = values[:4], values[4:8]
    return Klobuchar((alpha[0], alpha[1], alpha[2], alpha[3]), (beta[0], beta[1], beta[2], beta[3]))  # type: ignore[arg-type]


def read_rinex_nav_file(path: Path | str) -> NavFile:
    """Read a RINEX 2 GPS or RINEX 3 or 4 (GPS, Galileo, BeiDou or mixed) navigation file, keeping the GPS,
    Galileo I/NAV and BeiDou records.

    Records that are cut short or hold a field that is not a number are skipped and counted; other
    systems' records are counted as skipped. ReaderError if no record is usable.
    """
    path = Path(path)
    text = TextLines.load(path)
    end = end_of_header(text)
    lines = [text.line(i) for i in range(len(text))]
    first = lines[0]
    version = checked_version(path, first, "navigation ", "2.x GPS, 3.x, 4.x")
    ftype, fsys = first[20:21].upper(), first[40:41].upper()
    if version < 3 and ftype != "N":
        raise ReaderError(path, f"RINEX 2 navigation type {ftype!r}: only GPS navigation ('N') files carry GPS orbits")
    if version >= 3 and fsys not in _RINEX3_SYSTEMS:
        raise ReaderError(
            path, f"RINEX {int(version)} navigation file of system {fsys!r}: no GPS, Galileo or BeiDou records"
        )
    body = lines[end + 1 :]
    iono = _klobuchar(lines[: end + 1])
    v4_skipped: list[Skipped] = []
    if version >= 4:
        body, v4_iono, v4_skipped = _v4_records(path, body)
        iono = iono or v4_iono
    is_start = [(ln[:2].strip() != "") if version < 3 else (ln[:1].strip() != "") for ln in body]
    starts = [i for i, s in enumerate(is_start) if s]
    records: list[dict[str, float | int | str]] = []
    bad, other, fnav = 0, 0, 0
    first_bad: tuple[int, str] | None = None
    for a, b in zip(starts, [*starts[1:], len(body)][: len(starts)], strict=True):
        rec_lines = body[a:b]
        if version >= 3 and rec_lines[0][:1].upper() not in ORBIT_SYSTEMS:
            other += 1
            continue
        try:
            if len(rec_lines) < 7:
                raise ValueError(f"record cut short ({len(rec_lines)} of 8 lines)")
            if b == len(body) and not text.terminated and (len(rec_lines) < 8 or len(rec_lines[-1].rstrip()) < 22):
                raise ValueError("record cut short (file ends inside it)")
            records.append(_nav_record(rec_lines, version))
        except _FNavRecord:
            fnav += 1
        except (ValueError, IndexError, OverflowError) as err:
            bad += 1
            first_bad = first_bad or (end + 2 + a, str(err))
    skipped = list(v4_skipped)
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
        skipped.append(
            Skipped(path.name, "navigation records of GLONASS, QZSS, ... (GPS, Galileo, BeiDou orbits are used)", other)
        )
    if fnav:
        skipped.append(Skipped(path.name, "Galileo F/NAV records (the I/NAV records carry the same orbits)", fnav))
    if not records:
        where = f"; first problem at line {first_bad[0]}: {first_bad[1]}" if first_bad else ""
        raise ReaderError(path, f"no usable GPS, Galileo or BeiDou navigation record{where}")
    unique = {(r["sv_id"], r["week"], r["toe_sow"], r["iode"]): r for r in reversed(records)}
    if len(unique) < len(records):
        skipped.append(Skipped(path.name, "duplicate navigation records", len(records) - len(unique)))
    eph = GpsEphemerides.from_records(list(unique.values()), iono=iono)
    return NavFile(path, version, eph, len(eph), skipped)


def read_rinex_nav(path: Path | str) -> GpsEphemerides:
    """The broadcast ephemerides of a RINEX navigation file (`read_rinex_nav_file` for what was skipped)."""
    return read_rinex_nav_file(path).ephemerides


def _nav_siblings(obs: Path) -> list[Path]:
    """Navigation files named after an observation file (RINEX 2 short names, RINEX 3 long names)."""
    names: list[str] = []
    # shipped packed: `07590920.05o.gz`, Hatanaka `.05d.Z`, RINEX 3 `_MO.crx.gz`; the nav file packed or not
    base = re.sub(r"\.(gz|z|bz2|zip)$", "", obs.name, flags=re.IGNORECASE)
    stem, _, suffix = base.rpartition(".") if "." in base else (base, "", "")
    if len(suffix) >= 2 and suffix[-1] in "oOdD":
        names += [f"{stem}.{suffix[:-1]}{ch}" for ch in "nNpP"]
    m = re.match(r"(.*_)[A-Z]O\.[rc]nx$", base, flags=re.IGNORECASE)
    if m:
        names += [f"{m.group(1)}{kind}.rnx" for kind in ("GN", "MN")]
    if suffix.lower() == "obs":
        names += [stem + ".nav"]
    packed = [n + ext for n in names for ext in ("", ".gz", ".Z", ".zip", ".bz2")]
    return [obs.with_name(n) for n in dict.fromkeys(packed) if obs.with_name(n).is_file()]


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
    return sorted(p for p in obs.parent.iterdir() if p.is_file() and p != obs and is_broadcast_nav(p))
