"""The 15-state INS error model of seed 000 eq. (2), derived for our ENU mechanization.

In depth: docs/methods/navigation.md."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spooflens.navigation import kernels
from spooflens.navigation.strapdown import NavState

FloatArray = NDArray[np.float64]
STATE_NAMES = (
    "phi_e",
    "phi_n",
    "phi_u",
    "dv_e",
    "dv_n",
    "dv_u",
    "dp_e",
    "dp_n",
    "dp_u",
    "bg_x",
    "bg_y",
    "bg_z",
    "ba_x",
    "ba_y",
    "ba_z",
    "gnss_pos_err_e",
    "gnss_pos_err_n",
    "gnss_pos_err_u",
    "gnss_vel_err_e",
    "gnss_vel_err_n",
    "gnss_vel_err_u",
    "odo_err_x",
    "odo_err_y",
    "odo_err_z",
)
MEASUREMENT_NAMES = ("pos_e", "pos_n", "pos_u", "vel_e", "vel_n", "vel_u", "odo_x", "odo_y", "odo_z")
PHI, DV, DP, BG, BA = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15)
GM_POS, GM_VEL, GM_ODO = slice(15, 18), slice(18, 21), slice(21, 24)
POS_ROWS, VEL_ROWS, ODO_ROWS = slice(0, 3), slice(3, 6), slice(6, 9)


def error_dynamics(s: NavState, f_b: FloatArray) -> FloatArray:
    """F (15 x 15) at state `s` with body specific force `f_b` (bias-compensated)."""
    return kernels.error_dynamics(s.to_vector(), np.asarray(f_b, dtype=float))


def discretise(F: FloatArray, qc: FloatArray, T: float) -> tuple[FloatArray, FloatArray]:
    """Phi = I + F T + (F T)^2 / 2 and Qd by the trapezoid (Phi Qc Phi^T + Qc) T / 2.

    Noise enters the attitude and velocity errors through -C and C; with isotropic white noise per
    sensor that rotation leaves the covariance unchanged, so Qc is diagonal in the error state.
    """
    return kernels.discretise(np.ascontiguousarray(F), np.asarray(qc, dtype=float), float(T))
