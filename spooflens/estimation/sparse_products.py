"""Products with structured matrices, compiled: a matrix whose zeros are the same at every epoch, and a
block-diagonal matrix (a dense leading block and a diagonal, `statespace.BlockDiagonal`).

The navigation error model's transition matrices are block-diagonal (a 15 x 15 inertial block and a
diagonal of Gauss-Markov states: 142 of 576 entries non-zero) and its measurement matrices sparser
still. Dense BLAS products of such 24 x 24 or 30 x 30 operands spend most of their time on zeros and
call overhead, so the filters that run over every epoch of a log take the union of the non-zero
entries over all epochs once (`pattern`, CSR: row i's columns are col[ptr[i]:ptr[i + 1]]) and loop
over it. The results equal the dense products (the same sums, without the zero terms).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spooflens.compile.jit import njit

IntArray = NDArray[np.int64]


def pattern(X: NDArray[np.float64]) -> tuple[IntArray, IntArray]:
    """Where any of the matrices X[k] (shape (N, r, c)) is non-zero, as CSR (ptr, col)."""
    return pattern_of_mask(nonzero_mask(X))


def nonzero_mask(X: NDArray[np.float64], block: int = 4096) -> NDArray[np.bool_]:
    """(r, c): True where any X[k] is non-zero."""
    nz = np.zeros(X.shape[1:], dtype=bool)
    for i in range(0, X.shape[0], block):  # in blocks: no (N, r, c) boolean temporary
        nz |= np.any(X[i : i + block] != 0, axis=0)
    return nz


def pattern_of_mask(nz: NDArray[np.bool_]) -> tuple[IntArray, IntArray]:
    """CSR (ptr, col) of a boolean (r, c) mask."""
    ptr = np.r_[0, np.cumsum(nz.sum(axis=1))].astype(np.int64)
    return ptr, np.nonzero(nz)[1].astype(np.int64)


@njit(cache=True, nogil=True)
def full_pattern(rows: int, cols: int) -> tuple[np.ndarray, np.ndarray]:
    """The CSR pattern of a dense (rows, cols) matrix (a product with it is the dense product)."""
    ptr = np.arange(rows + 1) * cols
    col = np.empty(rows * cols, dtype=np.int64)
    for i in range(rows):
        for j in range(cols):
            col[i * cols + j] = j
    return ptr, col


@njit(cache=True, nogil=True)
def congruence(A: np.ndarray, M: np.ndarray, ptr: np.ndarray, col: np.ndarray, out: np.ndarray) -> np.ndarray:
    """out = A M A^T for symmetric M (out symmetric to the last bit), A's non-zeros in (ptr, col)."""
    n = A.shape[0]
    m = M.shape[0]
    AM = np.zeros((n, m))
    for i in range(n):
        for z in range(ptr[i], ptr[i + 1]):
            c = col[z]
            a = A[i, c]
            for j in range(m):
                AM[i, j] += a * M[c, j]
    for i in range(n):
        for j in range(i, n):
            s = 0.0
            for z in range(ptr[j], ptr[j + 1]):
                c = col[z]
                s += AM[i, c] * A[j, c]
            out[i, j] = s
            out[j, i] = s
    return out


@njit(cache=True, nogil=True)
def congruence_t(A: np.ndarray, M: np.ndarray, ptr: np.ndarray, col: np.ndarray, out: np.ndarray) -> np.ndarray:
    """out = A^T M A for exactly symmetric M (out symmetric), A's non-zeros in (ptr, col)."""
    n = A.shape[1]
    m = M.shape[0]
    # (M A)^T = A^T M, built a row at a time: row c of A^T M gathers A[r, c] M[r, :] over A's rows r,
    # contiguous rows rather than M's and M A's columns, each entry summed in the same order as
    # (M A)[i, c] += M[i, r] A[r, c] would be (M[i, r] == M[r, i]), so the same bits
    AtM = np.zeros((n, m))
    for r in range(A.shape[0]):
        for z in range(ptr[r], ptr[r + 1]):
            c = col[z]
            a = A[r, c]
            for i in range(m):
                AtM[c, i] += M[r, i] * a
    MA = np.ascontiguousarray(AtM.T)
    out[:, :] = 0.0
    for r in range(A.shape[0]):  # A^T (M A): row r of A adds A[r, c] (M A)[r, :] to out's row c
        for z in range(ptr[r], ptr[r + 1]):
            c = col[z]
            a = A[r, c]
            for j in range(c, n):
                out[c, j] += a * MA[r, j]
    for i in range(n):
        for j in range(i + 1, n):
            out[j, i] = out[i, j]
    return out


@njit(cache=True, nogil=True)
def times(A: np.ndarray, X: np.ndarray, ptr: np.ndarray, col: np.ndarray, out: np.ndarray) -> np.ndarray:
    """out = A X for a matrix X, A's non-zeros in (ptr, col)."""
    for i in range(A.shape[0]):
        for j in range(X.shape[1]):
            out[i, j] = 0.0
        for z in range(ptr[i], ptr[i + 1]):
            c = col[z]
            a = A[i, c]
            for j in range(X.shape[1]):
                out[i, j] += a * X[c, j]
    return out


@njit(cache=True, nogil=True)
def times_vector(A: np.ndarray, x: np.ndarray, ptr: np.ndarray, col: np.ndarray) -> np.ndarray:
    """A x, A's non-zeros in (ptr, col)."""
    out = np.empty(A.shape[0])
    for i in range(A.shape[0]):
        s = 0.0
        for z in range(ptr[i], ptr[i + 1]):
            s += A[i, col[z]] * x[col[z]]
        out[i] = s
    return out


@njit(cache=True, nogil=True)
def block_times_vector(head: np.ndarray, tail: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A x for A = blockdiag(head, diag(tail))."""
    h = head.shape[0]
    out = np.empty(x.shape[0])
    for i in range(h):
        s = 0.0
        for j in range(h):
            s += head[i, j] * x[j]
        out[i] = s
    for i in range(tail.shape[0]):
        out[h + i] = tail[i] * x[h + i]
    return out


@njit(cache=True, nogil=True)
def block_times(head: np.ndarray, tail: np.ndarray, X: np.ndarray, ptr: np.ndarray, col: np.ndarray, out: np.ndarray):
    """out = A X for A = blockdiag(head, diag(tail)), head's non-zeros in (ptr, col)."""
    h = head.shape[0]
    times(head, X[:h], ptr, col, out[:h])
    for i in range(tail.shape[0]):
        for j in range(X.shape[1]):
            out[h + i, j] = tail[i] * X[h + i, j]
    return out


@njit(cache=True, nogil=True)
def block_congruence(head: np.ndarray, tail: np.ndarray, P: np.ndarray, out: np.ndarray) -> np.ndarray:
    """out = A P A^T for A = blockdiag(head, diag(tail)) and symmetric P (out exactly symmetric)."""
    h, r = head.shape[0], tail.shape[0]
    Phh = np.ascontiguousarray(P[:h, :h])
    hh = head @ Phh @ head.T
    for i in range(h):
        for j in range(i + 1):
            v = 0.5 * (hh[i, j] + hh[j, i])
            out[i, j] = v
            out[j, i] = v
    if r > 0:
        cross = head @ np.ascontiguousarray(P[:h, h:])
        for j in range(r):
            for i in range(h):
                v = cross[i, j] * tail[j]
                out[i, h + j] = v
                out[h + j, i] = v
            for i in range(r):
                out[h + i, h + j] = P[h + i, h + j] * (tail[i] * tail[j])
    return out


@njit(cache=True, nogil=True)
def add_block_diagonal(P: np.ndarray, head: np.ndarray, tail: np.ndarray) -> np.ndarray:
    """P += blockdiag(head, diag(tail)), in place."""
    h = head.shape[0]
    for i in range(h):
        for j in range(h):
            P[i, j] += head[i, j]
    for i in range(tail.shape[0]):
        P[h + i, h + i] += tail[i]
    return P
