"""What every broadcast-message decoder needs: big-endian bit fields, a time of week placed in its
week, and the u-blox RXM-SFRBX frame around a message (`readers/lnav.py` GPS, `readers/inav.py`
Galileo, `readers/rtcm_ephemeris.py` RTCM3)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

WEEK_S = 604_800
SFRBX_HEADER = 8


class BitReader:
    """Unsigned and two's-complement fields of a `width`-bit message, bit 0 the most significant."""

    def __init__(self, value: int, width: int) -> None:
        self.value = value
        self.width = width

    def u(self, pos: int, n: int) -> int:
        return (self.value >> (self.width - pos - n)) & ((1 << n) - 1)

    def s(self, pos: int, n: int) -> int:
        v = self.u(pos, n)
        return v - (1 << n) if v >> (n - 1) else v


def near_in_week(sow: float, ref_s: float) -> float:
    """GPS seconds of a seconds-of-week value in the week that puts it within half a week of `ref_s`."""
    t = (ref_s // WEEK_S) * WEEK_S + sow
    return float(t + WEEK_S * round((ref_s - t) / WEEK_S))


def sfrbx_words(payload: bytes) -> tuple[int, int, NDArray[np.uint32]]:
    """gnssId, svId and the data words of an RXM-SFRBX payload; ValueError if its length does not add up."""
    if len(payload) < SFRBX_HEADER:
        raise ValueError(f"RXM-SFRBX of {len(payload)} bytes")
    gnss_id, sv, num_words = payload[0], payload[1], payload[4]
    if len(payload) != SFRBX_HEADER + 4 * num_words:
        raise ValueError(f"RXM-SFRBX with {num_words} words in {len(payload)} bytes")
    return gnss_id, sv, np.frombuffer(payload[SFRBX_HEADER:], "<u4")
