"""Strapdown mechanization: a noise-free IMU from simulated truth reproduces the truth."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from spooflens.navigation.kernels import local_radii
from spooflens.navigation.rotations import (
    euler_to_matrix,
    matrix_to_euler,
    matrix_to_quat,
    quat_from_rotvec,
    quat_multiply,
    quat_to_matrix,
    quat_to_rotvec,
)
from spooflens.navigation.strapdown import NavState, free_inertial, preintegrate
from spooflens.simulation.sensors import ideal_imu
from spooflens.simulation.trajectories import PROFILES, generate


@pytest.mark.parametrize(
    ("name", "seconds", "block"), [("aircraft", 600.0, 10), ("ground", 300.0, 10), ("ship", 900.0, 10)]
)
def test_noise_free_imu_reproduces_truth(name: str, seconds: float, block: int) -> None:
    truth = generate(PROFILES[name], 100.0)
    keep = truth.t <= seconds
    f, w = ideal_imu(truth)
    pre = preintegrate(truth.t[keep], f[keep], w[keep])
    s0 = NavState(0.0, truth.lat[0], truth.lon[0], truth.h[0], truth.v_enu[0].copy(), truth.C[0].copy())
    end = free_inertial(pre, s0, block)[-1]
    k = int(np.flatnonzero(keep)[-1])
    rm, rn = local_radii(truth.lat[k])
    pos = [
        (end.lon - truth.lon[k]) * (rn + end.h) * math.cos(end.lat),
        (end.lat - truth.lat[k]) * (rm + end.h),
        end.h - truth.h[k],
    ]
    att = np.linalg.norm(quat_to_rotvec(matrix_to_quat(end.C @ truth.C[k].T)))
    # stated bound, with the filter's 0.1 s blocks: 1 cm, 1 mm/s, 0.1 arcsec after up to 15 min
    assert np.max(np.abs(pos)) < 0.01
    assert np.max(np.abs(end.v - truth.v_enu[k])) < 1e-3
    assert np.degrees(att) * 3600 < 0.1


def test_coordinated_turn_has_no_sideways_specific_force() -> None:
    truth = generate(PROFILES["aircraft"], 100.0)
    f, _ = ideal_imu(truth)
    turning = (truth.t > 70) & (truth.t < 110)  # steady 3 deg/s turn
    assert np.max(np.abs(f[turning, 1])) < 0.05


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(*[st.floats(-0.5, 0.5)] * 3), min_size=1, max_size=40))
def test_preintegrated_attitude_is_the_sequential_product_of_the_rotations(
    rotvecs: list[tuple[float, float, float]],
) -> None:
    """Qb[k] = exp(w_0 dt) ... exp(w_{k-1} dt): the attitude the compiled preintegration carries."""
    theta = np.array(rotvecs)
    t = np.arange(len(theta) + 1) * 0.01
    w = np.vstack([theta / 0.01, np.zeros((1, 3))])
    pre = preintegrate(t.astype(np.float64), np.zeros_like(w), w)
    acc = np.array([1.0, 0.0, 0.0, 0.0])
    for k, q in enumerate(quat_from_rotvec(theta)):
        np.testing.assert_allclose(quat_to_matrix(pre.Qb[k]), quat_to_matrix(acc), atol=1e-12)
        acc = quat_multiply(acc, q)
    np.testing.assert_allclose(quat_to_matrix(pre.Qb[-1]), quat_to_matrix(acc), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(pre.Qb, axis=1), 1.0, atol=1e-14)


@settings(max_examples=50, deadline=None)
@given(st.floats(-3.0, 3.0), st.floats(-1.5, 1.5), st.floats(-3.1, 3.1))
def test_euler_and_quaternion_round_trips(roll: float, pitch: float, yaw: float) -> None:
    C = euler_to_matrix(roll, pitch, yaw)
    np.testing.assert_allclose(quat_to_matrix(matrix_to_quat(C)), C, atol=1e-12)
    np.testing.assert_allclose(euler_to_matrix(*matrix_to_euler(C)), C, atol=1e-9)


def test_integrals_kept_at_checkpoints_give_every_increment_bit_for_bit() -> None:
    """A long stream keeps its integrals every few samples and makes the others again from the nearest:
    increments, integrals and cut streams equal those of integrals kept at every sample, exactly."""
    truth = generate(PROFILES["aircraft"], 100.0)
    keep = truth.t <= 120.0
    f, w = ideal_imu(truth)
    f = f[keep] + np.random.default_rng(5).normal(0.0, 0.05, (int(keep.sum()), 3))  # noise: no round numbers
    dense = preintegrate(truth.t[keep], f, w[keep], every=1)
    sparse = preintegrate(truth.t[keep], f, w[keep], every=8)
    assert len(sparse.Qb) == -(-len(dense.t) // 8)
    for i, j in [(0, 1), (3, 5), (7, 8), (8, 16), (5, 300), (9, 10), (0, len(dense.t) - 1), (401, 1234), (16, 16)]:
        for a, b in zip(dense.increment(i, j), sparse.increment(i, j), strict=True):
            np.testing.assert_array_equal(a, b)
    rows = np.array([0, 1, 7, 8, 9, 30, 31, 31, 500, 2])
    for a, b in zip(dense.integrals(rows), sparse.integrals(rows), strict=True):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(dense.integrals(13), sparse.integrals(13), strict=True):
        np.testing.assert_array_equal(a, b)
    for k0, k1 in [(0, 700), (16, 900), (13, 611)]:  # a cut from a checkpoint, and from between two
        cut_dense, cut_sparse = dense.between(k0, k1), sparse.between(k0, k1)
        for i, j in [(0, 9), (3, 250), (1, k1 - k0 - 1)]:
            for a, b in zip(cut_dense.increment(i, j), cut_sparse.increment(i, j), strict=True):
                np.testing.assert_array_equal(a, b)
