"""A linear Gaussian state-space model over a sequence of epochs.

The navigation filter exports its linearised error model in this form and every model-based detector
(KF innovation test, GLRT, MLRT) consumes it, so detectors never depend on INS details.

Indexing: epoch k has x_k = A[k] x_{k-1} + w_k, w_k ~ N(0, Q[k]) (A[0], Q[0] unused: x_0 ~ N(x0, P0)),
and y_k = C[k] x_k + e_k, e_k ~ N(0, R[k]). NaN entries of y[k] are missing measurements.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class LinearGaussianModel:
    t: FloatArray  # (N,) epoch times, s since log start
    A: FloatArray  # (N, n, n) transition into epoch k
    Q: FloatArray  # (N, n, n) process noise covariance into epoch k
    C: FloatArray  # (N, p, n) measurement matrix
    R: FloatArray  # (N, p, p) measurement noise covariance
    y: FloatArray  # (N, p) measurements, NaN where missing
    x0: FloatArray  # (n,) prior mean of x_0
    P0: FloatArray  # (n, n) prior covariance of x_0
    state_names: tuple[str, ...] = ()
    measurement_names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        n_epochs, p = self.y.shape
        n = self.x0.shape[0]
        shapes = {
            "t": (n_epochs,),
            "A": (n_epochs, n, n),
            "Q": (n_epochs, n, n),
            "C": (n_epochs, p, n),
            "R": (n_epochs, p, p),
            "P0": (n, n),
        }
        for name, shape in shapes.items():
            if getattr(self, name).shape != shape:
                raise ValueError(f"LinearGaussianModel.{name} has shape {getattr(self, name).shape}, expected {shape}")

    @property
    def n_epochs(self) -> int:
        return int(self.y.shape[0])

    @property
    def n_states(self) -> int:
        return int(self.x0.shape[0])

    @property
    def n_measurements(self) -> int:
        return int(self.y.shape[1])

    def window(self, start: int, stop: int) -> LinearGaussianModel:
        """Epochs start..stop-1 as a model of their own (prior unchanged: caller sets it if needed)."""
        return LinearGaussianModel(
            self.t[start:stop],
            self.A[start:stop],
            self.Q[start:stop],
            self.C[start:stop],
            self.R[start:stop],
            self.y[start:stop],
            self.x0,
            self.P0,
            self.state_names,
            self.measurement_names,
        )
