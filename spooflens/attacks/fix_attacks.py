"""Attacks on reported fixes (seeds 000, 001, 003): offsets added to positions (and velocities).

Each kind is a function of time giving an ENU position offset and a velocity offset inside the attack
window; outside it nothing changes. A position-only attack leaves velocities alone unless `vel=1`
(seed 000's premise: positions come from code ranges, velocity from Doppler, and the attacker moves
only the former). Offsets are added in local ENU metres at each fix's own latitude.
"""

from __future__ import annotations

import copy

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.attacks.spec import KINDS, AttackError, AttackSpec, AttackTruth, Kind
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import add_enu_offset, geodetic_to_enu

FloatArray = NDArray[np.float64]


def _axes(spec: AttackSpec) -> FloatArray:
    return np.array([1.0 if a in spec.axes else 0.0 for a in "enu"])


def offsets_enu(
    spec: AttackSpec, t: FloatArray, end: float, p: FloatArray, v: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Position and velocity offsets (N, 3) for fixes at times t with positions p (ENU) and velocities v."""
    start = spec.start_s
    inside = (t >= start) & (t <= end)
    tau = np.where(inside, t - start, 0.0)[:, None]
    dp = np.zeros((len(t), 3))
    dv = np.zeros((len(t), 3))
    a = _axes(spec)
    k = spec.kind
    if k in (Kind.RAMP, Kind.SINGLE_ANTENNA):
        dp = tau * spec.params["rate"] * a
        dv = np.where(inside[:, None], spec.params["rate"] * a, 0.0)
    elif k == Kind.STEP:
        dp = np.where(inside[:, None], spec.params["offset"] * a, 0.0)
    elif k == Kind.VELOCITY_PULL:
        dp = tau * spec.params["dv"] * a
        dv = np.where(inside[:, None], spec.params["dv"] * a, 0.0)
    elif k == Kind.POSITION_PULL:
        frac = np.clip(tau / max(spec.params["ramp"], 1e-9), 0.0, 1.0)
        dp = frac * spec.params["offset"] * a
        dv = np.where(
            inside[:, None] & (tau < spec.params["ramp"]), spec.params["offset"] / spec.params["ramp"] * a, 0.0
        )
    elif k == Kind.HOVER:
        first = int(np.argmax(inside)) if inside.any() else 0
        dp = np.where(inside[:, None], p[first] - p, 0.0)
        dv = np.where(inside[:, None], -np.nan_to_num(v), 0.0)
    return dp, dv


def apply_fix_attack(table: EpochTable, spec: AttackSpec) -> tuple[EpochTable, AttackTruth]:
    """A spoofed copy of `table` and the attack's ground truth."""
    receivers = table.receivers()
    if not receivers:
        raise AttackError(f"{table.source}: no GNSS fixes to attack")
    if spec.kind == Kind.SINGLE_ANTENNA and len(receivers) < 2:
        raise AttackError(f"{table.source}: single_antenna needs two receivers; the log has {receivers}")
    targets = [spec.params["receiver"]] if "receiver" in spec.params else receivers
    unknown = [r for r in targets if r not in receivers]
    if unknown:
        raise AttackError(f"{table.source}: no receiver {unknown[0]!r}; receivers are {receivers}")
    end = table.duration_s if spec.end_s is None else min(spec.end_s, table.duration_s)
    vel = bool(spec.params.get("vel", 0))
    fixes = table.fixes.copy()
    truth = AttackTruth(
        spec.kind.value,
        dict(spec.params),
        spec.start_s,
        end,
        list(targets),
        KINDS[spec.kind].seed,
        str(table.source),
        table.t0_ns,
    )
    lead = table.fixes_of(receivers[0]) if spec.kind == Kind.SINGLE_ANTENNA else None
    for rid in targets:
        rows = np.flatnonzero(fixes["receiver_id"].to_numpy() == rid)
        fx = fixes.iloc[rows]
        t = fx["t_s"].to_numpy(dtype=float)
        lat, lon, h = (fx[c].to_numpy(dtype=float) for c in ("lat_deg", "lon_deg", "height_m"))
        v = fx[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy(dtype=float)
        p = geodetic_to_enu(lat, lon, h, lat[0], lon[0], h[0])
        dp, dv = offsets_enu(spec, t, end, p, v)
        if lead is not None:  # every receiver reports the lead receiver's (spoofed) position
            lt = lead["t_s"].to_numpy(dtype=float)
            idx = np.clip(np.searchsorted(lt, t), 0, len(lt) - 1)
            inside = (t >= spec.start_s) & (t <= end)
            src = np.c_[
                lead["lat_deg"].to_numpy()[idx], lead["lon_deg"].to_numpy()[idx], lead["height_m"].to_numpy()[idx]
            ]
            lat, lon, h = (np.where(inside, src[:, i], x) for i, x in enumerate((lat, lon, h)))
        new_lat, new_lon, new_h = add_enu_offset(lat, lon, h, dp)
        if spec.kind == Kind.HOVER:  # frozen exactly, not up to the ENU-to-geodetic round trip
            inside = (t >= spec.start_s) & (t <= end)
            if inside.any():
                first = int(np.argmax(inside))
                new_lat, new_lon, new_h = (np.where(inside, x[first], x) for x in (lat, lon, h))
        cols = fixes.columns
        fixes.iloc[rows, cols.get_loc("lat_deg")] = new_lat
        fixes.iloc[rows, cols.get_loc("lon_deg")] = new_lon
        fixes.iloc[rows, cols.get_loc("height_m")] = new_h
        if vel:
            for i, c in enumerate(("vel_e_mps", "vel_n_mps", "vel_u_mps")):
                fixes.iloc[rows, cols.get_loc(c)] = v[:, i] + dv[:, i]
        actual = geodetic_to_enu(new_lat, new_lon, new_h, lat[0], lon[0], h[0]) - p
        truth.offsets[rid] = np.c_[t, actual].round(4).tolist()
    spoofed = copy.copy(table)
    spoofed.fixes = pd.DataFrame(fixes).reset_index(drop=True)
    spoofed.validate()
    return spoofed, truth
