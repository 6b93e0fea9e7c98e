"""The pattern products equal the dense ones, for the union pattern of a stack of matrices."""

from __future__ import annotations

import numpy as np
import pytest

from spooflens.estimation.sparse_products import congruence, congruence_t, full_pattern, pattern, times, times_vector


def _stack(rng: np.random.Generator, N: int, r: int, c: int) -> np.ndarray:
    """Matrices zero where a fixed mask says, plus one epoch with an extra entry (the union must hold it)."""
    X = rng.normal(size=(N, r, c)) * (rng.random((r, c)) < 0.3)
    X[N // 2, 0, c - 1] = 2.5
    return X


def test_products_over_the_union_pattern_equal_the_dense_products() -> None:
    rng = np.random.default_rng(3)
    A = _stack(rng, 7, 9, 9)
    ptr, col = pattern(A)
    assert len(col) == np.count_nonzero(np.any(A != 0, axis=0))
    M = rng.normal(size=(9, 9))
    M = M @ M.T
    X = rng.normal(size=(9, 4))
    x = rng.normal(size=9)
    for k in range(len(A)):
        out = congruence(A[k], M, ptr, col, np.empty((9, 9)))
        np.testing.assert_allclose(out, A[k] @ M @ A[k].T, rtol=1e-12, atol=1e-12)
        assert np.array_equal(out, out.T)
        out_t = congruence_t(A[k], M, ptr, col, np.empty((9, 9)))
        np.testing.assert_allclose(out_t, A[k].T @ M @ A[k], rtol=1e-12, atol=1e-12)
        assert np.array_equal(out_t, out_t.T)
        np.testing.assert_allclose(times(A[k], X, ptr, col, np.empty((9, 4))), A[k] @ X, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(times_vector(A[k], x, ptr, col), A[k] @ x, rtol=1e-12, atol=1e-12)


def test_a_rectangular_pattern_and_the_full_pattern() -> None:
    rng = np.random.default_rng(4)
    C = _stack(rng, 5, 3, 8)
    ptr, col = pattern(C)
    X = rng.normal(size=(8, 2))
    np.testing.assert_allclose(times(C[2], X, ptr, col, np.empty((3, 2))), C[2] @ X, rtol=1e-12, atol=1e-12)
    fptr, fcol = full_pattern(3, 8)
    assert list(fptr) == [0, 8, 16, 24] and list(fcol[:8]) == list(range(8))
    dense = rng.normal(size=(3, 8))
    np.testing.assert_allclose(times(dense, X, fptr, fcol, np.empty((3, 2))), dense @ X, rtol=1e-12, atol=1e-12)


def test_block_diagonal_products_equal_the_dense_products() -> None:
    from spooflens.estimation.sparse_products import (
        add_block_diagonal,
        block_congruence,
        block_times,
        block_times_vector,
    )
    from spooflens.estimation.statespace import BlockDiagonal

    rng = np.random.default_rng(6)
    blocks = BlockDiagonal(rng.normal(size=(3, 4, 4)), rng.normal(size=(3, 2)))
    assert blocks.shape == (3, 6, 6) and len(blocks[1:]) == 2
    dense = blocks.dense()
    np.testing.assert_array_equal(dense[2], blocks.at(2))
    assert np.count_nonzero(dense[0][:4, 4:]) == 0 and np.count_nonzero(dense[0][4:, 4:] - np.diag(blocks.tail[0])) == 0
    M = rng.normal(size=(6, 6))
    M = M @ M.T
    X = rng.normal(size=(6, 3))
    ptr, col = pattern(blocks.head)
    for k in range(3):
        h, t, A = blocks.head[k], blocks.tail[k], dense[k]
        np.testing.assert_allclose(block_congruence(h, t, M, np.empty((6, 6))), A @ M @ A.T, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(block_times(h, t, X, ptr, col, np.empty((6, 3))), A @ X, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(block_times_vector(h, t, X[:, 0]), A @ X[:, 0], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(add_block_diagonal(M.copy(), h, t), M + A, rtol=0, atol=0)
    with pytest.raises(ValueError, match="do not fit"):
        BlockDiagonal(np.zeros((3, 4, 4)), np.zeros((2, 2)))
