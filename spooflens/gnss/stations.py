"""Known stations: a receiver's surveyed position (`--station`, or a RINEX header's APPROX POSITION for a
receiver that stayed put).

A station that starts to move during the log is evidence, not a reason to stop looking, so whether it
stayed put is judged on the fixes of its first `STATIC_WINDOW_S` (over 30 s spans, 90% of them slower than
0.5 m/s), and the header must lie within 100 m of its first fixes (a moving receiver's header is only where
it started; a rough one would bias the differences).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spooflens.epoch_table import EpochTable
from spooflens.errors import SpooflensError
from spooflens.geodesy import geodetic_to_ecef, geodetic_to_enu

FloatArray = NDArray[np.float64]
APPROX_POSITION_KEY = "rinex.approx_position_xyz_m"  # readers.rinex.APPROX_POSITION_KEY
STATIC_WINDOW_S = 300.0  # whether a station stayed put is judged on its first minutes (module notes)
STATION_OPTION = "station"  # AnalyzeOptions.extra key: list of (receiver id or None, lat deg, lon deg, h m)
STATIC_MIN_FIXES = 10
STATIC_SPAN_S = 30.0
STATIC_SPEED_MPS = 0.5
STATIC_FRACTION = 0.9
HEADER_AGREEMENT_M = 100.0


@dataclass(frozen=True)
class Station:
    receiver_id: str
    ecef_m: FloatArray  # (3,)
    source: str  # where the position came from, for the report


def parse_station(text: str) -> tuple[str | None, float, float, float]:
    """`[RECEIVER=]LAT,LON,H` (degrees, degrees, metres above the ellipsoid) -> (receiver or None, lat, lon, h)."""
    rid, sep, rest = text.rpartition("=")
    parts = [p.strip() for p in rest.split(",")]
    try:
        lat, lon, h = (float(p) for p in parts)
    except ValueError:
        raise ValueError(
            f"{text!r}: expected LAT,LON,H in degrees, degrees, metres (optionally RECEIVER=...)"
        ) from None
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 360.0 and -1000.0 < h < 1e5):
        raise ValueError(f"{text!r}: latitude, longitude or height out of range")
    return (rid.strip() or None) if sep else None, lat, lon, h


def _is_static(table: EpochTable, receiver_id: str) -> tuple[bool | None, str]:
    """Whether the receiver's fixes of its first STATIC_WINDOW_S (and at least its first STATIC_MIN_FIXES: a
    station logging every 5 min has two in them) stay put (see the module notes), with the measured figure;
    None when it has too few fixes to tell."""
    fx = table.fixes_of(receiver_id)
    t = fx["t_s"].to_numpy(float)
    if len(t):
        fx = fx[(t <= t[0] + STATIC_WINDOW_S) | (np.arange(len(t)) < STATIC_MIN_FIXES)]
    if len(fx) < 3:
        return None, f"{len(fx)} fix(es), too few to tell whether it stayed put"
    t = fx["t_s"].to_numpy(float)
    lat0, lon0, h0 = (float(fx[c].iloc[0]) for c in ("lat_deg", "lon_deg", "height_m"))
    p = geodetic_to_enu(fx["lat_deg"], fx["lon_deg"], fx["height_m"], lat0, lon0, h0)
    j = np.searchsorted(t, t - STATIC_SPAN_S, side="right") - 1
    ok = (j >= 0) & (t - t[np.maximum(j, 0)] > 0.5 * STATIC_SPAN_S)
    span_s = float(t[-1] - t[0])
    if not ok.any():  # shorter than a span: its first fix to its last
        speed = np.array([np.linalg.norm(p[-1, :2] - p[0, :2]) / span_s]) if span_s > 0 else np.array([np.inf])
        return bool(speed[0] <= STATIC_SPEED_MPS), (
            f"{speed[0]:.2g} m/s from its first fix to its last, {span_s:.0f} s later (no {STATIC_SPAN_S:g} s span "
            f"in it), {'within' if speed[0] <= STATIC_SPEED_MPS else 'beyond'} {STATIC_SPEED_MPS} m/s"
        )
    k = np.flatnonzero(ok)
    speed = np.linalg.norm(p[k, :2] - p[j[k], :2], axis=1) / (t[k] - t[j[k]])
    moving = float(np.mean(speed > STATIC_SPEED_MPS))
    if span_s > STATIC_WINDOW_S:
        judged = f"its first {len(t)} fixes ({span_s / 60:.0f} min)"
    else:
        judged = f"its first {STATIC_WINDOW_S / 60:g} min" if span_s == STATIC_WINDOW_S else f"its {span_s:.0f} s"
    spans = f"{STATIC_SPAN_S:g} s spans" if np.median(np.diff(t)) <= STATIC_SPAN_S else "spans between fixes"
    return moving <= 1.0 - STATIC_FRACTION, (
        f"{100 * moving:.0f}% of {spans} of {judged} faster than {STATIC_SPEED_MPS} m/s"
    )


def surveyed_station(table: EpochTable, receiver_id: str) -> tuple[Station | None, str]:
    """The receiver's RINEX header position as a known station when it is one (module notes), else why not."""
    text = table.metadata.get(f"{APPROX_POSITION_KEY}.{receiver_id}")
    if not text:
        return None, "no station position (give one with --station LAT,LON,H)"
    xyz = np.array([float(v) for v in text.split()])
    if not 6.2e6 < np.linalg.norm(xyz) < 6.5e6:
        return None, f"RINEX header position {text} is not on the Earth's surface"
    static, figure = _is_static(table, receiver_id)
    if static is None:
        return None, f"{figure}: its RINEX header position is not used as a station"
    if not static:
        return None, f"the receiver moves ({figure}): its RINEX header position is not a station"
    fx = table.fixes_of(receiver_id).iloc[:10]
    first = geodetic_to_ecef(fx["lat_deg"], fx["lon_deg"], fx["height_m"])
    gap = float(np.linalg.norm(np.median(first, axis=0) - xyz))
    if gap > HEADER_AGREEMENT_M:
        return None, (
            f"its first fixes lie {gap:.0f} m from the RINEX header position (more than "
            f"{HEADER_AGREEMENT_M:.0f} m: a rough header, or an attack from the start of the log): not used"
        )
    return Station(receiver_id, xyz, f"RINEX header APPROX POSITION (static receiver, {figure})"), ""


def stations(table: EpochTable, extra: dict[str, object]) -> tuple[dict[str, Station], dict[str, str]]:
    """Known stations per receiver with observations, and for the others why none is used."""
    receivers = list(dict.fromkeys(table.observations["receiver_id"].astype(str)))
    found: dict[str, Station] = {}
    why: dict[str, str] = {}
    given = extra.get(STATION_OPTION) or []
    for rid, lat, lon, h in given:  # type: ignore[attr-defined]
        target = rid or (receivers[0] if receivers else None)
        if target is None:
            continue
        if target not in receivers:
            raise SpooflensError(f"--station names receiver {target!r}, but the log's receivers are {receivers}")
        found[target] = Station(target, geodetic_to_ecef(lat, lon, h), f"--station {lat:.7f},{lon:.7f},{h:.2f}")
    for rid in receivers:
        if rid in found:
            continue
        station, reason = surveyed_station(table, rid)
        if station is None:
            why[rid] = reason
        else:
            found[rid] = station
    return found, why
