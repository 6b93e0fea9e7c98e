"""The filter's linearised error model as a LinearGaussianModel, for the model-based detectors.

The closed-loop filter corrects its nominal trajectory at every update, so its measurements z_k are
relative to a moving linearisation point. Adding back the INS corrections already applied, propagated
through the model (u_k = Phi_k (u_{k-1} + dx_{k-1}), u_0 = 0, INS part only: the receiver's
Gauss-Markov error states are estimated, never fed back), gives open-loop-equivalent measurements
y_k = z_k + H_k u_k that follow ONE linear model: eps_k = Phi_k eps_{k-1} + w_k, y_k = H_k eps_k + e_k.
A plain Kalman filter on it, started at zero with P_pred[0], reproduces the closed-loop filter's
innovations and covariances exactly (tests/test_navigation_filter.py).
"""

from __future__ import annotations

import numpy as np

from spooflens.navigation.error_model import MEASUREMENT_NAMES, STATE_NAMES
from spooflens.navigation.loosely_coupled import NavSolution
from spooflens.statespace import LinearGaussianModel


def error_model(sol: NavSolution) -> LinearGaussianModel:
    M, n = sol.dx.shape
    applied = sol.dx.copy()
    applied[:, 15:] = 0.0
    u = np.zeros((M, n))  # the Gauss-Markov part stays zero: nothing is applied there
    head = sol.Phi.head
    h = head.shape[1]
    for k in range(1, M):
        u[k, :h] = head[k] @ (u[k - 1, :h] + applied[k - 1, :h])
    y = sol.z + np.einsum("kij,kj->ki", sol.H, u)
    y = np.where(sol.used, y, np.nan)
    return LinearGaussianModel(
        # the solution's own arrays, not copies (166 MB each per hour of 10 Hz GNSS): nothing writes them
        t=sol.t,
        A=sol.Phi,
        Q=sol.Qd,
        C=sol.H,
        R=sol.R,
        y=y,
        x0=np.zeros(n),
        P0=sol.P_pred[0].copy(),
        state_names=STATE_NAMES,
        measurement_names=MEASUREMENT_NAMES,
    )
