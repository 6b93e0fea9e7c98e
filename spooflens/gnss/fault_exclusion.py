"""Receiver autonomous integrity monitoring with fault detection and exclusion (RAIM FDE) for the
batched single-point solver.

In depth: docs/methods/navigation.md."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.estimation.quantiles import chi2_isf
from spooflens.gnss.geometry import azimuth_elevation, line_of_sight
from spooflens.gnss.single_point import (
    SV_COLUMNS,
    SinglePointOptions,
    SinglePointSolution,
    epochs_of,
    padded_slots,
    solve,
)

FloatArray = NDArray[np.float64]
CLEAR, FAULT, UNKNOWN = 0, 1, 2


@dataclass(frozen=True)
class RaimOptions:
    p_false_alarm: float = 1e-3  # per epoch
    max_exclusions: int = 3


@dataclass(frozen=True)
class RaimResult:
    solution: SinglePointSolution  # with the faulty rows left out
    flag: NDArray[np.int8]  # per row: CLEAR, FAULT, UNKNOWN
    statistic: FloatArray  # per epoch: T / scale^2 of the solution before any exclusion
    dof: NDArray[np.int64]  # per epoch
    threshold: FloatArray  # per epoch
    scale: float  # residual scale learned from the log (multiplies the a-priori sigma)
    inconsistency_m: FloatArray  # per row: residual against the solution without it (faults), else NaN


def residual_design(
    obs: pd.DataFrame, sol: SinglePointSolution, opts: SinglePointOptions, used_rows: NDArray[np.bool_]
) -> tuple[NDArray[np.int64], NDArray[np.int64], FloatArray, FloatArray, FloatArray]:
    """Padded (E, W, m) design matrix at the solution, weights and post-fit residuals of the used rows."""
    epoch, _, _ = epochs_of(obs)
    n_e = len(sol.t_s)
    slot, width = padded_slots(epoch, n_e)
    systems = sol.systems
    sys_idx = np.array([systems.index(s[:1]) if s[:1] in systems else 0 for s in obs["sv_id"].astype(str)])
    m = 3 + len(systems)
    sv = obs[SV_COLUMNS].to_numpy(float)
    rx = sol.ecef_m[epoch]
    u = line_of_sight(sv, rx)
    _, el = azimuth_elevation(sv, rx)
    sin_el = np.sin(np.clip(np.nan_to_num(el), 0.05, None))
    w_row = 1.0 / (opts.sigma_zenith_m**2 * (1.0 + 1.0 / sin_el**2))
    ok = used_rows & np.isfinite(sol.residual_m) & np.isfinite(u).all(axis=1)
    H = np.zeros((n_e, width, m))
    W = np.zeros((n_e, width))
    r = np.zeros((n_e, width))
    h_rows = np.concatenate([-u, np.eye(len(systems))[sys_idx]], axis=1)
    H[epoch[ok], slot[ok]] = h_rows[ok]
    W[epoch[ok], slot[ok]] = w_row[ok]
    r[epoch[ok], slot[ok]] = sol.residual_m[ok]
    return epoch, slot, H, W, r


def _leave_one_out(H: FloatArray, W: FloatArray, r: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per epoch and slot: T without that row (inf where the row is not used), and its residual against
    the solution without it; and T of all rows."""
    n_e, width, m = H.shape
    N = np.einsum("eki,ek,ekj->eij", H, W, H)
    b = np.einsum("eki,ek,ek->ei", H, W, r)
    T_all = np.einsum("ek,ek,ek->e", W, r, r)
    T = np.full((n_e, width), np.inf)
    res_j = np.full((n_e, width), np.nan)
    eye = np.eye(m) * 1e-9
    for j in range(width):
        w = W[:, j]
        on = w > 0
        if not on.any():
            continue
        h = H[on, j]
        Nj = N[on] - w[on, None, None] * h[:, :, None] * h[:, None, :] + eye
        bj = b[on] - w[on, None] * h * r[on, j, None]
        try:
            d = np.linalg.solve(Nj, bj[..., None])[..., 0]
        except np.linalg.LinAlgError:
            continue
        after = r[on] - np.einsum("eki,ei->ek", H[on], d)
        keep = W[on].copy()
        keep[:, j] = 0.0
        T[on, j] = np.einsum("ek,ek,ek->e", keep, after, after)
        res_j[on, j] = after[:, j]
    return T, res_j, T_all


def _leave_two_out(
    H: FloatArray, W: FloatArray, r: FloatArray, epochs: NDArray[np.int64]
) -> tuple[FloatArray, NDArray[np.int64]]:
    """For the given epochs: the smallest T with two rows left out, and the two slots."""
    m = H.shape[2]
    He, We, re_ = H[epochs], W[epochs], r[epochs]
    N = np.einsum("eki,ek,ekj->eij", He, We, He)
    b = np.einsum("eki,ek,ek->ei", He, We, re_)
    best = np.full(len(epochs), np.inf)
    pair = np.full((len(epochs), 2), -1, dtype=np.int64)
    width = H.shape[1]
    eye = np.eye(m) * 1e-9
    for a in range(width):
        for c in range(a + 1, width):
            on = (We[:, a] > 0) & (We[:, c] > 0)
            if not on.any():
                continue
            ha, hc = He[on, a], He[on, c]
            wa, wc = We[on, a, None, None], We[on, c, None, None]
            Nj = N[on] - wa * ha[:, :, None] * ha[:, None, :] - wc * hc[:, :, None] * hc[:, None, :] + eye
            bj = b[on] - We[on, a, None] * ha * re_[on, a, None] - We[on, c, None] * hc * re_[on, c, None]
            try:
                d = np.linalg.solve(Nj, bj[..., None])[..., 0]
            except np.linalg.LinAlgError:
                continue
            after = re_[on] - np.einsum("eki,ei->ek", He[on], d)
            keep = We[on].copy()
            keep[:, [a, c]] = 0.0
            T = np.einsum("ek,ek,ek->e", keep, after, after)
            idx = np.flatnonzero(on)
            better = best[idx] > T
            best[idx[better]] = T[better]
            pair[idx[better]] = (a, c)
    return best, pair


def _fde(
    obs: pd.DataFrame,
    t_gps_s: FloatArray | None,
    opts: SinglePointOptions,
    ropts: RaimOptions,
    scale2: float | None,
) -> tuple[SinglePointSolution, NDArray[np.bool_], FloatArray, FloatArray, float, FloatArray, NDArray[np.int64]]:
    """One detection-and-exclusion loop. Without `scale2` the residual scale comes from the best
    leave-one-out subsets of the first solution."""
    excluded = np.zeros(len(obs), dtype=bool)
    sol = solve(obs, t_gps_s, opts)
    epoch, slot, H, W, r = residual_design(obs, sol, opts, np.isfinite(sol.residual_m))
    m = H.shape[2]
    dof = (W > 0).sum(axis=1) - m
    T_loo, _, T_all = _leave_one_out(H, W, r)
    if scale2 is None:
        best = np.min(T_loo, axis=1) / np.maximum(dof - 1, 1)
        testable = (dof >= 2) & np.isfinite(best)
        scale2 = max(float(np.median(best[testable])) if testable.any() else 1.0, 1.0)
    threshold = np.where(dof >= 1, chi2_isf(ropts.p_false_alarm, np.maximum(dof, 1)), np.nan)
    statistic = np.where(dof >= 1, T_all / scale2, np.nan)
    first_threshold = threshold
    row_of = np.full(H.shape[:2], -1, dtype=np.int64)
    row_of[epoch, slot] = np.arange(len(obs))
    for _ in range(ropts.max_exclusions):
        faulty = (np.nan_to_num(T_all / scale2) > np.nan_to_num(threshold, nan=np.inf)) & (dof >= 2)
        if not faulty.any():
            break
        j = np.argmin(np.where(W > 0, T_loo, np.inf), axis=1)
        fe = np.flatnonzero(faulty)
        T_one = T_loo[fe, j[fe]]
        one_clears = T_one / scale2 <= chi2_isf(ropts.p_false_alarm, np.maximum(dof[fe] - 1, 1))
        rows = row_of[fe[one_clears], j[fe[one_clears]]]
        excluded[rows[rows >= 0]] = True
        # where leaving out one satellite does not clear the test, two faults are likelier than one:
        # leave out the best pair (greedy single exclusions pick honest satellites when two are wrong)
        two = fe[~one_clears & (dof[fe] >= 3)]
        if len(two):
            T_two, pair = _leave_two_out(H, W, r, two)
            clears = T_two / scale2 <= chi2_isf(ropts.p_false_alarm, np.maximum(dof[two] - 2, 1))
            for k in range(2):
                rows = row_of[two[clears], pair[clears, k]]
                excluded[rows[rows >= 0]] = True
            rest = two[~clears]
        else:
            rest = two
        rest = np.r_[rest, fe[~one_clears & (dof[fe] < 3)]]
        rows = row_of[rest, j[rest]]
        excluded[rows[rows >= 0]] = True
        sol = solve(obs, t_gps_s, opts, exclude=excluded)
        epoch, slot, H, W, r = residual_design(obs, sol, opts, np.isfinite(sol.residual_m))
        dof = (W > 0).sum(axis=1) - m
        T_loo, _res_loo, T_all = _leave_one_out(H, W, r)
        threshold = np.where(dof >= 1, chi2_isf(ropts.p_false_alarm, np.maximum(dof, 1)), np.nan)
    final_ratio = np.where(dof >= 1, T_all / np.maximum(dof, 1), np.nan)
    return sol, excluded, statistic, first_threshold, scale2, final_ratio, dof


def solve_with_fde(
    obs: pd.DataFrame,
    t_gps_s: FloatArray | None = None,
    options: SinglePointOptions | None = None,
    raim: RaimOptions | None = None,
) -> RaimResult:
    opts = options or SinglePointOptions()
    ropts = raim or RaimOptions()
    # a first loop finds the gross faults; the residual scale of its cleaned solutions then judges again
    _, _, _, _, _, cleaned, dof = _fde(obs, t_gps_s, opts, ropts, None)
    ok = np.isfinite(cleaned) & (dof >= 1)
    scale2 = max(float(np.median(cleaned[ok])), 1.0) if ok.any() else 1.0
    sol, excluded, statistic, threshold, scale2, _, dof = _fde(obs, t_gps_s, opts, ropts, scale2)
    inconsistency = np.where(excluded, sol.residual_all_m, np.nan) if sol.residual_all_m is not None else None
    if inconsistency is None:
        inconsistency = np.full(len(obs), np.nan)
    epoch = sol.row_epoch
    flag = np.full(len(obs), UNKNOWN, dtype=np.int8)
    tested = np.isfinite(sol.residual_m) & (dof[epoch] >= 1)
    flag[tested] = CLEAR
    flag[excluded] = FAULT
    return RaimResult(sol, flag, statistic, dof.astype(np.int64), threshold, float(np.sqrt(scale2)), inconsistency)
