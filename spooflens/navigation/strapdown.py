"""Strapdown mechanization in the local-level ENU frame, in two rates (Savage's structure).

In depth: docs/methods/navigation.md."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from spooflens.geodesy import OMEGA_IE, radii
from spooflens.navigation import kernels
from spooflens.navigation.kernels import local_radii

FloatArray = NDArray[np.float64]


@dataclass
class NavState:
    """INS state: geodetic position (rad, rad, m), ENU velocity, attitude C_b^n, estimated IMU biases."""

    t: float
    lat: float
    lon: float
    h: float
    v: FloatArray
    C: FloatArray
    bg: FloatArray = field(default_factory=lambda: np.zeros(3))
    ba: FloatArray = field(default_factory=lambda: np.zeros(3))

    def copy(self) -> NavState:
        return NavState(
            self.t, self.lat, self.lon, self.h, self.v.copy(), self.C.copy(), self.bg.copy(), self.ba.copy()
        )

    def to_vector(self) -> FloatArray:
        """The kernels' layout: lat, lon, h, v (3), C_b^n (9, row-major), b_g (3), b_a (3), t."""
        return np.concatenate([(self.lat, self.lon, self.h), self.v, self.C.ravel(), self.bg, self.ba, (self.t,)])

    @classmethod
    def from_vector(cls, x: FloatArray) -> NavState:
        return cls(
            float(x[21]),
            float(x[0]),
            float(x[1]),
            float(x[2]),
            x[3:6].copy(),
            x[6:15].reshape(3, 3).copy(),
            x[15:18].copy(),
            x[18:21].copy(),
        )


Axes = tuple[FloatArray, FloatArray, FloatArray]


def read_only_column(c: FloatArray) -> FloatArray:
    """A contiguous float view that cannot be written. The kernels are compiled for read-only samples:
    a log whose body axes are flipped (FRD) hands them some writable columns and some read-only table
    views, and each mix of the two would be a signature compiled again (40 s for the filter loop)."""
    view = np.ascontiguousarray(c, dtype=float).view()
    view.flags.writeable = False
    return view


def axes_of(v: FloatArray | Sequence[FloatArray]) -> Axes:
    """x, y, z as three contiguous read-only float columns, from (N, 3) rows or three columns (taken as
    they are when already so: a table's own columns are not copied)."""
    cols = [v[:, j] for j in range(3)] if isinstance(v, np.ndarray) else list(v)
    x, y, z = (read_only_column(c) for c in cols)
    return x, y, z


# a stream up to this long keeps its integrals at every sample; a longer one at every CHECKPOINT_EVERY-th,
# the rest made again from the nearest when asked for (0.6 GB less for a day of 100 Hz)
DENSE_SAMPLES = 1_000_000
CHECKPOINT_EVERY = 8


@dataclass(frozen=True)
class Preintegrated:
    """High-rate integrals of one IMU stream; `increment(i, j)` gives any interval's increments.

    The integrals are kept at samples 0, every, 2 every, ... (`every` 1 for all but long streams) and
    made again from the nearest one for any other sample (`integrals`), from the samples themselves:
    the same step as the first pass, so the same numbers bit for bit."""

    t: FloatArray  # (N,) sample times
    Qb: FloatArray  # (M, 4) body attitude at t[k every] relative to the body at t[0]
    G: FloatArray  # (M, 3) cumulative velocity increment, first-body frame
    H: FloatArray  # (M, 3) cumulative integral of G, first-body frame
    f_axes: Axes  # the specific force samples (FLU), by axis: the table's columns when the body is FLU
    w_axes: Axes  # the angular rate samples (FLU), by axis
    every: int = 1

    def kernel_args(self) -> kernels.Stream:
        """What the compiled kernels take for this stream: t, the six sample columns, the integrals, every."""
        return (self.t, *self.f_axes, *self.w_axes, self.Qb, self.G, self.H, self.every)

    def increment(self, i: int, j: int) -> tuple[FloatArray, FloatArray, FloatArray, float]:
        """(dC_b (3x3), dv_b, dp_b, T) from sample i to sample j, in the body frame at t[i]."""
        dC, dv, dp, T = kernels.increment(self.kernel_args(), int(i), int(j))
        return dC, dv, dp, float(T)

    def integrals(self, rows: slice | NDArray[np.intp] | int) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(attitude (n, 4), velocity increment (n, 3), its integral (n, 3)) at `rows` (an int: one row)."""
        if self.every == 1:
            return self.Qb[rows], self.G[rows], self.H[rows]
        idx = np.arange(len(self.t))[rows]
        out = kernels.integrals_rows(self.kernel_args(), np.atleast_1d(idx).astype(np.int64))
        if np.ndim(idx) == 0:
            return out[0, 0:4], out[0, 4:7], out[0, 7:10]
        return out[:, 0:4], out[:, 4:7], out[:, 7:10]

    def f(self, rows: slice | NDArray[np.intp] = slice(None)) -> FloatArray:
        """(n, 3) specific force at `rows` (a copy of those rows only)."""
        return np.stack([a[rows] for a in self.f_axes], axis=1)

    def between(self, k0: int, k1: int) -> Preintegrated:
        """Samples k0 to k1 (exclusive): views, with integrals made again at the cut's own checkpoints
        when k0 is not one."""
        k0, k1 = max(int(k0), 0), min(int(k1), len(self.t))
        f = tuple(a[k0:k1] for a in self.f_axes)
        w = tuple(a[k0:k1] for a in self.w_axes)
        if k0 % self.every == 0:
            c0, c1 = k0 // self.every, -(-k1 // self.every)
            Qb, G, H = self.Qb[c0:c1], self.G[c0:c1], self.H[c0:c1]
        else:
            Qb, G, H = self.integrals(np.arange(k0, k1, self.every))
        return Preintegrated(self.t[k0:k1], Qb, G, H, (f[0], f[1], f[2]), (w[0], w[1], w[2]), self.every)


def preintegrate(
    t: FloatArray,
    f_b: FloatArray | Sequence[FloatArray],
    w_b: FloatArray | Sequence[FloatArray],
    every: int | None = None,
) -> Preintegrated:
    """The high-rate part over a whole IMU stream (times increasing), compiled (`kernels.preintegrate_rows`).
    `f_b` and `w_b` are (N, 3) rows or three columns each (columns are not copied); `every`: the
    checkpoints' spacing (default: 1 up to DENSE_SAMPLES samples, else CHECKPOINT_EVERY)."""
    t = read_only_column(t)
    every = every if every is not None else (1 if len(t) <= DENSE_SAMPLES else CHECKPOINT_EVERY)
    f, w = axes_of(f_b), axes_of(w_b)
    Qb, G, H = kernels.preintegrate_rows(t, *f, *w, int(every))
    return Preintegrated(t, Qb, G, H, f, w, int(every))


def rates(lat: float, h: float, v: FloatArray) -> tuple[FloatArray, FloatArray, float, float]:
    """omega_ie^n, omega_en^n (ENU), and R_M + h, R_N + h."""
    rm, rn = local_radii(lat)
    rmh, rnh = rm + h, rn + h
    ve, vn = float(v[0]), float(v[1])
    w_ie = np.array([0.0, OMEGA_IE * math.cos(lat), OMEGA_IE * math.sin(lat)])
    w_en = np.array([-vn / rmh, ve / rnh, ve * math.tan(lat) / rnh])
    return w_ie, w_en, rmh, rnh


def propagate(s: NavState, dC: FloatArray, dv_b: FloatArray, dp_b: FloatArray, T: float) -> NavState:
    """One low-rate block: the state at t + T from the block's body-frame increments."""
    return NavState.from_vector(kernels.propagate(s.to_vector(), dC, dv_b, dp_b, float(T)))


def free_inertial(pre: Preintegrated, s0: NavState, block_samples: int, hold_height: bool = False) -> list[NavState]:
    """Run the mechanization alone (no aiding) in blocks of `block_samples`; states at block ends.

    The free-inertial vertical channel is unstable (time constant sqrt(R/2g), about 9.5 min):
    `hold_height` keeps h and v_u at their initial values, as a barometer would, so the horizontal
    (Schuler) dynamics can be watched for hours.
    """
    states = [s0]
    idx = list(range(0, len(pre.t), block_samples))
    if idx[-1] != len(pre.t) - 1:
        idx.append(len(pre.t) - 1)
    s = s0
    for i, j in itertools.pairwise(idx):
        s = propagate(s, *pre.increment(i, j))
        if hold_height:
            s.h, s.v[2] = s0.h, s0.v[2]
        states.append(s)
    return states


def enu_offset(s: NavState, lat: float, lon: float, h: float) -> FloatArray:
    """ENU metres from (lat, lon, h) to the state's position (small-offset, at the state's latitude)."""
    rm, rn = radii(s.lat)
    return np.array([(s.lon - lon) * (rn + s.h) * math.cos(s.lat), (s.lat - lat) * (rm + s.h), s.h - h])
