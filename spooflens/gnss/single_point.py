"""Single-point positioning: a receiver's position, velocity and clock from its own pseudoranges.

In depth: docs/methods/navigation.md."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.epoch_table import EpochTable
from spooflens.geodesy import ecef_to_enu_vectors, ecef_to_geodetic, enu_rotation
from spooflens.gnss.ephemeris import Klobuchar
from spooflens.gnss.geometry import (
    atmospheric_delay,
    azimuth_elevation,
    expected_pseudorange,
    expected_range_rate,
    line_of_sight,
    sagnac_range,
)
from spooflens.schema import FixType, SpoofingFlag

FloatArray = NDArray[np.float64]
SV_COLUMNS = ["sv_x_m", "sv_y_m", "sv_z_m"]
SV_VEL_COLUMNS = ["sv_vx_mps", "sv_vy_mps", "sv_vz_mps"]


@dataclass(frozen=True)
class SinglePointOptions:
    elevation_mask_deg: float = 10.0
    max_iterations: int = 12
    sigma_zenith_m: float = 0.3  # sigma^2 = a^2 + a^2 / sin^2(el), RTKLIB's default weighting
    iono: Klobuchar | None = None


@dataclass(frozen=True)
class SinglePointSolution:
    """One row per (receiver, epoch); `row_epoch` maps each input observation row to its epoch."""

    t_s: FloatArray
    receiver_id: NDArray[np.str_]
    ecef_m: FloatArray  # (E, 3), NaN where the epoch could not be solved
    clock_m: FloatArray  # (E,) receiver clock bias times c for the first system (GPS when present)
    vel_ecef_mps: FloatArray  # (E, 3), NaN without pseudorange rates
    clock_drift_mps: FloatArray
    sats_used: NDArray[np.int64]
    pdop: FloatArray
    hdop: FloatArray
    vdop: FloatArray
    residual_rms_m: FloatArray
    residual_m: FloatArray  # per input row, NaN where the row was not used
    row_epoch: NDArray[np.int64]
    systems: tuple[str, ...]
    residual_all_m: FloatArray | None = None  # per input row against the solution, used or left out

    @property
    def ok(self) -> NDArray[np.bool_]:
        return np.asarray(np.isfinite(self.ecef_m).all(axis=1), dtype=bool)

    def geodetic(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        return ecef_to_geodetic(self.ecef_m)

    def vel_enu_mps(self) -> FloatArray:
        lat, lon, _ = self.geodetic()
        return ecef_to_enu_vectors(lat, lon, self.vel_ecef_mps)

    def fixes_columns(self) -> dict[str, object]:
        """This solution as columns of the `fixes` frame (t_s, not t_ns), solved epochs only."""
        ok = self.ok
        lat, lon, h = self.geodetic()
        v = self.vel_enu_mps()
        return {
            "t_s": self.t_s[ok],
            "receiver_id": self.receiver_id[ok],
            "lat_deg": lat[ok],
            "lon_deg": lon[ok],
            "height_m": h[ok],
            "vel_e_mps": v[ok, 0],
            "vel_n_mps": v[ok, 1],
            "vel_u_mps": v[ok, 2],
            "sats_used": self.sats_used[ok].astype(float),
            "fix_type": np.full(int(ok.sum()), FixType.FIX_3D, dtype=np.int8),
            "spoofing_flag": np.full(int(ok.sum()), SpoofingFlag.UNKNOWN, dtype=np.int8),
        }


def epochs_of(obs: pd.DataFrame) -> tuple[NDArray[np.int64], FloatArray, NDArray[np.str_]]:
    """Epoch index of each row (receiver, time), and each epoch's time and receiver."""
    keys = pd.MultiIndex.from_arrays([obs["receiver_id"].astype(str).to_numpy(), obs["t_s"].to_numpy(float)])
    codes, uniques = pd.factorize(keys, sort=True)
    return (
        codes.astype(np.int64),
        uniques.get_level_values(1).to_numpy(float),
        uniques.get_level_values(0).to_numpy(str),
    )


def padded_slots(epoch: NDArray[np.int64], n_epochs: int) -> tuple[NDArray[np.int64], int]:
    """Slot of each row within its epoch, and the widest epoch."""
    order = np.argsort(epoch, kind="stable")
    counts = np.bincount(epoch, minlength=n_epochs)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.empty(len(epoch), dtype=np.int64)
    slot[order] = np.arange(len(epoch)) - np.repeat(starts, counts)
    return slot, int(counts.max()) if len(counts) else 0


def _solve_normal(N: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, NDArray[np.bool_]]:
    """Solve the normal equations of each epoch at once; (steps, which epochs could be solved). An
    epoch whose matrix is singular (its satellites' geometry degenerate) is not, rather than failing
    the batch."""
    ok = np.ones(len(N), dtype=bool)
    try:
        return np.linalg.solve(N, b[..., None])[..., 0], ok
    except np.linalg.LinAlgError:
        pass
    with np.errstate(all="ignore"):
        cond = np.linalg.cond(N)
    ok = np.isfinite(cond) & (cond < 1e14)
    step = np.zeros_like(b)
    for k in np.flatnonzero(ok):  # only reached for a batch holding a singular epoch
        try:
            step[k] = np.linalg.solve(N[k], b[k])
        except np.linalg.LinAlgError:
            ok[k] = False
    return step, ok


def solve(
    obs: pd.DataFrame,
    t_gps_s: FloatArray | None = None,
    options: SinglePointOptions | None = None,
    exclude: NDArray[np.bool_] | None = None,
) -> SinglePointSolution:
    """Solve every (receiver, epoch) of an observations frame.

    `t_gps_s`: GPS seconds of each row (for the ionosphere model's local time); without it the
    ionosphere is not modelled. `exclude`: rows to leave out (satellites RAIM found faulty).
    """
    opts = options or SinglePointOptions()
    epoch, t_e, rx_e = epochs_of(obs)
    n_e = len(t_e)
    slot, width = padded_slots(epoch, n_e)
    sv = obs[SV_COLUMNS].to_numpy(float)
    pr = obs["pseudorange_m"].to_numpy(float)
    sv_clk = obs["sv_clock_bias_m"].to_numpy(float)
    usable = np.isfinite(pr) & np.isfinite(sv).all(axis=1) & np.isfinite(sv_clk)
    if exclude is not None:
        usable &= ~exclude
    systems = tuple(sorted({s[:1] for s in obs["sv_id"].astype(str)[usable]}, key=lambda s: (s != "G", s)))
    sys_idx = np.array([systems.index(s[:1]) if s[:1] in systems else 0 for s in obs["sv_id"].astype(str)])
    n_x = 3 + len(systems)

    def pad(values: np.ndarray, fill: float = np.nan) -> np.ndarray:
        out = np.full((n_e, width, *values.shape[1:]), fill, dtype=float)
        out[epoch, slot] = values
        return out

    P_sv, PR, CLK = pad(sv), pad(pr), pad(sv_clk)
    SYS = np.zeros((n_e, width, len(systems)))
    SYS[epoch, slot, sys_idx] = 1.0
    T_GPS = pad(np.asarray(t_gps_s, float)) if t_gps_s is not None else None
    use = pad(usable.astype(float), 0.0) > 0
    x = np.zeros((n_e, n_x))
    weight = use.astype(float)
    singular = np.zeros(n_e, dtype=bool)
    for it in range(opts.max_iterations):
        rx = x[:, None, :3]
        near_earth = np.linalg.norm(x[:, :3], axis=1) > 6.0e6
        rho = sagnac_range(P_sv, np.broadcast_to(rx, P_sv.shape))
        clock = np.einsum("eks,es->ek", SYS, x[:, 3:])
        pred = rho + clock - CLK
        if it >= 2:  # the atmosphere and the elevation mask need a position near the Earth's surface
            rx_b = np.broadcast_to(rx, P_sv.shape)
            atm = atmospheric_delay(rx_b, P_sv, T_GPS, opts.iono if T_GPS is not None else None)
            pred = pred + np.where(near_earth[:, None], np.nan_to_num(atm), 0.0)
            _, el = azimuth_elevation(P_sv, rx_b)
            sin_el = np.sin(np.clip(el, 0.05, None))
            var = opts.sigma_zenith_m**2 * (1.0 + 1.0 / sin_el**2)
            keep = use & (~near_earth[:, None] | (el >= np.radians(opts.elevation_mask_deg)))
            weight = np.where(keep, 1.0 / var, 0.0)
        res = np.where(weight > 0, PR - pred, 0.0)
        H = np.concatenate([-line_of_sight(P_sv, np.broadcast_to(rx, P_sv.shape)), SYS], axis=-1)
        H = np.where(weight[..., None] > 0, np.nan_to_num(H), 0.0)
        N = np.einsum("eki,ek,ekj->eij", H, weight, H)
        # a system with no satellite in an epoch leaves its clock column empty: pin it weakly
        N[:, np.arange(3, n_x), np.arange(3, n_x)] += 1e-9
        b = np.einsum("eki,ek,ek->ei", H, weight, res)
        solvable = (_redundancy(weight > 0, SYS) >= 0) & ~singular
        dx = np.zeros_like(x)
        idx = np.flatnonzero(solvable)
        step, ok = _solve_normal(N[idx], b[idx])
        singular[idx[~ok]] = True  # satellites in a degenerate geometry (e.g. damaged positions): unsolved
        dx[idx[ok]] = step[ok]
        x += dx
        if it >= 3 and np.max(np.abs(dx[solvable]), initial=0.0) < 1e-4:
            break
    # final residuals and quality at the converged state
    rx = np.broadcast_to(x[:, None, :3], P_sv.shape)
    clock = np.einsum("eks,es->ek", SYS, x[:, 3:])
    pred = expected_pseudorange(P_sv, CLK, rx, clock, T_GPS, opts.iono if T_GPS is not None else None)
    used = weight > 0
    res_pad = np.where(used, PR - pred, np.nan)
    res_all = np.where(np.isfinite(PR), PR - pred, np.nan)
    n_used = used.sum(axis=1)
    solved = (_redundancy(used, SYS) >= 0) & np.isfinite(x).all(axis=1) & ~singular
    rms = np.sqrt(np.sum(np.where(used, res_pad, 0.0) ** 2, axis=1) / np.maximum(n_used, 1))
    pdop, hdop, vdop = _dops(P_sv, np.where(solved[:, None], x[:, :3], np.nan), used, SYS)
    ecef = np.where(solved[:, None], x[:, :3], np.nan)
    vel, drift = _velocity(obs, epoch, slot, n_e, width, ecef, used)
    return SinglePointSolution(
        t_s=t_e,
        receiver_id=rx_e,
        ecef_m=ecef,
        clock_m=np.where(solved, x[:, 3] if n_x > 3 else np.nan, np.nan),
        vel_ecef_mps=vel,
        clock_drift_mps=drift,
        sats_used=n_used.astype(np.int64),
        pdop=pdop,
        hdop=hdop,
        vdop=vdop,
        residual_rms_m=np.where(solved, rms, np.nan),
        residual_m=res_pad[epoch, slot],
        row_epoch=epoch,
        systems=systems,
        residual_all_m=res_all[epoch, slot],
    )


def _redundancy(used: NDArray[np.bool_], SYS: FloatArray) -> NDArray[np.int64]:
    """Satellites used minus unknowns (position + one clock per system seen) per epoch; < 0: unsolvable."""
    systems_seen = np.count_nonzero((SYS * used[..., None]).any(axis=1), axis=1)
    return used.sum(axis=1) - 3 - np.maximum(systems_seen, 1)


def _dops(
    P_sv: FloatArray, x: FloatArray, used: NDArray[np.bool_], SYS: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Position, horizontal and vertical dilution of precision (unweighted geometry), NaN where unsolved."""
    out = np.full((3, len(x)), np.nan)
    good = (used.sum(axis=1) >= 4) & np.isfinite(x).all(axis=1)
    if not good.any():
        return out[0], out[1], out[2]
    xs = x[good]
    H = np.concatenate([-line_of_sight(P_sv[good], np.broadcast_to(xs[:, None, :], P_sv[good].shape)), SYS[good]], -1)
    H = np.where(used[good][..., None], np.nan_to_num(H), 0.0)
    N = np.einsum("eki,ekj->eij", H, H)
    N[:, np.arange(3, H.shape[-1]), np.arange(3, H.shape[-1])] += 1e-9
    cov = np.linalg.inv(N)[:, :3, :3]
    lat, lon, _ = ecef_to_geodetic(xs)
    R = enu_rotation(lat, lon)
    cov_enu = R @ cov @ np.swapaxes(R, 1, 2)
    d = np.diagonal(cov_enu, axis1=1, axis2=2)
    out[0, good] = np.sqrt(d.sum(axis=1))
    out[1, good] = np.sqrt(d[:, 0] + d[:, 1])
    out[2, good] = np.sqrt(d[:, 2])
    return out[0], out[1], out[2]


def _velocity(
    obs: pd.DataFrame,
    epoch: NDArray[np.int64],
    slot: NDArray[np.int64],
    n_e: int,
    width: int,
    ecef: FloatArray,
    used: NDArray[np.bool_],
) -> tuple[FloatArray, FloatArray]:
    """Receiver velocity and clock drift from pseudorange rates (least squares, one step: it is linear)."""
    vel = np.full((n_e, 3), np.nan)
    drift = np.full(n_e, np.nan)
    if "pseudorange_rate_mps" not in obs:
        return vel, drift
    rate = obs["pseudorange_rate_mps"].to_numpy(float)
    sv_v = obs[SV_VEL_COLUMNS].to_numpy(float)
    sv_d = obs["sv_clock_drift_mps"].to_numpy(float)
    sv = obs[SV_COLUMNS].to_numpy(float)
    ok = np.isfinite(rate) & np.isfinite(sv_v).all(axis=1) & np.isfinite(sv_d) & used[epoch, slot]
    ok &= np.isfinite(ecef[epoch]).all(axis=1)
    if not ok.any():
        return vel, drift
    rx = ecef[epoch[ok]]
    u = line_of_sight(sv[ok], rx)
    # rate = u.(v_sv - v_rx) + sagnac' + d_rx - d_sv: linear in (v_rx, d_rx); take the rest to the left
    known = expected_range_rate(sv[ok], sv_v[ok], sv_d[ok], rx, np.zeros_like(rx), np.zeros(int(ok.sum())))
    y = rate[ok] - known
    H = np.concatenate([-u, np.ones((len(u), 1))], axis=1)
    Hp = np.zeros((n_e, width, 4))
    yp = np.zeros((n_e, width))
    Hp[epoch[ok], slot[ok]] = H
    yp[epoch[ok], slot[ok]] = y
    n = np.count_nonzero(np.any(Hp != 0, axis=2), axis=1)
    good = n >= 4
    N = np.einsum("eki,ekj->eij", Hp[good], Hp[good])
    b = np.einsum("eki,ek->ei", Hp[good], yp[good])
    sol = np.linalg.solve(N, b[..., None])[..., 0]
    vel[good] = sol[:, :3]
    drift[good] = sol[:, 3]
    return vel, drift


def ranged_by_receiver(table: EpochTable) -> Iterator[tuple[str, pd.DataFrame, FloatArray | None]]:
    """Each receiver's observation rows a solution can use (a satellite position and a pseudorange), with
    their GPS times (None on a log without a GPS clock)."""
    obs = table.observations
    obs = obs[np.isfinite(obs[SV_COLUMNS].to_numpy(float)).all(axis=1) & np.isfinite(obs["pseudorange_m"])]
    for rid, rows in obs.groupby("receiver_id", sort=False):
        rows = rows.reset_index(drop=True)
        yield str(rid), rows, table.gps_seconds(rows["t_s"].to_numpy(float))


def solve_logged(table: EpochTable, rows: pd.DataFrame) -> SinglePointSolution:
    """Solve observation rows of `table` as its receiver would: the log's clock gives the ionosphere's
    local time, its navigation data the broadcast coefficients."""
    return solve(rows, table.gps_seconds(rows["t_s"].to_numpy(float)), SinglePointOptions(iono=table.ionosphere))
