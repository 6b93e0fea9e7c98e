"""NMEA sentences decoded with pynmeagps into plain values with units (the one NMEA mapping).

Read: GGA and GNS (position, MSL altitude and geoid separation, quality, satellites, HDOP), RMC
(position, speed, course, date, magnetic variation), GLL (position), VTG (speed, course), GSA (satellites
used, DOPs), GSV (per-satellite elevation, azimuth, C/N0), GST (position error sigmas), ZDA (date), and the
headings HDT and THS (true) and HDG (magnetic; made true with the deviation and variation it carries);
HDM, VHW's magnetic heading and an HDG without variation are magnetic headings, made true where they are
assembled with the variation of the log's RMC nearest in time (taken as true where there is none, said so).
Proprietary and variant sentences (Unicore, Trimble, Septentrio, Feyman, Fugro) are read in
`proprietary.py` into the same values. Every other sentence type is counted and skipped.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

from pynmeagps import NMEAReader
from pynmeagps.exceptions import NMEAMessageError, NMEAParseError, NMEATypeError
from pynmeagps.nmeahelpers import calc_checksum
from pynmeagps.nmeatypes_core import VALNONE

from readers.nmea.lines import Sentence
from spooflens.constants import KNOT_MPS
from spooflens.schema import FixType

# position sentences that carry their own height, satellites and velocity, no GSA/GSV/VTG beside them
# (proprietary.py): Trimble PTNL,GGK, Feyman FMI, Fugro FUGDP, Unicore HPD
SELF_CONTAINED_KINDS = ("GGK", "FMI", "FUGDP", "HPD")
POSITION_KINDS = ("GGA", "GNS", "RMC", "GLL", *SELF_CONTAINED_KINDS)
TIMED_KINDS = ("GGA", "GNS", "RMC", "GLL", "GST", "ZDA", *SELF_CONTAINED_KINDS)
# ATT: a proprietary attitude sentence's heading (proprietary.py), from GNSS antennas or a GNSS-aided INS
HEADING_KINDS = ("HDT", "THS", "HDG", "HDM", "VHW", "ATT")
EPOCH_KINDS = ("VTG", "GSA", "GSV")  # no time of their own: they belong to their receiver's current epoch
WANTED = frozenset(POSITION_KINDS + TIMED_KINDS + HEADING_KINDS + EPOCH_KINDS)

# GGA quality: 0 invalid, 1 GPS, 2 DGPS/SBAS, 3 PPS, 4 RTK fixed, 5 RTK float, 6 estimated (dead
# reckoning), 7 manual input, 8 simulation. The last three are not a GNSS fix: kept, as UNKNOWN.
GGA_QUALITY = {
    0: FixType.NO_FIX,
    1: FixType.FIX_3D,
    2: FixType.DGNSS,
    3: FixType.FIX_3D,
    4: FixType.RTK_FIXED,
    5: FixType.RTK_FLOAT,
    6: FixType.UNKNOWN,
    7: FixType.UNKNOWN,
    8: FixType.UNKNOWN,
}
# RMC/GLL/VTG/GNS mode indicator (NMEA >= 2.3): A autonomous, D differential, R RTK fixed, F RTK
# float, P precise, E estimated, M manual, S simulator, N not valid.
MODE = {
    "A": FixType.FIX_3D,
    "D": FixType.DGNSS,
    "R": FixType.RTK_FIXED,
    "F": FixType.RTK_FLOAT,
    "P": FixType.FIX_3D,
    "E": FixType.UNKNOWN,
    "M": FixType.UNKNOWN,
    "S": FixType.UNKNOWN,
    "N": FixType.NO_FIX,
}
FIX_MEANING = (
    "NMEA GGA quality 0 invalid, 1 GNSS, 2 DGNSS/SBAS, 3 PPS, 4 RTK fixed, 5 RTK float, 6 estimated (dead "
    "reckoning), 7 manual, 8 simulator; RMC/GLL/GNS mode A autonomous, D differential, R/F RTK, E estimated, "
    "M manual, S simulator, N invalid. Estimated, manual and simulator positions are kept with fix_type UNKNOWN"
)
# added to FIX_MEANING for a log with proprietary positions (a log without them needs no word of them)
PROPRIETARY_FIX_MEANING = (
    "Trimble PTNL,GGK quality 0 invalid, 1 autonomous, 2/6/8 RTK float, 3/7/9 RTK fixed, 4/13 DGPS, 5 SBAS, "
    "10/11 OmniSTAR (DGNSS), 12 Location RTK (UNKNOWN); Feyman FMI, Fugro FUGDP and Unicore HPD positions "
    "state no quality spooflens can map: UNKNOWN"
)

ParseErrors = (
    NMEAMessageError,
    NMEAParseError,
    NMEATypeError,
    ValueError,
    TypeError,
    IndexError,
    KeyError,
    OverflowError,
)


@dataclass
class Decoded:
    """One sentence's values, in SI units and degrees (NaN where the sentence leaves a field blank)."""

    sentence: Sentence
    kind: str = ""  # the role it plays in assembly: GGA for a Unicore GGAH, GGK for PTNL,GGK, ATT for PASHR
    name: str = ""  # as the log names it: GNGGAH, PTNLGGK, PASHR (its heading stream's id)
    receiver: str = ""  # receiver key: the talker, + "H" for a secondary antenna, or the proprietary address
    antenna: str = ""  # "H": a Unicore dual-antenna receiver's secondary antenna (its own receiver)
    tod_s: float = math.nan  # UTC seconds of day
    day: int | None = None  # days since 1970-01-01 (RMC, ZDA)
    lat: float = math.nan
    lon: float = math.nan
    valid: bool = True  # the sentence says its position (or heading) is usable
    fix_type: int = int(FixType.FIX_3D)
    alt_msl_m: float = math.nan
    geoid_sep_m: float = math.nan
    height_m: float = math.nan  # ellipsoidal height, where the sentence gives that (PTNL,GGK "EHT")
    speed_mps: float = math.nan
    course_deg: float = math.nan
    variation_deg: float = math.nan  # RMC: magnetic variation, east positive
    sats_used: float = math.nan
    used_svids: tuple[int, ...] = ()
    # GSA's system ID (NMEA 4.10: 1 GPS, 2 GLONASS, 3 Galileo, 4 BeiDou, 5 QZSS, 6 NavIC; 0 absent): a GN
    # talker's list is of that system alone
    gsa_system: int = 0
    nav_mode: int = 0  # GSA: 1 no fix, 2 2-D, 3 3-D
    hdop: float = math.nan
    vdop: float = math.nan
    std_lat_m: float = math.nan
    std_lon_m: float = math.nan
    std_alt_m: float = math.nan
    heading_deg: float = math.nan
    water_speed_mps: float = math.nan  # VHW: the vessel's log, speed through the water
    magnetic_only: bool = False  # HDM, VHW magnetic, HDG without variation: a magnetic heading, no variation
    heading_talker: str = ""  # the talker a heading row is filed under when not the sentence's own
    satellites: list[tuple[int, float, float, float, int]] = field(default_factory=list)  # svid, el, az, C/N0, sig

    def __post_init__(self) -> None:
        self.kind = self.kind or self.sentence.kind
        self.name = self.name or f"{self.sentence.talker}{self.sentence.kind}"
        self.receiver = self.receiver or self.sentence.talker

    @property
    def talker(self) -> str:
        return self.sentence.talker


def field_number(msg: Any, name: str) -> float:
    """A decoded sentence's numeric field (NaN when empty or not a number)."""
    v = getattr(msg, name, "")
    return float(v) if isinstance(v, int | float) and not isinstance(v, bool) else math.nan


def field_text(msg: Any, name: str) -> str:
    """A decoded sentence's text field ("" when empty)."""
    v = getattr(msg, name, "")
    return v if isinstance(v, str) else ""


def time_of_day(msg: Any, name: str = "time") -> float:
    """A decoded sentence's time field as seconds of the day (NaN when empty)."""
    t = getattr(msg, name, None)
    if not isinstance(t, dt.time):
        return math.nan
    return t.hour * 3600 + t.minute * 60 + t.second + t.microsecond / 1e6


def _day(year: int, month: int, day: int) -> int | None:
    try:
        return (dt.date(year, month, day) - dt.date(1970, 1, 1)).days
    except (ValueError, OverflowError):  # a damaged field can hold a 19-digit "year"
        return None


def _position(d: Decoded, msg: Any) -> None:
    d.lat, d.lon = field_number(msg, "lat"), field_number(msg, "lon")


def _mode(d: Decoded, mode: str) -> None:
    if mode[:1] in MODE:  # GNS carries one letter per system: the first (GPS) decides
        d.fix_type = int(MODE[mode[:1]])
        d.valid = d.valid and mode[:1] != "N"


def _gga(d: Decoded, msg: Any) -> None:
    d.tod_s = time_of_day(msg)
    _position(d, msg)
    quality = getattr(msg, "quality", "")
    if isinstance(quality, int):
        d.fix_type = int(GGA_QUALITY.get(quality, FixType.UNKNOWN))
        d.valid = quality != 0
    d.sats_used, d.hdop = field_number(msg, "numSV"), field_number(msg, "HDOP")
    d.alt_msl_m, d.geoid_sep_m = field_number(msg, "alt"), field_number(msg, "sep")


def _gns(d: Decoded, msg: Any) -> None:
    d.tod_s = time_of_day(msg)
    _position(d, msg)
    _mode(d, field_text(msg, "posMode"))
    d.sats_used, d.hdop = field_number(msg, "numSV"), field_number(msg, "HDOP")
    d.alt_msl_m, d.geoid_sep_m = field_number(msg, "alt"), field_number(msg, "sep")


_EAST = {"E": 1.0, "W": -1.0}  # a variation's or deviation's sign: east is added to a magnetic heading


def _rmc(d: Decoded, msg: Any) -> None:
    d.tod_s = time_of_day(msg)
    _position(d, msg)
    d.valid = field_text(msg, "status") == "A"
    _mode(d, field_text(msg, "posMode"))
    d.speed_mps = field_number(msg, "spd") * KNOT_MPS
    d.course_deg = field_number(msg, "cog")
    date = getattr(msg, "date", None)
    if isinstance(date, dt.date):
        d.day = (date - dt.date(1970, 1, 1)).days
    d.variation_deg = field_number(msg, "mv") * _EAST.get(field_text(msg, "mvEW"), math.nan)


def _gll(d: Decoded, msg: Any) -> None:
    d.tod_s = time_of_day(msg)
    _position(d, msg)
    d.valid = field_text(msg, "status") == "A"
    _mode(d, field_text(msg, "posMode"))


def _vtg(d: Decoded, msg: Any) -> None:
    knots, kmh = field_number(msg, "sogn"), field_number(msg, "sogk")
    d.speed_mps = knots * KNOT_MPS if math.isfinite(knots) else kmh / 3.6
    d.course_deg = field_number(msg, "cogt")
    _mode(d, field_text(msg, "posMode"))


def _gsa(d: Decoded, msg: Any) -> None:
    svids = [getattr(msg, f"svid_{i:02d}", "") for i in range(1, 13)]
    d.used_svids = tuple(v for v in svids if isinstance(v, int))
    d.gsa_system = _hex_id(getattr(msg, "systemId", ""))
    nav = getattr(msg, "navMode", "")
    d.nav_mode = nav if isinstance(nav, int) else 0
    d.hdop, d.vdop = field_number(msg, "HDOP"), field_number(msg, "VDOP")


def _hex_id(value: object) -> int:
    """An NMEA 4.10 system or signal ID as pynmeagps gives it (a hex digit as text, or a number); 0 when
    absent or not one."""
    if isinstance(value, int):
        return value
    if isinstance(value, str) and value.strip():
        try:
            return int(value.strip(), 16)
        except ValueError:
            return 0
    return 0


def _gsv(d: Decoded, msg: Any) -> None:
    sig = _hex_id(getattr(msg, "signalID", ""))
    for i in range(1, 5):
        sv = getattr(msg, f"svid_{i:02d}", "")
        if isinstance(sv, int):
            d.satellites.append(
                (
                    sv,
                    field_number(msg, f"elv_{i:02d}"),
                    field_number(msg, f"az_{i:02d}"),
                    field_number(msg, f"cno_{i:02d}"),
                    int(sig),
                )
            )


def _gst(d: Decoded, msg: Any) -> None:
    d.tod_s = time_of_day(msg)
    d.std_lat_m, d.std_lon_m, d.std_alt_m = (
        field_number(msg, "stdLat"),
        field_number(msg, "stdLong"),
        field_number(msg, "stdAlt"),
    )


def _zda(d: Decoded, msg: Any) -> None:
    d.tod_s = time_of_day(msg)
    y, m, day = (getattr(msg, k, "") for k in ("year", "month", "day"))
    if isinstance(y, int) and isinstance(m, int) and isinstance(day, int):
        d.day = _day(y, m, day)


def _hdt(d: Decoded, msg: Any) -> None:
    d.heading_deg = field_number(msg, "headingT")


def _ths(d: Decoded, msg: Any) -> None:
    d.heading_deg = field_number(msg, "headt")
    d.valid = field_text(msg, "mi") not in ("V",)  # V: data not valid; A autonomous, E estimated, M manual, S simulator


def _hdg(d: Decoded, msg: Any) -> None:
    """Magnetic sensor heading + deviation + variation (east positive) = true heading; without a variation, the
    magnetic heading (+ deviation), `magnetic_only`."""
    heading, deviation, variation = (
        field_number(msg, "headingM"),
        field_number(msg, "deviation"),
        field_number(msg, "variation"),
    )
    dev = deviation * _EAST.get(field_text(msg, "deviationEW"), 0.0) if math.isfinite(deviation) else 0.0
    if not math.isfinite(variation) or field_text(msg, "variationEW") not in _EAST:
        d.heading_deg = heading + dev
        d.magnetic_only = True
        return
    d.heading_deg = heading + dev + variation * _EAST[field_text(msg, "variationEW")]


def _hdm(d: Decoded, msg: Any) -> None:
    """A magnetic heading (an autopilot's, a fluxgate's), no variation of its own to make it true."""
    d.heading_deg = field_number(msg, "headingM")
    d.magnetic_only = True


def _vhw(d: Decoded, msg: Any) -> None:
    """The speed log's sentence: true heading (when the compass feeds it), else its magnetic heading (as HDM:
    an NKE or Garmin bus writes `$IIVHW,,T,15.0,M,3.3,N,6.0,K`), and speed through the water."""
    d.heading_deg = field_number(msg, "hdgT")
    if not math.isfinite(d.heading_deg):
        d.heading_deg = field_number(msg, "hdgM")
        d.magnetic_only = math.isfinite(d.heading_deg)
    knots, kmh = field_number(msg, "spdN"), field_number(msg, "spdK")
    d.water_speed_mps = knots * KNOT_MPS if math.isfinite(knots) else kmh / 3.6


Reader = Callable[[Decoded, Any], None]

DECODERS: dict[str, Reader] = {
    "GGA": _gga,
    "GNS": _gns,
    "RMC": _rmc,
    "GLL": _gll,
    "VTG": _vtg,
    "GSA": _gsa,
    "GSV": _gsv,
    "GST": _gst,
    "ZDA": _zda,
    "HDT": _hdt,
    "THS": _ths,
    "HDG": _hdg,
    "HDM": _hdm,
    "VHW": _vhw,
}


def is_empty(sentence: Sentence) -> bool:
    """True for a sentence with no digit in its data fields (`$IIHDT,,T*0C`, an empty GSV)."""
    star = sentence.text.rfind(b"*")
    body = sentence.text[sentence.text.find(b",") : star if star >= 0 else len(sentence.text)]
    return not any(48 <= b <= 57 for b in body)


def with_checksum(text: bytes) -> bytes:
    """The sentence with its checksum: pynmeagps parses nothing without one, and a sentence of a file whose
    talker sends none (lines.py takes those unverified) is decoded as the same sentence checksummed."""
    if b"*" in text:
        return text
    return text + b"*" + calc_checksum(text[1:].decode("latin-1")).encode("ascii")


def parse(sentence: Sentence) -> Any:
    """pynmeagps' message of a sentence; raises one of ParseErrors when its fields are not valid."""
    msg = _parsed(sentence.text)
    if msg is None:
        raise NMEAParseError(f"pynmeagps does not know {sentence.talker}{sentence.kind}")
    return msg


@lru_cache(maxsize=1 << 14)
def _parsed(text: bytes) -> Any:
    """pynmeagps' message of a sentence's text, remembered: a receiver repeats sentences (a sky's GSV while
    it holds still, a GSA's satellites, an instrument's steady HDT), and pynmeagps takes ~0.2 ms for each.
    The message is only read from, never changed, so one is shared by every sentence of the same text.
    `forget_parsed` empties it once a file is decoded (16k messages hold ~40 MB)."""
    # checksum already verified (lines.py), or absent from the whole file
    return NMEAReader.parse(with_checksum(text), validate=VALNONE)


def forget_parsed() -> None:
    _parsed.cache_clear()


def decode(sentence: Sentence) -> Decoded:
    """Values of a sentence of a WANTED kind; raises one of ParseErrors when its fields are not valid."""
    msg = parse(sentence)
    out = Decoded(sentence)
    DECODERS[sentence.kind](out, msg)
    return out
