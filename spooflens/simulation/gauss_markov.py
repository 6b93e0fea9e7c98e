"""First-order Gauss-Markov noise, the one time-correlated error model of the simulated sensors, receivers
and attacks (a receiver's solution error, a sky's slow wander, a jammed fix's drift)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def stationary_ar1(white: FloatArray, a: float) -> FloatArray:
    """x_k = a x_(k-1) + sqrt(1 - a^2) w_k along axis 0 from unit white noise `white`, started stationary
    (x_0 = w_0): unit variance throughout."""
    from scipy.signal import lfilter  # imported when noise is made: scipy.signal takes over a second to load

    s = np.sqrt(1.0 - a * a)
    x, _ = lfilter([s], [1.0, -a], white, axis=0, zi=((1.0 - s) * white[0])[None, ...])
    return np.asarray(x, dtype=float)


def gauss_markov(n: int, dt: float, sigma: FloatArray | float, tau: float, rng: np.random.Generator) -> FloatArray:
    """n samples `dt` apart of first-order Gauss-Markov series of standard deviation `sigma` (one series, or
    one per element of an array) and correlation time `tau`, started stationary."""
    shape = (n,) if np.ndim(sigma) == 0 else (n, len(np.atleast_1d(sigma)))
    return stationary_ar1(rng.normal(0.0, 1.0, shape), float(np.exp(-dt / tau))) * sigma
