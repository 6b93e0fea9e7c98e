"""Galileo broadcast ephemerides from the E1-B (or E5b-I) I/NAV pages a receiver passes on (u-blox
RXM-SFRBX with gnssId 2, Android GnssLogger `Nav` records of TYPE_GAL_I).

A multi-constellation capture under a GPS-only spoofer (the open SDR spoofers transmit GPS L1 C/A
alone) keeps its real Galileo satellites: with their orbits the single-point solution and RAIM see
the two systems disagree, which no GPS-only check can.

Layout (Galileo OS SIS ICD 4.3; u-blox interface description, RXM-SFRBX): one message is a nominal
page, an even and an odd part of 120 bits, in eight U4 words (four each, most significant bit first).
Each part starts with its even/odd bit and page type (1: alert page, not used); the 128-bit data word
is the even part's 112 data bits and the odd part's first 16, and a CRC-24Q (RTCM3's, from pyrtcm)
covers both parts' data (114 + 82 bits): a page that fails it is dropped. Word types 1-4 carry the
orbit and clock with one issue of data (IODnav) that must agree; word 5 the group delays, the E1-B
health and GST (week and time of week). The GST week counts from GPS week 1024 (1999-08-22), so
week + 1024 is the GPS week. The clock is the I/NAV one (for E1/E5b), corrected for an E1 user with
BGD(E1, E5b).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

from pyrtcm.rtcmhelpers import calc_crc24q

from readers.navbits import WEEK_S, BitReader, near_in_week, sfrbx_words
from spooflens.epoch_table import Skipped

GST_WEEK_OFFSET = 1024  # GPS week of GST week 0
GALILEO_GNSS_ID = 2
INAV_WORDS = 8
ANDROID_PAGE_BYTES = 29
PAGE_S = 2.0  # a nominal page (even + odd part) lasts 2 s; word 5's time of week is its start
SEMICIRCLE = math.pi


class _AlertPage(Exception):
    pass


def page_word(page: int) -> int | None:
    """The 128-bit data word of a 256-bit nominal page (even part in the high 128 bits, as u-blox sends
    it), or None when it is an alert page, its parts are out of order or the CRC fails."""
    even, odd = BitReader(page >> 128, 128), BitReader(page & ((1 << 128) - 1), 128)
    if even.u(1, 1) or odd.u(1, 1):
        raise _AlertPage
    if even.u(0, 1) != 0 or odd.u(0, 1) != 1:
        return None
    covered = (even.u(0, 114) << 82) | odd.u(0, 82)  # 196 bits, padded to 200
    if calc_crc24q(covered.to_bytes(25, "big")) != odd.u(82, 24):
        return None
    return (even.u(2, 112) << 16) | odd.u(2, 16)


def _word1(w: BitReader) -> dict[str, float]:
    return {
        "iod": w.u(6, 10),
        "toe_sow": w.u(16, 14) * 60.0,
        "m0": w.s(30, 32) * 2.0**-31 * SEMICIRCLE,
        "e": w.u(62, 32) * 2.0**-33,
        "sqrt_a": w.u(94, 32) * 2.0**-19,
    }


def _word2(w: BitReader) -> dict[str, float]:
    return {
        "iod": w.u(6, 10),
        "omega0": w.s(16, 32) * 2.0**-31 * SEMICIRCLE,
        "i0": w.s(48, 32) * 2.0**-31 * SEMICIRCLE,
        "omega": w.s(80, 32) * 2.0**-31 * SEMICIRCLE,
        "idot": w.s(112, 14) * 2.0**-43 * SEMICIRCLE,
    }


def _word3(w: BitReader) -> dict[str, float]:
    return {
        "iod": w.u(6, 10),
        "omega_dot": w.s(16, 24) * 2.0**-43 * SEMICIRCLE,
        "delta_n": w.s(40, 16) * 2.0**-43 * SEMICIRCLE,
        "cuc": w.s(56, 16) * 2.0**-29,
        "cus": w.s(72, 16) * 2.0**-29,
        "crc": w.s(88, 16) * 2.0**-5,
        "crs": w.s(104, 16) * 2.0**-5,
    }


def _word4(w: BitReader) -> dict[str, float]:
    return {
        "iod": w.u(6, 10),
        "svid": w.u(16, 6),
        "cic": w.s(22, 16) * 2.0**-29,
        "cis": w.s(38, 16) * 2.0**-29,
        "toc_sow": w.u(54, 14) * 60.0,
        "af0": w.s(68, 31) * 2.0**-34,
        "af1": w.s(99, 21) * 2.0**-46,
        "af2": w.s(120, 6) * 2.0**-59,
    }


def _word5(w: BitReader) -> dict[str, float]:
    # ionosphere (NeQuick a_i0..2 and the region flags: 41 bits) first, then the group delays
    return {
        "bgd_e5a": w.s(47, 10) * 2.0**-32,
        "bgd_e5b": w.s(57, 10) * 2.0**-32,
        "e1b_hs": w.u(69, 2),
        "e1b_dvs": w.u(72, 1),
        "week": w.u(73, 12) + GST_WEEK_OFFSET,
        "tow": float(w.u(85, 20)),
    }


_DECODE = {1: _word1, 2: _word2, 3: _word3, 4: _word4, 5: _word5}


@dataclass
class InavDecoder:
    """Collects I/NAV pages (`add`: an RXM-SFRBX payload; `add_word`: a checked 128-bit word);
    `records()` gives the ephemerides assembled, `dropped()` what was dropped."""

    words: dict[int, dict[int, tuple[dict[str, float], float | None]]] = field(default_factory=dict)
    assembled: dict[tuple[object, ...], dict[str, float | int | str]] = field(default_factory=dict)
    counts: Counter[str] = field(default_factory=Counter)

    def add(self, payload: bytes, now_gps_s: float | None = None) -> None:
        """One RXM-SFRBX payload of a Galileo satellite; `now_gps_s`: the receiver's GPS time when it came."""
        gnss_id, sv, words = sfrbx_words(payload)
        if gnss_id != GALILEO_GNSS_ID or len(words) != INAV_WORDS or not 1 <= sv <= 36:
            self.counts["not Galileo I/NAV"] += 1
            return
        page = 0
        for w in words:
            page = (page << 32) | int(w)
        self._add_page(sv, page, now_gps_s)

    def _add_page(self, sv: int, page: int, now_gps_s: float | None) -> None:
        try:
            word = page_word(page)
        except _AlertPage:
            self.counts["alert page"] += 1
            return
        if word is None:
            self.counts["CRC failed"] += 1
            return
        self.add_word(sv, word, now_gps_s)

    def add_android(self, sv: int, data: bytes, now_gps_s: float | None = None) -> None:
        """One Android GnssNavigationMessage of TYPE_GAL_I: the even and odd page parts without sync and
        tail, 114 bits each, in 29 bytes most significant bit first."""
        if len(data) != ANDROID_PAGE_BYTES or not 1 <= sv <= 36:
            self.counts["not Galileo I/NAV"] += 1
            return
        bits = int.from_bytes(data, "big") >> 4  # 232 bits, the last four unused
        even, odd = bits >> 114, bits & ((1 << 114) - 1)
        self._add_page(sv, (even << 14 << 128) | (odd << 14), now_gps_s)

    def add_word(self, sv: int, word: int, now_gps_s: float | None = None) -> None:
        """One checked 128-bit I/NAV data word of satellite E`sv`."""
        w = BitReader(word, 128)
        kind = w.u(0, 6)  # the word type
        decode = _DECODE.get(kind)
        if decode is None:
            return
        fields_ = decode(w)
        if kind == 4 and fields_["svid"] != sv:
            self.counts["word 4 of another satellite"] += 1
            return
        parts = self.words.setdefault(sv, {})
        parts[kind] = (fields_, now_gps_s)
        self._assemble(sv, parts)

    def _assemble(self, sv: int, parts: dict[int, tuple[dict[str, float], float | None]]) -> None:
        if not all(k in parts for k in _DECODE):
            return
        iods = {int(parts[k][0]["iod"]) for k in (1, 2, 3, 4)}
        if len(iods) != 1:
            return
        w1, w2, w3, w4, w5 = (parts[k][0] for k in (1, 2, 3, 4, 5))
        sent_s = float(w5["week"]) * WEEK_S + float(w5["tow"])
        toe_s = near_in_week(float(w1["toe_sow"]), sent_s)
        toe_week = int(toe_s // WEEK_S)
        record: dict[str, float | int | str] = {
            "sv_id": f"E{sv:02d}",
            "week": toe_week,
            "toe_sow": toe_s - toe_week * WEEK_S,
            "toc_s": near_in_week(float(w4["toc_sow"]), sent_s),
            "af0": w4["af0"],
            "af1": w4["af1"],
            "af2": w4["af2"],
            "tgd": w5["bgd_e5b"],
            "health": (int(w5["e1b_hs"]) << 1) | int(w5["e1b_dvs"]),
            "iode": iods.pop(),
        }
        for key in ("m0", "e", "sqrt_a"):
            record[key] = w1[key]
        for key in ("omega0", "i0", "omega", "idot"):
            record[key] = w2[key]
        for key in ("omega_dot", "delta_n", "cuc", "cus", "crc", "crs"):
            record[key] = w3[key]
        for key in ("cic", "cis"):
            record[key] = w4[key]
        if not 5000.0 < float(record["sqrt_a"]) < 6000.0:  # Galileo's orbit: 29,600 km
            self.counts["implausible orbit"] += 1
            return
        now = parts[5][1]
        offset = math.nan
        if now is not None:
            offset = sent_s + PAGE_S - now
            offset -= WEEK_S * round(offset / WEEK_S)
        # the same broadcast again (every 30 s) is one record; the same orbit on another clock is not
        identity = (*sorted(record.items()), None if math.isnan(offset) else round(offset / 60.0))
        if identity in self.assembled:
            return
        received = [t for _, t in parts.values() if t is not None]
        record["message_offset_s"] = offset
        record["received_s"] = max(received) if received else math.nan
        self.assembled[identity] = record

    def records(self) -> list[dict[str, float | int | str]]:
        return list(self.assembled.values())

    def dropped(self, stream: str) -> list[Skipped]:
        """Skipped, not lost: pages the receiver decoded wrong, in messages the file carried whole (`LnavDecoder`)."""
        return [
            Skipped(stream, f"Galileo I/NAV pages dropped: {what}", self.counts[what], "skipped")
            for what in ("CRC failed", "implausible orbit", "word 4 of another satellite")
            if self.counts[what]
        ]
