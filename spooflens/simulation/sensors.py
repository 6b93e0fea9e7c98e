"""Sensors from truth: an IMU by inverse mechanization, GNSS fixes with a chosen noise model.

The IMU is the exact inverse of one single-sample step of `spooflens.navigation.strapdown.propagate`,
so noise-free samples fed back through the mechanization reproduce the truth (up to how much the
block structure differs from single samples: measured by the tests).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spooflens.geodesy import OMEGA_IE, normal_gravity, radii
from spooflens.navigation.imu_models import ImuGrade
from spooflens.navigation.rotations import matrix_to_quat, quat_to_rotvec, rotvec_to_matrix, skew
from spooflens.simulation.gauss_markov import gauss_markov, stationary_ar1
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
    correlated = noise.correlation_s > 0
    pos = stationary_ar1(white, float(np.exp(-dt / noise.correlation_s))) if correlated else white
    vel = rng.normal(0.0, noise.sigma_vel_mps, (n, 3))
    return pos * sigma, vel


@dataclass(frozen=True)
class ReceiverModel:
    """A receiver as real ones behave: errors with a white part and a slowly wandering first-order
    Gauss-Markov part (30-300 s), accuracies it reports that misstate its real scatter by a factor, and
    the indicators it logs beside each fix (satellites used, DOP, noise, jamming indicator, AGC, mean
    C/N0), each with its own small fluctuation. `realistic_receiver` draws one."""

    white_m: tuple[float, float] = (0.3, 0.6)  # horizontal, vertical 1 sigma
    gm_m: tuple[float, float] = (1.5, 3.0)
    gm_tau_s: float = 120.0
    vel_white_mps: float = 0.05
    vel_gm_mps: float = 0.03
    vel_tau_s: float = 5.0
    accuracy_factor: float = 3.0  # reported accuracy / real 1 sigma
    sats: float = 12.0
    hdop: float = 0.9
    noise_per_ms: float = 95.0
    jamming_indicator: float = 25.0
    agc: float = 3200.0
    cn0_dbhz: float = 41.0


def realistic_receiver(rng: np.random.Generator) -> ReceiverModel:
    """One draw of the receivers the real-world benchmark tries: correlated errors of 30-300 s, reported
    accuracies 0.2-5 times the real scatter."""
    tau = float(np.exp(rng.uniform(np.log(30.0), np.log(300.0))))
    gm_h = float(rng.uniform(0.5, 3.0))
    white_h = float(rng.uniform(0.05, 0.5))
    return ReceiverModel(
        white_m=(white_h, 2 * white_h),
        gm_m=(gm_h, 2 * gm_h),
        gm_tau_s=tau,
        vel_white_mps=float(rng.uniform(0.02, 0.1)),
        vel_gm_mps=float(rng.uniform(0.01, 0.08)),
        vel_tau_s=float(rng.uniform(1.0, 20.0)),
        accuracy_factor=float(np.exp(rng.uniform(np.log(0.2), np.log(5.0)))),
        sats=float(rng.integers(8, 16)),
        hdop=float(rng.uniform(0.6, 1.6)),
        noise_per_ms=float(rng.uniform(70.0, 120.0)),
        jamming_indicator=float(rng.uniform(5.0, 60.0)),
        agc=float(rng.uniform(1500.0, 6000.0)),
        cn0_dbhz=float(rng.uniform(36.0, 45.0)),
    )


def receiver_fix_errors(
    n: int, dt: float, model: ReceiverModel, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray, dict[str, FloatArray]]:
    """(position error ENU (n, 3), velocity error (n, 3), reported columns) of one receiver."""
    wh, wv = model.white_m
    gh, gv = model.gm_m
    pos = rng.normal(0.0, 1.0, (n, 3)) * [wh, wh, wv] + gauss_markov(n, dt, np.array([gh, gh, gv]), model.gm_tau_s, rng)
    vel = rng.normal(0.0, model.vel_white_mps, (n, 3)) + gauss_markov(
        n, dt, np.full(3, model.vel_gm_mps), model.vel_tau_s, rng
    )
    h_sigma = float(np.hypot(wh, gh))
    v_sigma = float(np.hypot(wv, gv))
    vel_sigma = float(np.hypot(model.vel_white_mps, model.vel_gm_mps))
    slow = gauss_markov(n, dt, np.ones(6), 60.0, rng)  # indicators wander a little, slowly
    sats = np.clip(np.round(model.sats + 1.5 * slow[:, 0]), 4, 32)
    hdop = np.clip(model.hdop * (1.0 + 0.1 * slow[:, 1]) * (model.sats / sats), 0.5, None)
    reported = {
        "h_acc_m": model.accuracy_factor * h_sigma * hdop / model.hdop,
        "v_acc_m": model.accuracy_factor * v_sigma * hdop / model.hdop,
        "vel_acc_mps": model.accuracy_factor * vel_sigma * (1.0 + 0.05 * slow[:, 2]),
        "sats_used": sats,
        "hdop": hdop,
        "vdop": 1.5 * hdop,
        "noise_per_ms": np.round(model.noise_per_ms * (1.0 + 0.03 * slow[:, 3]) + rng.normal(0.0, 2.0, n)),
        "jamming_indicator": np.clip(
            np.round(model.jamming_indicator + 3.0 * slow[:, 4] + rng.normal(0, 2, n)), 0, 255
        ),
        "agc": np.round(model.agc * (1.0 + 0.02 * slow[:, 5]) + rng.normal(0.0, 10.0, n)),
        "cn0_mean_dbhz": model.cn0_dbhz + 0.5 * slow[:, 0] + rng.normal(0.0, 0.3, n),
    }
    return pos, vel, reported


@dataclass(frozen=True)
class CompassModel:
    """A vessel's own heading and speed sensors as real ones are: a gyrocompass (a few tenths of a degree)
    or a magnetic compass with its residual deviation (a one-cycle curve over the heading, degrees), a
    speed log with a calibration error of some per cent, and the water the vessel moves through: a
    current with a tidal part (12.42 h) and a leeway angle. The vessel's ground track is the truth; its
    heading and speed through the water follow from it and the water's motion. `realistic_compass`
    draws one."""

    noise_deg: float = 0.3
    deviation_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)  # A + B sin(h) + C cos(h)
    talker: str = "HE"  # HE gyro, HC magnetic compass made true
    log_scale: float = 1.0  # speed log reading / true speed through the water
    log_noise_mps: float = 0.05
    current_mps: tuple[float, float] = (0.0, 0.0)  # mean east, north
    tide_mps: tuple[float, float] = (0.0, 0.0)  # tidal amplitude east, north
    tide_phase: float = 0.0
    leeway_deg: float = 0.0  # heading minus the water track's direction


TIDE_PERIOD_S = 12.42 * 3600.0


def realistic_compass(rng: np.random.Generator) -> CompassModel:
    """One draw: half gyrocompasses, half magnetic compasses with up to 3 degrees of residual deviation;
    a speed log within 8 % of the truth; currents up to 1 m/s with tides up to 1 m/s; leeway up to
    3 degrees."""
    magnetic = bool(rng.random() < 0.5)
    dev = tuple(float(x) for x in rng.uniform(-3.0, 3.0, 3)) if magnetic else (0.0, 0.0, 0.0)
    current = rng.normal(0.0, 0.5, 2)
    tide_dir = rng.uniform(0.0, 2 * np.pi)
    tide = float(rng.uniform(0.0, 1.0))
    return CompassModel(
        noise_deg=float(rng.uniform(0.5, 1.5) if magnetic else rng.uniform(0.1, 0.5)),
        deviation_deg=(dev[0], dev[1], dev[2]),
        talker="HC" if magnetic else "HE",
        log_scale=float(rng.uniform(0.92, 1.08)),
        log_noise_mps=float(rng.uniform(0.02, 0.15)),
        current_mps=(float(current[0]), float(current[1])),
        tide_mps=(tide * float(np.sin(tide_dir)), tide * float(np.cos(tide_dir))),
        tide_phase=float(rng.uniform(0.0, 2 * np.pi)),
        leeway_deg=float(rng.uniform(-3.0, 3.0)),
    )


def compass_readings(
    t: FloatArray, v_ground_en: FloatArray, model: CompassModel, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray]:
    """(true heading in degrees [0, 360), speed-log reading in m/s) at times t of a vessel whose ground
    velocity (east, north) is v_ground_en: through the water it moves at v_ground - current, its bow
    `leeway_deg` off that track."""
    tide = np.sin(2 * np.pi * t / TIDE_PERIOD_S + model.tide_phase)[:, None] * np.asarray(model.tide_mps)
    water = v_ground_en - np.asarray(model.current_mps) - tide
    h = np.degrees(np.arctan2(water[:, 0], water[:, 1])) + model.leeway_deg
    a, b, c = model.deviation_deg
    hr = np.radians(h)
    shown = h + a + b * np.sin(hr) + c * np.cos(hr) + rng.normal(0.0, model.noise_deg, len(t))
    stw = np.hypot(water[:, 0], water[:, 1]) * np.cos(np.radians(model.leeway_deg))
    log = np.clip(model.log_scale * stw + rng.normal(0.0, model.log_noise_mps, len(t)), 0.0, None)
    return shown % 360.0, log
