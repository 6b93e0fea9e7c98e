"""The error model F against a finite-difference Jacobian of our own mechanization; Schuler period."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spooflens.geodesy import OMEGA_IE
from spooflens.navigation.error_model import BA, BG, DP, DV, PHI, discretise, error_dynamics
from spooflens.navigation.kernels import gravity, local_radii
from spooflens.navigation.rotations import euler_to_matrix, matrix_to_quat, quat_to_rotvec, rotvec_to_matrix
from spooflens.navigation.strapdown import NavState, free_inertial, preintegrate, propagate


def _perturb(s: NavState, dx: np.ndarray) -> NavState:
    p = s.copy()
    rm, rn = local_radii(s.lat)
    p.C = rotvec_to_matrix(-dx[PHI]) @ s.C
    p.v = s.v + dx[DV]
    p.lat = s.lat + dx[DP][1] / (rm + s.h)
    p.lon = s.lon + dx[DP][0] / ((rn + s.h) * math.cos(s.lat))
    p.h = s.h + dx[DP][2]
    p.bg = s.bg - dx[BG]  # the error state is the bias NOT yet removed
    p.ba = s.ba - dx[BA]
    return p


def _error(p: NavState, s: NavState) -> np.ndarray:
    rm, rn = local_radii(s.lat)
    dx = np.zeros(15)
    dx[PHI] = -quat_to_rotvec(matrix_to_quat(p.C @ s.C.T))
    dx[DV] = p.v - s.v
    dx[DP] = [(p.lon - s.lon) * (rn + s.h) * math.cos(s.lat), (p.lat - s.lat) * (rm + s.h), p.h - s.h]
    dx[BG] = s.bg - p.bg
    dx[BA] = s.ba - p.ba
    return dx


@pytest.mark.parametrize("speed", [0.0, 120.0])
def test_F_matches_finite_difference_jacobian_of_the_mechanization(speed: float) -> None:
    rate_hz, seconds = 200.0, 1.0
    t = np.arange(0.0, seconds + 1e-9, 1.0 / rate_hz)
    n = len(t)
    w_b = np.tile([0.02, -0.03, 0.15], (n, 1))  # turning and rolling
    f_b = np.tile([0.8, 1.5, 9.6], (n, 1))
    pre = preintegrate(t, f_b, w_b)
    C0 = euler_to_matrix(0.1, 0.05, 0.7)
    s0 = NavState(
        0.0,
        math.radians(52.0),
        math.radians(13.0),
        900.0,
        np.array([speed, 0.3 * speed, 3.0]),
        C0,
        np.array([1e-4, -2e-4, 5e-5]),
        np.array([0.01, -0.02, 0.03]),
    )
    sub = 10  # reference Phi: product of per-sub-block transitions along the nominal trajectory
    Phi_ref = np.eye(15)
    s = s0
    for i in range(0, n - 1, sub):
        j = min(i + sub, n - 1)
        F = error_dynamics(s, f_b[i] - s.ba)
        Phi_k, _ = discretise(F, np.zeros(15), t[j] - t[i])
        Phi_ref = Phi_k @ Phi_ref
        s = propagate(s, *pre.increment(i, j))

    def run(x0: NavState) -> NavState:
        return propagate(x0, *pre.increment(0, n - 1))

    nominal = run(s0)
    steps = np.r_[np.full(3, 1e-6), np.full(3, 1e-4), np.full(3, 1e-2), np.full(3, 1e-7), np.full(3, 1e-5)]
    Phi_fd = np.zeros((15, 15))
    for k in range(15):
        dx = np.zeros(15)
        dx[k] = steps[k]
        plus, minus = _error(run(_perturb(s0, dx)), nominal), _error(run(_perturb(s0, -dx)), nominal)
        Phi_fd[:, k] = (plus - minus) / (2 * steps[k])
    # compare in units where every state has its perturbation scale, so entries are comparable
    scaled_fd = Phi_fd * steps[None, :] / steps[:, None]
    scaled_ref = Phi_ref * steps[None, :] / steps[:, None]
    err = np.abs(scaled_fd - scaled_ref)
    assert np.max(err) < 2e-3 * max(1.0, np.max(np.abs(scaled_ref))), np.unravel_index(np.argmax(err), err.shape)


def test_stationary_free_inertial_oscillates_with_the_schuler_period() -> None:
    lat = math.radians(45.0)
    C = euler_to_matrix(0.0, 0.0, 0.3)
    g_up = gravity(lat, 0.0)
    w_ie_n = np.array([0.0, OMEGA_IE * math.cos(lat), OMEGA_IE * math.sin(lat)])
    rate_hz, hours = 10.0, 3.0
    t = np.arange(0.0, hours * 3600.0, 1.0 / rate_hz)
    f_b = np.tile(C.T @ np.array([0.0, 0.0, g_up]), (len(t), 1))
    w_b = np.tile(C.T @ w_ie_n, (len(t), 1))
    pre = preintegrate(t, f_b, w_b)
    s0 = NavState(0.0, lat, 0.0, 0.0, np.array([0.0, 0.1, 0.0]), C)  # 0.1 m/s north velocity error
    states = free_inertial(pre, s0, block_samples=20, hold_height=True)
    tt = np.array([s.t for s in states])
    vn = np.array([s.v[1] for s in states])
    crossings = tt[1:][np.diff(np.sign(vn)) != 0]
    period_min = 2 * np.mean(np.diff(crossings)) / 60.0
    assert period_min == pytest.approx(84.4, rel=0.02)
    assert np.max(np.abs(vn)) < 0.11  # bounded oscillation, no growth


def test_the_filters_covariance_propagation_equals_the_dense_product() -> None:
    """Phi P Phi^T for Phi = blockdiag(Phi15, diag(a)) as the filter makes it: with the bias rows of a
    discretised F (identity rows: half the products) and, for any other Phi15, by the dense form."""
    from spooflens.navigation.kernels import _propagate_blocks

    rng = np.random.default_rng(2)
    v, C = np.array([60.0, -20.0, 2.0]), euler_to_matrix(0.1, -0.2, 1.0)
    s = NavState(0.0, math.radians(47.0), math.radians(8.0), 400.0, v, C)
    Phi15, _ = discretise(error_dynamics(s, np.array([0.3, -0.1, 9.9])), np.ones(15), 0.1)
    assert np.array_equal(Phi15[9:], np.eye(15)[9:])
    G = rng.normal(size=(24, 24))
    P = 0.5 * (G @ G.T + (G @ G.T).T)  # exactly symmetric, as the filter's
    a = rng.uniform(0.9, 1.0, 9)
    for phi in (Phi15, Phi15 + 0.01 * rng.normal(size=(15, 15))):
        dense = np.zeros((24, 24))
        dense[:15, :15] = phi
        dense[15:, 15:] = np.diag(a)
        out = np.full((24, 24), np.nan)  # the filter's own room, holding the last block's product
        _propagate_blocks(P, phi, a, out, np.full((9, 24), np.nan))
        np.testing.assert_allclose(out, dense @ P @ dense.T, rtol=1e-12, atol=1e-10)
        assert np.array_equal(out, out.T)
