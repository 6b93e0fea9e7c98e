"""The Kalman measurement update with missing entries, compiled: one copy for every filter.

A measurement vector y may have NaN entries (a receiver that logged position but no velocity, an
epoch with some channels missing); those rows of y, C and R (and columns of R) are left out of the
update. Every filter in spooflens (the detectors' forward filter, the MLRT backward covariance filter,
and the navigation filter) makes this update the same way, so the numbers they compare agree.
"""

from __future__ import annotations

import math

import numpy as np

from spooflens.compile.jit import njit


@njit(cache=True, inline="always")
def observed_rows_into(y: np.ndarray, rows: np.ndarray) -> int:
    """The indices of the entries of y that are not NaN into `rows` (room for len(y)); returns how many."""
    m = 0
    for i in range(y.shape[0]):
        if not math.isnan(y[i]):
            rows[m] = i
            m += 1
    return m


@njit(cache=True)
def observed_rows(y: np.ndarray) -> np.ndarray:
    """Indices of the entries of y that are not NaN."""
    rows = np.empty(y.shape[0], dtype=np.int64)
    return rows[: observed_rows_into(y, rows)]


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
    S and the updated P are symmetrised against round-off. log det S comes from the Cholesky factor the
    inverse needs; when S is not positive definite to working precision, from numpy's determinant, or
    with `with_logdet` False NaN (no determinant beyond the factor: the navigation filter runs some 90
    times per log, and its likelihood has no use for an S that is not a covariance).
    """
    rows = observed_rows(y)
    m = rows.shape[0]
    n = x.shape[0]
    if m == 0:
        return x, P, rows, np.empty(0), np.empty((0, 0)), np.empty((0, 0)), np.empty((n, 0)), math.nan, 0.0
    scratch = update_scratch(n, m)
    x_new = np.empty(n)
    P_new = np.empty((n, n))
    nis, logdet = update_into(x, P, C, R, y, rows, m, with_logdet, scratch, x_new, P_new)
    _, e, _, S, _, _, Sinv, K = scratch
    return x_new, P_new, rows, e, S, Sinv, K, nis, logdet


UpdateScratch = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


@njit(cache=True)
def update_scratch(n: int, m: int) -> UpdateScratch:
    """The working arrays of `update_into` for n states and up to m observed rows: (P C^T, e, each row's
    nonzero columns, S, its Cholesky factor, that factor's inverse, S^-1, K). A filter makes them once."""
    return (
        np.zeros((n, m)),
        np.empty(m),
        np.empty((m, n + 1), dtype=np.int64),
        np.empty((m, m)),
        np.zeros((m, m)),
        np.zeros((m, m)),
        np.empty((m, m)),
        np.empty((n, m)),
    )


@njit(cache=True, inline="always")
def update_into(
    x: np.ndarray,
    P: np.ndarray,
    C: np.ndarray,
    R: np.ndarray,
    y: np.ndarray,
    rows: np.ndarray,
    m: int,
    with_logdet: bool,
    scratch: UpdateScratch,
    x_new: np.ndarray,
    P_new: np.ndarray,
) -> tuple[float, float]:
    """`masked_update` of the first m `rows` (m > 0) into x_new and P_new, its e, S, S^-1 and K left in
    the leading m rows and columns of `scratch` (`update_scratch`, for at least m rows): a filter that
    updates at every epoch makes no array (its allocations were a fifth of the navigation filter's time).
    Returns (nis, log det S)."""
    PCt, e, nonzero, S, L, Li, Sinv, K = scratch
    n = x.shape[0]
    # loops rather than matrix products: measurement matrices are mostly zeros (the navigation's H has
    # 33 of 216 entries) and the operands so small that BLAS calls and temporaries cost more than the sums
    for i in range(n):
        for a in range(m):
            PCt[i, a] = 0.0
    for a in range(m):
        r = rows[a]
        v = y[r]
        k = 0
        for j in range(n):
            c = C[r, j]
            if c != 0.0:
                v -= c * x[j]
                nonzero[a, k] = j
                k += 1
                for i in range(n):
                    PCt[i, a] += P[i, j] * c
        nonzero[a, k] = n
        e[a] = v
    for a in range(m):
        for b in range(a + 1):
            v = 0.5 * (R[rows[a], rows[b]] + R[rows[b], rows[a]])
            ra, rb = rows[a], rows[b]
            # the columns where either row is nonzero, ascending (the terms of the dense sum, in its order)
            ia, ib = 0, 0
            while nonzero[a, ia] < n or nonzero[b, ib] < n:
                ja, jb = nonzero[a, ia], nonzero[b, ib]
                j = min(ja, jb)
                if ja == j:
                    v += 0.5 * C[ra, j] * PCt[j, b]
                    ia += 1
                if jb == j:
                    v += 0.5 * C[rb, j] * PCt[j, a]
                    ib += 1
            S[a, b] = v
            S[b, a] = v
    logdet = spd_inverse_into(S, m, L, Li, Sinv)
    if math.isnan(logdet):  # not positive definite to working precision: the general inverse
        Sm = np.ascontiguousarray(S[:m, :m])
        Sinv[:m, :m] = np.linalg.inv(Sm)
        logdet = np.linalg.slogdet(Sm)[1] if with_logdet else math.nan
    for i in range(n):
        x_new[i] = x[i]
    for i in range(n):
        for b in range(m):
            v = 0.0
            for a in range(m):
                v += PCt[i, a] * Sinv[a, b]
            K[i, b] = v
            x_new[i] += v * e[b]
    for i in range(n):  # P - K PCt^T, symmetric: the lower triangle made, the upper mirrored
        for j in range(i + 1):
            v = 0.0
            for a in range(m):
                v += K[i, a] * PCt[j, a]
            v = 0.5 * (P[i, j] + P[j, i]) - v
            P_new[i, j] = v
            P_new[j, i] = v
    nis = 0.0
    for a in range(m):
        for b in range(m):
            nis += e[a] * Sinv[a, b] * e[b]
    return nis, logdet


@njit(cache=True, inline="always")
def masked_update_into(
    x: np.ndarray,
    P: np.ndarray,
    C: np.ndarray,
    R: np.ndarray,
    y: np.ndarray,
    with_logdet: bool,
    rows: np.ndarray,
    scratch: UpdateScratch,
    x_new: np.ndarray,
    P_new: np.ndarray,
) -> tuple[int, float, float]:
    """`masked_update` for a filter that makes its arrays once: the observed rows into `rows` (room for
    len(y)), the updated estimate into x_new and P_new, e, S, S^-1 and K in the leading rows and columns
    of `scratch` (`update_scratch(n, len(y))`). Returns (observed rows m, nis, log det S); with m = 0
    nothing is written (x and P stand)."""
    m = observed_rows_into(y, rows)
    if m == 0:
        return 0, math.nan, 0.0
    nis, logdet = update_into(x, P, C, R, y, rows, m, with_logdet, scratch, x_new, P_new)
    return m, nis, logdet


@njit(cache=True, nogil=True)
def cholesky_logdet(M: np.ndarray, L: np.ndarray) -> float:
    """Writes the lower Cholesky factor of M into L; returns log det M, or NaN when M is not positive
    definite (small matrices: written out, no LAPACK call)."""
    return cholesky_logdet_of(M, M.shape[0], L)


@njit(cache=True, nogil=True)
def cholesky_logdet_of(M: np.ndarray, m: int, L: np.ndarray) -> float:
    """`cholesky_logdet` of the leading m x m block of M."""
    logdet = 0.0
    for i in range(m):
        for j in range(i + 1):
            v = M[i, j]
            for c in range(j):
                v -= L[i, c] * L[j, c]
            if i == j:
                if not v > 0.0:
                    return math.nan
                L[i, i] = math.sqrt(v)
                logdet += 2.0 * math.log(L[i, i])
            else:
                L[i, j] = v / L[j, j]
    return logdet


@njit(cache=True)
def spd_inverse_into(S: np.ndarray, m: int, L: np.ndarray, Li: np.ndarray, out: np.ndarray) -> float:
    """S^-1 of the leading m x m block of a symmetric positive definite S by Cholesky, into `out`
    (L and Li: room for the factor and its inverse); returns log det S, NaN (out untouched) when S is not
    positive definite."""
    logdet = cholesky_logdet_of(S, m, L)
    if math.isnan(logdet):
        return math.nan
    for j in range(m):  # L^-1, lower triangular
        Li[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, m):
            v = 0.0
            for c in range(j, i):
                v -= L[i, c] * Li[c, j]
            Li[i, j] = v / L[i, i]
    for i in range(m):  # S^-1 = L^-T L^-1
        for j in range(i + 1):
            v = 0.0
            for c in range(i, m):
                v += Li[c, i] * Li[c, j]
            out[i, j] = v
            out[j, i] = v
    return logdet
