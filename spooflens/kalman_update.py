"""The Kalman measurement update with missing entries, compiled: one copy for every filter.

A measurement vector y may have NaN entries (a receiver that logged position but no velocity, an
epoch with some channels missing); those rows of y, C and R (and columns of R) are left out of the
update. Every filter in spooflens (the detectors' forward filter, the MLRT backward covariance filter,
and the navigation filter) makes this update the same way, so the numbers they compare agree.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def observed_rows(y: np.ndarray) -> np.ndarray:
    """Indices of the entries of y that are not NaN."""
    m = 0
    for i in range(y.shape[0]):
        if not math.isnan(y[i]):
            m += 1
    rows = np.empty(m, dtype=np.int64)
    j = 0
    for i in range(y.shape[0]):
        if not math.isnan(y[i]):
            rows[j] = i
            j += 1
    return rows


@njit(cache=True)
def observed_parts(
    C: np.ndarray, R: np.ndarray, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(rows, C, R, y) of one epoch restricted to the observed entries of y."""
    rows = observed_rows(y)
    m = rows.shape[0]
    Cm = np.empty((m, C.shape[1]))
    Rm = np.empty((m, m))
    ym = np.empty(m)
    for a in range(m):
        Cm[a] = C[rows[a]]
        ym[a] = y[rows[a]]
        for b in range(m):
            Rm[a, b] = R[rows[a], rows[b]]
    return rows, Cm, Rm, ym


@njit(cache=True)
def masked_update(
    x: np.ndarray, P: np.ndarray, C: np.ndarray, R: np.ndarray, y: np.ndarray, with_logdet: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Update (x, P) with the observed entries of y = C x + e, e ~ N(0, R).

    Returns (x, P, rows, e, S, Sinv, K, nis, logdet_S) with e, S, Sinv, K over the observed rows only
    (K is n x m). With nothing observed, x and P come back unchanged, nis is NaN and logdet_S 0.
    S and the updated P are symmetrised against round-off. `with_logdet` False skips the determinant
    (logdet_S NaN) for the filters that never use it (the navigation filter runs some 90 times per log).
    """
    rows, Ck, Rk, yk = observed_parts(C, R, y)
    if rows.shape[0] == 0:
        return x, P, rows, np.empty(0), np.empty((0, 0)), np.empty((0, 0)), np.empty((x.shape[0], 0)), math.nan, 0.0
    e = yk - Ck @ x
    PCt = P @ Ck.T
    S = Ck @ PCt + Rk
    S = 0.5 * (S + S.T)
    Sinv = np.linalg.inv(S)
    K = PCt @ Sinv
    x_new = x + K @ e
    P_new = P - K @ PCt.T
    P_new = 0.5 * (P_new + P_new.T)
    nis = e @ Sinv @ e
    logdet = np.linalg.slogdet(S)[1] if with_logdet else math.nan
    return x_new, P_new, rows, e, S, Sinv, K, nis, logdet
