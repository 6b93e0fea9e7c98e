"""A linear Gaussian state-space model over a sequence of epochs.

The navigation filter exports its linearised error model in this form and every model-based detector
(KF innovation test, GLRT, MLRT) consumes it, so detectors never depend on INS details.

Indexing: epoch k has x_k = A[k] x_{k-1} + w_k, w_k ~ N(0, Q[k]) (A[0], Q[0] unused: x_0 ~ N(x0, P0)),
and y_k = C[k] x_k + e_k, e_k ~ N(0, R[k]). NaN entries of y[k] are missing measurements.

A and Q are held as `BlockDiagonal`: a dense leading block and a diagonal. The navigation error model
is that shape (15 inertial error states, then Gauss-Markov sensor errors that evolve each on its own),
and holding it so is 0.4 of the memory of the full matrices (0.2 GB less per hour of 10 Hz GNSS) and
less arithmetic in every filter over it; a general model is a leading block of full size and an
empty diagonal (`BlockDiagonal.full`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def kernel_array(a: FloatArray) -> FloatArray:
    """Per-epoch matrices as a compiled kernel reads them: contiguous, but a matrix broadcast over the
    epochs (stride 0: the navigation's H of a log without odometry) as it is, not copied to every epoch."""
    return a if a.ndim and a.strides[0] == 0 else np.ascontiguousarray(a)


@dataclass(frozen=True)
class BlockDiagonal:
    """Per-epoch (n, n) matrices blockdiag(head[k], diag(tail[k])): head (N, h, h), tail (N, n - h)."""

    head: FloatArray
    tail: FloatArray

    def __post_init__(self) -> None:
        N, h, h2 = self.head.shape
        if h != h2 or self.tail.ndim != 2 or self.tail.shape[0] != N:
            raise ValueError(f"BlockDiagonal: head {self.head.shape} and tail {self.tail.shape} do not fit")

    @classmethod
    def full(cls, matrices: FloatArray) -> BlockDiagonal:
        """General (N, n, n) matrices: all head, no diagonal part."""
        return cls(matrices, np.zeros((matrices.shape[0], 0)))

    @property
    def shape(self) -> tuple[int, int, int]:
        N, h, _ = self.head.shape
        n = h + self.tail.shape[1]
        return (N, n, n)

    def __len__(self) -> int:
        return int(self.head.shape[0])

    def __getitem__(self, epochs: slice) -> BlockDiagonal:
        return BlockDiagonal(self.head[epochs], self.tail[epochs])

    def at(self, k: int) -> FloatArray:
        """The (n, n) matrix of epoch k."""
        h = self.head.shape[1]
        out = np.diag(np.r_[np.zeros(h), self.tail[k]])
        out[:h, :h] = self.head[k]
        return out

    def dense(self) -> FloatArray:
        """All epochs as (N, n, n) (for the small models of tests and benchmarks)."""
        N, n, _ = self.shape
        h = self.head.shape[1]
        out = np.zeros((N, n, n))
        out[:, :h, :h] = self.head
        idx = np.arange(h, n)
        out[:, idx, idx] = self.tail
        return out


@dataclass(frozen=True)
class LinearGaussianModel:
    t: FloatArray  # (N,) epoch times, s since log start
    A: BlockDiagonal  # (N, n, n) transition into epoch k
    Q: BlockDiagonal  # (N, n, n) process noise covariance into epoch k
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
