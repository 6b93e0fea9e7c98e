"""GPS broadcast ephemerides from the L1 C/A LNAV subframes a receiver passes on (u-blox RXM-SFRBX,
Android GnssLogger `Nav` records).

A RAWX capture carries pseudoranges but no satellite positions; the receiver's SFRBX messages carry the
navigation message it demodulated, so decoding subframes 1-3 (clock, orbit) and subframe 4 page 18
(Klobuchar ionosphere) gives the same broadcast records a RINEX navigation file would, and RAIM and the
raw-measurement detectors can run on the capture alone.

Layout (IS-GPS-200 20.3.2-20.3.3; u-blox interface description, RXM-SFRBX): ten 30-bit words per
subframe, each in the 30 least significant bits of a little-endian U4, 24 data bits then 6 parity
bits. Receivers differ in whether the data bits are still complemented by the previous word's D30
bit as transmitted; every subframe is parity-checked both ways and kept only when all ten words pass
one of them, so a damaged or mis-assembled subframe never becomes an orbit.

The 10-bit week of subframe 1 is resolved against the capture's GPS time (RAWX, NAV-TIMEGPS); the
weeks of toe and toc are those within half a week of the subframe's transmission time. A record is
assembled when subframes 1, 2 and 3 of one satellite come from one 30-s frame and agree on the issue
of data (IODC low byte = IODE of subframes 2 and 3).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from readers.navbits import WEEK_S, BitReader, near_in_week, sfrbx_words
from spooflens.epoch_table import Skipped
from spooflens.gnss.ephemeris import GpsEphemerides, Klobuchar

SEMICIRCLE = math.pi  # LNAV angles are in semicircles
TLM_PREAMBLE = 0x8B
GPS_GNSS_ID = 0

# IS-GPS-200 Table 20-XIV: the data bits (1..24) each parity bit D25..D30 sums, and which of the
# previous word's D29*/D30* enters it
_PARITY_BITS: tuple[tuple[int, tuple[int, ...]], ...] = (
    (29, (1, 2, 3, 5, 6, 10, 11, 12, 13, 14, 17, 18, 20, 23)),
    (30, (2, 3, 4, 6, 7, 11, 12, 13, 14, 15, 18, 19, 21, 24)),
    (29, (1, 3, 4, 5, 7, 8, 12, 13, 14, 15, 16, 19, 20, 22)),
    (30, (2, 4, 5, 6, 8, 9, 13, 14, 15, 16, 17, 20, 21, 23)),
    (30, (1, 3, 5, 6, 7, 9, 10, 14, 15, 16, 17, 18, 21, 22, 24)),
    (29, (3, 5, 6, 8, 9, 10, 11, 13, 15, 19, 22, 23, 24)),
)
_PARITY_MASKS = tuple((star, sum(1 << (24 - b) for b in bits)) for star, bits in _PARITY_BITS)


def parity(data24: int, d29_star: int, d30_star: int) -> int:
    """The six parity bits (D25..D30, as a 6-bit int) of 24 source data bits."""
    out = 0
    for star, mask in _PARITY_MASKS:
        bit = (d29_star if star == 29 else d30_star) ^ (bin(data24 & mask).count("1") & 1)
        out = (out << 1) | bit
    return out


def _source_words(words30: list[int]) -> list[int] | None:
    """The 24 source data bits of each word, or None when parity fails under both conventions: data as
    transmitted (complemented when the previous word's D30 is 1) or already restored by the receiver."""
    for transmitted in (True, False):
        out = []
        prev = 0  # word 10 of every subframe ends in D29 = D30 = 0, so TLM sees zeros
        for w in words30:
            d29s, d30s = (prev >> 1) & 1, prev & 1
            data = (w >> 6) & 0xFFFFFF
            if transmitted and d30s:
                data ^= 0xFFFFFF
            if parity(data, d29s, d30s) != w & 0x3F:
                break
            out.append(data)
            prev = w
        else:
            return out
    return None


def _subframe1(b: BitReader) -> dict[str, float]:
    tgd = b.s(160, 8)
    return {
        "week10": b.u(48, 10),
        "ura": b.u(60, 4),
        "health": b.u(64, 6),
        "iodc": (b.u(70, 2) << 8) | b.u(168, 8),
        "tgd": 0.0 if tgd == -128 else tgd * 2.0**-31,
        "toc_sow": b.u(176, 16) * 16.0,
        "af2": b.s(192, 8) * 2.0**-55,
        "af1": b.s(200, 16) * 2.0**-43,
        "af0": b.s(216, 22) * 2.0**-31,
    }


def _subframe2(b: BitReader) -> dict[str, float]:
    return {
        "iode": b.u(48, 8),
        "crs": b.s(56, 16) * 2.0**-5,
        "delta_n": b.s(72, 16) * 2.0**-43 * SEMICIRCLE,
        "m0": b.s(88, 32) * 2.0**-31 * SEMICIRCLE,
        "cuc": b.s(120, 16) * 2.0**-29,
        "e": b.u(136, 32) * 2.0**-33,
        "cus": b.s(168, 16) * 2.0**-29,
        "sqrt_a": b.u(184, 32) * 2.0**-19,
        "toe_sow": b.u(216, 16) * 16.0,
        "fit_flag": b.u(232, 1),
    }


def _subframe3(b: BitReader) -> dict[str, float]:
    return {
        "cic": b.s(48, 16) * 2.0**-29,
        "omega0": b.s(64, 32) * 2.0**-31 * SEMICIRCLE,
        "cis": b.s(96, 16) * 2.0**-29,
        "i0": b.s(112, 32) * 2.0**-31 * SEMICIRCLE,
        "crc": b.s(144, 16) * 2.0**-5,
        "omega": b.s(160, 32) * 2.0**-31 * SEMICIRCLE,
        "omega_dot": b.s(192, 24) * 2.0**-43 * SEMICIRCLE,
        "iode": b.u(216, 8),
        "idot": b.s(224, 14) * 2.0**-43 * SEMICIRCLE,
    }


def _klobuchar(b: BitReader) -> Klobuchar | None:
    """Subframe 4 page 18 (SV ID 56): ionosphere alpha/beta; None for any other page."""
    if b.u(50, 6) != 56:
        return None
    scale_a = (2.0**-30, 2.0**-27, 2.0**-24, 2.0**-24)
    scale_b = (2.0**11, 2.0**14, 2.0**16, 2.0**16)
    raw = [b.s(56 + 8 * k, 8) for k in range(8)]
    alpha = tuple(raw[k] * scale_a[k] for k in range(4))
    beta = tuple(raw[4 + k] * scale_b[k] for k in range(4))
    return Klobuchar(alpha, beta)  # type: ignore[arg-type]


@dataclass
class LnavDecoder:
    """Collects subframes (`add`: an RXM-SFRBX payload; `add_words`: any receiver's ten words);
    `ephemerides()` gives the records assembled, `dropped()` what was dropped."""

    # per satellite, the latest decoded subframe of each id 1-3 (with its transmission time)
    satellites: dict[str, dict[int, dict[str, float]]] = field(default_factory=dict)
    assembled: dict[tuple[object, ...], dict[str, float | int | str]] = field(default_factory=dict)
    iono: Klobuchar | None = None
    counts: Counter[str] = field(default_factory=Counter)  # "parity failed", "subframe k" ...

    def add(self, payload: bytes, ref_gps_s: float | None, now_gps_s: float | None = None) -> None:
        """One RXM-SFRBX payload. `ref_gps_s`: the capture's GPS time near it (resolves the 10-bit week);
        `now_gps_s`: the receiver's GPS time when the message came (its latest epoch), if known."""
        gnss_id, sv, words = sfrbx_words(payload)
        if gnss_id != GPS_GNSS_ID or len(words) != 10 or not 1 <= sv <= 32:
            self.counts["not GPS L1 C/A LNAV"] += 1
            return
        self.add_words(sv, [int(w) for w in words], ref_gps_s, now_gps_s)

    def add_words(self, sv: int, words: list[int], ref_gps_s: float | None, now_gps_s: float | None = None) -> None:
        """One GPS L1 C/A subframe of satellite `sv` as ten 30-bit words (any receiver's)."""
        if len(words) != 10 or not 1 <= sv <= 32:
            self.counts["not GPS L1 C/A LNAV"] += 1
            return
        if (int(words[0]) >> 22) & 0xFF not in (TLM_PREAMBLE, TLM_PREAMBLE ^ 0xFF):
            self.counts["CNAV or no TLM preamble"] += 1
            return
        data = _source_words([int(w) & 0x3FFFFFFF for w in words])
        if data is None:
            self.counts["parity failed"] += 1
            return
        bits = BitReader(sum(w << (24 * (9 - k)) for k, w in enumerate(data)), 240)  # parity removed
        sf_id = bits.u(43, 3)
        tow = bits.u(24, 17) * 6.0  # time of the next subframe's start; this one began 6 s earlier
        self.counts[f"subframe {sf_id}"] += 1
        if sf_id == 4:
            self.iono = _klobuchar(bits) or self.iono
            return
        if sf_id not in (1, 2, 3):
            return
        decode = {1: _subframe1, 2: _subframe2, 3: _subframe3}[sf_id]
        fields_ = decode(bits) | {"tow": tow - 6.0}
        if ref_gps_s is not None:
            fields_["ref_gps_s"] = ref_gps_s
        if now_gps_s is not None:
            # the subframe ended at `tow` (its HOW counts the next one's start) just before it was output
            offset = tow - now_gps_s % WEEK_S
            fields_["offset_s"] = offset - WEEK_S * round(offset / WEEK_S)
            fields_["now_s"] = now_gps_s
        sv_id = f"G{sv:02d}"
        parts = self.satellites.setdefault(sv_id, {})
        parts[sf_id] = fields_
        self._assemble(sv_id, parts)

    def _assemble(self, sv_id: str, parts: dict[int, dict[str, float]]) -> None:
        if not all(k in parts for k in (1, 2, 3)):
            return
        sf1, sf2, sf3 = parts[1], parts[2], parts[3]
        tows = [float(sf["tow"]) for sf in (sf1, sf2, sf3)]
        if max(tows) - min(tows) > 24.0 and max(tows) - min(tows) < WEEK_S - 24.0:
            return  # not one 30-s frame: its parts may belong to different uploads
        iode = int(sf2["iode"])
        if not (int(sf1["iodc"]) & 0xFF == iode == int(sf3["iode"])):
            return
        ref = sf1.get("ref_gps_s")
        if ref is None:
            self.counts["no GPS time to resolve the week"] += 1
            return
        week = int(sf1["week10"])
        ref_week = int(ref // WEEK_S)
        week += 1024 * round((ref_week - week) / 1024)
        tow = float(sf1["tow"])
        toe_s = near_in_week(float(sf2["toe_sow"]), week * WEEK_S + tow)
        toc_s = near_in_week(float(sf1["toc_sow"]), week * WEEK_S + tow)
        toe_week = int(toe_s // WEEK_S)
        record: dict[str, float | int | str] = {
            "sv_id": sv_id,
            "week": toe_week,
            "toe_sow": toe_s - toe_week * WEEK_S,
            "toc_s": toc_s,
            "health": int(sf1["health"]),
            "iode": iode,
        }
        for key in ("af0", "af1", "af2", "tgd"):
            record[key] = float(sf1[key])
        for key in ("crs", "delta_n", "m0", "cuc", "e", "cus", "sqrt_a"):
            record[key] = float(sf2[key])
        for key in ("cic", "omega0", "cis", "i0", "crc", "omega", "omega_dot", "idot"):
            record[key] = float(sf3[key])
        if not 2000.0 < float(record["sqrt_a"]) < 10000.0:
            self.counts["implausible orbit"] += 1
            return
        offsets = [float(sf["offset_s"]) for sf in (sf1, sf2, sf3) if "offset_s" in sf]
        offset = float(np.median(offsets)) if offsets else math.nan
        # the same broadcast again (every 30 s) is one record; the same orbit on another clock is not
        identity = (*sorted(record.items()), round(offset / 60.0) if offsets else None)
        if identity in self.assembled:
            return
        record["message_offset_s"] = offset
        record["received_s"] = max(float(sf.get("now_s", math.nan)) for sf in (sf1, sf2, sf3))
        self.assembled[identity] = record

    def records(self) -> list[dict[str, float | int | str]]:
        return list(self.assembled.values())

    def ephemerides(self) -> GpsEphemerides | None:
        """The records assembled (with the ionosphere page when one came), None when none did."""
        records = self.records()
        return GpsEphemerides.from_records(records, self.iono) if records else None

    def dropped(self, stream: str) -> list[Skipped]:
        """What was dropped, for the reader's skipped list: subframes that failed parity, orbits out of
        range, subframes without a GPS time to resolve their week. Skipped, not lost: each came in a message
        the file carried whole (its checksum or its line intact); the bits are the receiver's decoding, which
        fails on a weak signal (a 2016 phone's every navigation message)."""
        return [
            Skipped(stream, f"GPS subframes dropped: {what}", self.counts[what], "skipped")
            for what in ("parity failed", "implausible orbit", "no GPS time to resolve the week")
            if self.counts[what]
        ]
