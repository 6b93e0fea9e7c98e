"""Thinning series for display only: the analysis always runs on every sample.

A plot a few hundred pixels wide cannot show more than a few points per pixel, yet an hour of 200 Hz
data is 720,000 of them. Min/max decimation keeps, for each of `max_points / 2` buckets of consecutive
samples, the bucket's smallest and largest value, so every spike (an alarm peak, a jump) stays visible
at its height while the file stays small. All-NaN buckets stay NaN, so gaps stay gaps.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
MAX_POINTS = 2000


def minmax(t: FloatArray, y: FloatArray, max_points: int = MAX_POINTS) -> tuple[FloatArray, FloatArray]:
    """(t, y) with y of shape (N,) or (N, k), at most `max_points` rows, extremes of each bucket kept."""
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    n = len(t)
    if n <= max_points:
        return t, y
    buckets = max(max_points // 2, 1)
    starts = np.linspace(0, n, buckets + 1).astype(np.int64)[:-1]
    ends = np.r_[starts[1:], n] - 1
    with np.errstate(invalid="ignore"):
        lo = np.fmin.reduceat(y, starts, axis=0)
        hi = np.fmax.reduceat(y, starts, axis=0)
    t_out = np.empty(2 * buckets)
    t_out[0::2], t_out[1::2] = t[starts], t[ends]
    y_out = np.empty((2 * buckets, *y.shape[1:]))
    y_out[0::2], y_out[1::2] = lo, hi
    return t_out, y_out


def stride(n: int, max_points: int = MAX_POINTS) -> NDArray[np.int64]:
    """Indices of every k-th of n samples (first and last kept) for smooth curves such as tracks."""
    if n <= max_points:
        return np.arange(n)
    idx = np.linspace(0, n - 1, max_points).round().astype(np.int64)
    return np.unique(idx)
