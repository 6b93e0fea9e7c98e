"""Building u-blox captures for tests: GPS LNAV subframes encoded from broadcast records (IS-GPS-200,
independently of the reader's decoder: field by field from the ICD's tables) in RXM-SFRBX, and RXM-RAWX
epochs from an observation table."""

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


def sfrbx(sv: int, words30: list[int], gnss_id: int = 0) -> bytes:
    payload = bytes((gnss_id, sv, 0, 0, len(words30), 0, 2, 0)) + struct.pack(f"<{len(words30)}I", *words30)
    return UBXMessage("RXM", "RXM-SFRBX", GET, payload=payload).serialize()


def rawx(gps_s: float, rows: pd.DataFrame) -> bytes:
    """One RXM-RAWX epoch of GPS L1 C/A rows (sv_id, pseudorange_m, carrier_phase_cycles, doppler_hz, cn0_dbhz)."""
    week, tow = divmod(gps_s, WEEK_S)
    head = struct.pack("<dHbBBB2x", tow, int(week), 18, len(rows), 1, 1)
    meas = b""
    for r in rows.itertuples():
        cp = r.carrier_phase_cycles if np.isfinite(r.carrier_phase_cycles) else 0.0
        do = r.doppler_hz if np.isfinite(r.doppler_hz) else 0.0
        cn0 = int(r.cn0_dbhz) if np.isfinite(r.cn0_dbhz) else 32 + (7 * int(r.sv_id[1:])) % 17  # a spread sky
        trk = 1 | (2 if np.isfinite(r.carrier_phase_cycles) else 0)
        meas += struct.pack(
            "<ddfBBBBHBBBBBx", r.pseudorange_m, cp, do, 0, int(r.sv_id[1:]), 0, 0, 64000, cn0, 4, 2, 3, trk
        )
    return UBXMessage("RXM", "RXM-RAWX", GET, payload=head + meas).serialize()


def capture_from_rinex(
    obs: pd.DataFrame,
    t0_gps_s: float,
    records: list[dict[str, float]],
    iono: tuple[tuple[float, ...], ...] | None,
    counterfeit: Sequence[tuple[float, dict[str, float], float]] = (),
) -> bytes:
    """A RAWX + SFRBX capture of a RINEX observation table (t_s from t0_gps_s): before each epoch, the
    subframes 1-3 of every record whose toe is nearest, and the ionosphere page once. `counterfeit`:
    (t_s from which, record, clock error s) messages sent instead for that satellite from then on."""
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
            for words in lnav_subframes(rec, frame_start, clock_error_s=error):
                out.append(sfrbx(int(sv[1:]), words))
        if iono is not None and first:
            out.append(sfrbx(1, iono_subframe(iono[0], iono[1], frame_start)))
        first = False
        out.append(rawx(gps_s, rows))
    return b"".join(out)
