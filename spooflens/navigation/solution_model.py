"""The filter's linearised error model as a LinearGaussianModel, for the model-based detectors.

The closed-loop filter corrects its nominal trajectory at every update, so its measurements z_k are
relative to a moving linearisation point. Adding back the corrections already applied, propagated
through the model (u_k = Phi_k (u_{k-1} + dx_{k-1}), u_0 = 0), gives open-loop-equivalent
measurements y_k = z_k + H u_k that follow ONE linear model: eps_k = Phi_k eps_{k-1} + w_k,
y_k = H eps_k + e_k. A plain Kalman filter on it, started at zero with P_pred[0], reproduces the
closed-loop filter's innovations and covariances exactly (tests/test_navigation_filter.py).
"""

from __future__ import annotations

import numpy as np

from spooflens.navigation.error_model import H_FULL, MEASUREMENT_NAMES, STATE_NAMES
from spooflens.navigation.loosely_coupled import NavSolution
from spooflens.statespace import LinearGaussianModel


def error_model(sol: NavSolution) -> LinearGaussianModel:
    M = len(sol.t)
    u = np.zeros((M, 15))
    for k in range(1, M):
        u[k] = sol.Phi[k] @ (u[k - 1] + sol.dx[k - 1])
    y = sol.z + u @ H_FULL.T
    y = np.where(sol.used, y, np.nan)
    return LinearGaussianModel(
        t=sol.t.copy(),
        A=sol.Phi.copy(),
        Q=sol.Qd.copy(),
        C=np.broadcast_to(H_FULL, (M, 6, 15)).copy(),
        R=sol.R.copy(),
        y=y,
        x0=np.zeros(15),
        P0=sol.P_pred[0].copy(),
        state_names=STATE_NAMES,
        measurement_names=MEASUREMENT_NAMES,
    )
