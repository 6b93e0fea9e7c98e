"""Broadcast ephemerides from the RTCM3 correction stream a receiver was fed (messages 1019, GPS, 1042,
BeiDou, and 1046, Galileo I/NAV), decoded with pyrtcm.

A capture of an RTK rover often carries its base station's corrections, and the base sends the
broadcast orbits with them. They are the base's copy of the satellites' messages, received at another
antenna: satellite states for the rover's raw observations when the capture has no subframes of its
own, and never evidence about the rover's signals (they get no reception time, so the checks of
`spooflens.detectors.navigation_message` leave them alone). Galileo F/NAV (1045) carries the orbits of
1046 again with the E5a clock and no E1 health, and is counted, not used.

pyrtcm scales every field to its unit (angles in semicircles); the GPS week is sent modulo 1024 and
resolved against the capture's GPS time; the Galileo week counts from GPS week 1024, BeiDou's (BDT, 14 s
behind GPS time) from GPS week 1356; BeiDou's group delay is sent in nanoseconds.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from functools import partial
from typing import Any

from pyrtcm import RTCMReader

from readers.navbits import WEEK_S, near_in_week
from spooflens.epoch_table import Skipped
from spooflens.gnss.ephemeris import BDT_OFFSET_S, BDT_WEEK_OFFSET

RTCM_EPHEMERIS = frozenset({1019, 1042, 1045, 1046})
GST_WEEK_OFFSET = 1024
PI = math.pi
Record = dict[str, float | int | str]


def _times(week: int, toe_sow: float, toc_sow: float) -> dict[str, float | int]:
    """The record's times, toc in the week that puts it near toe."""
    return {"week": week, "toe_sow": toe_sow, "toc_s": near_in_week(toc_sow, week * WEEK_S + toe_sow)}


def _gps(msg: Any, ref_gps_s: float) -> Record:
    week = int(msg.DF076)
    week += 1024 * round((ref_gps_s / WEEK_S - week) / 1024)
    return {
        "sv_id": f"G{int(msg.DF009):02d}",
        **_times(week, float(msg.DF093), float(msg.DF081)),
        "af0": msg.DF084, "af1": msg.DF083, "af2": msg.DF082, "tgd": msg.DF101,
        "sqrt_a": msg.DF092, "e": msg.DF090, "m0": msg.DF088 * PI, "delta_n": msg.DF087 * PI,
        "omega": msg.DF099 * PI, "i0": msg.DF097 * PI, "idot": msg.DF079 * PI,
        "omega0": msg.DF095 * PI, "omega_dot": msg.DF100 * PI,
        "cuc": msg.DF089, "cus": msg.DF091, "crc": msg.DF098, "crs": msg.DF086, "cic": msg.DF094, "cis": msg.DF096,
        "health": int(msg.DF102), "iode": int(msg.DF071),
    }  # fmt: skip


def _galileo(msg: Any) -> Record:
    return {
        "sv_id": f"E{int(msg.DF252):02d}",
        **_times(int(msg.DF289) + GST_WEEK_OFFSET, float(msg.DF304), float(msg.DF293)),
        "af0": msg.DF296, "af1": msg.DF295, "af2": msg.DF294, "tgd": msg.DF313,
        "sqrt_a": msg.DF303, "e": msg.DF301, "m0": msg.DF299 * PI, "delta_n": msg.DF298 * PI,
        "omega": msg.DF310 * PI, "i0": msg.DF308 * PI, "idot": msg.DF292 * PI,
        "omega0": msg.DF306 * PI, "omega_dot": msg.DF311 * PI,
        "cuc": msg.DF300, "cus": msg.DF302, "crc": msg.DF309, "crs": msg.DF297, "cic": msg.DF305, "cis": msg.DF307,
        "health": (int(msg.DF287) << 1) | int(msg.DF288), "iode": int(msg.DF290),
    }  # fmt: skip


def _beidou(msg: Any) -> Record:
    # on the GPS scale: toe_sow may pass the week's end
    times = _times(int(msg.DF489) + BDT_WEEK_OFFSET, float(msg.DF505) + BDT_OFFSET_S, float(msg.DF493) + BDT_OFFSET_S)
    return {
        "sv_id": f"C{int(msg.DF488):02d}", **times,
        "af0": msg.DF496, "af1": msg.DF495, "af2": msg.DF494, "tgd": msg.DF513 * 1e-9,
        "sqrt_a": msg.DF504, "e": msg.DF502, "m0": msg.DF500 * PI, "delta_n": msg.DF499 * PI,
        "omega": msg.DF511 * PI, "i0": msg.DF509 * PI, "idot": msg.DF491 * PI,
        "omega0": msg.DF507 * PI, "omega_dot": msg.DF512 * PI,
        "cuc": msg.DF501, "cus": msg.DF503, "crc": msg.DF510, "crs": msg.DF498, "cic": msg.DF506, "cis": msg.DF508,
        "health": int(msg.DF515), "iode": int(msg.DF492),
    }  # fmt: skip


def rtcm_ephemerides(frames: list[bytes], ref_gps_s: float | None) -> tuple[list[Record], list[Skipped]]:
    """The distinct GPS, BeiDou and Galileo records of whole RTCM3 frames, and what was not used."""
    records: dict[tuple[object, ...], Record] = {}
    counts: Counter[str] = Counter()
    decoders: dict[int, Callable[[Any], Record]] = {
        1019: partial(_gps, ref_gps_s=ref_gps_s or math.nan),
        1042: _beidou,
        1046: _galileo,
    }
    for frame in frames:
        try:
            msg = RTCMReader.parse(frame)
            number = int(msg.identity)
            if number == 1045:
                counts["1045: Galileo F/NAV ephemerides (1046, I/NAV, carries the same orbits)"] += 1
                continue
            if number == 1019 and ref_gps_s is None:
                counts["1019: GPS ephemerides without a GPS time in the capture to resolve their week"] += 1
                continue
            rec = decoders[number](msg)
        except Exception as err:  # noqa: BLE001 - pyrtcm raises its own and plain errors on damaged payloads
            counts[f"ephemeris messages pyrtcm cannot decode ({type(err).__name__})"] += 1
            continue
        if not 2000.0 < float(rec["sqrt_a"]) < 10000.0:
            counts[f"{number}: implausible orbit"] += 1
            continue
        records.setdefault((rec["sv_id"], rec["week"], rec["toe_sow"], rec["iode"]), rec)
    lost = ("cannot", "implausible")
    skipped = [
        Skipped("RTCM3", what, n, "lost" if any(w in what for w in lost) else "skipped") for what, n in counts.items()
    ]
    return list(records.values()), skipped
