"""Attacks on raw pseudoranges (seeds 002, 004): delays, meaconing, blocking, a spoofed subset.

A spoofer acts on signals, so these kinds change the observations (pseudorange, carrier phase and
Doppler consistently: a delayed signal is delayed on code and carrier alike) and never edit fixes by
hand. The receiver's reported fixes move by exactly what its own single-point solution does: both the
clean and the attacked observations are solved (`spooflens.gnss.single_point`) and the
difference is added to each fix. A log with observations but no fixes gets its fixes from the
observations at analysis time, so there is nothing more to move.
"""

from __future__ import annotations

import copy

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.attacks.fix_attacks import offsets_enu
from spooflens.attacks.spec import KINDS, OBSERVATION_KINDS, AttackError, AttackSpec, AttackTruth, Kind
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import add_enu_offset, ecef_to_enu_vectors, ecef_to_geodetic, enu_rotation, geodetic_to_ecef
from spooflens.gnss.ephemeris import C_MPS, GPS_L1_HZ
from spooflens.gnss.geometry import line_of_sight, sagnac_range
from spooflens.gnss.single_point import SV_COLUMNS, SV_VEL_COLUMNS, SinglePointSolution, solve_logged

FloatArray = NDArray[np.float64]


def _chosen_satellites(spec: AttackSpec, obs: pd.DataFrame, start: float) -> tuple[list[str], list[str]]:
    """(attacked, authentic) satellite ids. Random choices are among the satellites tracked at `start` whose
    orbit the log gives (a satellite without one is used by no solution: a counterfeit of it moves nothing a
    receiver computes, nor anything an analysis can check), all tracked ones where none has an orbit."""
    tracked_all = sorted(set(obs["sv_id"].astype(str)))
    at_start = obs[obs["t_s"] >= start]
    placed = np.isfinite(at_start[SV_COLUMNS].to_numpy(float)).all(axis=1)
    at_start = at_start[placed] if placed.any() else at_start
    first = at_start["t_s"].min() if len(at_start) else np.nan
    tracked = sorted(set(at_start.loc[at_start["t_s"] == first, "sv_id"].astype(str)))
    rng = np.random.default_rng(int(spec.params.get("seed", 0)))
    if "systems" in spec.params:
        systems = str(spec.params["systems"]).upper().replace("+", "")
        chosen = [s for s in tracked_all if s[:1] in systems]
        if not chosen:
            raise AttackError(f"{spec.kind.value}: no satellite of systems {systems!r}; the log has {tracked_all}")
        return chosen, [s for s in tracked_all if s not in chosen]
    if "svs" in spec.params:
        named = [s.strip().upper() for s in str(spec.params["svs"]).replace(",", "+").split("+") if s.strip()]
        unknown = [s for s in named if s not in tracked_all]
        if unknown:
            raise AttackError(f"{spec.kind.value}: satellites {unknown} are not in the log; it has {tracked_all}")
        return named, [s for s in tracked_all if s not in named]
    if spec.kind == Kind.SPOOFED_SUBSET:
        keep = int(spec.params["keep"])
        if keep > len(tracked):
            raise AttackError(
                f"spoofed_subset: keep={keep} but only {len(tracked)} satellites are tracked at {start} s"
            )
        authentic = sorted(rng.choice(tracked, keep, replace=False).tolist()) if keep else []
        return [s for s in tracked_all if s not in authentic], authentic
    if "count" in spec.params:
        count = int(spec.params["count"])
        if count > len(tracked):
            raise AttackError(
                f"{spec.kind.value}: count={count} but only {len(tracked)} satellites are tracked at {start} s"
            )
        chosen = sorted(rng.choice(tracked, count, replace=False).tolist())
        return chosen, [s for s in tracked_all if s not in chosen]
    return tracked_all, []


def _wavelength(obs: pd.DataFrame) -> FloatArray:
    f = obs["carrier_freq_hz"].to_numpy(float)
    return C_MPS / np.where(np.isfinite(f) & (f > 0), f, GPS_L1_HZ)


def _meaconing_delta(
    spec: AttackSpec, obs: pd.DataFrame, clean: SinglePointSolution, start: float
) -> tuple[FloatArray, FloatArray]:
    """Range and range-rate change of each row when the sky is received at the meaconer's antenna."""
    ok_epochs = np.flatnonzero(clean.ok & (clean.t_s >= start))
    if not len(ok_epochs):
        raise AttackError(f"meaconing: no position solution at or after {start} s to place the meaconer")
    lat0, lon0, h0 = (float(v[ok_epochs[0]]) for v in clean.geodetic())
    offset = np.array([spec.params["east"], spec.params["north"], spec.params["up"]], dtype=float)
    M = geodetic_to_ecef(*add_enu_offset(lat0, lon0, h0, offset))
    # Where the receiver really was: its solution smoothed. Its own noisy solution would cancel the
    # noise of every epoch exactly and leave a receiver that reports the meaconer without any noise.
    ref_pos, ref_vel = _smoothed_track(clean)
    R = ref_pos[clean.row_epoch]
    v_R = np.nan_to_num(ref_vel[clean.row_epoch])
    sv = obs[SV_COLUMNS].to_numpy(float)
    sv_v = np.nan_to_num(obs[SV_VEL_COLUMNS].to_numpy(float))
    M_b = np.broadcast_to(M, R.shape)
    d_range = sagnac_range(sv, M_b) - sagnac_range(sv, R) + np.linalg.norm(M - R, axis=1) + spec.params["delay"]
    e_MR = (R - M) / np.maximum(np.linalg.norm(R - M, axis=1, keepdims=True), 1e-9)
    d_rate = (
        np.sum(line_of_sight(sv, M_b) * sv_v, axis=1)
        - np.sum(line_of_sight(sv, R) * (sv_v - v_R), axis=1)
        + np.sum(e_MR * v_R, axis=1)
    )
    return d_range, d_rate


def _fix_offset_delta(
    spec: AttackSpec, obs: pd.DataFrame, clean: SinglePointSolution, end: float
) -> tuple[FloatArray, FloatArray]:
    """A fix-level attack (ramp, step, hover, pulls) on a receiver that logged only pseudoranges: each
    row's range and range-rate change when the receiver's antenna is where the attack puts the fix.

    The offsets are the fix-level kind's own, at each solved epoch in its local ENU frame; the ranges are
    exact geometry (with the Earth's rotation) from the moved position, the clock untouched, so the
    receiver's own solution of the attacked pseudoranges lands on the attacked fix.
    """
    ok = clean.ok
    lat, lon, _ = clean.geodetic()
    first = int(np.argmax(ok))
    p = np.where(ok[:, None], ecef_to_enu_vectors(lat[first], lon[first], clean.ecef_m - clean.ecef_m[first]), 0.0)
    dp_enu, dv_enu = offsets_enu(spec, clean.t_s, end, p, np.nan_to_num(clean.vel_enu_mps()))
    rotation = np.swapaxes(enu_rotation(lat, lon), -1, -2)  # ENU -> ECEF per epoch
    dp = np.where(ok[:, None], np.einsum("eij,ej->ei", rotation, dp_enu), 0.0)
    dv = np.where(ok[:, None], np.einsum("eij,ej->ei", rotation, dv_enu), 0.0)
    sv = obs[SV_COLUMNS].to_numpy(float)
    R = clean.ecef_m[clean.row_epoch]
    d_range = sagnac_range(sv, R + dp[clean.row_epoch]) - sagnac_range(sv, R)
    d_rate = -np.sum(line_of_sight(sv, R) * dv[clean.row_epoch], axis=1)
    usable = np.isfinite(d_range) & np.isfinite(d_rate)
    return np.where(usable, d_range, 0.0), np.where(usable, d_rate, 0.0)


def _smoothed_track(sol: SinglePointSolution, half_window_s: float = 5.0) -> tuple[FloatArray, FloatArray]:
    """Each epoch's position and velocity estimated from its neighbours within +-`half_window_s`.

    Position: the mean of the neighbours' positions, each carried to the epoch along the integrated
    Doppler velocity, so it follows turns and accelerations. Velocity: a local quadratic fit (a plain
    mean would shorten the velocity in a turn by up to a metre per second).
    """
    pos, vel = sol.ecef_m.copy(), sol.vel_ecef_mps.copy()
    for rid in np.unique(sol.receiver_id):
        idx = np.flatnonzero((sol.receiver_id == rid) & sol.ok)
        if len(idx) < 3:
            continue
        t, p = sol.t_s[idx], sol.ecef_m[idx]
        v = sol.vel_ecef_mps[idx]
        v = np.where(np.isfinite(v), v, np.gradient(p, t, axis=0))
        travelled = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t)[:, None], 0)])
        lo = np.searchsorted(t, t - half_window_s, side="left")
        hi = np.searchsorted(t, t + half_window_s, side="right")
        carried = np.cumsum(np.vstack([np.zeros((1, 3)), p - travelled]), axis=0)  # sums of p_j - I_j
        pos[idx] = travelled + (carried[hi] - carried[lo]) / (hi - lo)[:, None]
        for k in range(len(idx)):
            tau = t[lo[k] : hi[k]] - t[k]
            if len(tau) >= 4:
                coef = np.linalg.lstsq(np.vander(tau, 3), v[lo[k] : hi[k]], rcond=None)[0]
                vel[idx[k]] = coef[-1]  # the fit's value at tau = 0
    return pos, vel


def _solution_shift(clean: SinglePointSolution, attacked: SinglePointSolution) -> tuple[FloatArray, ...]:
    """Per epoch of the clean solution: times, ECEF position change and ECEF velocity change (0 where unsolved)."""
    key = {(r, t): i for i, (r, t) in enumerate(zip(attacked.receiver_id, attacked.t_s, strict=True))}
    j = np.array([key.get((r, t), -1) for r, t in zip(clean.receiver_id, clean.t_s, strict=True)], dtype=np.int64)
    ok = (j >= 0) & clean.ok & np.where(j >= 0, attacked.ok[np.maximum(j, 0)], False)
    dp = np.where(ok[:, None], attacked.ecef_m[np.maximum(j, 0)] - clean.ecef_m, 0.0)
    dv = np.where(ok[:, None], np.nan_to_num(attacked.vel_ecef_mps[np.maximum(j, 0)] - clean.vel_ecef_mps), 0.0)
    return clean.t_s, dp, dv


def apply_observation_attack(table: EpochTable, spec: AttackSpec) -> tuple[EpochTable, AttackTruth]:
    """A spoofed copy of `table` (observations changed, fixes moved through the solver) and its truth."""
    obs_all = table.observations
    if not len(obs_all):
        raise AttackError(
            f"{table.source}: {spec.kind.value} acts on raw pseudoranges and this log has none "
            "(use a fix-level kind such as ramp or step)"
        )
    if not np.isfinite(obs_all[SV_COLUMNS].to_numpy(float)).all(axis=1).any():
        raise AttackError(
            f"{table.source}: {spec.kind.value} needs satellite positions (a navigation file beside the log)"
        )
    receivers = list(dict.fromkeys(obs_all["receiver_id"].astype(str)))
    targets = [spec.params["receiver"]] if "receiver" in spec.params else receivers
    unknown = [r for r in targets if r not in receivers]
    if unknown:
        raise AttackError(f"{table.source}: no receiver {unknown[0]!r} with observations; receivers are {receivers}")
    start = spec.start_s
    end = table.duration_s if spec.end_s is None else min(spec.end_s, table.duration_s)
    target_obs = obs_all[obs_all["receiver_id"].astype(str).isin(targets)]
    attacked_svs, authentic = _chosen_satellites(spec, target_obs, start)
    truth = AttackTruth(
        spec.kind.value,
        dict(spec.params),
        start,
        end,
        list(targets),
        KINDS[spec.kind].seed,
        str(table.source),
        table.t0_ns,
        satellites=attacked_svs,
        authentic=authentic if spec.kind == Kind.SPOOFED_SUBSET else [],
    )
    new_obs = obs_all.copy()
    drop = np.zeros(len(new_obs), dtype=bool)
    fixes = table.fixes.copy()
    for rid in targets:
        rows = np.flatnonzero(new_obs["receiver_id"].astype(str).to_numpy() == rid)
        obs = new_obs.iloc[rows]
        t = obs["t_s"].to_numpy(float)
        inside = (t >= start) & (t <= end)
        hit = inside & obs["sv_id"].astype(str).isin(attacked_svs).to_numpy()
        clean = solve_logged(table, obs)
        if spec.kind == Kind.BLOCKING:
            drop[rows[hit]] = True
        else:
            if spec.kind == Kind.MEACONING:
                d_range, d_rate = _meaconing_delta(spec, obs, clean, start)
            elif spec.kind not in OBSERVATION_KINDS:
                d_range, d_rate = _fix_offset_delta(spec, obs, clean, end)
            else:
                d_range = spec.params["delay"] + spec.params["rate"] * (t - start)
                d_rate = np.full(len(t), spec.params["rate"])
            d_range = np.where(hit, d_range, 0.0)
            d_rate = np.where(hit, d_rate, 0.0)
            lam = _wavelength(obs)
            cols = new_obs.columns
            for col, delta in (
                ("pseudorange_m", d_range),
                ("carrier_phase_cycles", d_range / lam),
                ("pseudorange_rate_mps", d_rate),
                ("doppler_hz", -d_rate / lam),
            ):
                new_obs.iloc[rows, cols.get_loc(col)] = obs[col].to_numpy(float) + delta
            if float(spec.params.get("cn0", 0.0)):
                cn0 = obs["cn0_dbhz"].to_numpy(float) + np.where(hit, float(spec.params["cn0"]), 0.0)
                new_obs.iloc[rows, cols.get_loc("cn0_dbhz")] = cn0
        attacked = solve_logged(table, new_obs.iloc[rows][~drop[rows]])
        t_e, dp, dv = _solution_shift(clean, attacked)
        fix_rows = np.flatnonzero(fixes["receiver_id"].astype(str).to_numpy() == rid)
        if len(fix_rows):
            before = fixes.iloc[fix_rows][["lat_deg", "lon_deg", "height_m"]].to_numpy(float, copy=True)
            fixes = _moved_fixes(fixes, fix_rows, t_e, dp, dv)
            after = fixes.iloc[fix_rows][["lat_deg", "lon_deg", "height_m"]].to_numpy(float)
            t_fix = fixes.iloc[fix_rows]["t_s"].to_numpy(float)
        else:  # no fixes in the log: the offset of the solution the analysis will compute
            before = np.stack(clean.geodetic(), axis=1)
            after = np.stack(ecef_to_geodetic(clean.ecef_m + dp), axis=1)
            t_fix = t_e
        truth.offsets[rid] = np.c_[t_fix, _local_offsets(before, after)].round(4).tolist()
    spoofed = copy.copy(table)
    spoofed.observations = new_obs[~drop].reset_index(drop=True)
    spoofed.fixes = fixes.reset_index(drop=True)
    spoofed.validate()
    return spoofed, truth


def _interp_rows(t: FloatArray, t_e: FloatArray, d: FloatArray) -> FloatArray:
    """`d` (per solution epoch) at times `t`; zero outside the solved span."""
    return np.stack([np.interp(t, t_e, d[:, i], left=0.0, right=0.0) for i in range(d.shape[1])], axis=1)


def _local_offsets(before: FloatArray, after: FloatArray) -> FloatArray:
    """Exact ENU offset of each `after` position (lat, lon, h rows) in the local frame of its `before`."""
    d = geodetic_to_ecef(after[:, 0], after[:, 1], after[:, 2]) - geodetic_to_ecef(
        before[:, 0], before[:, 1], before[:, 2]
    )
    return np.nan_to_num(ecef_to_enu_vectors(before[:, 0], before[:, 1], d))


def _moved_fixes(
    fixes: pd.DataFrame, rows: NDArray[np.int64], t_e: FloatArray, dp: FloatArray, dv: FloatArray
) -> pd.DataFrame:
    """The fixes at `rows` moved by the solution's ECEF change (and velocity change) at their times: exact,
    whatever the size of the offset."""
    d_pos = _interp_rows(fixes.iloc[rows]["t_s"].to_numpy(float), t_e, dp)
    moved = np.any(d_pos != 0.0, axis=1)  # rows the attack left alone stay bit for bit
    rows, d_pos = rows[moved], d_pos[moved]
    fx = fixes.iloc[rows]
    t = fx["t_s"].to_numpy(float)
    lat, lon, h = (fx[c].to_numpy(float) for c in ("lat_deg", "lon_deg", "height_m"))
    new_lat, new_lon, new_h = ecef_to_geodetic(geodetic_to_ecef(lat, lon, h) + d_pos)
    dv_enu = ecef_to_enu_vectors(lat, lon, _interp_rows(t, t_e, dv))
    cols = fixes.columns
    for c, values in (("lat_deg", new_lat), ("lon_deg", new_lon), ("height_m", new_h)):
        fixes.iloc[rows, cols.get_loc(c)] = values
    for i, c in enumerate(("vel_e_mps", "vel_n_mps", "vel_u_mps")):
        fixes.iloc[rows, cols.get_loc(c)] = fx[c].to_numpy(float) + dv_enu[:, i]
    return fixes
