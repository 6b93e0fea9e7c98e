"""Seed 004's attack simulation on pseudoranges (section 1.2) and the position offset vectors (POVs) it
causes, for many receivers and many Monte Carlo runs at once.

In depth: docs/methods/fleet.md."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.constants import SPEED_OF_LIGHT_MPS
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import ecef_to_enu_vectors, ecef_to_geodetic
from spooflens.gnss.ephemeris import Klobuchar
from spooflens.gnss.single_point import SV_COLUMNS, SinglePointOptions, solve

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
NS_TO_M = SPEED_OF_LIGHT_MPS * 1e-9
AUTHENTIC = 7  # the paper's spoofing keeps the first 7 satellites of the order authentic


@dataclass(frozen=True)
class Snapshot:
    """Every receiver's pseudoranges of the same N satellites at one instant."""

    receivers: tuple[str, ...]
    sv_id: tuple[str, ...]
    sv_pos: FloatArray  # (R, N, 3) ECEF at transmission
    sv_clock_m: FloatArray  # (R, N)
    pseudorange_m: FloatArray  # (R, N)
    t_gps_s: FloatArray  # (R,) for the ionosphere model's local time
    iono: Klobuchar | None = None

    @property
    def n_receivers(self) -> int:
        return len(self.receivers)

    @property
    def n_satellites(self) -> int:
        return len(self.sv_id)


def snapshot_from_table(table: EpochTable, t_s: float | None = None, receivers: list[str] | None = None) -> Snapshot:
    """The satellites every receiver logged at the epoch nearest `t_s` (default: the epoch with the most
    such satellites), each receiver at its own nearest epoch tag (receiver clocks differ by ms)."""
    obs = table.observations
    obs = obs[np.isfinite(obs[[*SV_COLUMNS, "pseudorange_m", "sv_clock_bias_m"]].to_numpy(float)).all(axis=1)]
    rids = receivers or list(dict.fromkeys(obs["receiver_id"].astype(str)))
    epoch = np.round(obs["t_s"].to_numpy(float)).astype(np.int64)
    obs = obs.assign(epoch=epoch, rid=obs["receiver_id"].astype(str), sv=obs["sv_id"].astype(str))
    obs = obs[obs["rid"].isin(rids)]
    common = obs.groupby(["epoch", "sv"])["rid"].nunique()
    common = common[common == len(rids)].reset_index()
    counts = common.groupby("epoch").size()
    if not len(counts):
        raise ValueError(f"{table.source}: no epoch at which receivers {rids} share satellites")
    if t_s is None:
        chosen = int(counts.idxmax())
    else:
        chosen = int(counts.index[np.argmin(np.abs(counts.index.to_numpy() - t_s))])
    svs = tuple(sorted(common.loc[common["epoch"] == chosen, "sv"]))
    rows = obs[(obs["epoch"] == chosen) & obs["sv"].isin(svs)].sort_values(["rid", "sv"])
    rows = rows.drop_duplicates(["rid", "sv"])
    order = {r: i for i, r in enumerate(rids)}
    rows = rows.iloc[np.argsort([order[r] for r in rows["rid"]], kind="stable")]
    R, N = len(rids), len(svs)
    t = rows.groupby("rid", sort=False)["t_s"].first().reindex(rids).to_numpy(float)
    gps = table.gps_seconds(t)
    return Snapshot(
        tuple(rids),
        svs,
        rows[SV_COLUMNS].to_numpy(float).reshape(R, N, 3),
        rows["sv_clock_bias_m"].to_numpy(float).reshape(R, N),
        rows["pseudorange_m"].to_numpy(float).reshape(R, N),
        np.asarray(gps if gps is not None else np.full(R, np.nan), dtype=float),
        table.ionosphere,
    )


def solve_sets(snap: Snapshot, use: BoolArray, bias_m: FloatArray | None = None, mask_deg: float = 0.0) -> FloatArray:
    """Single-point solutions of many satellite sets: `use` (M, R, N) chooses satellites per solution and
    receiver, `bias_m` (M, R, N) is added to their pseudoranges. Returns ECEF (M, R, 3), NaN if unsolved.

    The elevation mask is off by default: the sets are chosen by the attack, not by the solver.
    """
    M, R, _ = use.shape
    m, r, n = np.nonzero(use)
    pr = snap.pseudorange_m[r, n] + (bias_m[m, r, n] if bias_m is not None else 0.0)
    frame = pd.DataFrame(
        {
            "t_s": m.astype(float),
            "receiver_id": np.asarray(snap.receivers, dtype=object)[r],
            "sv_id": np.asarray(snap.sv_id, dtype=object)[n],
            "pseudorange_m": pr,
            "sv_x_m": snap.sv_pos[r, n, 0],
            "sv_y_m": snap.sv_pos[r, n, 1],
            "sv_z_m": snap.sv_pos[r, n, 2],
            "sv_clock_bias_m": snap.sv_clock_m[r, n],
        }
    )
    t_gps = snap.t_gps_s[r] if np.isfinite(snap.t_gps_s).all() else None
    sol = solve(
        frame, t_gps, SinglePointOptions(elevation_mask_deg=mask_deg, iono=snap.iono if t_gps is not None else None)
    )
    out = np.full((M, R, 3), np.nan)
    rx_index = {rid: i for i, rid in enumerate(snap.receivers)}
    ri = np.array([rx_index[x] for x in sol.receiver_id])
    out[sol.t_s.astype(np.int64), ri] = sol.ecef_m
    return out


def pov_enu(attacked: FloatArray, reference: FloatArray) -> FloatArray:
    """East/north offsets (..., 2) of attacked minus reference positions, in the reference's local frame."""
    lat, lon, _ = ecef_to_geodetic(reference)
    out: FloatArray = ecef_to_enu_vectors(lat, lon, attacked - reference)[..., :2]
    return out


@dataclass(frozen=True)
class AttackRuns:
    """POVs of one attack at one n for every run and receiver."""

    kind: str
    n: int
    pov: FloatArray  # (runs, R, 2)
    bias_m: float


def _orders(runs: int, N: int, rng: np.random.Generator) -> NDArray[np.int64]:
    return np.argsort(rng.random((runs, N)), axis=1)


def blocking(snap: Snapshot, n: int, runs: int, rng: np.random.Generator, full: FloatArray | None = None) -> AttackRuns:
    N, R = snap.n_satellites, snap.n_receivers
    full = solve_sets(snap, np.ones((1, R, N), bool))[0] if full is None else full
    blocked = _orders(runs, N, rng)[:, :n]
    use = np.ones((runs, N), bool)
    np.put_along_axis(use, blocked, False, axis=1)
    pos = solve_sets(snap, np.broadcast_to(use[:, None, :], (runs, R, N)))
    return AttackRuns("blocking", n, pov_enu(pos, np.broadcast_to(full, pos.shape)), 0.0)


def spoofing(snap: Snapshot, n: int, runs: int, rng: np.random.Generator, bias_m: float) -> AttackRuns:
    N, R = snap.n_satellites, snap.n_receivers
    order = _orders(runs, N, rng)
    rank = np.argsort(order, axis=1)  # position of each satellite in the run's order
    true_use = rank < AUTHENTIC
    use = rank < AUTHENTIC + n
    bias = np.where((rank >= AUTHENTIC) & use, bias_m, 0.0)
    both = np.concatenate([true_use, use])[:, None, :].repeat(R, axis=1)
    b = np.concatenate([np.zeros_like(bias), bias])[:, None, :].repeat(R, axis=1)
    pos = solve_sets(snap, both, b)
    return AttackRuns("spoofing", n, pov_enu(pos[runs:], pos[:runs]), bias_m)


def bias_injection(
    snap: Snapshot, n: int, runs: int, rng: np.random.Generator, bias_m: float, full: FloatArray | None = None
) -> AttackRuns:
    N, R = snap.n_satellites, snap.n_receivers
    full = solve_sets(snap, np.ones((1, R, N), bool))[0] if full is None else full
    rank = np.argsort(_orders(runs, N, rng), axis=1)
    bias = np.where(rank < n, bias_m, 0.0)[:, None, :].repeat(R, axis=1)
    pos = solve_sets(snap, np.ones((runs, R, N), bool), bias)
    return AttackRuns("bias_injection", n, pov_enu(pos, np.broadcast_to(full, pos.shape)), bias_m)


def amplitude_sweep(
    snap: Snapshot, amplitudes_ns: FloatArray, runs: int, rng: np.random.Generator, full: FloatArray | None = None
) -> FloatArray:
    """POVs (runs, amplitudes, R, 2) of bias injection with a random count (1 .. N-1) and random satellites
    per run, at every amplitude (the same satellites across amplitudes: one line per run, as Fig. 7)."""
    N, R = snap.n_satellites, snap.n_receivers
    full = solve_sets(snap, np.ones((1, R, N), bool))[0] if full is None else full
    count = rng.integers(1, N, runs)
    rank = np.argsort(_orders(runs, N, rng), axis=1)
    hit = rank < count[:, None]
    A = len(amplitudes_ns)
    bias = hit[:, None, None, :] * (np.asarray(amplitudes_ns, float) * NS_TO_M)[None, :, None, None]
    bias = np.broadcast_to(bias, (runs, A, R, N)).reshape(runs * A, R, N)
    pos = solve_sets(snap, np.ones((runs * A, R, N), bool), bias).reshape(runs, A, R, 3)
    return pov_enu(pos, np.broadcast_to(full, pos.shape))


ATTACKS: dict[str, Callable[..., AttackRuns]] = {
    "blocking": blocking,
    "spoofing": spoofing,
    "bias_injection": bias_injection,
}
