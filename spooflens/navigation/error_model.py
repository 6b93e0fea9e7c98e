"""The 15-state INS error model of seed 000 eq. (2), derived for our ENU mechanization.

State x = [phi (3), dv (3), dp (3), eps (3), nabla (3)]:
- phi: attitude error, the computed C~ = (I - [phi x]) C (radians, ENU axes);
- dv = v~ - v (m/s, ENU);
- dp: position error in local metres, dp = [(R_N+h) cos L dlambda, (R_M+h) dL, dh] (ENU). The paper
  uses (dL, dlambda, dh); metres keep the state well scaled and make H a plain selection;
- eps, nabla: gyro and accelerometer biases not yet removed (rad/s, m/s^2, body axes).
Continuous dynamics (first order; the 1/R^2 terms kept, the e^2 derivatives of R_M, R_N dropped):
    phi'   = -omega_in x phi + d omega_in - C eps
    dv'    = f^n x phi + C nabla - (2 omega_ie + omega_en) x dv + v x (2 d omega_ie + d omega_en) + dg
    dp'_e  = dv_e - v_e dh/(R_N+h) + v_e tanL dp_n/(R_M+h) + (v_u/(R_N+h) - tanL v_n/(R_M+h)) dp_e
    dp'_n  = dv_n - v_n dh/(R_M+h) + v_u dp_n/(R_M+h)
    dp'_u  = dv_u
with d omega_ie = [0, -W sinL, W cosL] dL, dL = dp_n/(R_M+h), and d omega_en from the transport rate;
dg_u = 2 g/R dh (free-air gradient). Versus the paper's printed blocks: F11, F12, F21, F14 = -C,
F25 = C agree; F13/F23/F32/F33 differ because our position error is in metres. F is checked against a
finite-difference Jacobian of the mechanization in tests/navigation/test_error_model.py.
Measurement: z = INS - GNSS, position (ENU metres) then velocity: H = [0 0 I 0 0; 0 I 0 0 0] (6 x 15;
the paper prints a 3 x 15 H, an erratum: its text says position AND velocity are measured).

The filter appends nine first-order Gauss-Markov states for the sensors' own slowly wandering errors
(receiver position ENU, receiver velocity ENU: real receivers' errors are time-correlated, and a filter
that takes them as white has innovations with lag-1 autocorrelation near 1; and wheel odometry's scale
and skid errors, vehicle frame), which enter their measurement rows with -I, and three measurement
rows for wheel odometry (`kernels.measurement_matrix_into`).
"""

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
