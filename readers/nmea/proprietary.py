"""Proprietary and variant NMEA sentences that carry the receiver's own position, heading or satellites.

Each family is decoded with pynmeagps (its attribute names and units: `nmeatypes_get.py`,
`nmeatypes_get_prop.py`) into the values `sentences.Decoded` holds for the standard sentences, and plays a
standard sentence's part in assembly (`Family.kind`):

- Unicore's "H" sentences (GGAH, GNSH, RMCH, GLLH, VTGH, GSAH, GSVH, GSTH) have the standard sentence's
  fields; pynmeagps names them the secondary antenna's, so they make a receiver of their own (talker + "H"),
  never mixed with the primary antenna's epochs. THS2 is a THS; HPR, HPR2 and TRA2 give the dual-antenna
  heading; HPD a position and velocity on GPS week and time of week.
- Trimble PTNL,GGK: time, position, ellipsoidal height, quality (Trimble's own codes), satellites used.
  PTNL,AVR: the moving-baseline yaw. PASHR (RT300 attitude): the true heading.
- Septentrio PSSN,HRP: the dual-antenna true heading.
- Feyman GPFMI: time, position, altitude and satellites of the module's solution.
- Fugro PFUGDP: time and position.

The heading of an attitude sentence is a GNSS heading (antennas, or an INS the GNSS aids), so its rows are
filed under the talker GN: the heading reference never takes one for a compass. What is known but not
read is in `NOT_READ`, with why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from readers.nmea.lines import Sentence
from readers.nmea.sentences import DECODERS, Decoded, Reader, field_number, field_text, parse, time_of_day
from spooflens.epoch_table import GPS_EPOCH_UNIX_NS, NS, gps_utc_offset_ns
from spooflens.schema import FixType

# the proprietary addresses whose first field names the message (`$PTNL,GGK,...`), as pynmeagps splits them
_SUB_ID = ("TNL", "SSN", "ASHR")
GNSS_HEADING_TALKER = "GN"


@dataclass(frozen=True)
class Family:
    """How one sentence reads: the standard kind it plays in assembly, and its decoder."""

    kind: str
    read: Reader
    antenna: str = ""  # "H": Unicore's secondary antenna
    own_receiver: bool = False  # a position sentence of a source of its own (its address is its receiver)


def sentence_name(s: Sentence) -> str:
    """The sentence's name as the log writes it, with a proprietary message id: `PTNLGGK`, `PASHR`, `GNGGAH`."""
    if s.talker == "P" and s.kind in _SUB_ID:
        comma = s.text.find(b",")
        sub = s.text[comma + 1 : s.text.find(b",", comma + 1)]
        if sub.isalpha():  # PASHR's own sentence starts with its time, its other messages with an id
            return f"P{s.kind}{sub.decode('ascii')}"
    return f"{s.talker}{s.kind}"


def _key(s: Sentence) -> str:
    return sentence_name(s) if s.talker == "P" else s.kind


# ----- Unicore ------------------------------------------------------------------------------------------


def _unicore_attitude(d: Decoded, msg: Any) -> None:
    """HPR, HPR2, TRA2: heading of the antenna baseline, degrees from true north."""
    d.heading_deg = field_number(msg, "heading")


def _unicore_hpd(d: Decoded, msg: Any) -> None:
    """HPD: position (degrees), altitude, east/north velocity (m/s), timed by GPS week and time of week.

    pynmeagps does not say which height `alt` is: it is taken as the GGA altitude is (above MSL, no
    separation), which assembly lists as a repair. The heading it carries is not read: one sentence makes one
    row, and the receiver's own heading sentences (HPR, THS2) carry it too."""
    week, tow = field_number(msg, "wno"), field_number(msg, "tow")
    if math.isfinite(week) and math.isfinite(tow):
        gps_ns = round((week * 7 * 86_400 + tow) * NS)
        unix_s = (gps_ns - int(gps_utc_offset_ns(gps_ns)) + GPS_EPOCH_UNIX_NS) / NS
        d.day, d.tod_s = int(unix_s // 86_400), unix_s % 86_400
    d.lat, d.lon, d.alt_msl_m = field_number(msg, "lat"), field_number(msg, "lon"), field_number(msg, "alt")
    east, north = field_number(msg, "velE"), field_number(msg, "velN")
    d.speed_mps = math.hypot(east, north)
    d.course_deg = math.degrees(math.atan2(east, north)) % 360.0
    d.fix_type = int(FixType.UNKNOWN)


# ----- Trimble ------------------------------------------------------------------------------------------

# PTNL,GGK's own quality codes (Trimble receiver help, "PTNL,GGK"), not GGA's: 5 is SBAS here, RTK float there
TRIMBLE_GGK_QUALITY = {
    0: FixType.NO_FIX,
    1: FixType.FIX_3D,
    2: FixType.RTK_FLOAT,
    3: FixType.RTK_FIXED,
    4: FixType.DGNSS,
    5: FixType.SBAS,
    6: FixType.RTK_FLOAT,  # network RTK float
    7: FixType.RTK_FIXED,  # network RTK fixed
    8: FixType.RTK_FLOAT,  # network RTK float, 2-D
    9: FixType.RTK_FIXED,  # network RTK fixed, 2-D
    10: FixType.DGNSS,  # OmniSTAR HP/XP
    11: FixType.DGNSS,  # OmniSTAR VBS
    # "Location RTK": an RTK solution held to a set accuracy; a Trimble R2 writes GGA quality 5 (RTK float) for
    # the same epochs
    12: FixType.RTK_FLOAT,
    13: FixType.DGNSS,  # beacon DGPS
}


def _ellipsoidal(text: str) -> float:
    """PTNL's height field: `EHT150.790` is above the ellipsoid; `GHT` (PJK) is above the geoid, not read."""
    if not text.startswith("EHT"):
        return math.nan
    try:
        return float(text[3:])
    except ValueError:
        return math.nan


def _trimble_ggk(d: Decoded, msg: Any) -> None:
    """PTNL,GGK. Its date is not read: Trimble's manuals give it as ddmmyy and as mmddyy (pynmeagps reads
    ddmmyy, and finds no date in `051910`), so the receiver's times stay days-less as a GGA's. Its DOP is a
    PDOP, which the schema has no column for."""
    d.tod_s = time_of_day(msg, "utctime")
    d.lat, d.lon = field_number(msg, "lat"), field_number(msg, "lon")
    quality = getattr(msg, "gpsQual", "")
    if isinstance(quality, int):
        d.fix_type = int(TRIMBLE_GGK_QUALITY.get(quality, FixType.UNKNOWN))
        d.valid = quality != 0
    d.sats_used = field_number(msg, "sip")
    d.height_m = _ellipsoidal(field_text(msg, "height"))


def _trimble_avr(d: Decoded, msg: Any) -> None:
    """PTNL,AVR: yaw of the moving-baseline vector, degrees; quality 0 is no vector."""
    d.heading_deg = field_number(msg, "yaw")
    d.valid = getattr(msg, "gpsQual", "") != 0
    d.heading_talker = GNSS_HEADING_TALKER


def _pashr(d: Decoded, msg: Any) -> None:
    """PASHR (RT300 attitude): the heading, when flagged T (true north)."""
    d.heading_deg = field_number(msg, "trueHdg")
    d.valid = field_text(msg, "trueHdgInd") == "T"
    d.heading_talker = GNSS_HEADING_TALKER


# ----- Septentrio, Feyman, Fugro ------------------------------------------------------------------------


def _septentrio_hrp(d: Decoded, msg: Any) -> None:
    """PSSN,HRP: the true heading, degrees. Its attitude-mode code is not documented in pynmeagps: not read."""
    d.heading_deg = field_number(msg, "hdg")
    d.heading_talker = GNSS_HEADING_TALKER


def _feyman_fmi(d: Decoded, msg: Any) -> None:
    """GPFMI: time, position (degrees), altitude and satellites used. Exactly 0 deg, 0 deg is the module
    before it has a solution (pynmeagps' own sample starts so), not a place. Its attitude angles are not read:
    pynmeagps gives no unit for them; nor is its navigation mode, whose codes it does not list."""
    d.tod_s = time_of_day(msg)
    d.lat, d.lon, d.alt_msl_m = field_number(msg, "lat"), field_number(msg, "lon"), field_number(msg, "alt")
    d.valid = not (d.lat == 0.0 and d.lon == 0.0)
    d.sats_used = field_number(msg, "numSV")
    d.fix_type = int(FixType.UNKNOWN)


def _fugro_gdp(d: Decoded, msg: Any) -> None:
    """PFUGDP: time and position. Its satellites are in view (not used), its quality code is undocumented."""
    d.tod_s = time_of_day(msg, "utctime")
    d.lat, d.lon = field_number(msg, "lat"), field_number(msg, "lon")
    d.fix_type = int(FixType.UNKNOWN)


def _secondary(kind: str) -> Family:
    return Family(kind, DECODERS[kind], antenna="H")


def _attitude(read: Reader) -> Family:
    return Family("ATT", read)


# keyed by the address after the talker (Unicore, Feyman), or the whole name of a P sentence
FAMILIES: dict[str, Family] = {
    **{f"{k}H": _secondary(k) for k in ("GGA", "GNS", "RMC", "GLL", "VTG", "GSA", "GSV", "GST")},
    "THS2": Family("THS", DECODERS["THS"]),
    "HPR": _attitude(_unicore_attitude),
    "HPR2": _attitude(_unicore_attitude),
    "TRA2": _attitude(_unicore_attitude),
    "HPD": Family("HPD", _unicore_hpd, own_receiver=True),
    "PTNLGGK": Family("GGK", _trimble_ggk, own_receiver=True),
    "PTNLAVR": _attitude(_trimble_avr),
    "PASHR": _attitude(_pashr),
    "PSSNHRP": _attitude(_septentrio_hrp),
    "FMI": Family("FMI", _feyman_fmi, own_receiver=True),
    "PFUGDP": Family("FUGDP", _fugro_gdp, own_receiver=True),
}

# sentences that look as if they held the receiver's position or heading, and why they are not read
NOT_READ: dict[str, str] = {
    "LLQ": "Leica local grid position (easting/northing, no latitude/longitude): not read",
    "PTNLPJK": "Trimble local grid position (northing/easting, no latitude/longitude): not read",
    "PTNLBPQ": "Trimble base station's position, not the receiver's: not read",
    "PTNLVGK": "Trimble vector between two antennas (east/north/up), not a position: not read",
    "PTNLVHD": "Trimble vector azimuth/elevation/range between two antennas, not the vehicle's heading: not read",
    "PSSNRBP": "Septentrio rover-to-base vector, not a position: not read",
    "PSSNRBD": "Septentrio rover-to-base direction, not the vehicle's heading: not read",
    "PSSNRBV": "Septentrio rover-to-base velocity: not read",
    "GRSH": "range residuals (secondary antenna): no place in the schema",
    "ROT2": "rate of turn: no place in the schema",
}


def family_of(s: Sentence) -> Family | None:
    return FAMILIES.get(_key(s))


def not_read_reason(s: Sentence) -> str | None:
    return NOT_READ.get(_key(s))


def decode_variant(s: Sentence, family: Family) -> Decoded:
    """Values of a proprietary or variant sentence; raises one of sentences.ParseErrors when not valid."""
    name = sentence_name(s)
    # a position sentence of its own source is its own receiver, named by its address (PTNL, PFUGDP, GPFMI)
    address = f"P{s.kind}" if s.talker == "P" else name
    receiver = address if family.own_receiver else s.talker + family.antenna
    out = Decoded(s, family.kind, name, receiver, family.antenna)
    family.read(out, parse(s))
    return out
