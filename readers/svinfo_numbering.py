"""u-blox's single satellite numbering (NAV-SVINFO `svid`, and PX4's `satellite_info.svid` that copies it).

Before NAV-SAT (u-blox 8, protocol 15+) gave each satellite a (gnssId, svId) pair, u-blox numbered all
constellations in one byte; PX4's u-blox driver still writes that number.
"""

from __future__ import annotations

import numpy as np

# (first, last, RINEX system letter, number of the first)
SVINFO_RANGES = (
    (1, 32, "G", 1),
    (33, 64, "C", 5),
    (65, 96, "R", 1),
    (120, 158, "S", 20),
    (159, 163, "C", 1),
    (193, 202, "J", 1),
    (211, 246, "E", 1),
)


def svinfo_sv_id(svid: int) -> str | None:
    """RINEX-style id of a u-blox single-byte `svid`; None for 0, 255 (GLONASS slot unknown) and numbers
    no range assigns."""
    for first, last, system, number in SVINFO_RANGES:
        if first <= svid <= last:
            return f"{system}{svid - first + number:02d}"
    return None


SVINFO_IDS = np.array([svinfo_sv_id(v) or "" for v in range(256)], dtype=object)  # svid -> id, "" for none
