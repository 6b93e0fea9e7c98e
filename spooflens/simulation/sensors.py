"""Sensors from truth: an IMU by inverse mechanization, GNSS fixes with a chosen noise model.

The IMU is the exact inverse of one single-sample step of `spooflens.navigation.strapdown.propagate`,
so noise-free samples fed back through the mechanization reproduce the truth (up to how much the
block structure differs from single samples: measured by the tests).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from spooflens.geodesy import OMEGA_IE, normal_gravity, radii
from spooflens.navigation.imu_models import ImuGrade
from spooflens.navigation.rotations import matrix_to_quat, quat_to_rotvec, rotvec_to_matrix, skew
from spooflens.simulation.trajectories import Truth

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ImuSamples:
    t: FloatArray
    f_b: FloatArray  # specific force, FLU body, m/s^2
    w_b: FloatArray  # angular rate, FLU body, rad/s
    gyro_bias: FloatArray  # (N, 3) the bias actually in the samples (truth for tests)
    accel_bias: FloatArray


def ideal_imu(truth: Truth) -> tuple[FloatArray, FloatArray]:
    """Noise-free specific force and angular rate (FLU) that reproduce `truth` sample by sample."""
    t, lat, h, v, C = truth.t, truth.lat, truth.h, truth.v_enu, truth.C
    dt = np.diff(t)
    v_mid = 0.5 * (v[1:] + v[:-1])
    lat_mid = 0.5 * (lat[1:] + lat[:-1])
    h_mid = 0.5 * (h[1:] + h[:-1])
    rm, rn = radii(lat_mid)
    w_ie = np.stack([np.zeros_like(lat_mid), OMEGA_IE * np.cos(lat_mid), OMEGA_IE * np.sin(lat_mid)], -1)
    w_en = np.stack(
        [-v_mid[:, 1] / (rm + h_mid), v_mid[:, 0] / (rn + h_mid), v_mid[:, 0] * np.tan(lat_mid) / (rn + h_mid)], -1
    )
    zeta = (w_ie + w_en) * dt[:, None]
    # body rotation: C_{k+1} = exp(-zeta) C_k dC_b  =>  dC_b = C_k^T exp(zeta) C_{k+1}
    dC = np.swapaxes(C[:-1], -1, -2) @ rotvec_to_matrix(zeta) @ C[1:]
    theta = quat_to_rotvec(matrix_to_quat(dC))
    g = np.zeros_like(v_mid)
    g[:, 2] = -normal_gravity(lat_mid, h_mid)
    acc = g - np.cross(2 * w_ie + w_en, v_mid)
    dv_n = v[1:] - v[:-1] - acc * dt[:, None]
    # v_{k+1} = v_k + (I - 1/2 [zeta x]) C_k dv_b + acc dt,  dv_b = (I + 1/2 [theta x]) f dt
    eye = np.eye(3)
    dv_b = np.swapaxes(C[:-1], -1, -2) @ np.linalg.solve(eye - 0.5 * skew(zeta), dv_n[..., None])
    f = np.linalg.solve(eye + 0.5 * skew(theta), dv_b)[..., 0] / dt[:, None]
    w = theta / dt[:, None]
    # the last sample has no interval after it: repeat the previous one
    return np.vstack([f, f[-1:]]), np.vstack([w, w[-1:]])


def noisy_imu(truth: Truth, grade: ImuGrade, rng: np.random.Generator) -> ImuSamples:
    """The ideal IMU plus white noise (ARW, VRW), turn-on biases and bias random walks."""
    f, w = ideal_imu(truth)
    n = len(truth.t)
    dt = float(np.median(np.diff(truth.t)))
    bg = rng.normal(0.0, grade.gyro_bias_sigma, 3) + np.cumsum(
        rng.normal(0.0, grade.gyro_bias_rw * np.sqrt(dt), (n, 3)), axis=0
    )
    ba = rng.normal(0.0, grade.accel_bias_sigma, 3) + np.cumsum(
        rng.normal(0.0, grade.accel_bias_rw * np.sqrt(dt), (n, 3)), axis=0
    )
    w_noisy = w + bg + rng.normal(0.0, grade.gyro_arw / np.sqrt(dt), (n, 3))
    f_noisy = f + ba + rng.normal(0.0, grade.accel_vrw / np.sqrt(dt), (n, 3))
    return ImuSamples(truth.t, f_noisy, w_noisy, bg, ba)


@dataclass(frozen=True)
class GnssNoise:
    """Fix errors: white (correlation_s = 0) or first-order Gauss-Markov with that correlation time."""

    sigma_enu_m: tuple[float, float, float] = (3.7, 3.7, 6.0)  # seed 000's R
    sigma_vel_mps: float = 0.1
    correlation_s: float = 0.0


def gnss_errors(n: int, dt: float, noise: GnssNoise, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """(position error ENU (n, 3), velocity error (n, 3)) with the stationary standard deviations given."""
    sigma = np.asarray(noise.sigma_enu_m, dtype=float)
    white = rng.normal(0.0, 1.0, (n, 3))
    if noise.correlation_s > 0:
        a = np.exp(-dt / noise.correlation_s)
        s = np.sqrt(1.0 - a * a)
        # x_k = a x_{k-1} + s w_k, started stationary (x_0 = w_0)
        pos, _ = lfilter([s], [1.0, -a], white, axis=0, zi=((1.0 - s) * white[0])[None, :])
    else:
        pos = white
    vel = rng.normal(0.0, noise.sigma_vel_mps, (n, 3))
    return pos * sigma, vel
