"""Seed 004's homology index of position offset vectors (POVs), Algorithm 1.

In depth: docs/methods/fleet.md."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def rotate_to_diagonal(pov: FloatArray) -> FloatArray:
    """The POVs rotated (about the origin) so that their mean vector lies at 45 degrees (steps 4-6)."""
    pov = np.asarray(pov, dtype=float)
    mean = pov.mean(axis=0)
    gamma = np.arctan2(mean[1], mean[0]) - np.pi / 4.0
    c, s = np.cos(gamma), np.sin(gamma)
    rot = np.array([[c, s], [-s, c]])  # clockwise by gamma
    out: FloatArray = pov @ rot.T
    return out


def homology_index(pov: FloatArray, ddof: int = 1, zero_tol_m: float = 1e-3, rotate: bool = True) -> float:
    """theta of a set of POVs (n, 2) in metres (eq. 2). `rotate=False` skips the rotation (the paper's own
    counter-example, to show why it is there)."""
    pov = np.asarray(pov, dtype=float)
    pov = pov[np.isfinite(pov).all(axis=1)]
    if len(pov) <= ddof:
        return float("nan")
    if np.all(np.linalg.norm(pov, axis=1) <= zero_tol_m):
        return 0.0
    r = rotate_to_diagonal(pov) if rotate else pov
    mu = r.mean(axis=0)
    sd = r.std(axis=0, ddof=ddof)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_cv = np.where(sd > 0, mu / np.where(sd > 0, sd, 1.0), np.where(mu != 0, np.inf, 0.0))
    return float(np.sum(inv_cv))


def homology_batch(pov: FloatArray, ddof: int = 1, zero_tol_m: float = 1e-3) -> FloatArray:
    """theta of many sets at once: `pov` (runs, n, 2) -> (runs,). Same rules as `homology_index`."""
    pov = np.asarray(pov, dtype=float)
    mean = pov.mean(axis=1)
    gamma = np.arctan2(mean[:, 1], mean[:, 0]) - np.pi / 4.0
    c, s = np.cos(gamma)[:, None], np.sin(gamma)[:, None]
    x = c * pov[..., 0] + s * pov[..., 1]
    y = -s * pov[..., 0] + c * pov[..., 1]
    theta = np.zeros(len(pov))
    for v in (x, y):
        mu, sd = v.mean(axis=1), v.std(axis=1, ddof=ddof)
        with np.errstate(divide="ignore", invalid="ignore"):
            theta += np.where(sd > 0, mu / np.where(sd > 0, sd, 1.0), np.where(mu != 0, np.inf, 0.0))
    zero = np.all(np.linalg.norm(pov, axis=2) <= zero_tol_m, axis=1)
    return np.where(zero, 0.0, theta)


def null_quantile(n: int, p: float, runs: int = 200_000, seed: int = 0, ddof: int = 1) -> float:
    """The (1 - p) quantile of theta for n independent isotropic Gaussian POVs (no common cause).

    theta is scale-free, so this depends on n alone: offsets that exceed it are more alike than
    independent errors make them by chance.
    """
    rng = np.random.default_rng(seed)
    theta = homology_batch(rng.normal(0.0, 1.0, (runs, n, 2)), ddof)
    return float(np.quantile(theta, 1.0 - p))
