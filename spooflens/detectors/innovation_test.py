"""Kalman-filter innovation test (seed 000's first competitor): NIS of the position innovation.

Under no attack the position innovation's NIS is chi-square with 3 degrees of freedom; seed 000 uses
the threshold 25.9, which is chi2(3) at P_FA = 1e-5 per epoch.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spooflens.detectors.kalman import ForwardResult
from spooflens.navigation.loosely_coupled import quadratic_forms
from spooflens.quantiles import chi2_isf

FloatArray = NDArray[np.float64]


def threshold(p_false_alarm: float = 1e-5, dof: int = 3) -> float:
    return float(chi2_isf(p_false_alarm, dof))


def position_nis(fwd: ForwardResult, rows: tuple[int, ...] = (0, 1, 2)) -> FloatArray:
    """eps_p^T S_pp^-1 eps_p per epoch (NaN where the position was not measured)."""
    idx = np.array(rows)
    return quadratic_forms(fwd.eps[:, idx], fwd.S[:, idx][:, :, idx])
