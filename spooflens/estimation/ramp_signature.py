"""A ramp of unknown rate on chosen measurement rows, starting at an unknown epoch: its signature on
the forward filter's innovations (Willsky and Jones), shared by the GLRT and both MLRT variants.

In depth: docs/methods/mlrt.md."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spooflens.compile.jit import kernel_array, njit
from spooflens.estimation.kalman import ForwardResult
from spooflens.estimation.kalman_update import cholesky_logdet
from spooflens.estimation.sparse_products import pattern
from spooflens.estimation.statespace import LinearGaussianModel

FloatArray = NDArray[np.float64]
LOG_2PI = math.log(2 * math.pi)


@dataclass(frozen=True)
class RampStatistics:
    """Per epoch k: the best candidate onset and the statistics at it (NaN before any candidate)."""

    glr: FloatArray  # max over m of d^T I^-1 d
    glr_onset: NDArray[np.int64]  # argmax m (-1 if none)
    mlr: FloatArray  # max over m of the flat-prior MLR
    mlr_onset: NDArray[np.int64]
    log_bf: FloatArray  # max over m of 2 log BF (proper prior)
    bf_onset: NDArray[np.int64]
    log_odds: FloatArray  # log posterior odds of "a ramp began in the window" vs none (natural log)
    candidates: NDArray[np.int64]  # the candidate onset epochs


@njit(cache=True, nogil=True, inline="always")
def _quad_inv(L: np.ndarray, d: np.ndarray, w: np.ndarray) -> float:
    """d^T M^-1 d with L = chol(M): |L^-1 d|^2 (w is scratch)."""
    q = d.shape[0]
    out = 0.0
    for i in range(q):
        s = d[i]
        for c in range(i):
            s -= L[i, c] * w[c]
        w[i] = s / L[i, i]
        out += w[i] * w[i]
    return out


@njit(cache=True, nogil=True, inline="always")
def _axpy(a: float, x: np.ndarray, y: np.ndarray) -> None:
    """y += a x over contiguous slices, indexed from 0 (no negative-index wrap: the loop vectorises)."""
    for c in range(y.shape[0]):
        y[c] += a * x[c]


@njit(cache=True, nogil=True, inline="always")
def _pattern_times(
    A: np.ndarray, ptr: np.ndarray, col: np.ndarray, X: np.ndarray, out: np.ndarray, ca: int, cb: int
) -> None:
    """out[i, :, ca:cb] = (A X)[i] for every row i of A, the candidates ca..cb - 1 side by side; A's
    non-zeros in (ptr, col), summed in their order as `sparse_products.times` does."""
    for i in range(A.shape[0]):
        for j in range(X.shape[1]):
            for c in range(ca, cb):
                out[i, j, c] = 0.0
        for z in range(ptr[i], ptr[i + 1]):
            a = A[i, col[z]]
            for j in range(X.shape[1]):
                _axpy(a, X[col[z], j, ca:cb], out[i, j, ca:cb])


@njit(cache=True, nogil=True, inline="always")
def _multiply_add(x: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
    """out += x * y elementwise, as `_axpy`."""
    for c in range(out.shape[0]):
        out[c] += x[c] * y[c]


@njit(cache=True, nogil=True)
def _ramp_pass(
    A_head: np.ndarray,
    A_tail: np.ndarray,
    C: np.ndarray,
    K: np.ndarray,
    Sinv: np.ndarray,
    eps: np.ndarray,
    t: np.ndarray,
    rows: np.ndarray,
    cands: np.ndarray,
    window_s: float,
    sigma_inv: np.ndarray,
    log_sigma_det: float,
    log_prior: np.ndarray,
    min_after: int,
    a_ptr: np.ndarray,
    a_col: np.ndarray,
    c_ptr: np.ndarray,
    c_col: np.ndarray,
    used_rows: np.ndarray,
    off: int,
    glr: np.ndarray,
    glr_m: np.ndarray,
    mlr: np.ndarray,
    mlr_m: np.ndarray,
    lbf: np.ndarray,
    lbf_m: np.ndarray,
    lodds: np.ndarray,
) -> None:
    """The candidates `cands` (epochs of the log, with their `log_prior`) into the log's statistics
    (glr ... lodds, updated in place). The other arrays (the model's A and C, the forward filter's K,
    S^-1 and innovations, t, `used_rows`) hold epochs off.. of the log: every epoch within `window_s` after
    the last candidate. Candidates in increasing order, a block after another, give each epoch's
    statistics exactly as one pass over the log."""
    # All the candidates within the window of an epoch advance together, the candidate the innermost
    # (contiguous) index of every array, so each sum runs over the candidates side by side (SIMD) in
    # the order of one candidate at a time: every candidate's numbers are those of its own loop.
    # Explicit loops over the non-zero pattern of A's leading block and of C, and a hand Cholesky for the
    # q x q matrices: the navigation model's A is block-diagonal (142 of 576 entries) and BLAS/LAPACK calls
    # on 24 x 3 and 3 x 3 operands cost more in overhead than in arithmetic.
    nc = cands.shape[0]
    if nc == 0:
        return
    end = off + eps.shape[0]
    h = A_head.shape[1]
    n = h + A_tail.shape[1]
    p = C.shape[1]
    q = rows.shape[0]
    e0 = np.where(np.isnan(eps), 0.0, eps)
    # each epoch's used rows, in order: the sums below skip the others, whose gains, S^-1 and innovations
    # are zero (the same sums without their zero terms)
    B = eps.shape[0]
    used_idx = np.empty((B, p), dtype=np.int64)
    n_used = np.zeros(B, dtype=np.int64)
    for e in range(B):
        for r in range(p):
            if used_rows[e, r]:
                used_idx[e, n_used[e]] = r
                n_used[e] += 1
    mu = np.zeros((n, q, nc))
    mu_p = np.zeros((n, q, nc))
    G = np.zeros((p, q, nc))
    SG = np.zeros((p, q, nc))
    d = np.zeros((q, nc))
    info = np.zeros((q, q, nc))
    dt = np.zeros(nc)
    part = np.zeros(nc)
    dc = np.zeros(q)
    info_c = np.zeros((q, q))
    M = np.zeros((q, q))
    L = np.zeros((q, q))
    w = np.zeros(q)
    ca, cb = 0, 0  # the candidates within the window: ca..cb - 1
    k = cands[0] + 1
    while k < end:
        kb = k - off
        while cb < nc and cands[cb] < k:
            cb += 1
        while ca < cb and t[kb] - t[cands[ca] - off] > window_s:
            ca += 1
        if ca == cb:  # none: on to the next candidate's first epoch
            if cb == nc:
                break
            k = cands[cb] + 1
            continue
        for c in range(ca, cb):
            dt[c] = t[kb] - t[cands[c] - off]
        # mu_p = A mu (A block-diagonal, its head's non-zeros in a_ptr, a_col)
        _pattern_times(A_head[kb], a_ptr, a_col, mu, mu_p, ca, cb)
        for i in range(n - h):
            a = A_tail[kb, i]
            for j in range(q):
                for c in range(ca, cb):
                    mu_p[h + i, j, c] = a * mu[h + i, j, c]
        # G = E dt - C mu_p
        _pattern_times(C[kb], c_ptr, c_col, mu_p, G, ca, cb)
        for r in range(p):
            for j in range(q):
                for c in range(ca, cb):
                    G[r, j, c] = -G[r, j, c]
        for j in range(q):
            for c in range(ca, cb):
                G[rows[j], j, c] += dt[c]
        nu = n_used[kb]
        ur = used_idx[kb]
        # mu = mu_p + K G
        for i in range(n):
            for j in range(q):
                for c in range(ca, cb):
                    mu[i, j, c] = mu_p[i, j, c]
                for z in range(nu):
                    _axpy(K[kb, i, ur[z]], G[ur[z], j, ca:cb], mu[i, j, ca:cb])
        # SG = S^-1 G
        for z in range(nu):
            r = ur[z]
            for j in range(q):
                for c in range(ca, cb):
                    SG[r, j, c] = 0.0
                for z2 in range(nu):
                    _axpy(Sinv[kb, r, ur[z2]], G[ur[z2], j, ca:cb], SG[r, j, ca:cb])
        # d += SG^T eps, info += G^T SG
        for j in range(q):
            for c in range(ca, cb):
                part[c] = 0.0
            for z in range(nu):
                _axpy(e0[kb, ur[z]], SG[ur[z], j, ca:cb], part[ca:cb])
            for c in range(ca, cb):
                d[j, c] += part[c]
            for jj in range(q):
                for c in range(ca, cb):
                    part[c] = 0.0
                for z in range(nu):
                    _multiply_add(G[ur[z], j, ca:cb], SG[ur[z], jj, ca:cb], part[ca:cb])
                for c in range(ca, cb):
                    info[j, jj, c] += part[c]
        for c in range(ca, cb):  # in the candidates' order: the maxima and the odds as one at a time
            m = cands[c]
            if k - m < min_after:
                continue
            for j in range(q):
                dc[j] = d[j, c]
                for jj in range(q):
                    info_c[j, jj] = info[j, jj, c]
            logdet_i = cholesky_logdet(info_c, L)
            if math.isnan(logdet_i) or logdet_i < -700:
                continue
            g = _quad_inv(L, dc, w)
            f = g - logdet_i + q * 1.8378770664093453
            for j in range(q):
                for jj in range(q):
                    M[j, jj] = info_c[j, jj] + sigma_inv[j, jj]
            ld = cholesky_logdet(M, L)
            bq = _quad_inv(L, dc, w)
            bf = bq - (ld + log_sigma_det)
            if math.isnan(glr[k]) or g > glr[k]:
                glr[k] = g
                glr_m[k] = m
            if math.isnan(mlr[k]) or f > mlr[k]:
                mlr[k] = f
                mlr_m[k] = m
            if math.isnan(lbf[k]) or bf > lbf[k]:
                lbf[k] = bf
                lbf_m[k] = m
            v = log_prior[c] + 0.5 * bf
            top = max(lodds[k], v)
            lodds[k] = top + math.log(math.exp(lodds[k] - top) + math.exp(v - top))
        k += 1


def candidate_grid(t: FloatArray, step_s: float) -> NDArray[np.int64]:
    """Epoch indices spaced at least `step_s` apart (every epoch when the step is shorter)."""
    out = [0]
    for k in range(1, len(t)):
        if t[k] - t[out[-1]] >= step_s - 1e-9:
            out.append(k)
    return np.array(out, dtype=np.int64)


class RampPass:
    """The three statistics for every epoch of `model`, candidates every `step_s` within `window_s` of it,
    filled a block of candidates at a time from the forward filter over that block and the epochs it
    reaches (`reach`), or at once from the filter over the whole log (`whole_log`).

    A candidate m is judged only from epoch m + min_after on (the paper's L: at least L samples after it).
    Prior for the calibrated variant: ramp rate theta ~ N(0, diag(sigma_rate^2)); an onset in a candidate's
    interval with probability attacks_per_hour * interval / 3600 (so the log odds are a posterior).
    """

    def __init__(
        self,
        model: LinearGaussianModel,
        rows: tuple[int, ...],
        window_s: float,
        step_s: float,
        sigma_rate: FloatArray,
        attacks_per_hour: float,
        min_after: int = 1,
    ) -> None:
        self.model, self.window_s, self.min_after = model, float(window_s), int(min_after)
        self.t = model.t.astype(float)
        self.rows = np.array(rows, dtype=np.int64)
        self.cands = candidate_grid(self.t, step_s)
        spacing = np.diff(np.r_[self.t[self.cands], self.t[self.cands[-1]] + step_s])
        self.log_prior = np.log(np.clip(attacks_per_hour * spacing / 3600.0, 1e-300, 0.5))
        sigma = np.asarray(sigma_rate, dtype=float)
        self.sigma_inv, self.log_sigma_det = np.diag(1.0 / sigma**2), float(np.sum(np.log(sigma**2)))
        self.patterns = (*pattern(model.A.head), *pattern(model.C))  # over the whole log, as one pass
        N = model.n_epochs
        self.glr, self.mlr, self.lbf = (np.full(N, np.nan) for _ in range(3))
        self.glr_m, self.mlr_m, self.lbf_m = (np.full(N, -1) for _ in range(3))
        self.lodds = np.full(N, -np.inf)

    def reach(self, hi: int) -> int:
        """One past the last epoch the candidates before epoch `hi` read (those within the window)."""
        # a margin over the window: t[k] - t[m] <= window must never fall outside by a rounding
        return int(np.searchsorted(self.t, self.t[hi - 1] + self.window_s + 1e-6, side="right"))

    def add(self, lo: int, hi: int, fwd: ForwardResult) -> None:
        """The candidates in epochs lo..hi - 1, from `fwd`: the forward filter over epochs lo..reach(hi) - 1."""
        c0, c1 = np.searchsorted(self.cands, [lo, hi])
        end = lo + fwd.eps.shape[0]
        epochs = slice(lo, end)
        A, C = self.model.A[epochs], self.model.C[epochs]
        _ramp_pass(
            kernel_array(A.head),
            kernel_array(A.tail),
            kernel_array(C),
            kernel_array(fwd.K),
            kernel_array(fwd.Sinv),
            kernel_array(fwd.eps),
            self.t[epochs],
            self.rows,
            self.cands[c0:c1],
            self.window_s,
            self.sigma_inv,
            self.log_sigma_det,
            self.log_prior[c0:c1],
            self.min_after,
            *self.patterns,
            np.any(fwd.Sinv != 0.0, axis=2),  # the rows each epoch's update used (once, not per candidate)
            lo,
            self.glr,
            self.glr_m,
            self.mlr,
            self.mlr_m,
            self.lbf,
            self.lbf_m,
            self.lodds,
        )

    def whole_log(self, fwd: ForwardResult) -> RampStatistics:
        """The statistics from `fwd`, the forward filter over the whole log."""
        self.add(0, self.model.n_epochs, fwd)
        return self.result()

    def result(self) -> RampStatistics:
        # log odds of "some candidate" vs the no-attack prior (1 - P(attack in window) ~ 1)
        return RampStatistics(
            self.glr, self.glr_m, self.mlr, self.mlr_m, self.lbf, self.lbf_m, self.lodds, candidates=self.cands
        )
