"""IMU noise grades: what the filter's Q and P0 are made of, and what the simulator draws.

White noise as angle / velocity random walk; biases as a turn-on value (initial uncertainty) plus a
random walk whose strength comes from the bias instability over a correlation time. Units are SI
(rad, m, s) internally; presets are written in the units data sheets and papers use.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

DEG = np.pi / 180.0
HOUR = 3600.0
UG = 9.80665e-6  # one micro-g in m/s^2
ARCSEC = DEG / 3600.0


@dataclass(frozen=True)
class ImuGrade:
    name: str
    gyro_arw: float  # rad/sqrt(s)
    accel_vrw: float  # m/s/sqrt(s)
    gyro_bias_sigma: float  # rad/s, turn-on bias uncertainty (P0)
    accel_bias_sigma: float  # m/s^2
    gyro_bias_rw: float  # rad/s/sqrt(s), bias random walk
    accel_bias_rw: float  # m/s^2/sqrt(s)
    position_noise: float = 0.0  # m/sqrt(s): extra process noise on position (seed 000 uses 1 m/sqrt(h))
    attitude_sigma0: tuple[float, float, float] = (2 * DEG, 2 * DEG, 5 * DEG)  # rad, initial (E, N, U)
    velocity_sigma0: float = 0.5  # m/s
    position_sigma0: tuple[float, float, float] = (5.0, 5.0, 10.0)  # m
    source: str = ""

    def with_initial(
        self, attitude: tuple[float, float, float], velocity: float, position: tuple[float, float, float]
    ) -> ImuGrade:
        return replace(self, attitude_sigma0=attitude, velocity_sigma0=velocity, position_sigma0=position)

    def qc_diagonal(self) -> np.ndarray:
        """Continuous-time white-noise spectral densities of the 15 error states."""
        return np.concatenate(
            [
                np.full(3, self.gyro_arw**2),
                np.full(3, self.accel_vrw**2),
                np.full(3, self.position_noise**2),
                np.full(3, self.gyro_bias_rw**2),
                np.full(3, self.accel_bias_rw**2),
            ]
        )

    def p0_diagonal(self) -> np.ndarray:
        return np.concatenate(
            [
                np.square(self.attitude_sigma0),
                np.full(3, self.velocity_sigma0**2),
                np.square(self.position_sigma0),
                np.full(3, self.gyro_bias_sigma**2),
                np.full(3, self.accel_bias_sigma**2),
            ]
        )


def _bias_rw(instability: float, correlation_time_s: float) -> float:
    """Random-walk strength that reaches `instability` after one correlation time."""
    return instability / np.sqrt(correlation_time_s)


PRESETS: dict[str, ImuGrade] = {
    # Seed 000 section 4: Q = diag(0.005 deg/sqrt(h) x3, 20 ug/sqrt(Hz) x3, 1 m/sqrt(h) x3, 0 x6)^2,
    # P0 = diag(20", 20", 180", 0.1 m/s, 3.7/3.7/6 m, 0.01 deg/h, 100 ug) x 3^2 (the paper's x3^2 on
    # variances, i.e. 3-sigma values). Biases are random constants (no random walk), as in the paper.
    "seed000": ImuGrade(
        "seed000",
        gyro_arw=0.005 * DEG / np.sqrt(HOUR),
        accel_vrw=20 * UG,
        gyro_bias_sigma=3 * 0.01 * DEG / HOUR,
        accel_bias_sigma=3 * 100 * UG,
        gyro_bias_rw=0.0,
        accel_bias_rw=0.0,
        position_noise=1.0 / np.sqrt(HOUR),
        attitude_sigma0=(3 * 20 * ARCSEC, 3 * 20 * ARCSEC, 3 * 180 * ARCSEC),
        velocity_sigma0=3 * 0.1,
        position_sigma0=(3 * 3.7, 3 * 3.7, 3 * 6.0),
        source="seed 000, section 4",
    ),
    # Seed 001's two INS grades: accelerometer bias 10 ug / gyro drift 0.1 deg/h (N1) and 50 ug / 0.5 deg/h
    # (N2). Noise densities are not printed: navigation-grade values matching those biases are assumed.
    "seed001_n1": ImuGrade(
        "seed001_n1",
        gyro_arw=0.01 * DEG / np.sqrt(HOUR),
        accel_vrw=10 * UG,
        gyro_bias_sigma=0.1 * DEG / HOUR,
        accel_bias_sigma=10 * UG,
        gyro_bias_rw=_bias_rw(0.01 * DEG / HOUR, HOUR),
        accel_bias_rw=_bias_rw(1 * UG, HOUR),
        attitude_sigma0=(10 * ARCSEC, 10 * ARCSEC, 60 * ARCSEC),
        velocity_sigma0=0.1,
        position_sigma0=(3.0, 3.0, 5.0),
        source="seed 001, Table 5 grade N1",
    ),
    "seed001_n2": ImuGrade(
        "seed001_n2",
        gyro_arw=0.05 * DEG / np.sqrt(HOUR),
        accel_vrw=50 * UG,
        gyro_bias_sigma=0.5 * DEG / HOUR,
        accel_bias_sigma=50 * UG,
        gyro_bias_rw=_bias_rw(0.05 * DEG / HOUR, HOUR),
        accel_bias_rw=_bias_rw(5 * UG, HOUR),
        attitude_sigma0=(30 * ARCSEC, 30 * ARCSEC, 300 * ARCSEC),
        velocity_sigma0=0.1,
        position_sigma0=(3.0, 3.0, 5.0),
        source="seed 001, Table 5 grade N2",
    ),
    # A consumer MEMS IMU (phone / small drone class, e.g. Bosch BMI088 / TDK ICM-42688 data sheets:
    # gyro noise ~0.004-0.014 deg/s/sqrt(Hz), accel ~70-190 ug/sqrt(Hz), bias instability ~2-10 deg/h
    # and 40-100 ug after turn-on residuals of ~0.5 deg/s and ~50 mg that a static calibration removes).
    "consumer_mems": ImuGrade(
        "consumer_mems",
        gyro_arw=0.3 * DEG / np.sqrt(60.0),
        accel_vrw=0.05 / np.sqrt(60.0),
        gyro_bias_sigma=0.05 * DEG,
        accel_bias_sigma=0.05,
        gyro_bias_rw=_bias_rw(10 * DEG / HOUR, 300.0),
        accel_bias_rw=_bias_rw(100 * UG, 300.0),
        attitude_sigma0=(2 * DEG, 2 * DEG, 10 * DEG),
        velocity_sigma0=0.5,
        position_sigma0=(5.0, 5.0, 10.0),
        source="consumer MEMS data-sheet class",
    ),
    # A tactical-grade IMU (fibre-optic gyro class): 1 deg/h, 1 mg.
    "tactical": ImuGrade(
        "tactical",
        gyro_arw=0.1 * DEG / np.sqrt(HOUR),
        accel_vrw=0.03 / np.sqrt(HOUR),
        gyro_bias_sigma=1 * DEG / HOUR,
        accel_bias_sigma=1e-3 * 9.80665,
        gyro_bias_rw=_bias_rw(0.1 * DEG / HOUR, HOUR),
        accel_bias_rw=_bias_rw(50 * UG, HOUR),
        attitude_sigma0=(0.1 * DEG, 0.1 * DEG, 1 * DEG),
        velocity_sigma0=0.2,
        position_sigma0=(3.0, 3.0, 5.0),
        source="tactical-grade class",
    ),
}


def grade(name: str) -> ImuGrade:
    try:
        return PRESETS[name]
    except KeyError:
        raise KeyError(f"unknown IMU grade {name!r}; presets are {sorted(PRESETS)}") from None


def from_ros_covariances(gyro_var: float, accel_var: float, rate_hz: float, base: str = "consumer_mems") -> ImuGrade:
    """A grade whose white noise comes from a ROS Imu's per-sample covariances (variances per sample)."""
    b = grade(base)
    return replace(
        b,
        name=f"ros_covariance({base})",
        gyro_arw=float(np.sqrt(gyro_var / rate_hz)),
        accel_vrw=float(np.sqrt(accel_var / rate_hz)),
        source="ROS Imu covariances + " + b.source,
    )
