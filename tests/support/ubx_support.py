"""Building u-blox captures for tests: GPS LNAV subframes and Galileo I/NAV pages encoded from broadcast
records (IS-GPS-200, Galileo OS SIS ICD; independently of the reader's decoders: field by field from the
ICDs' tables) in RXM-SFRBX, and RXM-RAWX epochs from an observation table."""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd
from pyubx2 import GET, UBXMessage

WEEK_S = 604_800


def _parity(d: int, d29s: int, d30s: int) -> int:
    """D25..D30 of 24 source bits d (bit 1 = MSB), by IS-GPS-200 Table 20-XIV written out."""

    def b(i: int) -> int:
        return (d >> (24 - i)) & 1

    def x(*ids: int) -> int:
        v = 0
        for i in ids:
            v ^= b(i)
        return v

    p = (
        d29s ^ x(1, 2, 3, 5, 6, 10, 11, 12, 13, 14, 17, 18, 20, 23),
        d30s ^ x(2, 3, 4, 6, 7, 11, 12, 13, 14, 15, 18, 19, 21, 24),
        d29s ^ x(1, 3, 4, 5, 7, 8, 12, 13, 14, 15, 16, 19, 20, 22),
        d30s ^ x(2, 4, 5, 6, 8, 9, 13, 14, 15, 16, 17, 20, 21, 23),
        d30s ^ x(1, 3, 5, 6, 7, 9, 10, 14, 15, 16, 17, 18, 21, 22, 24),
        d29s ^ x(3, 5, 6, 8, 9, 10, 11, 13, 15, 19, 22, 23, 24),
    )
    return sum(bit << (5 - k) for k, bit in enumerate(p))


class _Writer:
    def __init__(self) -> None:
        self.bits: list[int] = [0] * 240

    def put(self, pos: int, n: int, value: int) -> None:
        value &= (1 << n) - 1
        for k in range(n):
            self.bits[pos + k] = (value >> (n - 1 - k)) & 1

    def words(self) -> list[int]:
        return [int("".join(map(str, self.bits[24 * i : 24 * i + 24])), 2) for i in range(10)]


def _transmit(data_words: list[int], restored: bool = False) -> list[int]:
    """30-bit words as transmitted: parity chained over D29*/D30*; words 2 and 10 get their two
    't' bits solved so that D29 = D30 = 0 (IS-GPS-200 20.3.5.2). `restored`: data not complemented."""
    out: list[int] = []
    prev = 0
    for i, d in enumerate(data_words):
        d29s, d30s = (prev >> 1) & 1, prev & 1
        if i in (1, 9):
            d = next(c for c in (d & ~3 | t for t in range(4)) if _parity(c, d29s, d30s) & 3 == 0)
        sent = d if restored or not d30s else d ^ 0xFFFFFF
        word = (sent << 6) | _parity(d, d29s, d30s)
        out.append(word)
        prev = word
    return out


def _head(w: _Writer, tow_next: float, sf_id: int) -> None:
    w.put(0, 8, 0x8B)
    w.put(24, 17, round(tow_next / 6.0))
    w.put(43, 3, sf_id)


def lnav_subframes(
    rec: Mapping[str, float], tx_gps_s: float, restored: bool = False, clock_error_s: float = 0.0
) -> list[list[int]]:
    """Subframes 1, 2, 3 of one broadcast record (GpsEphemerides field names), the first sent at GPS
    second `tx_gps_s` (a multiple of 30), as ten 30-bit words each; `clock_error_s` shifts the time the
    message says (a spoofer's clock), not when it is sent."""
    week, tow_s = divmod(tx_gps_s + clock_error_s, WEEK_S)
    sc = math.pi
    w1, w2, w3 = _Writer(), _Writer(), _Writer()
    for k, w in enumerate((w1, w2, w3)):
        _head(w, tow_s + 6.0 * (k + 1), k + 1)
    iode = int(rec["iode"])
    w1.put(48, 10, int(week) % 1024)
    w1.put(64, 6, int(rec["health"]))
    w1.put(70, 2, 0)
    w1.put(160, 8, round(rec["tgd"] / 2.0**-31))
    w1.put(168, 8, iode)
    w1.put(176, 16, round((rec["toc_s"] % WEEK_S) / 16))
    w1.put(192, 8, round(rec["af2"] / 2.0**-55))
    w1.put(200, 16, round(rec["af1"] / 2.0**-43))
    w1.put(216, 22, round(rec["af0"] / 2.0**-31))
    w2.put(48, 8, iode)
    w2.put(56, 16, round(rec["crs"] / 2.0**-5))
    w2.put(72, 16, round(rec["delta_n"] / sc / 2.0**-43))
    w2.put(88, 32, round(rec["m0"] / sc / 2.0**-31))
    w2.put(120, 16, round(rec["cuc"] / 2.0**-29))
    w2.put(136, 32, round(rec["e"] / 2.0**-33))
    w2.put(168, 16, round(rec["cus"] / 2.0**-29))
    w2.put(184, 32, round(rec["sqrt_a"] / 2.0**-19))
    w2.put(216, 16, round(rec["toe_sow"] / 16))
    w3.put(48, 16, round(rec["cic"] / 2.0**-29))
    w3.put(64, 32, round(rec["omega0"] / sc / 2.0**-31))
    w3.put(96, 16, round(rec["cis"] / 2.0**-29))
    w3.put(112, 32, round(rec["i0"] / sc / 2.0**-31))
    w3.put(144, 16, round(rec["crc"] / 2.0**-5))
    w3.put(160, 32, round(rec["omega"] / sc / 2.0**-31))
    w3.put(192, 24, round(rec["omega_dot"] / sc / 2.0**-43))
    w3.put(216, 8, iode)
    w3.put(224, 14, round(rec["idot"] / sc / 2.0**-43))
    return [_transmit(w.words(), restored) for w in (w1, w2, w3)]


def iono_subframe(alpha: tuple[float, ...], beta: tuple[float, ...], tx_gps_s: float) -> list[int]:
    """Subframe 4 page 18 (SV ID 56) with Klobuchar coefficients, sent at GPS second `tx_gps_s`."""
    tow_s = tx_gps_s % WEEK_S
    w = _Writer()
    _head(w, tow_s + 24.0, 4)
    w.put(48, 2, 1)
    w.put(50, 6, 56)
    scales = (2.0**-30, 2.0**-27, 2.0**-24, 2.0**-24, 2.0**11, 2.0**14, 2.0**16, 2.0**16)
    for k, (v, s) in enumerate(zip((*alpha, *beta), scales, strict=True)):
        w.put(56 + 8 * k, 8, round(v / s))
    return _transmit(w.words())


class _Bits:
    """A sequential bit writer: fields appended in the ICD's order, most significant bit first."""

    def __init__(self) -> None:
        self.bits: list[int] = []

    def add(self, n: int, value: float) -> _Bits:
        v = round(value) & ((1 << n) - 1)
        self.bits += [(v >> (n - 1 - k)) & 1 for k in range(n)]
        return self

    def value(self, width: int) -> int:
        assert len(self.bits) <= width, len(self.bits)
        return int("".join(map(str, self.bits + [0] * (width - len(self.bits)))), 2)


def _crc24q_of_bits(bits: list[int]) -> int:
    """CRC-24Q of a bit sequence, one bit at a time (the ICD's polynomial, no table)."""
    poly = [int(c) for c in f"{0x1864CFB:025b}"][1:]
    reg = [0] * 24
    for b in bits:
        feedback = reg[0] ^ b
        reg = [*reg[1:], 0]
        if feedback:
            reg = [r ^ p for r, p in zip(reg, poly, strict=True)]
    return int("".join(map(str, reg)), 2)


def inav_words(rec: Mapping[str, float], tx_gps_s: float, health: int = 0) -> list[int]:
    """Galileo I/NAV word types 1-5 (128 bits each, Galileo OS SIS ICD Tables 40-42) of one record
    (GpsEphemerides field names; `tgd` is BGD(E1, E5b)); word 5's time is `tx_gps_s`."""
    sc = math.pi
    iod = int(rec["iode"])
    toe, toc = rec["toe_sow"], rec["toc_s"] % WEEK_S
    week, tow = divmod(tx_gps_s, WEEK_S)
    w1 = _Bits().add(6, 1).add(10, iod).add(14, toe / 60).add(32, rec["m0"] / sc / 2.0**-31)
    w1.add(32, rec["e"] / 2.0**-33).add(32, rec["sqrt_a"] / 2.0**-19)
    w2 = _Bits().add(6, 2).add(10, iod).add(32, rec["omega0"] / sc / 2.0**-31).add(32, rec["i0"] / sc / 2.0**-31)
    w2.add(32, rec["omega"] / sc / 2.0**-31).add(14, rec["idot"] / sc / 2.0**-43)
    w3 = (
        _Bits().add(6, 3).add(10, iod).add(24, rec["omega_dot"] / sc / 2.0**-43).add(16, rec["delta_n"] / sc / 2.0**-43)
    )
    for key in ("cuc", "cus"):
        w3.add(16, rec[key] / 2.0**-29)
    w3.add(16, rec["crc"] / 2.0**-5).add(16, rec["crs"] / 2.0**-5).add(8, 107)  # SISA index
    w4 = _Bits().add(6, 4).add(10, iod).add(6, int(str(rec["sv_id"])[1:]))
    w4.add(16, rec["cic"] / 2.0**-29).add(16, rec["cis"] / 2.0**-29).add(14, toc / 60)
    w4.add(31, rec["af0"] / 2.0**-34).add(21, rec["af1"] / 2.0**-46).add(6, rec["af2"] / 2.0**-59)
    w5 = _Bits().add(6, 5).add(11, 0).add(11, 0).add(14, 0).add(5, 0)  # NeQuick coefficients, region flags
    w5.add(10, 0).add(10, rec["tgd"] / 2.0**-32)  # BGD(E1, E5a), BGD(E1, E5b)
    w5.add(2, 0).add(2, health >> 1).add(1, 0).add(1, health & 1)  # E5b HS, E1-B HS, E5b DVS, E1-B DVS
    w5.add(12, week - 1024).add(20, tow)
    return [w.value(128) for w in (w1, w2, w3, w4, w5)]


def inav_page(word: int, alert: bool = False) -> list[int]:
    """A nominal page carrying one 128-bit word as u-blox sends it: even then odd part, 120 bits each in
    four U4 words (8 bits of padding), the CRC-24Q over both parts' data."""
    data = [(word >> (127 - k)) & 1 for k in range(128)]
    even = [0, int(alert), *data[:112]]
    odd = [1, int(alert), *data[112:], *([0] * 64)]
    crc = _crc24q_of_bits([0] * 4 + even + odd)
    odd += [(crc >> (23 - k)) & 1 for k in range(24)] + [0] * 8
    parts = [even + [0] * (128 - len(even)), odd + [0] * (128 - len(odd))]
    bits = parts[0] + parts[1]
    return [int("".join(map(str, bits[32 * i : 32 * i + 32])), 2) for i in range(8)]


def sfrbx(sv: int, words30: list[int], gnss_id: int = 0) -> bytes:
    payload = bytes((gnss_id, sv, 0, 0, len(words30), 0, 2, 0)) + struct.pack(f"<{len(words30)}I", *words30)
    return UBXMessage("RXM", "RXM-SFRBX", GET, payload=payload).serialize()


GNSS_ID = {"G": 0, "E": 2, "C": 3}  # u-blox gnssId; signal 0 is GPS L1 C/A, Galileo E1C, BeiDou B1I D1


def rawx(gps_s: float, rows: pd.DataFrame) -> bytes:
    """One RXM-RAWX epoch of GPS L1 C/A and Galileo E1C rows (sv_id, pseudorange_m, carrier_phase_cycles,
    doppler_hz, cn0_dbhz). A carrier is tracked as a receiver in steady lock reports it: cpValid with the
    half-cycle resolved (trkStat 7), lock time saturated (64500 ms); columns `trk_stat` and `locktime_ms`,
    where given, say otherwise."""
    week, tow = divmod(gps_s, WEEK_S)
    head = struct.pack("<dHbBBB2x", tow, int(week), 18, len(rows), 1, 1)
    meas = b""
    for r in rows.itertuples():
        cp = r.carrier_phase_cycles if np.isfinite(r.carrier_phase_cycles) else 0.0
        do = r.doppler_hz if np.isfinite(r.doppler_hz) else 0.0
        cn0 = int(r.cn0_dbhz) if np.isfinite(r.cn0_dbhz) else 32 + (7 * int(r.sv_id[1:])) % 17  # a spread sky
        trk = int(getattr(r, "trk_stat", 1 | (6 if np.isfinite(r.carrier_phase_cycles) else 0)))
        lock = int(getattr(r, "locktime_ms", 64500))
        ids = (GNSS_ID[r.sv_id[0]], int(r.sv_id[1:]))
        meas += struct.pack("<ddfBBBBHBBBBBx", r.pseudorange_m, cp, do, *ids, 0, 0, lock, cn0, 4, 2, 3, trk)
    return UBXMessage("RXM", "RXM-RAWX", GET, payload=head + meas).serialize()


def capture_from_rinex(
    obs: pd.DataFrame,
    t0_gps_s: float,
    records: list[dict[str, float]],
    iono: tuple[tuple[float, ...], ...] | None,
    counterfeit: Sequence[tuple[float, dict[str, float], float]] = (),
) -> bytes:
    """A RAWX + SFRBX capture of a RINEX observation table (t_s from t0_gps_s): before each epoch, the
    subframes 1-3 (a Galileo satellite's I/NAV word types 1-5, just sent) of every record whose toe is
    nearest, and the ionosphere page once. `counterfeit`: (t_s from which, record, clock error s)
    messages sent instead for that satellite from then on."""
    out: list[bytes] = []
    sent: set[tuple[str, int]] = set()
    first = True
    for t_s, rows in obs.groupby("t_s", sort=True):
        gps_s = t0_gps_s + float(t_s)
        frame_start = math.floor(gps_s / 30.0) * 30.0 - 30.0
        for sv in rows["sv_id"]:
            fake = [(k, r, e) for k, (start, r, e) in enumerate(counterfeit) if r["sv_id"] == sv and t_s >= start]
            if fake:
                k, rec, error = fake[-1]
                key = (sv, -1 - k)
            else:
                cands = [r for r in records if r["sv_id"] == sv]
                if not cands:
                    continue
                rec = min(cands, key=lambda r: abs(r["week"] * WEEK_S + r["toe_sow"] - gps_s))
                key, error = (sv, int(rec["iode"])), 0.0
            if key in sent:
                continue
            sent.add(key)
            if sv.startswith("E"):
                for word in inav_words(rec, gps_s - 3.0 + error):
                    out.append(sfrbx(int(sv[1:]), inav_page(word), GNSS_ID["E"]))
                continue
            for words in lnav_subframes(rec, frame_start, clock_error_s=error):
                out.append(sfrbx(int(sv[1:]), words))
        if iono is not None and first:
            out.append(sfrbx(1, iono_subframe(iono[0], iono[1], frame_start)))
        first = False
        out.append(rawx(gps_s, rows))
    return b"".join(out)
