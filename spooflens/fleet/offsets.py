"""Each vehicle's position offset (POV): its reported GNSS position minus an independent reference of its
own, and the homology of those offsets across a fleet over time (seed 004 applied to logs).

In depth: docs/methods/fleet.md."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.detectors.base import DetectorResult, Track
from spooflens.epoch_table import EpochTable
from spooflens.fleet.homology import homology_index, null_quantile
from spooflens.geodesy import ecef_to_enu_vectors, geodetic_to_ecef
from spooflens.navigation.product import NAVIGATION, SMOOTHED_TRACK
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.verdict import Verdict

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class FleetOptions:
    # per epoch: theta above its quantile for independent offsets. This is the "alike" part only: both
    # offsets must also exceed min_offset_m from independent references, which clean vehicles rarely do
    p_false_alarm: float = 1e-2
    min_offset_m: float = 10.0  # smaller offsets are what nearby receivers share without an attacker
    max_gap_factor: float = 2.5
    reference_sats: tuple[str, ...] = ()
    merge_gap_s: float = 5.0


@dataclass
class VehicleOffsets:
    """One vehicle's offsets against its own reference, on its own time base and in UNIX seconds."""

    name: str  # the log's name
    receiver_id: str
    reference: str  # what the offsets are measured against
    t_s: FloatArray  # the log's own time base
    unix_s: FloatArray
    pov: FloatArray  # (n, 2) east, north metres
    fix_llh: FloatArray  # (n, 3) reported
    ref_llh: FloatArray  # (n, 3) reference

    @property
    def span(self) -> tuple[float, float]:
        return float(self.unix_s[0]), float(self.unix_s[-1])


def _ecef(lat: FloatArray, lon: FloatArray, h: FloatArray) -> FloatArray:
    return geodetic_to_ecef(lat, lon, h)


def _track_at(track: Track, t: FloatArray, max_gap_s: float) -> FloatArray:
    """A track's (lat, lon, h) at times t, linearly within its samples, NaN beyond `max_gap_s` of them."""
    out = np.full((len(t), 3), np.nan)
    tt = np.asarray(track.t, float)
    if len(tt) < 2:
        return out
    for i, v in enumerate((track.lat_deg, track.lon_deg, track.height_m)):
        out[:, i] = np.interp(t, tt, np.asarray(v, float))
    j = np.clip(np.searchsorted(tt, t), 1, len(tt) - 1)
    bad = (t < tt[0]) | (t > tt[-1]) | (tt[j] - tt[j - 1] > max_gap_s)
    out[bad] = np.nan
    return out


def _offsets(fix_llh: FloatArray, ref_llh: FloatArray) -> FloatArray:
    d = _ecef(*fix_llh.T) - _ecef(*ref_llh.T)
    out: FloatArray = ecef_to_enu_vectors(ref_llh[:, 0], ref_llh[:, 1], d)[:, :2]
    return out


def vehicle_offsets(
    name: str, table: EpochTable, results: list[DetectorResult], verdict: Verdict, opts: FleetOptions
) -> tuple[VehicleOffsets | None, str]:
    """The vehicle's offsets and what they are measured against, or (None, why there are none); during a
    confirmed incident the reference is the verdict's track reconstructed with GNSS left out."""
    receivers = table.receivers()
    if not receivers:
        return None, "no GNSS fixes"
    rid = receivers[0]
    fx = table.fixes_of(rid)
    t = fx["t_s"].to_numpy(float)
    unix = table.unix_ns(t)
    if unix is None:
        return None, f"no absolute clock ({table.time_reference}): cannot be placed in time with the others"
    fix = fx[["lat_deg", "lon_deg", "height_m"]].to_numpy(float)
    period = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    ref, how = _reference(table, rid, t, fix, results, verdict.reconstructed, opts, opts.max_gap_factor * period)
    if ref is None:
        return None, how
    ok = np.isfinite(ref).all(axis=1)
    if ok.sum() < 2:
        return None, f"{how}: fewer than 2 epochs of it overlap the fixes"
    pov = _offsets(fix[ok], ref[ok])
    return VehicleOffsets(name, rid, how, t[ok], unix[ok] / 1e9, pov, fix[ok], ref[ok]), how


def _reference(
    table: EpochTable,
    rid: str,
    t: FloatArray,
    fix: FloatArray,
    results: list[DetectorResult],
    reconstructed: tuple[Track, ...],
    opts: FleetOptions,
    max_gap_s: float,
) -> tuple[FloatArray | None, str]:
    from spooflens.geodesy import ecef_to_geodetic
    from spooflens.gnss.stations import surveyed_station

    station, _ = surveyed_station(table, rid)  # judged on its first minutes: a spoofer moves the fixes later
    if station is not None:
        lat, lon, h = ecef_to_geodetic(station.ecef_m)
        return np.tile([float(lat), float(lon), float(h)], (len(t), 1)), "surveyed site (RINEX APPROX POSITION)"
    nav = next((r for r in results if r.name == NAVIGATION and r.ran), None)
    if nav is not None and nav.tracks:
        rec = reconstructed[0] if reconstructed else None
        base = next((tr for tr in nav.tracks if tr.name == SMOOTHED_TRACK), nav.tracks[0])
        ref = _track_at(base, t, max_gap_s)
        how = "INS (smoothed GNSS/INS)"
        if rec is not None:
            inside = (t >= rec.t[0]) & (t <= rec.t[-1])
            ref[inside] = _track_at(rec, t[inside], max_gap_s)
            how = f"INS ({rec.name} during its incident, smoothed GNSS/INS elsewhere)"
        return ref, how
    return _authentic_subset(table, rid, t, results, opts)


def _authentic_subset(
    table: EpochTable, rid: str, t: FloatArray, results: list[DetectorResult], opts: FleetOptions
) -> tuple[FloatArray | None, str]:
    from spooflens.gnss.single_point import SV_COLUMNS, solve_logged

    obs = table.observations
    obs = obs[(obs["receiver_id"].astype(str) == rid) & np.isfinite(obs[SV_COLUMNS].to_numpy(float)).all(axis=1)]
    if not len(obs):
        return None, "no independent reference (no IMU, no surveyed site, no raw observations)"
    flagged = {
        s
        for r in results
        if r.evidence == Evidence.RAW_MEASUREMENT and r.ran and not r.advisory
        for a in r.alarms
        for s in a.satellites
    }
    if opts.reference_sats:
        keep, how = set(opts.reference_sats), f"authentic-subset solution ({'+'.join(opts.reference_sats)}, given)"
    elif flagged:
        keep = set(obs["sv_id"].astype(str)) - flagged
        how = f"authentic-subset solution (without {'+'.join(sorted(flagged))}, flagged by raw-measurement detectors)"
    else:
        return None, "no independent reference (no IMU, no surveyed site, no trusted satellites: --reference-sats)"
    rows = obs[obs["sv_id"].astype(str).isin(keep)]
    if not len(rows):
        return None, f"{how}: none of those satellites is in the log"
    sol = solve_logged(table, rows)
    lat, lon, h = sol.geodetic()
    ok = sol.ok
    ts = sol.t_s[ok]
    out = np.full((len(t), 3), np.nan)
    idx = np.searchsorted(ts, t)
    idx = np.clip(idx, 0, max(len(ts) - 1, 0))
    same = len(ts) > 0
    if same:
        hit = np.abs(ts[idx] - t) < 1e-3
        out[hit] = np.c_[lat[ok][idx[hit]], lon[ok][idx[hit]], h[ok][idx[hit]]]
    return out, how


@dataclass
class FleetHomology:
    """The homology index over a common time grid (UNIX seconds) and the common-attack intervals."""

    t_unix: FloatArray
    theta_all: FloatArray  # Algorithm 1 over every vehicle with an offset at that time
    theta: FloatArray  # over the vehicles whose offset exceeds min_offset_m
    threshold: FloatArray  # chance quantile for that many vehicles (NaN with fewer than 2)
    members: list[tuple[str, ...]]  # the vehicles with significant offsets at each time
    common: BoolArray  # a common attack: >= 2 significant offsets more alike than chance
    pov: dict[str, FloatArray] = field(default_factory=dict)  # each vehicle's offset on the grid


def _on_grid(v: VehicleOffsets, grid: FloatArray, max_gap_s: float) -> FloatArray:
    out = np.full((len(grid), 2), np.nan)
    t = v.unix_s
    if len(t) < 2:
        return out
    for i in range(2):
        out[:, i] = np.interp(grid, t, v.pov[:, i])
    j = np.clip(np.searchsorted(t, grid), 1, len(t) - 1)
    out[(grid < t[0]) | (grid > t[-1]) | (t[j] - t[j - 1] > max_gap_s)] = np.nan
    return out


def overlap_groups(vehicles: list[VehicleOffsets]) -> tuple[list[VehicleOffsets], list[str]]:
    """The vehicles that share time with at least one other, and notes on those that do not."""
    keep, notes = [], []
    for v in vehicles:
        others = [w for w in vehicles if w is not v and min(v.span[1], w.span[1]) > max(v.span[0], w.span[0])]
        if others:
            keep.append(v)
        else:
            a, b = (pd.Timestamp(x, unit="s", tz="UTC").isoformat() for x in v.span)
            notes.append(f"{v.name}: {a} to {b} does not overlap in time with any other log; left out")
    return keep, notes


def fleet_homology(vehicles: list[VehicleOffsets], opts: FleetOptions) -> FleetHomology:
    periods = [float(np.median(np.diff(v.unix_s))) for v in vehicles if len(v.unix_s) > 1]
    step = max(periods) if periods else 1.0
    start = min(v.span[0] for v in vehicles)
    end = max(v.span[1] for v in vehicles)
    grid = np.arange(start, end + 0.5 * step, step)
    povs = {v.name: _on_grid(v, grid, opts.max_gap_factor * step) for v in vehicles}
    names = list(povs)
    stack = np.stack([povs[n] for n in names], axis=1)  # (T, V, 2)
    have: BoolArray = np.asarray(np.isfinite(stack).all(axis=2), dtype=bool)
    sig: BoolArray = have & (np.linalg.norm(np.nan_to_num(stack), axis=2) > opts.min_offset_m)
    quantiles: dict[int, float] = {}
    theta_all = np.full(len(grid), np.nan)
    theta = np.full(len(grid), np.nan)
    thr = np.full(len(grid), np.nan)
    members: list[tuple[str, ...]] = []
    for k in range(len(grid)):
        if have[k].sum() >= 2:
            theta_all[k] = homology_index(stack[k, have[k]])
        m = tuple(n for n, s in zip(names, sig[k], strict=True) if s)
        members.append(m)
        if len(m) >= 2:
            if len(m) not in quantiles:
                quantiles[len(m)] = null_quantile(
                    len(m), opts.p_false_alarm, runs=max(200_000, int(20 / opts.p_false_alarm))
                )
            theta[k] = homology_index(stack[k, sig[k]])
            thr[k] = quantiles[len(m)]
    common = np.nan_to_num(theta) > np.nan_to_num(thr, nan=np.inf)
    return FleetHomology(grid, theta_all, theta, thr, members, common, povs)
