"""UBX messages -> values with units: the one place each u-blox message is mapped.

Decoded with pyubx2, except RXM-RAWX, whose fixed layout (16-byte header, 32 bytes per measurement)
is cut out with numpy: pyubx2 takes ~7 ms per RAWX message, this ~20 us, and a test checks the two
agree on every field of the real capture.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from pyubx2 import UBXReader
from pyubx2.exceptions import UBXMessageError, UBXParseError, UBXTypeError

from readers.carrier_arcs import CP_VALID, PR_VALID
from readers.ubx.frames import UbxFrame, fletcher
from spooflens.gnss.ephemeris import C_MPS
from spooflens.schema import FixType, SpoofingFlag

MSG = {  # (class, id) -> name, for the messages spooflens reads
    (0x01, 0x07): "NAV-PVT",
    (0x01, 0x35): "NAV-SAT",
    (0x01, 0x03): "NAV-STATUS",
    (0x01, 0x04): "NAV-DOP",
    (0x01, 0x20): "NAV-TIMEGPS",
    (0x02, 0x15): "RXM-RAWX",
    (0x02, 0x13): "RXM-SFRBX",
    (0x0A, 0x38): "MON-RF",
    (0x0A, 0x09): "MON-HW",
    (0x0A, 0x04): "MON-VER",
    (0x27, 0x09): "SEC-SIG",
    (0x10, 0x03): "ESF-RAW",
    (0x10, 0x02): "ESF-MEAS",
    # receivers before NAV-PVT (u-blox 5-7, timing firmware) and the messages that carry their fixes
    (0x01, 0x02): "NAV-POSLLH",
    (0x01, 0x01): "NAV-POSECEF",
    (0x01, 0x06): "NAV-SOL",
    (0x01, 0x12): "NAV-VELNED",
    (0x01, 0x11): "NAV-VELECEF",
    (0x01, 0x30): "NAV-SVINFO",
    (0x01, 0x21): "NAV-TIMEUTC",
    (0x0D, 0x01): "TIM-TP",
    # NAV-PVT's layout again: sensor fusion's PVAT, and fixes the receiver batched in its memory
    (0x01, 0x17): "NAV-PVAT",
    (0x21, 0x11): "LOG-BATCH",
    # the receiver's stored position log read back: fixes it recorded earlier, each with its UTC date
    (0x21, 0x0B): "LOG-RETRIEVEPOS",
}
PVT_LIKE = ("NAV-PVT", "NAV-PVAT", "LOG-BATCH")  # a whole fix in one message, NAV-PVT's field names
LEGACY_FIX = ("NAV-POSLLH", "NAV-POSECEF", "NAV-SOL", "NAV-VELNED", "NAV-VELECEF")  # a fix in parts
TIME_ONLY = ("NAV-TIMEUTC", "NAV-TIMEGPS", "TIM-TP", "NAV-CLOCK", "TIM-SVIN", "TIM-TM2", "NAV-TIMELS")
ParseErrors = (UBXMessageError, UBXParseError, UBXTypeError, ValueError, TypeError, IndexError, KeyError)

SPOOF_MEANING = (
    "u-blox NAV-STATUS spoofDetState: 0 unknown or deactivated, 1 no spoofing indicated, 2 spoofing "
    "indicated, 3 multiple spoofing indications (SEC-SIG spoofingState where NAV-STATUS is absent: 0 unknown, "
    "1 no spoofing, 2 spoofing indicated, 3 spoofing affirmed); spoofing_flag INDICATED for 2 and 3"
)
JAM_MEANING = (
    "u-blox jammingState (SEC-SIG, else MON-RF block 0, else MON-HW): 0 unknown or disabled, 1 ok (no "
    "significant jamming), 2 warning (interference visible, fix OK), 3 critical (interference visible, no fix)"
)
FIX_MEANING = (
    "u-blox NAV-PVT fixType 0 no fix, 1 dead reckoning only (UNKNOWN), 2 2-D, 3 3-D (DGNSS with diffSoln, "
    "RTK float/fixed with carrSoln 1/2), 4 GNSS + dead reckoning (3-D), 5 time only (no fix); gnssFixOK 0 "
    "or invalidLlh means no fix"
)


def parse(frame: UbxFrame) -> Any:
    """The pyubx2 message of a frame (its checksum was verified when it was framed)."""
    head = bytes((frame.msg_class, frame.msg_id)) + len(frame.payload).to_bytes(2, "little") + frame.payload
    return UBXReader.parse(b"\xb5\x62" + head + fletcher(head))


def _get(msg: Any, name: str, default: float = math.nan) -> float:
    v = getattr(msg, name, None)
    return float(v) if isinstance(v, int | float) and not isinstance(v, bool) else default


def pvt_values(msg: Any) -> dict[str, float] | None:
    """A NAV-PVT fix in schema names, or None when the receiver says it is no fix."""
    fix_type = int(_get(msg, "fixType", 0))
    fix_ok = _get(msg, "gnssFixOk", _get(msg, "gnssFixOK", 0))  # NAV-PVAT and LOG-BATCH spell it gnssFixOK
    if fix_type in (0, 5) or not int(fix_ok) or int(_get(msg, "invalidLlh", 0)):
        return None
    kind = fix_kind(fix_type, int(_get(msg, "carrSoln", 0)), int(_get(msg, "diffSoln", 0)))
    return posllh_values(msg) | {
        "vel_e_mps": _get(msg, "velE") / 1000,
        "vel_n_mps": _get(msg, "velN") / 1000,
        "vel_u_mps": -_get(msg, "velD") / 1000,
        "vel_acc_mps": _get(msg, "sAcc") / 1000,
        "sats_used": _get(msg, "numSV"),
        "fix_type": float(kind),
    }


def fix_kind(fix_type: int, carr_soln: int = 0, diff_soln: int = 0) -> FixType:
    """NAV-PVT's fixType (1 dead reckoning only, 2 2-D, 3 3-D, 4 GNSS + dead reckoning) with its carrier
    and differential solution flags as a FixType."""
    if fix_type == 1:
        return FixType.UNKNOWN
    if fix_type == 2:
        return FixType.FIX_2D
    if carr_soln == 2:
        return FixType.RTK_FIXED
    if carr_soln == 1:
        return FixType.RTK_FLOAT
    return FixType.DGNSS if diff_soln else FixType.FIX_3D


def retrievepos_values(msg: Any) -> dict[str, float] | None:
    """A fix of the receiver's stored log (LOG-RETRIEVEPOS) in schema names, or None when the record says
    it is no fix (fixType as NAV-PVT's). The record has NAV-PVT's position and horizontal accuracy, a
    height above mean sea level (hMSL: no geoid separation, kept as the height), ground speed and heading
    of motion (no vertical velocity, no vertical or speed accuracy)."""
    fix_type = int(_get(msg, "fixType", 0))
    if fix_type in (0, 5):
        return None
    speed_mps, heading = _get(msg, "gSpeed") / 1000, math.radians(_get(msg, "heading"))
    return posllh_values(msg) | {
        "height_m": _get(msg, "hMSL") / 1000,
        "vel_e_mps": speed_mps * math.sin(heading),
        "vel_n_mps": speed_mps * math.cos(heading),
        "sats_used": _get(msg, "numSV"),
        "fix_type": float(fix_kind(fix_type)),
    }


def retrievepos_utc_ns(msg: Any) -> int | None:
    """UTC of a stored-log record (to the second: the record has no fraction), None when it is no date."""
    return _utc_ns(msg, "second", 0, minute="minute")


def pvt_utc_ns(msg: Any) -> int | None:
    """UTC of a NAV-PVT (or NAV-PVAT, LOG-BATCH) in ns since 1970, when the receiver says date and time
    are valid."""
    if not (int(_get(msg, "validDate", 0)) and int(_get(msg, "validTime", 0))):
        return None
    return _utc_ns(msg, "second" if hasattr(msg, "second") else "sec", _get(msg, "nano", _get(msg, "fracSec", 0)))


def _utc_ns(msg: Any, seconds: str, nano: float, minute: str = "min") -> int | None:
    import datetime as dt

    try:
        stamp = dt.datetime(
            int(msg.year),
            int(msg.month),
            int(msg.day),
            int(msg.hour),
            int(getattr(msg, minute)),
            int(getattr(msg, seconds)),
            tzinfo=dt.UTC,
        )
    except (ValueError, TypeError, AttributeError, OverflowError):
        return None
    if stamp.year < 1999:  # a receiver before its first fix counts from its firmware's epoch, not a date
        return None
    return int(stamp.timestamp()) * 1_000_000_000 + (int(nano) if math.isfinite(nano) else 0)


GPS_EPOCH_UNIX_S = 315_964_800  # 1980-01-06 in UNIX seconds


def timeutc_utc_ns(msg: Any) -> int | None:
    """UTC of a NAV-TIMEUTC when the receiver says it is valid (validUTC)."""
    if not int(_get(msg, "validUTC", 0)):
        return None
    return _utc_ns(msg, "sec", _get(msg, "nano", 0))


def sol_gps_s(msg: Any) -> float | None:
    """GPS time of a NAV-SOL whose week and time of week the receiver has set (wknSet, towSet)."""
    week = int(_get(msg, "week", 0))
    if not (int(_get(msg, "wknSet", 0)) and int(_get(msg, "towSet", 0))) or week <= 0:
        return None
    return week * 604_800 + _get(msg, "iTOW") / 1000 + _get(msg, "fTOW", 0) * 1e-9


def tim_tp_week_tow(msg: Any) -> tuple[int, float, bool] | None:
    """(week, time of week s, on UTC) of a TIM-TP's next time pulse; None before the receiver knows its
    week. timeBase 1: the pulse is aligned to UTC, its week and time of week counted on UTC."""
    week = int(_get(msg, "week", 0))
    if week <= 0:
        return None
    return week, _get(msg, "towMS") / 1000, bool(int(_get(msg, "timeBase", 0)))


def posllh_values(msg: Any) -> dict[str, float]:
    """Position and its accuracies, as NAV-POSLLH and NAV-PVT both give them (deg, mm)."""
    return {
        "lat_deg": _get(msg, "lat"),
        "lon_deg": _get(msg, "lon"),
        "height_m": _get(msg, "height") / 1000,
        "h_acc_m": _get(msg, "hAcc") / 1000,
        "v_acc_m": _get(msg, "vAcc") / 1000,
    }


def velned_values(msg: Any) -> dict[str, float]:
    return {
        "vel_e_mps": _get(msg, "velE") / 100,
        "vel_n_mps": _get(msg, "velN") / 100,
        "vel_u_mps": -_get(msg, "velD") / 100,
        "vel_acc_mps": _get(msg, "sAcc") / 100,
    }


def ecef_values(msg: Any) -> dict[str, float]:
    """NAV-POSECEF, NAV-VELECEF or NAV-SOL: whichever of ECEF position (cm) and velocity (cm/s) it has."""
    out = {f"ecef_{a}_m": _get(msg, f"ecef{a.upper()}") / 100 for a in "xyz"}
    out |= {f"ecef_v{a}_mps": _get(msg, f"ecefV{a.upper()}") / 100 for a in "xyz"}
    if hasattr(msg, "sAcc"):
        out["vel_acc_mps"] = _get(msg, "sAcc") / 100
    return {k: v for k, v in out.items() if math.isfinite(v)}


def fix_status(msg: Any) -> dict[str, float]:
    """NAV-SOL's or NAV-STATUS's fix: gpsFix (0 none, 1 dead reckoning, 2 2-D, 3 3-D, 4 GNSS + dead
    reckoning, 5 time only), whether it is valid (gpsFixOk) and differential (diffSoln)."""
    ok = _get(msg, "gpsfixOK", _get(msg, "gpsFixOk"))
    out = {"gps_fix": _get(msg, "gpsFix"), "fix_ok": ok, "diff_soln": _get(msg, "diffSoln")}
    if hasattr(msg, "numSV"):
        out["sats_used"] = _get(msg, "numSV")
    return out


NAV_SAT_SV = np.dtype(
    [
        ("gnssId", "u1"),
        ("svId", "u1"),
        ("cno", "u1"),
        ("elev", "i1"),
        ("azim", "<i2"),
        ("prRes", "<i2"),
        ("flags", "<u4"),
    ]
)


@dataclass(frozen=True)
class NavSat:
    itow_ms: int
    rows: dict[str, np.ndarray]  # satellites-frame columns (no t_ns, receiver_id)

    @property
    def cn0_mean(self) -> float:
        """Mean C/N0 of the satellites reported as tracked (C/N0 > 0)."""
        cn0 = self.rows["cn0_dbhz"]
        tracked = cn0[np.isfinite(cn0)]
        return float(tracked.mean()) if len(tracked) else math.nan


def nav_sat(frame: UbxFrame) -> NavSat:
    """NAV-SAT decoded at once: per satellite C/N0, elevation, azimuth, residual, used and health
    (flags: qualityInd bits 0-2, svUsed bit 3, health bits 4-5 with 0 unknown, 1 healthy, 2 unhealthy)."""
    p = frame.payload
    if len(p) < 8 or len(p) != 8 + 12 * p[5]:
        raise ValueError(f"NAV-SAT with {p[5] if len(p) > 5 else 0} satellites in {len(p)} bytes")
    itow = int.from_bytes(p[:4], "little")
    sv = np.frombuffer(p[8:], NAV_SAT_SV)
    ids, ok = sv_ids(sv["gnssId"], sv["svId"])
    sv = sv[ok]
    flags = sv["flags"].astype(np.int64)
    health = (flags >> 4) & 3
    known_elev = (sv["elev"] >= -90) & ((flags >> 8) & 7 > 0)  # -91: unknown; orbitSource 0: no orbit
    rows = {
        "sv_id": ids[ok],
        "cn0_dbhz": np.where(sv["cno"] > 0, sv["cno"].astype(float), np.nan),
        "elevation_deg": np.where(known_elev, sv["elev"].astype(float), np.nan),
        "azimuth_deg": np.where(known_elev, sv["azim"].astype(float), np.nan),
        "used": ((flags >> 3) & 1).astype(float),
        "residual_m": np.where((flags >> 3) & 1 == 1, sv["prRes"] * 0.1, np.nan),
        "healthy": np.select([health == 1, health == 2], [1.0, 0.0], np.nan),
    }
    return NavSat(itow, rows)


def status_values(msg: Any) -> dict[str, float]:
    state = _get(msg, "spoofDetState")
    return {"spoofing_state": state, "spoofing_flag": float(spoofing_flag(state))}


def spoofing_flag(state: float) -> SpoofingFlag:
    if not math.isfinite(state) or state == 0:
        return SpoofingFlag.UNKNOWN
    return SpoofingFlag.INDICATED if state >= 2 else SpoofingFlag.CLEAR


def sec_sig_values(msg: Any) -> dict[str, float]:
    out = {"sec_spoofing_state": _get(msg, "spoofingState"), "sec_jamming_state": _get(msg, "jammingState")}
    return {k: v for k, v in out.items() if math.isfinite(v)}


def mon_rf_values(frame: UbxFrame, msg: Any) -> dict[str, float]:
    """The first RF block (L1) of MON-RF; a 'compact' message cut inside a later block is fine."""
    full_blocks = (len(frame.payload) - 4) // 24
    if full_blocks < 1:
        return {}
    return {
        "rf_jamming_state": _get(msg, "jammingState_01"),
        "noise_per_ms": _get(msg, "noisePerMS_01"),
        "agc": _get(msg, "agcCnt_01"),
        "jamming_indicator": _get(msg, "jamInd_01"),
    }


def mon_hw_values(msg: Any) -> dict[str, float]:
    return {
        "hw_jamming_state": _get(msg, "jammingState"),
        "hw_noise_per_ms": _get(msg, "noisePerMS"),
        "hw_agc": _get(msg, "agcCnt"),
        "hw_jamming_indicator": _get(msg, "jamInd"),
    }


def mon_ver(msg: Any) -> dict[str, str]:
    """MON-VER's versions; {} for a message pyubx2 leaves without them (a poll the host sent, which has no
    payload, or a reply it cannot lay out)."""

    def text(v: Any) -> str:
        return (v.decode("latin-1") if isinstance(v, bytes) else str(v)).strip("\x00 ")

    ext = [text(getattr(msg, name)) for name in sorted(vars(msg)) if name.startswith("extension")]
    versions = {
        "receiver.sw_version": getattr(msg, "swVersion", None),
        "receiver.hw_version": getattr(msg, "hwVersion", None),
    }
    out = {k: text(v) for k, v in versions.items() if v is not None and text(v)}
    if ext and out:
        out["receiver.extensions"] = "; ".join(e for e in ext if e)
    return out


SVINFO_SV = np.dtype(
    [
        ("chn", "u1"),
        ("svid", "u1"),
        ("flags", "u1"),
        ("quality", "u1"),
        ("cno", "u1"),
        ("elev", "i1"),
        ("azim", "<i2"),
        ("prRes", "<i4"),
    ]
)


def nav_svinfo(frame: UbxFrame) -> NavSat:
    """NAV-SVINFO (NAV-SAT's predecessor) decoded at once: per channel its satellite in u-blox's single
    numbering, C/N0, elevation and azimuth (when the receiver has an orbit: flags bit 2), residual (cm),
    used (bit 0) and health (bit 4 unhealthy; healthy when it has an ephemeris, bit 3)."""
    from readers.svinfo_numbering import SVINFO_IDS

    p = frame.payload
    if len(p) < 8 or len(p) != 8 + 12 * p[4]:
        raise ValueError(f"NAV-SVINFO with {p[4] if len(p) > 4 else 0} channels in {len(p)} bytes")
    itow = int.from_bytes(p[:4], "little")
    sv = np.frombuffer(p[8:], SVINFO_SV)
    ids = SVINFO_IDS[sv["svid"]].astype(str)
    sv, ids = sv[ids != ""], ids[ids != ""]
    flags = sv["flags"].astype(np.int64)
    used = (flags & 1).astype(float)
    orbit = (flags >> 2) & 1 == 1
    rows = {
        "sv_id": ids,
        "cn0_dbhz": np.where(sv["cno"] > 0, sv["cno"].astype(float), np.nan),
        "elevation_deg": np.where(orbit, sv["elev"].astype(float), np.nan),
        "azimuth_deg": np.where(orbit, sv["azim"].astype(float), np.nan),
        "used": used,
        "residual_m": np.where(used == 1, sv["prRes"] * 0.01, np.nan),
        "healthy": np.select([(flags >> 4) & 1 == 1, (flags >> 3) & 1 == 1], [0.0, 1.0], np.nan),
    }
    return NavSat(itow, rows)


# --- RXM-RAWX, vectorised ------------------------------------------------------------------------

RAWX_MEAS = np.dtype(
    [
        ("prMes", "<f8"),
        ("cpMes", "<f8"),
        ("doMes", "<f4"),
        ("gnssId", "u1"),
        ("svId", "u1"),
        ("sigId", "u1"),
        ("freqId", "u1"),
        ("locktime", "<u2"),
        ("cno", "u1"),
        ("prStdev", "u1"),
        ("cpStdev", "u1"),
        ("doStdev", "u1"),
        ("trkStat", "u1"),
        ("reserved3", "u1"),
    ]
)
SYSTEM_LETTER = {0: "G", 1: "S", 2: "E", 3: "C", 5: "J", 6: "R", 7: "I"}
# L1-band signal priority per system (u-blox sigId), like the RINEX reader's lists: GPS L1C/A; SBAS L1C/A;
# Galileo E1C, E1B; BeiDou B1I D1, D2, then B1C; QZSS L1C/A, L1S; GLONASS L1OF; NavIC L5A (no L1 signal)
L1_SIGNALS = {0: (0,), 1: (0,), 2: (0, 1), 3: (0, 1, 5, 6), 5: (0, 1), 6: (0,), 7: (0,)}
L1_HZ, B1I_HZ, L5_HZ = 1575.42e6, 1561.098e6, 1176.45e6
RAWX_TRACKING = ("trk_stat", "locktime_ms", "sig_id")  # rawx_rows' columns for the carrier's continuity only


@dataclass
class RawxEpoch:
    gps_s: float  # week * 604800 + rcvTow
    meas: np.ndarray  # RAWX_MEAS records


def rawx(frame: UbxFrame) -> RawxEpoch:
    """One RXM-RAWX: receiver time and its measurements; ValueError if its length does not add up."""
    p = frame.payload
    if len(p) < 16:
        raise ValueError(f"RXM-RAWX of {len(p)} bytes")
    rcv_tow = float(np.frombuffer(p[:8], "<f8")[0])
    week = int.from_bytes(p[8:10], "little")
    n = p[11]
    if len(p) != 16 + 32 * n:
        raise ValueError(f"RXM-RAWX with {n} measurements in {len(p)} bytes")
    return RawxEpoch(week * 604800 + rcv_tow, np.frombuffer(p[16:], RAWX_MEAS))


def sv_ids(gnss_id: np.ndarray, sv_id: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RINEX-style ids of u-blox (gnssId, svId) pairs, and which are real satellites (GLONASS 255:
    unknown slot)."""
    letter = np.array([SYSTEM_LETTER.get(int(g), "") for g in gnss_id], dtype="<U1")
    prn = sv_id.astype(np.int64)
    prn = np.where(gnss_id == 1, prn - 100, prn)  # SBAS PRN 120-158 -> S20-S58
    prn = np.where((gnss_id == 5) & (prn > 192), prn - 192, prn)  # QZSS 193-202 -> J01-J10
    ok = (letter != "") & (prn > 0) & (prn < 100) & ~((gnss_id == 6) & (sv_id == 255))
    ids = np.char.add(letter, np.char.zfill(np.clip(prn, 0, 99).astype(str), 2))
    return ids, ok


def rawx_rows(epoch: RawxEpoch) -> dict[str, np.ndarray]:
    """One row per satellite: its L1-band signal's code, phase, Doppler and C/N0 (RINEX-style sv id), and
    what says whether its carrier is continuous (`RAWX_TRACKING`: trkStat, locktime, sigId)."""
    m = epoch.meas
    sv, ok = sv_ids(m["gnssId"], m["svId"])
    rank = np.full(len(m), 99)
    for system, sigs in L1_SIGNALS.items():
        for r, sig in enumerate(sigs):
            rank[(m["gnssId"] == system) & (m["sigId"] == sig)] = r
    ok &= rank < 99
    # one signal per satellite: the best-ranked
    order = np.lexsort((rank, sv))
    order = order[ok[order]]
    first = np.ones(len(order), dtype=bool)
    first[1:] = sv[order][1:] != sv[order][:-1]
    idx = order[first]
    g, sig = m["gnssId"][idx], m["sigId"][idx]
    freq = np.full(len(idx), L1_HZ)
    freq[(g == 3) & (sig <= 1)] = B1I_HZ
    freq[g == 7] = L5_HZ
    glo = g == 6
    freq[glo] = 1602.0e6 + (m["freqId"][idx][glo].astype(float) - 7) * 0.5625e6
    trk = m["trkStat"][idx]
    pr = np.where(trk & PR_VALID, m["prMes"][idx], np.nan)
    doppler = m["doMes"][idx].astype(np.float64)
    return {
        "sv_id": sv[idx],
        "pseudorange_m": pr,
        "pseudorange_rate_mps": -doppler * C_MPS / freq,
        "doppler_hz": doppler,
        "carrier_phase_cycles": np.where(trk & CP_VALID, m["cpMes"][idx], np.nan),
        "carrier_freq_hz": freq,
        "cn0_dbhz": m["cno"][idx].astype(np.float64),
        "trk_stat": trk,
        "locktime_ms": m["locktime"][idx],
        "sig_id": sig,
    }


# --- ESF (IMU) ------------------------------------------------------------------------------------

ESF_GYRO = {14: "wx_radps", 13: "wy_radps", 5: "wz_radps"}  # deg/s * 2^-12
ESF_ACCEL = {16: "ax_mps2", 17: "ay_mps2", 18: "az_mps2"}  # m/s^2 * 2^-10


def _signed24(v: int) -> int:
    return v - (1 << 24) if v & 0x800000 else v


def esf_samples(name: str, frame: UbxFrame) -> list[tuple[int, dict[str, float]]]:
    """(sensor time tag, IMU values in SI) per sample of an ESF-RAW or ESF-MEAS message."""
    p = frame.payload
    words: list[tuple[int, int]] = []  # (data word, time tag)
    if name == "ESF-RAW":
        for k in range(4, len(p) - 7, 8):
            words.append((int.from_bytes(p[k : k + 4], "little"), int.from_bytes(p[k + 4 : k + 8], "little")))
    else:
        tag = int.from_bytes(p[:4], "little")
        n = (int.from_bytes(p[4:6], "little") >> 11) & 0x1F
        for k in range(8, min(8 + 4 * n, len(p) - 3), 4):
            words.append((int.from_bytes(p[k : k + 4], "little"), tag))
    samples: dict[int, dict[str, float]] = {}
    for word, tag in words:
        kind, value = (word >> 24) & 0x3F, _signed24(word & 0xFFFFFF)
        if kind in ESF_GYRO:
            samples.setdefault(tag, {})[ESF_GYRO[kind]] = math.radians(value / 4096.0)
        elif kind in ESF_ACCEL:
            samples.setdefault(tag, {})[ESF_ACCEL[kind]] = value / 1024.0
    return [(tag, v) for tag, v in samples.items() if len(v) == 6]
