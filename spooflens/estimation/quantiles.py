"""The few distribution functions every analysis needs, from scipy.special.

They are the functions scipy.stats' chi-square, t, F and normal distributions evaluate underneath
(`chi2.isf` is `chdtri`, `t.isf` is -`stdtrit`, `f.isf` is `fdtri` of 1 - p, `halfnorm.ppf` is
`ndtri((1 + q) / 2)`), called directly: importing scipy.stats takes about a second, which every
analysis of a small log paid. The detectors that need rarer distributions (noncentral chi-square and
t, Rayleigh, Rice) import scipy.stats where they use it.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special


def chi2_isf(p: ArrayLike, dof: ArrayLike) -> NDArray[np.float64]:
    """x with P(chi2(dof) > x) = p (scipy.stats.chi2.isf)."""
    return np.asarray(special.chdtri(np.asarray(dof, dtype=np.float64), np.asarray(p, dtype=np.float64)))


def f_isf(p: float, dfn: float, dfd: float) -> float:
    """x with P(F(dfn, dfd) > x) = p (scipy.stats.f.isf)."""
    return float(special.fdtri(dfn, dfd, 1.0 - p))


def t_isf(p: float, dof: float) -> float:
    """x with P(t(dof) > x) = p (scipy.stats.t.isf)."""
    return float(-special.stdtrit(dof, p))


def norm_isf(p: float) -> float:
    """z with P(N(0, 1) > z) = p."""
    return float(-special.ndtri(p))


def t_as_normal(t: ArrayLike, dof: float) -> NDArray[np.float64]:
    """The normal deviate with the same one-sided tail probability as t(dof) has beyond t (signed: -t gives
    its negative), so tests of different degrees of freedom read on one scale."""
    x = np.asarray(t, dtype=np.float64)
    tail = special.stdtr(dof, -np.abs(x))
    return np.asarray(np.sign(x) * -special.ndtri(tail), dtype=np.float64)


def two_sided_as_one_sided(z: ArrayLike) -> NDArray[np.float64]:
    """The one-sided normal deviate of the same p-value as a two-sided |z|: standard normal when z is, so a
    change either way adds as much evidence as a change one way does (0 for |z| = 0.674, the median)."""
    p = np.minimum(2.0 * special.ndtr(-np.abs(np.asarray(z, dtype=np.float64))), 1.0)
    return np.asarray(-special.ndtri(p), dtype=np.float64)


def largest_of_k_as_normal(z: ArrayLike, k: int) -> NDArray[np.float64]:
    """The normal deviate of the p-value of the largest of k standard normal deviates (Sidak): the largest
    of six is beyond 1.9 as often as one alone is beyond 1, so it weighs as 1. Exact for independent ones,
    conservative for correlated ones."""
    tail = special.ndtr(-np.asarray(z, dtype=np.float64))
    with np.errstate(divide="ignore"):  # a deviate of -inf: every one of the k below anything, tail 1
        return np.asarray(-special.ndtri(-np.expm1(k * np.log1p(-tail))), dtype=np.float64)


def norm_cdf(x: float) -> float:
    return float(special.ndtr(x))


def norm_pdf(x: float) -> float:
    return math.exp(-0.5 * x * x) / math.sqrt(2.0 * math.pi)


def halfnorm_ppf(q: float) -> float:
    """The q-quantile of |N(0, 1)|."""
    return float(special.ndtri(0.5 + 0.5 * q))
