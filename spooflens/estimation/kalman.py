"""Kalman filters on a LinearGaussianModel, compiled: the forward filter every detector starts from,
and the backward information filter of the two-filter methods.

Missing measurement entries (NaN in y) are left out of that epoch's update. Indexing follows
spooflens.estimation.statespace: x_k = A[k] x_{k-1} + w_k (A[0] unused), y_k = C[k] x_k + e_k, x_0 ~ N(x0, P0).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spooflens.compile.jit import kernel_array, njit
from spooflens.estimation.kalman_update import masked_update_into, observed_parts, update_scratch
from spooflens.estimation.sparse_products import (
    add_block_diagonal,
    block_congruence,
    block_times_vector,
    congruence_t,
    full_pattern,
)
from spooflens.estimation.statespace import LinearGaussianModel

FloatArray = NDArray[np.float64]
CACHE = True


@dataclass(frozen=True)
class ForwardResult:
    eps: FloatArray  # (N, p) innovations, NaN where not measured
    S: FloatArray  # (N, p, p) innovation covariance (used rows; identity elsewhere)
    Sinv: FloatArray  # (N, p, p) its inverse on the used rows, zero elsewhere
    K: FloatArray  # (N, n, p) gains (zero columns for unused rows)
    x_pred: FloatArray  # (N, n); (0, n) when the filter ran without keep_states, as the three below
    P_pred: FloatArray  # (N, n, n)
    x_upd: FloatArray
    P_upd: FloatArray
    nis: FloatArray  # (N,)
    logdet_S: FloatArray  # (N,)
    dof: NDArray[np.int64]  # (N,)

    @property
    def V(self) -> FloatArray:
        """The paper's V^F(t): running sum of normalised innovation squares."""
        return np.cumsum(np.nan_to_num(self.nis))

    @property
    def D(self) -> FloatArray:
        """The paper's D^F(t): running sum of log det S."""
        return np.cumsum(self.logdet_S)


@njit(cache=CACHE, nogil=True)
def _forward(
    A_head: np.ndarray,
    A_tail: np.ndarray,
    Q_head: np.ndarray,
    Q_tail: np.ndarray,
    C: np.ndarray,
    R: np.ndarray,
    y: np.ndarray,
    x0: np.ndarray,
    P0: np.ndarray,
    keep_states: bool = True,
    continued: bool = False,
    carry: int = -1,
):
    """The filter over the epochs of the arrays from (x0, P0): the prior of the first epoch, or, when
    `continued`, the estimate after the epoch before it (a block of a longer log: the first epoch is
    predicted too). The last two returned are the estimate after epoch `carry` (the last when -1)."""
    B, p = y.shape
    if carry < 0:
        carry = B - 1
    n = x0.shape[0]
    eps = np.full((B, p), np.nan)
    S_out = np.zeros((B, p, p))
    Sinv_out = np.zeros((B, p, p))
    K_out = np.zeros((B, n, p))
    Ns = B if keep_states else 0
    xp = np.zeros((Ns, n))
    Pp = np.zeros((Ns, n, n))
    xu = np.zeros((Ns, n))
    Pu = np.zeros((Ns, n, n))
    nis = np.full(B, np.nan)
    logdet = np.zeros(B)
    dof = np.zeros(B, dtype=np.int64)
    x = x0.copy()
    P = P0.copy()
    x_carry = x0.copy()
    P_carry = P0.copy()
    # the update's arrays made once (a filter over an hour of 10 Hz made some 400 000)
    rows = np.empty(p, dtype=np.int64)
    scratch = update_scratch(n, p)
    e, S, Sinv, K = scratch[1], scratch[3], scratch[6], scratch[7]
    x_new, P_new = np.empty(n), np.empty((n, n))
    for b in range(B):
        if b > 0 or continued:
            x = block_times_vector(A_head[b], A_tail[b], x)
            P = add_block_diagonal(block_congruence(A_head[b], A_tail[b], P, np.empty((n, n))), Q_head[b], Q_tail[b])
        if keep_states:
            xp[b] = x
            Pp[b] = P
        for i in range(p):
            S_out[b, i, i] = 1.0
        m, nis_k, logdet_k = masked_update_into(x, P, C[b], R[b], y[b], True, rows, scratch, x_new, P_new)
        if m > 0:
            x, x_new = x_new, x
            P, P_new = P_new, P
            nis[b] = nis_k
            logdet[b] = logdet_k
            dof[b] = m
            for a in range(m):
                eps[b, rows[a]] = e[a]
                K_out[b, :, rows[a]] = K[:, a]
                for c in range(m):
                    S_out[b, rows[a], rows[c]] = S[a, c]
                    Sinv_out[b, rows[a], rows[c]] = Sinv[a, c]
        if keep_states:
            xu[b] = x
            Pu[b] = P
        if b == carry:
            x_carry = x.copy()
            P_carry = P.copy()
    return eps, S_out, Sinv_out, K_out, xp, Pp, xu, Pu, nis, logdet, dof, x_carry, P_carry


ModelArrays = tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]


def model_arrays(model: LinearGaussianModel, epochs: slice = slice(None)) -> ModelArrays:
    """The arrays `_forward` reads, of `epochs` (views where the model's are as the kernels take them)."""
    A, Q = model.A[epochs], model.Q[epochs]
    c = kernel_array
    return c(A.head), c(A.tail), c(Q.head), c(Q.tail), c(model.C[epochs]), c(model.R[epochs]), c(model.y[epochs])


def prior(model: LinearGaussianModel) -> tuple[FloatArray, FloatArray]:
    """(x0, P0) of `model` as the kernels take them: float, the covariance C-contiguous."""
    return model.x0.astype(float), np.ascontiguousarray(model.P0, dtype=float)


def forward_filter(model: LinearGaussianModel, keep_states: bool = True) -> ForwardResult:
    """The forward filter; without `keep_states` the state estimates and their covariances are not kept
    (x_pred, P_pred, x_upd, P_upd come back empty: two (N, n, n) arrays a detector that reads only the
    innovations, gains and S does without)."""
    out = _forward(*model_arrays(model), *prior(model), keep_states)
    return ForwardResult(*out[:-2])


def forward_blocks(
    model: LinearGaussianModel, block: int, reach: Callable[[int], int]
) -> Iterator[tuple[int, int, ForwardResult]]:
    """The forward filter (without states) a block of `block` epochs at a time: (lo, hi, result over
    epochs lo..reach(hi) - 1). A consumer that reads some epochs past each block's end (a sliding window)
    gets them from `reach`; the next block starts from the estimate after hi - 1, so every epoch's numbers
    are those of `forward_filter`, and only a block and its reach are held at a time."""
    x, P = prior(model)
    N, block = model.n_epochs, max(1, block)
    for lo in range(0, N, block):
        hi = min(lo + block, N)
        end = max(hi, min(reach(hi), N))
        *out, x, P = _forward(*model_arrays(model, slice(lo, end)), x, P, False, lo > 0, hi - 1 - lo)
        yield lo, hi, ForwardResult(*out)


@njit(cache=CACHE)
def noise_factor(Q: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Q = B Qr B^T with Qr diagonal and invertible (singular Q: states without process noise)."""
    w, V = np.linalg.eigh(0.5 * (Q + Q.T))
    scale = max(np.max(np.abs(w)), 1e-300)
    keep = w > tol * scale
    r = 0
    for i in range(w.shape[0]):
        if keep[i]:
            r += 1
    B = np.zeros((Q.shape[0], r))
    Qr = np.zeros((r, r))
    j = 0
    for i in range(w.shape[0]):
        if keep[i]:
            B[:, j] = V[:, i]
            Qr[j, j] = w[i]
            j += 1
    return B, Qr


@njit(cache=CACHE)
def information_predict_back(
    Lam: np.ndarray,
    alpha: np.ndarray,
    A: np.ndarray,
    Q: np.ndarray,
    noisy: int,
    a_ptr: np.ndarray,
    a_col: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """From information on x_k to information on x_{k-1} through x_k = A x_{k-1} + w, w ~ N(0, Q), Q zero
    outside its leading (noisy, noisy) block (states after those carry no process noise: a detector's
    augmented attack states).

    Lambda_{k-1} = A^T (Lambda - Lambda B (B^T Lambda B + Qr^-1)^-1 B^T Lambda) A, and
    alpha_{k-1}  = A^T (I - Lambda B (B^T Lambda B + Qr^-1)^-1 B^T) alpha, with Q = B Qr B^T.
    (The paper's printed step computes G and never uses it: this is the standard form it garbled.)
    By the matrix inversion lemma both brackets are (I + Lambda Q)^-1 applied to Lambda and to alpha,
    which needs no factorisation of a singular Q (no eigendecomposition and no tolerance for what counts
    as a zero eigenvalue) and is always solvable: I + Lambda Q has eigenvalues >= 1. Its columns after
    `noisy` are the identity's, so it is block lower triangular: only its leading block is factorised
    (24 of 30 states for an MLRT's ramp: half the work) and the rows after follow by substitution.
    A's non-zeros are (a_ptr, a_col) (`spooflens.estimation.sparse_products`).
    """
    n = Lam.shape[0]
    s = noisy
    LQ = np.ascontiguousarray(Lam[:, :s]) @ np.ascontiguousarray(Q[:s, :s])  # Lambda Q's non-zero columns
    X = LQ[:s].copy()
    for i in range(s):
        X[i, i] += 1.0
    rhs = np.empty((s, n + 1))
    rhs[:, :n] = Lam[:s]
    rhs[:, n] = alpha[:s]
    sol = np.empty((n, n + 1))
    sol[:s] = np.linalg.solve(X, rhs)
    if s < n:
        sol[s:, :n] = Lam[s:]
        sol[s:, n] = alpha[s:]
        sol[s:] -= np.ascontiguousarray(LQ[s:]) @ sol[:s]
    Lam_m = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            Lam_m[i, j] = 0.5 * (sol[i, j] + sol[j, i])
    return congruence_t(A, Lam_m, a_ptr, a_col, np.empty((n, n))), A.T @ np.ascontiguousarray(sol[:, n])


@njit(cache=CACHE)
def information_update(
    Lam: np.ndarray, alpha: np.ndarray, Ck: np.ndarray, Rk: np.ndarray, yk: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Add one epoch's measurement (used rows only) to the information: Lambda + C^T R^-1 C and
    alpha + C^T R^-1 y, the products over C's non-zeros (a measurement row reads a few states)."""
    rows, Cm, Rm, ym = observed_parts(Ck, Rk, yk)
    m = rows.shape[0]
    if m == 0:
        return Lam, alpha
    n = Lam.shape[0]
    rhs = np.empty((m, n + 1))
    rhs[:, :n] = Cm
    rhs[:, n] = ym
    W = np.linalg.solve(Rm, rhs)  # R^-1 [C y]
    Lam_new = Lam.copy()
    alpha_new = alpha.copy()
    for r in range(m):
        for c in range(n):
            v = Cm[r, c]
            if v != 0.0:
                for j in range(n):
                    Lam_new[c, j] += v * W[r, j]
                alpha_new[c] += v * W[r, n]
    return Lam_new, alpha_new


@njit(cache=CACHE)
def backward_information(
    A: np.ndarray, Q: np.ndarray, C: np.ndarray, R: np.ndarray, y: np.ndarray, last: int, first: int
) -> tuple[np.ndarray, np.ndarray]:
    """Information (Lambda, alpha) on x_k from y_{k+1..last}, for k = first..last (zero at k = last).

    Lam[k] is the information the FUTURE measurements (after k) carry about x_k: exactly what a
    forward estimate at k is combined with.
    """
    n = A.shape[1]
    cnt = last - first + 1
    Lam = np.zeros((cnt, n, n))
    alpha = np.zeros((cnt, n))
    L = np.zeros((n, n))
    a = np.zeros(n)
    ptr, col = full_pattern(n, n)
    for k in range(last, first - 1, -1):
        Lam[k - first] = L
        alpha[k - first] = a
        if k == first:
            break
        L, a = information_update(L, a, C[k], R[k], y[k])
        L, a = information_predict_back(L, a, A[k], Q[k], n, ptr, col)
    return Lam, alpha
