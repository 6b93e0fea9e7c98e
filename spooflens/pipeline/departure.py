"""How far GNSS went from where the vehicle really was during an incident.

"Really was" is the reconstructed track: the INS solution with the spoofed GNSS left out (any track an
analysis returns whose name starts with `reconstructed`). The distance is horizontal, between each
reported fix inside the incident (onset to end) and the reconstructed position interpolated at the
fix's time; the peak and the value at the incident's end (the last fix inside it) are what an
operator asks first ("how far off did the navigation system think it was").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from spooflens.detectors.base import DetectorResult, Track
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import geodetic_to_enu
from spooflens.navigation.product import NAVIGATION
from spooflens.pipeline.verdict import Incident

RECONSTRUCTED = "reconstructed"


@dataclass(frozen=True)
class Departure:
    receiver_id: str
    track: str  # the reconstructed track's name
    peak_m: float
    peak_s: float
    end_m: float
    end_s: float


def reconstructed_tracks(results: Sequence[DetectorResult]) -> list[Track]:
    """Every reconstructed track, the INS's first (`navigation`: the IMU with the log's own noise, where a
    vessel's dead reckoning from its compass and log, `heading_reference`, carries an unknown current)."""
    ordered = sorted(results, key=lambda r: r.name != NAVIGATION)
    return [tr for r in ordered if r.ran for tr in r.tracks if tr.name.startswith(RECONSTRUCTED)]


def _horizontal_gap(table: EpochTable, rid: str, track: Track, start_s: float, end_s: float) -> Departure | None:
    fx = table.fixes_of(rid)
    t = fx["t_s"].to_numpy(dtype=float)
    inside = (t >= start_s) & (t <= end_s) & (t >= track.t[0]) & (t <= track.t[-1])
    if inside.sum() == 0 or len(track.t) < 2:
        return None
    t = t[inside]
    lat0, lon0, h0 = float(track.lat_deg[0]), float(track.lon_deg[0]), float(track.height_m[0])
    ref = geodetic_to_enu(track.lat_deg, track.lon_deg, track.height_m, lat0, lon0, h0)
    gnss = geodetic_to_enu(
        fx["lat_deg"].to_numpy(dtype=float)[inside],
        fx["lon_deg"].to_numpy(dtype=float)[inside],
        fx["height_m"].to_numpy(dtype=float)[inside],
        lat0,
        lon0,
        h0,
    )
    at = np.c_[np.interp(t, track.t, ref[:, 0]), np.interp(t, track.t, ref[:, 1])]
    gap = np.hypot(gnss[:, 0] - at[:, 0], gnss[:, 1] - at[:, 1])
    k = int(np.argmax(gap))
    return Departure(rid, track.name, float(gap[k]), float(t[k]), float(gap[-1]), float(t[-1]))


def gnss_departure(table: EpochTable, results: Sequence[DetectorResult], incident: Incident) -> list[Departure]:
    """Per receiver of the incident (every receiver when it names none), against the first reconstructed
    track; empty when no analysis reconstructed a track or no fix falls inside the incident."""
    tracks = reconstructed_tracks(results)
    if not tracks or not incident.is_spoofing:
        return []
    receivers = list(incident.receivers) or table.receivers()
    found = (_horizontal_gap(table, rid, tracks[0], incident.onset_s, incident.end_s) for rid in receivers)
    return [d for d in found if d is not None]
