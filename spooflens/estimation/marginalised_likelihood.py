"""Marginalised likelihood ratio tests (seed 000, after Gustafsson 1996), in two forms.

In depth: docs/methods/mlrt.md."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import numpy as np
from numpy.typing import NDArray

from spooflens.compile.jit import njit
from spooflens.estimation.kalman import (
    backward_information,
    forward_filter,
    information_predict_back,
    information_update,
    noise_factor,
    prior,
)
from spooflens.estimation.kalman_update import masked_update, masked_update_into, observed_parts, update_scratch
from spooflens.estimation.sparse_products import congruence, full_pattern, nonzero_mask, pattern_of_mask, times_vector
from spooflens.estimation.statespace import BlockDiagonal, LinearGaussianModel, kernel_array
from spooflens.threads import both, in_parallel

FloatArray = NDArray[np.float64]
LOG_2PI = math.log(2 * math.pi)


# --- 1. the paper's two-filter algorithm (full-state jump) ------------------------------------------


@dataclass(frozen=True)
class PaperMlrt:
    t_index: int  # the current epoch t
    L: int
    m: NDArray[np.int64]  # candidate epochs m = 0 .. t-L-1 (the jump is between m and m+1)
    ell: FloatArray  # the paper's l_t(m)
    VF: FloatArray  # V^F, D^F over epochs 0..t
    DF: FloatArray
    VB: FloatArray  # V^B(i), D^B(i) for i = 0 .. t-L (sums over i..t-L)
    DB: FloatArray


@njit(cache=True)
def _backward_covariance(
    A: np.ndarray, Q: np.ndarray, C: np.ndarray, R: np.ndarray, y: np.ndarray, start: int, x: np.ndarray, P: np.ndarray
):
    """Paper's backward covariance filter from epoch `start` (prior x, P from later data) down to 0."""
    VB = np.zeros(start + 2)
    DB = np.zeros(start + 2)
    for i in range(start, -1, -1):
        x, P, rows, _, _, _, _, v, dd = masked_update(x, P, C[i], R[i], y[i])
        if rows.shape[0] == 0:
            v = 0.0
        VB[i] = VB[i + 1] + v
        DB[i] = DB[i + 1] + dd
        if i > 0:
            Ainv = np.linalg.inv(A[i])
            x = Ainv @ x
            P = Ainv @ (P + Q[i]) @ Ainv.T
            P = 0.5 * (P + P.T)
    return VB[: start + 1], DB[: start + 1]


def paper_two_filter(
    model: LinearGaussianModel, t: int, L: int, prior_information: FloatArray | None = None
) -> PaperMlrt:
    """l_t(m) for m = 0..t-L-1, exactly as seed 000 section 3.2 builds it (with the corrected step).

    `prior_information` (default none, the paper's zero information) is added to the backward filter's
    information on x_{t-L}: the INS error model is not observable from a few samples (accelerometer
    bias and tilt, for one, are inseparable without manoeuvres), so on it the paper's start is singular
    and a weak prior (e.g. a small multiple of P0^-1) is the only way to run the algorithm.
    """
    if not 1 <= L <= t:
        raise ValueError(f"need 1 <= L <= t, got L={L}, t={t}")
    w = model.window(0, t + 1)
    fwd = forward_filter(w)
    VF, DF = fwd.V, fwd.D
    A, Q, C, R, y = (np.ascontiguousarray(a) for a in (w.A.dense(), w.Q.dense(), w.C, w.R, w.y))
    info_L, info_a = backward_information(A, Q, C, R, y, t, t - L)
    Lam, alpha = info_L[0], info_a[0]  # information on x_{t-L} from y_{t-L+1..t}
    if prior_information is not None:
        Lam = Lam + prior_information
    if np.linalg.cond(Lam) > 1e10:
        raise ValueError(
            f"the last L={L} samples do not observe the whole state (information matrix "
            f"condition {np.linalg.cond(Lam):.1e}): the paper's backward filter needs a larger L"
        )
    P = np.linalg.inv(Lam)
    x = P @ alpha
    VB, DB = _backward_covariance(A, Q, C, R, y, t - L, x, P)
    m = np.arange(0, t - L)
    ell = VF[t] + DF[t] - VF[m] - DF[m] - VB[m + 1] - DB[m + 1]
    return PaperMlrt(t, L, m, ell, VF, DF, VB, DB)


@njit(cache=True)
def _info_constant(
    A: np.ndarray, Q: np.ndarray, C: np.ndarray, R: np.ndarray, y: np.ndarray, last: int, first: int
) -> tuple[np.ndarray, np.ndarray, float]:
    """Backward information on x_first from y_{first+1..last} WITH the scalar constant c of
    L(x) = exp(c - x^T Lambda x / 2 + alpha^T x) = p(y_{first+1..last} | x_first)."""
    n = A.shape[1]
    Lam = np.zeros((n, n))
    alpha = np.zeros(n)
    c = 0.0
    ptr, col = full_pattern(n, n)
    for k in range(last, first, -1):
        yk = y[k]
        rows, _, Rm, ym = observed_parts(C[k], R[k], yk)
        m = rows.shape[0]
        if m > 0:
            c += -0.5 * ym @ np.linalg.solve(Rm, ym) - 0.5 * (m * 1.8378770664093453 + np.linalg.slogdet(Rm)[1])
        Lam, alpha = information_update(Lam, alpha, C[k], R[k], yk)
        B, Qr = noise_factor(Q[k], 1e-12)
        if B.shape[1] > 0:
            M = B.T @ Lam @ B
            for i in range(M.shape[0]):
                M[i, i] += 1.0 / Qr[i, i]
            Ba = B.T @ alpha
            c += (
                0.5 * Ba @ np.linalg.solve(M, Ba)
                - 0.5 * np.linalg.slogdet(np.eye(M.shape[0]) + Qr @ (B.T @ Lam @ B))[1]
            )
        Lam, alpha = information_predict_back(Lam, alpha, A[k], Q[k], n, ptr, col)
    return Lam, alpha, c


def full_jump_constants(model: LinearGaussianModel, res: PaperMlrt) -> FloatArray:
    """What the paper's l_t(m) leaves out, per m: 2 log LR_flat(m) = l_t(m) + constants(m).

    (the L dropped epochs' 2 pi terms) + 2 log Z_L (the flat-prior evidence of the last L samples)
    - 2 log |det(A_{t-L} ... A_{m+2})| (a density-1 flat prior on x_{m+1} is a density 1/|det| on x_{t-L}).
    """
    t, L = res.t_index, res.L
    w = model.window(0, t + 1)
    A, Q, C, R, y = (np.ascontiguousarray(a) for a in (w.A.dense(), w.Q.dense(), w.C, w.R, w.y))
    Lam, alpha, c = _info_constant(A, Q, C, R, y, t, t - L)
    n = model.n_states
    _, logdet_lam = np.linalg.slogdet(Lam)
    log_z = c + 0.5 * n * LOG_2PI - 0.5 * logdet_lam + 0.5 * alpha @ np.linalg.solve(Lam, alpha)
    p_dropped = int(np.sum(np.isfinite(y[t - L + 1 : t + 1])))
    logdet_A = np.array([np.linalg.slogdet(A[k])[1] for k in range(len(A))])
    # sum over k = m+2 .. t-L of log|det A_k|
    cum = np.concatenate([[0.0], np.cumsum(logdet_A)])
    det_term = np.array([cum[t - L + 1] - cum[min(m + 2, t - L + 1)] for m in res.m])
    return p_dropped * LOG_2PI + 2 * log_z - 2 * det_term


@njit(cache=True)
def _full_jump_wj(
    A: np.ndarray, C: np.ndarray, K: np.ndarray, Sinv: np.ndarray, eps: np.ndarray, t: int, m: int
) -> tuple[float, float]:
    n = A.shape[1]
    e = np.eye(n)  # effect of the jump on the prior estimate error at m+1
    d = np.zeros(n)
    info = np.zeros((n, n))
    e0 = np.where(np.isnan(eps), 0.0, eps)
    for k in range(m + 1, t + 1):
        if k > m + 1:
            e = A[k] @ e
        G = C[k] @ e
        SG = Sinv[k] @ G
        d += SG.T @ e0[k]
        info += G.T @ SG
        e = e - K[k] @ G
    _, logdet = np.linalg.slogdet(info)
    return float(d @ np.linalg.solve(info, d)), float(logdet)


def full_jump_wj(model: LinearGaussianModel, t: int, m: NDArray[np.integer] | FloatArray) -> FloatArray:
    """2 log LR of a full-state jump after m, flat prior of density 1, from Willsky-Jones signatures."""
    fwd = forward_filter(model.window(0, t + 1))
    A = model.A[: t + 1].dense()
    C = np.ascontiguousarray(model.C[: t + 1])
    out = []
    for mm in m:
        g, logdet = _full_jump_wj(
            A, C, np.ascontiguousarray(fwd.K), np.ascontiguousarray(fwd.Sinv), np.ascontiguousarray(fwd.eps), t, int(mm)
        )
        out.append(g - logdet + model.n_states * LOG_2PI)
    return np.array(out)


# --- 2. the ramp MLR offline, all m in linear time ---------------------------------------------------


def augment_ramp(model: LinearGaussianModel, rows: tuple[int, ...]) -> LinearGaussianModel:
    """[x; theta; r]: theta_k = theta_{k-1} + (t_k - t_{k-1}) r_{k-1} on the attacked rows, r constant."""
    n, q, N = model.n_states, len(rows), model.n_epochs
    na = n + 2 * q
    A = np.zeros((N, na, na))
    A[:, :n, :n] = model.A.dense()
    A[:, n : n + q, n : n + q] = np.eye(q)
    A[:, n + q :, n + q :] = np.eye(q)
    dt = np.r_[0.0, np.diff(model.t)]
    A[:, n : n + q, n + q :] = dt[:, None, None] * np.eye(q)
    Q = np.zeros((N, na, na))
    Q[:, :n, :n] = model.Q.dense()
    C = np.zeros((N, model.n_measurements, na))
    C[:, :, :n] = model.C
    for j, r in enumerate(rows):
        C[:, r, n + j] = 1.0
    P0 = np.zeros((na, na))
    P0[:n, :n] = model.P0
    names = (*model.state_names, *[f"theta_{r}" for r in rows], *[f"rate_{r}" for r in rows])
    return LinearGaussianModel(
        model.t,
        BlockDiagonal.full(A),
        BlockDiagonal.full(Q),
        C,
        model.R,
        model.y,
        np.r_[model.x0, np.zeros(2 * q)],
        P0,
        names,
        model.measurement_names,
    )


@njit(cache=True)
def _offline_at(
    mu: np.ndarray, P: np.ndarray, L: np.ndarray, a: np.ndarray, n: int, q: int, Sigma: np.ndarray, first: int
) -> tuple[float, float]:
    """(2 log BF, flat MLR) of a jump after one epoch from its forward estimate N(mu, P) and the backward
    information (L, a) of the data after it; the jumping states are the q from `first` (-1: n + q).

    With X = I + P L, b = a - L mu and B the jumping states' selector, 2 log of the integral of
    N(x; mu, P) exp(-x^T L x / 2 + a^T x) is -log det X + b^T X^-1 P b - mu^T L mu + 2 a^T mu (P may be
    singular); a jump x -> x + B d, d ~ N(0, Sigma), makes P into P + B Sigma B^T. Both figures need only
    X^-1 and q x q matrices: with J = B^T L X^-1 B, the determinant lemma and Woodbury's identity give
    2 log BF = -log det(I + J Sigma) + u^T Sigma B^T b - u^T Sigma (I + J Sigma)^-1 B^T L X^-1 (P b + B Sigma B^T b),
    u = (X^-1 B)^T b, and the flat MLR (d maximised, density 1 per unit^q) -log det J + u^T J^-1 (B^T b -
    B^T L X^-1 P b) + q log 2 pi: one inverse of X per candidate where each form written out takes five
    factorisations and as many products of (n + q)-square matrices."""
    na = mu.shape[0]
    j0 = n + q if first < 0 else first
    X = P @ L
    for i in range(na):
        X[i, i] += 1.0
    Xi = np.linalg.inv(X)
    b = a - L @ mu
    s = Xi @ (P @ b)  # X^-1 P b
    XiB = np.ascontiguousarray(Xi[:, j0 : j0 + q])
    BL = np.ascontiguousarray(L[j0 : j0 + q])  # B^T L (L symmetric)
    J = BL @ XiB
    u = XiB.T @ b
    Bb = np.ascontiguousarray(b[j0 : j0 + q])
    SBb = Sigma @ Bb
    h = BL @ (s + XiB @ SBb)  # B^T L X^-1 (P b + B Sigma B^T b)
    M = J @ Sigma
    for i in range(q):
        M[i, i] += 1.0
    _, ld_m = np.linalg.slogdet(M)
    bf = -ld_m + u @ SBb - u @ (Sigma @ np.linalg.solve(M, h))
    sJ, ldJ = np.linalg.slogdet(J)
    if sJ <= 0:
        return bf, np.nan
    v = Bb - BL @ s
    return bf, -ldJ + u @ np.linalg.solve(J, v) + q * 1.8378770664093453


@dataclass(frozen=True)
class RampOffline:
    t: FloatArray  # onset candidates: the ramp starts after epoch m (at t[m])
    log_bf: FloatArray  # 2 log BF(m), proper prior
    mlr_flat: FloatArray  # flat-prior MLR (density 1 per (m/s)^q): the paper's l_N(m)


@njit(cache=True)
def _augmented_into(
    A_head: np.ndarray,
    A_tail: np.ndarray,
    Q_head: np.ndarray,
    Q_tail: np.ndarray,
    C: np.ndarray,
    n: int,
    q: int,
    rows: np.ndarray,
    dt: float,
    ramp: bool,
    Aa: np.ndarray,
    Qa: np.ndarray,
    Ca: np.ndarray,
) -> None:
    """One epoch of `augment_ramp` (ramp) or `augment_step` (not ramp) from the model's blocks, written into
    Aa, Qa, Ca: the same numbers, built when needed rather than stored for every epoch (three (N, na, na)
    arrays: 0.6 GB per hour at 10 Hz). The three are zero wherever it writes nothing (zeros made once, or
    an earlier epoch's: the passes over every epoch fill the same three, not ~16 kB of new zeros each)."""
    na = Aa.shape[0]
    h = A_head.shape[0]
    Aa[:h, :h] = A_head
    Qa[:h, :h] = Q_head
    for i in range(n - h):
        Aa[h + i, h + i] = A_tail[i]
        Qa[h + i, h + i] = Q_tail[i]
    Ca[:, :n] = C
    for j in range(na - n):
        Aa[n + j, n + j] = 1.0
    if ramp:
        for j in range(q):
            Aa[n + j, n + q + j] = dt
    for j in range(q):
        Ca[rows[j], n + j] = 1.0


def block_mask(A: BlockDiagonal) -> NDArray[np.bool_]:
    """Where the (n, n) matrices of A can be non-zero: the leading block's non-zeros and the diagonal."""
    n = A.shape[1]
    h = A.head.shape[1]
    out = np.eye(n, dtype=bool)
    out[:h, :h] = nonzero_mask(A.head)
    return out


def augmented_mask(a_mask: NDArray[np.bool_], q: int, ramp: bool) -> NDArray[np.bool_]:
    """Where `_augmented_into`'s transition can be non-zero, from where the model's can (`a_mask`)."""
    n = a_mask.shape[0]
    na = n + (2 * q if ramp else q)
    out = np.zeros((na, na), dtype=bool)
    out[:n, :n] = a_mask
    out[np.arange(n, na), np.arange(n, na)] = True
    if ramp:
        out[np.arange(n, n + q), np.arange(n + q, na)] = True
    return out


OFFLINE_BLOCK = 256  # epochs of forward estimates and backward information held at a time
# the forward estimates at the epochs evaluated are kept (not made again block by block) up to this size
OFFLINE_KEEP_BYTES = 64_000_000


@njit(cache=True)
def _forward_block(
    model: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    rows: np.ndarray,
    ramp: bool,
    x: np.ndarray,
    P: np.ndarray,
    lo: int,
    hi: int,
    xs: np.ndarray,
    Ps: np.ndarray,
    a_ptr: np.ndarray,
    a_col: np.ndarray,
    every: int = 1,
    base: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """`forward_filter`'s _forward on the augmented model over epochs lo..hi from the estimate after
    epoch lo - 1 (the prior at lo = 0); the update of each epoch k >= base * every that is a multiple of
    `every` into xs, Ps[k // every - base] when given (non-empty). `model` is (A_head, A_tail, Q_head,
    Q_tail, C, R, y, t); the augmented transitions' non-zeros are (a_ptr, a_col)."""
    A_head, A_tail, Q_head, Q_tail, C, R, y, t = model
    n, q = A_head.shape[1] + A_tail.shape[1], rows.shape[0]
    na = x.shape[0]
    Aa, Qa, Ca = np.zeros((na, na)), np.zeros((na, na)), np.zeros((C.shape[1], na))
    # the update's arrays made once; x and P copied first, so the caller's arrays are never written
    p = y.shape[1]
    observed, scratch = np.empty(p, dtype=np.int64), update_scratch(na, p)
    x, P, x_new, P_new = x.copy(), P.copy(), np.empty(na), np.empty((na, na))
    for k in range(lo, hi + 1):
        dt = t[k] - t[k - 1] if k > 0 else 0.0
        _augmented_into(A_head[k], A_tail[k], Q_head[k], Q_tail[k], C[k], n, q, rows, dt, ramp, Aa, Qa, Ca)
        if k > 0:
            x = times_vector(Aa, x, a_ptr, a_col)
            P = congruence(Aa, P, a_ptr, a_col, np.empty((na, na)))
            P += Qa
        if masked_update_into(x, P, Ca, R[k], y[k], False, observed, scratch, x_new, P_new)[0] > 0:
            x, x_new = x_new, x
            P, P_new = P_new, P
        if xs.shape[0] > 0 and k % every == 0 and k >= base * every:
            xs[k // every - base] = x
            Ps[k // every - base] = P
    return x, P


@njit(cache=True, nogil=True)
def _two_filter_offline(
    A_head: np.ndarray,
    A_tail: np.ndarray,
    Q_head: np.ndarray,
    Q_tail: np.ndarray,
    C: np.ndarray,
    R: np.ndarray,
    y: np.ndarray,
    t: np.ndarray,
    x0: np.ndarray,
    P0: np.ndarray,
    rows: np.ndarray,
    ramp: bool,
    Sigma: np.ndarray,
    last: int,
    block: int,
    stride: int,
    a_ptr: np.ndarray,
    a_col: np.ndarray,
    from_epoch: int = 0,
):
    """`_offline_at` for every `stride`-th epoch m < last from `from_epoch` on (NaN elsewhere) of the
    augmented model over epochs 0..last (the backward pass stops below `from_epoch`), from the forward
    filter (`forward_filter`) and the backward information filter (`backward_information`), with the
    numbers those give, in bounded memory: the augmented matrices are made epoch by epoch; the forward
    pass keeps only its estimate before every `block` epochs; the backward pass then runs down block by
    block, the block's forward estimates made again from its checkpoint and combined with its backward
    information (the whole forward record, gains and augmented matrices were 1.5 GB per hour of 10 Hz
    GNSS; this holds two blocks). When the epochs evaluated are few (a curve every tenth epoch),
    `_forward_kept`, `_backward_kept` and `_offline_kept` give the same numbers, the two passes side by
    side and none made again."""
    n, q = x0.shape[0], rows.shape[0]
    model = (A_head, A_tail, Q_head, Q_tail, C, R, y, t)
    na = n + (2 * q if ramp else q)
    first = -1 if ramp else n
    N = last + 1
    nb = (N + block - 1) // block
    # forward pass: the estimate after epoch b * block - 1 (the prior for block 0)
    ck_x = np.zeros((nb, na))
    ck_P = np.zeros((nb, na, na))
    x, P = _augmented_prior(x0, P0, na)
    nothing_x, nothing_P = np.zeros((0, na)), np.zeros((0, na, na))
    for b in range(nb):
        ck_x[b] = x
        ck_P[b] = P
        if b < nb - 1:
            hi = min((b + 1) * block, N) - 1
            x, P = _forward_block(model, rows, ramp, x, P, b * block, hi, nothing_x, nothing_P, a_ptr, a_col)
    bf = np.full(N, np.nan)
    flat = np.full(N, np.nan)
    xs = np.zeros((block, na))
    Ps = np.zeros((block, na, na))
    Ls = np.zeros((block, na, na))
    als = np.zeros((block, na))
    L = np.zeros((na, na))
    a = np.zeros(na)
    Aa, Qa, Ca = np.zeros((na, na)), np.zeros((na, na)), np.zeros((C.shape[1], na))
    for b in range(nb - 1, -1, -1):
        lo, hi = b * block, min((b + 1) * block, N) - 1
        if hi < from_epoch:
            break
        _forward_block(model, rows, ramp, ck_x[b].copy(), ck_P[b].copy(), lo, hi, xs, Ps, a_ptr, a_col, 1, lo)
        for k in range(hi, lo - 1, -1):
            Ls[k - lo] = L
            als[k - lo] = a
            if k == 0:
                break
            L, a = _information_back(model, n, q, rows, ramp, k, L, a, Aa, Qa, Ca, a_ptr, a_col)
        top = hi if hi < N - 1 else hi - 1  # the last epoch has no data after it
        for k in range(max(lo, from_epoch), top + 1):
            if k % stride == 0:
                bf[k], flat[k] = _offline_at(xs[k - lo], Ps[k - lo], Ls[k - lo], als[k - lo], n, q, Sigma, first)
    return bf, flat


@njit(cache=True)
def _augmented_prior(x0: np.ndarray, P0: np.ndarray, na: int) -> tuple[np.ndarray, np.ndarray]:
    """The augmented model's prior: the model's, and the added states known to be zero."""
    n = x0.shape[0]
    x = np.zeros(na)
    x[:n] = x0
    P = np.zeros((na, na))
    P[:n, :n] = P0
    return x, P


@njit(cache=True)
def _information_back(
    model: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    n: int,
    q: int,
    rows: np.ndarray,
    ramp: bool,
    k: int,
    L: np.ndarray,
    a: np.ndarray,
    Aa: np.ndarray,
    Qa: np.ndarray,
    Ca: np.ndarray,
    a_ptr: np.ndarray,
    a_col: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """`backward_information`'s step from the information of the data after epoch k to that of the data
    after k - 1 (k >= 1), on the augmented model made into Aa, Qa, Ca."""
    A_head, A_tail, Q_head, Q_tail, C, R, y, t = model
    _augmented_into(A_head[k], A_tail[k], Q_head[k], Q_tail[k], C[k], n, q, rows, t[k] - t[k - 1], ramp, Aa, Qa, Ca)
    L, a = information_update(L, a, Ca, R[k], y[k])
    return information_predict_back(L, a, Aa, Qa, n, a_ptr, a_col)


@njit(cache=True)
def _kept_rows(n: int, q: int, ramp: bool, span: tuple[int, int, int]) -> tuple[int, int, int]:
    """(augmented states, first kept row's stride index, rows kept) of the stride-th epochs from
    `from_epoch // stride * stride` to `last` (`span` is (last, stride, from_epoch))."""
    last, stride, from_epoch = span
    base = from_epoch // stride
    return n + (2 * q if ramp else q), base, last // stride - base + 1


@njit(cache=True, nogil=True)
def _forward_kept(
    model: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    x0: np.ndarray,
    P0: np.ndarray,
    rows: np.ndarray,
    ramp: bool,
    span: tuple[int, int, int],
    pattern: tuple[np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """`_two_filter_offline`'s forward pass over epochs 0..last, its estimates kept at every stride-th
    epoch from `from_epoch // stride * stride` on (row k // stride - from_epoch // stride), for `span`
    (last, stride, from_epoch); `pattern` is (a_ptr, a_col)."""
    last, stride, _ = span
    na, base, kept = _kept_rows(x0.shape[0], rows.shape[0], ramp, span)
    xs, Ps = np.zeros((kept, na)), np.zeros((kept, na, na))
    x, P = _augmented_prior(x0, P0, na)
    _forward_block(model, rows, ramp, x, P, 0, last, xs, Ps, pattern[0], pattern[1], stride, base)
    return xs, Ps


@njit(cache=True, nogil=True)
def _backward_kept(
    model: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    n: int,
    rows: np.ndarray,
    ramp: bool,
    span: tuple[int, int, int],
    pattern: tuple[np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """`_two_filter_offline`'s backward information filter from `last` down to `from_epoch`: the
    information (L, a) of the data after every stride-th epoch, indexed as `_forward_kept` keeps them."""
    last, stride, from_epoch = span
    q = rows.shape[0]
    na, base, kept = _kept_rows(n, q, ramp, span)
    Ls, als = np.zeros((kept, na, na)), np.zeros((kept, na))
    L = np.zeros((na, na))
    a = np.zeros(na)
    Aa, Qa, Ca = np.zeros((na, na)), np.zeros((na, na)), np.zeros((model[4].shape[1], na))
    for k in range(last, from_epoch - 1, -1):
        if k % stride == 0:
            Ls[k // stride - base] = L
            als[k // stride - base] = a
        if k == 0:
            break
        L, a = _information_back(model, n, q, rows, ramp, k, L, a, Aa, Qa, Ca, pattern[0], pattern[1])
    return Ls, als


@njit(cache=True, nogil=True)
def _offline_kept(
    xs: np.ndarray,
    Ps: np.ndarray,
    Ls: np.ndarray,
    als: np.ndarray,
    n: int,
    q: int,
    Sigma: np.ndarray,
    first: int,
    span: tuple[int, int, int],
    lo: int,
    hi: int,
    bf: np.ndarray,
    flat: np.ndarray,
) -> None:
    """`_offline_at` of the kept estimates and information into bf[k], flat[k] at every stride-th epoch k
    in lo..hi - 1 that is a candidate (from `from_epoch`, below `last`: the last epoch has no data after
    it), for `span` (last, stride, from_epoch) as `_forward_kept` and `_backward_kept` kept them."""
    last, stride, from_epoch = span
    base = from_epoch // stride
    for k in range(max(lo, from_epoch), min(hi, last)):
        if k % stride == 0:
            i = k // stride - base
            bf[k], flat[k] = _offline_at(xs[i], Ps[i], Ls[i], als[i], n, q, Sigma, first)


def ramp_two_filter_offline(
    model: LinearGaussianModel,
    rows: tuple[int, ...],
    sigma_rate: FloatArray,
    last: int | None = None,
    stride: int = 1,
    first: int = 0,
) -> RampOffline:
    """2 log BF and the flat MLR for a ramp after every epoch m, using data up to epoch `last` (the
    model `augment_ramp` makes, filtered forward and backward); with `stride` > 1 only every stride-th
    candidate is evaluated (the others are left out of the result): the same numbers there, for a
    fraction of the cost (the two filters still run over every epoch). Candidates before epoch `first`
    are left out too, and the backward filter stops there (an onset sought near an alarm late in a long
    log costs one forward pass, not two filters over the whole log)."""
    return _offline(model, rows, np.asarray(sigma_rate, dtype=float), last, ramp=True, stride=stride, first=first)


def _offline(
    model: LinearGaussianModel,
    rows: tuple[int, ...],
    sigma: FloatArray,
    last: int | None,
    ramp: bool,
    stride: int = 1,
    first: int = 0,
) -> RampOffline:
    last = model.n_epochs - 1 if last is None else last
    first = min(max(0, int(first)), last)
    stride = max(1, int(stride))
    # views where the model's arrays are contiguous already (the navigation's are): no copies
    A, Q = model.A[: last + 1], model.Q[: last + 1]
    C, R, y = (kernel_array(a[: last + 1]) for a in (model.C, model.R, model.y))
    na = model.n_states + (2 if ramp else 1) * len(rows)
    kept_bytes = (last // stride - first // stride + 1) * na * (na + 1) * 8
    parts = (
        np.ascontiguousarray(A.head),
        np.ascontiguousarray(A.tail),
        np.ascontiguousarray(Q.head),
        np.ascontiguousarray(Q.tail),
        C,
        R,
        y,
        np.ascontiguousarray(model.t[: last + 1], dtype=float),
    )
    x0, P0 = prior(model)
    rows_index, Sigma = np.array(rows, dtype=np.int64), np.diag(sigma**2)
    a_ptr, a_col = pattern_of_mask(augmented_mask(block_mask(A), len(rows), ramp))
    jumping = -1 if ramp else model.n_states  # `_offline_at`'s `first`
    if 2 * kept_bytes <= OFFLINE_KEEP_BYTES:  # the estimates and the information at the epochs evaluated
        span = (last, stride, first)
        # the backward filter, twice the forward's work, on this thread: the forward one waits its turn
        # when the other threads are busy (seed 000's windowed pass, the smoother) and is taken by the
        # first of them to finish
        (Ls, als), (xs, Ps) = both(
            partial(_backward_kept, parts, model.n_states, rows_index, ramp, span, (a_ptr, a_col)),
            partial(_forward_kept, parts, x0, P0, rows_index, ramp, span, (a_ptr, a_col)),
        )
        bf, flat = np.full(last + 1, np.nan), np.full(last + 1, np.nan)
        middle = (first + last) // 2  # each half's candidates on a thread of their own
        evaluate = partial(_offline_kept, xs, Ps, Ls, als, model.n_states, len(rows), Sigma, jumping, span)
        in_parallel([partial(evaluate, first, middle, bf, flat), partial(evaluate, middle, last + 1, bf, flat)])
    else:
        bf, flat = _two_filter_offline(
            *parts, x0, P0, rows_index, ramp, Sigma, last, OFFLINE_BLOCK, stride, a_ptr, a_col, first
        )
    epochs = np.arange(last + 1)
    kept = (epochs % stride == 0) & (epochs >= first)
    return RampOffline(model.t[: last + 1][kept], bf[kept], flat[kept])


def augment_step(model: LinearGaussianModel, rows: tuple[int, ...]) -> LinearGaussianModel:
    """[x; b]: a constant offset b on the attacked rows, which jumps once (a step, a meaconer switched on)."""
    n, q, N = model.n_states, len(rows), model.n_epochs
    na = n + q
    A = np.zeros((N, na, na))
    A[:, :n, :n] = model.A.dense()
    A[:, n:, n:] = np.eye(q)
    Q = np.zeros((N, na, na))
    Q[:, :n, :n] = model.Q.dense()
    C = np.zeros((N, model.n_measurements, na))
    C[:, :, :n] = model.C
    for j, r in enumerate(rows):
        C[:, r, n + j] = 1.0
    P0 = np.zeros((na, na))
    P0[:n, :n] = model.P0
    names = (*model.state_names, *[f"step_{r}" for r in rows])
    return LinearGaussianModel(
        model.t,
        BlockDiagonal.full(A),
        BlockDiagonal.full(Q),
        C,
        model.R,
        model.y,
        np.r_[model.x0, np.zeros(q)],
        P0,
        names,
        model.measurement_names,
    )


def step_two_filter_offline(
    model: LinearGaussianModel,
    rows: tuple[int, ...],
    sigma_step: FloatArray,
    last: int | None = None,
    first: int = 0,
) -> RampOffline:
    """2 log BF of a step of the attacked rows after every epoch m (offset ~ N(0, sigma_step^2) per row),
    from one forward and one backward pass, as `ramp_two_filter_offline` does for a ramp (the model
    `augment_step` makes), candidates from epoch `first` on."""
    return _offline(model, rows, np.asarray(sigma_step, dtype=float), last, ramp=False, first=first)


def onset_posterior(
    t: FloatArray, log_bf2: FloatArray, attacks_per_hour: float, credible: float = 0.9
) -> tuple[FloatArray, float, tuple[float, float], float]:
    """Posterior over the onset (uniform onset prior at `attacks_per_hour`, plus 'no attack').

    Returns (posterior per candidate, MAP onset time, credible interval, posterior probability of an attack).
    """
    dt = np.diff(np.r_[t, t[-1] + (t[-1] - t[-2] if len(t) > 1 else 1.0)])
    log_prior = np.log(np.clip(attacks_per_hour * dt / 3600.0, 1e-300, 0.5))
    lw = np.where(np.isfinite(log_bf2), log_prior + 0.5 * log_bf2, -np.inf)
    top = max(np.max(lw), 0.0)
    w = np.exp(lw - top)
    null = np.exp(0.0 - top)  # prior odds of no attack ~ 1
    total = w.sum() + null
    post = w / max(w.sum(), 1e-300)
    k = int(np.argmax(post))
    order = np.argsort(post)[::-1]
    mass = np.cumsum(post[order])
    keep = order[: int(np.searchsorted(mass, credible) + 1)]
    return post, float(t[k]), (float(t[keep].min()), float(t[keep].max())), float(w.sum() / total)


# --- smoothing from the two filters (the paper's last equations) -------------------------------------


def two_filter_smoother(model: LinearGaussianModel) -> tuple[FloatArray, FloatArray]:
    """x_s = P (P_F^-1 x_F + Lambda_B-part), P = (P_F^-1 + Lambda_B)^-1, combining the forward filtered
    estimate with the backward information from the later data (Lambda_B = (P^B_{t|t+1})^-1)."""
    fwd = forward_filter(model)
    A, Q, C, R, y = (np.ascontiguousarray(a) for a in (model.A.dense(), model.Q.dense(), model.C, model.R, model.y))
    Lam, alpha = backward_information(A, Q, C, R, y, model.n_epochs - 1, 0)
    xs = np.zeros_like(fwd.x_upd)
    Ps = np.zeros_like(fwd.P_upd)
    for k in range(model.n_epochs):
        Pf_inv = np.linalg.inv(fwd.P_upd[k])
        Ps[k] = np.linalg.inv(Pf_inv + Lam[k])
        xs[k] = Ps[k] @ (Pf_inv @ fwd.x_upd[k] + alpha[k])
    return xs, Ps
