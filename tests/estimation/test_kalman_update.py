"""The one NaN-masked Kalman update against a plain numpy update written out from the textbook."""

from __future__ import annotations

import numpy as np
import pytest

from spooflens.estimation.kalman_update import masked_update, observed_rows, update_into, update_scratch


def _plain(x: np.ndarray, P: np.ndarray, C: np.ndarray, R: np.ndarray, y: np.ndarray):
    """Textbook update on the observed rows, with numpy's own solve (no inverse kept)."""
    keep = ~np.isnan(y)
    Ck, Rk, yk = C[keep], R[np.ix_(keep, keep)], y[keep]
    S = Ck @ P @ Ck.T + Rk
    K = np.linalg.solve(S, Ck @ P).T  # P C^T S^-1, S symmetric
    e = yk - Ck @ x
    return x + K @ e, (np.eye(len(x)) - K @ Ck) @ P, e, S, float(e @ np.linalg.solve(S, e)), np.linalg.slogdet(S)[1]


def _spd(rng: np.random.Generator, n: int) -> np.ndarray:
    a = rng.normal(size=(n, n))
    return a @ a.T + n * np.eye(n)


@pytest.mark.parametrize("seed", range(20))
def test_masked_update_matches_the_plain_update(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, p = int(rng.integers(2, 16)), int(rng.integers(1, 7))
    x, P, C, R = rng.normal(size=n), _spd(rng, n), rng.normal(size=(p, n)), _spd(rng, p)
    if seed % 2:  # sparse rows, as the navigation's (2 of 24 nonzero), one of them all zeros: S sums those only
        C[rng.random((p, n)) < 0.7] = 0.0
        C[int(rng.integers(p))] = 0.0
    y = rng.normal(size=p) * 10
    y[rng.random(p) < 0.4] = np.nan
    if np.isnan(y).all():
        y[0] = 1.0
    x1, P1, rows, e, S, Sinv, K, nis, logdet = masked_update(x, P, C, R, y)
    x2, P2, e2, S2, nis2, logdet2 = _plain(x, P, C, R, y)
    np.testing.assert_array_equal(rows, np.flatnonzero(~np.isnan(y)))
    np.testing.assert_allclose(x1, x2, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(P1, P2, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(e, e2, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(S, S2, rtol=1e-12)
    np.testing.assert_allclose(Sinv @ S, np.eye(len(rows)), atol=1e-9)
    np.testing.assert_allclose(K, P @ C[rows].T @ np.linalg.inv(S2), rtol=1e-9, atol=1e-12)
    assert nis == pytest.approx(nis2, rel=1e-9) and logdet == pytest.approx(logdet2, rel=1e-9)
    np.testing.assert_allclose(P1, P1.T, atol=0)  # symmetrised


def test_nothing_observed_leaves_the_state_alone() -> None:
    rng = np.random.default_rng(0)
    x, P = rng.normal(size=4), _spd(rng, 4)
    x1, P1, rows, _e, _S, _Sinv, K, nis, logdet = masked_update(
        x, P, rng.normal(size=(3, 4)), _spd(rng, 3), np.full(3, np.nan)
    )
    assert len(rows) == 0 and K.shape == (4, 0) and np.isnan(nis) and logdet == 0.0
    np.testing.assert_array_equal(x1, x)
    np.testing.assert_array_equal(P1, P)
    np.testing.assert_array_equal(observed_rows(np.array([np.nan, 1.0, np.nan, 2.0])), [1, 3])


def test_an_innovation_covariance_that_is_not_positive_definite_takes_the_general_inverse() -> None:
    """S is inverted by Cholesky; when that fails (here R has a negative variance, so S is indefinite)
    the update still gives the textbook numbers, from the general inverse."""
    rng = np.random.default_rng(5)
    x, P, C = rng.normal(size=3), 0.01 * np.eye(3), np.eye(2, 3)
    R = np.diag([1.0, -4.0])
    y = np.array([0.5, -1.0])
    x1, P1, _rows, _e, S, Sinv, _K, nis, logdet = masked_update(x, P, C, R, y)
    x2, P2, _e2, S2, nis2, logdet2 = _plain(x, P, C, R, y)
    assert np.linalg.eigvalsh(S2).min() < 0
    np.testing.assert_allclose(Sinv @ S, np.eye(2), atol=1e-12)
    np.testing.assert_allclose(x1, x2, rtol=1e-12)
    np.testing.assert_allclose(P1, P2, rtol=1e-12, atol=1e-15)
    assert nis == pytest.approx(nis2) and logdet == pytest.approx(logdet2)


def test_without_logdet_the_determinant_is_the_cholesky_factors_or_nan_when_s_is_not_a_covariance() -> None:
    """`with_logdet` False computes no determinant beyond the Cholesky factor the inverse needs: log det S
    of a positive definite S all the same (the navigation filter's likelihood reads it), NaN for an
    indefinite S, and the update's numbers unchanged either way."""
    rng = np.random.default_rng(7)
    x, P, C, y = rng.normal(size=4), _spd(rng, 4), rng.normal(size=(3, 4)), rng.normal(size=3)
    R = _spd(rng, 3)
    full, bare = masked_update(x, P, C, R, y), masked_update(x, P, C, R, y, False)
    assert bare[8] == full[8] == pytest.approx(np.linalg.slogdet(full[4])[1], rel=1e-12)
    x, P, C, R, y = rng.normal(size=3), 0.01 * np.eye(3), np.eye(2, 3), np.diag([1.0, -4.0]), np.array([0.5, -1.0])
    full, bare = masked_update(x, P, C, R, y), masked_update(x, P, C, R, y, False)
    assert np.isfinite(full[8]) and np.isnan(bare[8])
    for a, b in zip(full[:8], bare[:8], strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("seed", range(6))
def test_an_update_into_a_filters_reused_room_equals_the_update_made_afresh(seed: int) -> None:
    """The navigation filter keeps one room for every epoch's update, sized for all its rows and holding
    the last epoch's numbers: the update of fewer rows made in it is the fresh one, bit for bit (S not
    positive definite too: the general inverse of the leading block)."""
    rng = np.random.default_rng(seed)
    n, p = 12, 9
    x, P, C, R = rng.normal(size=n), _spd(rng, n), rng.normal(size=(p, n)), _spd(rng, p)
    if seed == 5:
        R = -R  # S = C P C^T + R not positive definite
    scratch = update_scratch(n, p)
    for a in scratch:
        a[...] = 7  # another epoch's numbers
    for used in (p, 4, 1):
        y = rng.normal(size=p)
        y[rng.permutation(p)[used:]] = np.nan
        x1, P1, rows, _, S, _, K, nis, logdet = masked_update(x, P, C, R, y, False)
        x2, P2 = np.full(n, np.nan), np.full((n, n), np.nan)
        nis2, logdet2 = update_into(x, P, C, R, y, rows, len(rows), False, scratch, x2, P2)
        m = len(rows)
        assert np.array_equal(x1, x2) and np.array_equal(P1, P2)
        assert np.array_equal(S, scratch[3][:m, :m]) and np.array_equal(K, scratch[7][:, :m])
        assert nis == nis2 and (logdet == logdet2 or (np.isnan(logdet) and np.isnan(logdet2)))


@pytest.mark.parametrize("seed", range(6))
def test_the_masked_update_into_reused_room_equals_the_masked_update(seed: int) -> None:
    """The detectors' forward filter and the MLRT's forward pass update into arrays made once: each
    epoch's numbers are `masked_update`'s bit for bit, whatever the last epoch left in the room, and an
    epoch with nothing observed writes nothing."""
    from spooflens.estimation.kalman_update import masked_update_into

    rng = np.random.default_rng(seed)
    n, p = 10, 6
    x, P, C, R = rng.normal(size=n), _spd(rng, n), rng.normal(size=(p, n)), _spd(rng, p)
    if seed == 5:
        R = -R  # S not positive definite: the general inverse and numpy's determinant
    rows, scratch = np.full(p, 99, dtype=np.int64), update_scratch(n, p)
    for a in scratch:
        a[...] = 7
    x_new, P_new = np.full(n, 3.0), np.full((n, n), 3.0)
    x_prev, P_prev = x_new.copy(), P_new.copy()
    for used in (p, 3, 0, 1):
        y = rng.normal(size=p)
        y[rng.permutation(p)[used:]] = np.nan
        x1, P1, rows1, e, S, Sinv, K, nis, logdet = masked_update(x, P, C, R, y)
        m, nis2, logdet2 = masked_update_into(x, P, C, R, y, True, rows, scratch, x_new, P_new)
        assert m == len(rows1) == used
        if m == 0:
            assert np.isnan(nis2) and logdet2 == 0.0 and (x_new == x_prev).all() and (P_new == P_prev).all()
            continue
        assert np.array_equal(rows[:m], rows1) and np.array_equal(x_new, x1) and np.array_equal(P_new, P1)
        assert np.array_equal(scratch[1][:m], e) and np.array_equal(scratch[3][:m, :m], S)
        assert np.array_equal(scratch[6][:m, :m], Sinv) and np.array_equal(scratch[7][:, :m], K)
        assert nis2 == nis and logdet2 == logdet
        x_prev, P_prev = x_new.copy(), P_new.copy()
