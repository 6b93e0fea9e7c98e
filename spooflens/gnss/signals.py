"""GNSS systems and signal bands by name: what a satellite id's letter and a carrier frequency mean.

One place for the names findings use ("GPS L1", "Galileo E1"), so detectors that say which systems and
bands an event hit word them alike.
"""

from __future__ import annotations

import math

SYSTEM_NAMES: dict[str, str] = {
    "G": "GPS",
    "E": "Galileo",
    "R": "GLONASS",
    "C": "BeiDou",
    "J": "QZSS",
    "S": "SBAS",
    "I": "NavIC",
}

# (low Hz, high Hz, band name per system letter, name for any other system)
_BANDS: tuple[tuple[float, float, dict[str, str], str], ...] = (
    (1570.0e6, 1581.0e6, {"E": "E1", "C": "B1C"}, "L1"),
    (1559.0e6, 1565.0e6, {"C": "B1I"}, "B1I"),
    (1590.0e6, 1611.0e6, {"R": "G1"}, "G1"),
    (1224.0e6, 1231.0e6, {}, "L2"),
    (1240.0e6, 1260.0e6, {"R": "G2"}, "G2"),
    (1172.0e6, 1181.0e6, {"E": "E5a", "C": "B2a"}, "L5"),
    (1200.0e6, 1212.0e6, {"E": "E5b", "C": "B2I"}, "E5b"),
    (1265.0e6, 1270.0e6, {"C": "B3I"}, "B3I"),
    (1274.0e6, 1283.0e6, {"E": "E6", "J": "L6"}, "E6"),
)
# the band a receiver's sky view reports per satellite when it does not say which (NAV-SAT, GSV, PX4
# satellite_info and GnssStatus give the L1-band signal, or the strongest, which is the L1-band one)
_L1_BAND: dict[str, str] = {"G": "L1", "E": "E1", "R": "G1", "C": "B1", "J": "L1", "S": "L1", "I": "L5"}


def system_of(sv_id: str) -> str:
    """The system's name of a RINEX-style satellite id (G05 -> GPS); the letter itself when unknown."""
    letter = sv_id[:1]
    return SYSTEM_NAMES.get(letter, letter)


def band_of(sv_id: str, carrier_hz: float | None = None) -> str:
    """The signal band of a satellite's signal: by its carrier frequency when known, else the L1 band of
    its system (the band receivers report their sky in)."""
    letter = sv_id[:1]
    if carrier_hz is not None and math.isfinite(carrier_hz):
        for low, high, names, default in _BANDS:
            if low <= carrier_hz <= high:
                return names.get(letter, default)
    return _L1_BAND.get(letter, "L1")
