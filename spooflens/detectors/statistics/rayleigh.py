"""Seed 003's statistics: the Rayleigh scale of a sliding window, its null distribution with an
effective window for time-correlated samples, and the spread of pseudorange differences (eq. 13).

Notation of the paper (Dobryakova, Lemieszewski, Ochin): D is the distance between the two receivers'
positions (eq. 9), sigma the Rayleigh scale of a sample of D (eq. 16). The maximum-likelihood scale
of K samples has a closed form, sigma_hat^2 = sum(D^2) / (2K), and when the samples are Rayleigh with
scale sigma and independent, 2K sigma_hat^2 / sigma^2 is chi-square with 2K degrees of freedom.

Two corrections to the paper, both derived here and tested:
- A baseline that is not short against the position errors makes D Rice-distributed around the true
  distance nu, not Rayleigh. The same statistic then has 2K sigma_hat^2 / sigma^2 ~ noncentral
  chi-square(2K, K nu^2 / sigma^2) (D^2 / sigma^2 is noncentral chi-square(2, nu^2 / sigma^2)), which
  reduces to the paper's model at nu = 0. nu and sigma are fitted in closed form from the second and
  fourth moments of D.
- Consecutive samples are correlated (receiver errors wander for minutes), so K samples carry the
  information of fewer independent ones. The window's sum is matched in mean and variance by the
  same distribution with K_eff = K / (1 + 2 sum_l (1 - l/K) rho_l) samples (Satterthwaite), rho_l the
  autocorrelation of D^2 on the clean part of the log, summed over the initial positive sequence.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

# Above this noncentrality the noncentral chi-square is Gaussian to far better than the thresholds need
# (and scipy's ppf becomes slow).
_GAUSSIAN_NC = 1e4


def eq13_as_printed(d: FloatArray) -> float:
    """The radicand of eq. (13) exactly as printed: sum(d^2)/(N-1) - (sum d)^2/N. It is not a variance
    (it can be negative, e.g. d = (1, 1)); kept to show the erratum."""
    d = np.asarray(d, dtype=float)
    n = len(d)
    return float(np.sum(d**2) / (n - 1) - np.sum(d) ** 2 / n)


def difference_sd(d: FloatArray, system: NDArray[np.int64] | None = None) -> float:
    """Eq. (13) corrected: sqrt((sum d^2 - (sum d)^2 / N) / (N - 1)), computed in two passes (the
    differences carry the receivers' clock difference, up to 1e6 m, which a one-pass sum would cancel
    catastrophically). With several satellite systems each keeps its own mean (its own clock
    difference) and the spread is pooled: sqrt(sum_s sum_i (d_i - mean_s)^2 / (N - n_systems))."""
    d = np.asarray(d, dtype=float)
    sys = np.zeros(len(d), dtype=np.int64) if system is None else np.asarray(system, dtype=np.int64)
    ss, dof = 0.0, 0
    for s in np.unique(sys):
        x = d[sys == s]
        ss += float(np.sum((x - x.mean()) ** 2))
        dof += len(x) - 1
    return float(np.sqrt(ss / dof)) if dof > 0 else float("nan")


def rayleigh_scale(x: FloatArray) -> float:
    """Maximum-likelihood Rayleigh scale of a sample: sqrt(sum x^2 / (2n)) (NaNs ignored)."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2) / 2.0)) if len(x) else float("nan")


def windowed_scale(x: FloatArray, k: int, include_current: bool = False) -> FloatArray:
    """Rayleigh ML scale of each sliding window of `k` samples (eqs. 17-18): the window of sample j is
    j-1 ... j-K as the paper writes it, or j-K+1 ... j with `include_current`. NaN until the window is
    full or where it holds a NaN."""
    x = np.asarray(x, dtype=float)
    n = len(x)
    out = np.full(n, np.nan)
    if n < k or k < 1:
        return out
    sq = np.where(np.isfinite(x), x * x, 0.0)
    bad = (~np.isfinite(x)).astype(np.int64)
    cs = np.concatenate([[0.0], np.cumsum(sq)])
    cb = np.concatenate([[0], np.cumsum(bad)])
    end = np.arange(n) + (1 if include_current else 0)  # window is [end - k, end)
    ok = end - k >= 0
    e = end[ok]
    s = (cs[e] - cs[e - k]) / (2.0 * k)
    nbad = cb[e] - cb[e - k]
    out[ok] = np.where(nbad == 0, np.sqrt(s), np.nan)
    return out


def rice_fit(x: FloatArray) -> tuple[float, float]:
    """(nu, sigma) of a Rice distribution from the second and fourth moments of the sample (closed form).

    E x^2 = nu^2 + 2 sigma^2 and E x^4 = nu^4 + 8 nu^2 sigma^2 + 8 sigma^4, so sigma^2 is the smaller root
    of s^2 - m2 s + (m4 - m2^2) / 4 = 0. A sample with a heavier tail than Rayleigh (2 m2^2 < m4) gets
    nu = 0 and the Rayleigh ML scale.
    """
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if not len(x):
        return float("nan"), float("nan")
    m2, m4 = float(np.mean(x**2)), float(np.mean(x**4))
    disc = 2.0 * m2 * m2 - m4
    if disc <= 0:
        return 0.0, float(np.sqrt(m2 / 2.0))
    s = 0.5 * (m2 - np.sqrt(disc))
    return float(np.sqrt(max(m2 - 2.0 * s, 0.0))), float(np.sqrt(max(s, 0.0)))


LOWER_QUANTILE = 0.1  # the quantile of the lower tail a collapse test's null is matched to, with the median
MIN_FLOOR_RATIO = 2.0  # nu/sigma from which the lower tail is read off the quantiles, not the moments


@functools.cache
def _rice_lower_table(q: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(nu/sigma, the q-quantile over the median, the median over sigma) of the Rice family on a grid."""
    from scipy import stats

    r = np.r_[0.0, np.geomspace(0.05, 200.0, 160)]
    median = np.asarray(stats.rice.median(r), dtype=float)
    return r, np.asarray(stats.rice.ppf(q, r), dtype=float) / median, median


def rice_fit_lower_tail(x: FloatArray, q: float = LOWER_QUANTILE) -> tuple[float, float]:
    """(nu, sigma) of the Rice distribution whose median and lower `q` quantile are the sample's.

    What a collapse test needs of its null is the lower tail. Real receiver pairs' distances have a floor
    near the antennas' separation and excursions above it (one receiver's multipath, a jump): matched in
    moments, those excursions make sigma several times what the lower tail shows, and the threshold falls
    far below any collapse the receivers' own tracking noise leaves (a real ZED-F9K and SPAN pair 0.46 m
    apart: sigma 0.18 m by moments, 0.028 m by the lower tail; a drag left 0.14 m and stayed above the
    moment-fitted threshold of 0.057 m). Where the quantiles show no floor (nu below `MIN_FLOOR_RATIO`
    sigma) the moment fit stands."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if len(x) < 3:
        return rice_fit(x)
    m, lo = float(np.median(x)), float(np.quantile(x, q))
    r, ratio, median = _rice_lower_table(q)
    target = lo / m if m > 0 else 0.0
    if target < float(np.interp(MIN_FLOOR_RATIO, r, ratio)):
        # the quantiles hardly tell nu below about sigma (the ratio is flat there): no floor to speak of,
        # the moments decide, as for the paper's short baselines
        return rice_fit(x)
    k = len(r) - 1 if target >= ratio[-1] else int(np.searchsorted(ratio, target))
    # ratio rises with nu/sigma: interpolate between the grid's neighbours
    k = min(max(k, 1), len(r) - 1)
    w = float(np.clip((target - ratio[k - 1]) / (ratio[k] - ratio[k - 1]), 0.0, 1.0))
    rr = float(r[k - 1] + w * (r[k] - r[k - 1]))
    sigma = m / float(median[k - 1] + w * (median[k] - median[k - 1]))
    return rr * sigma, sigma


def effective_window(x: FloatArray, clean: BoolArray, k: int) -> float:
    """K_eff of a window of `k` samples of `x` (the window sums x^2): k / (1 + 2 sum_l (1 - l/k) rho_l),
    rho_l the lag-l autocorrelation of x^2 over pairs of clean samples, summed while positive."""
    if k <= 1:
        return float(k)
    z = np.asarray(x, dtype=float) ** 2
    ok = np.asarray(clean, dtype=bool) & np.isfinite(z)
    if ok.sum() < 3:
        return 1.0
    mu = float(z[ok].mean())
    zc = np.where(ok, z - mu, 0.0)
    var = float(np.sum(zc[ok] ** 2) / ok.sum())
    if var <= 0:
        return float(k)
    factor = 1.0
    for lag in range(1, min(k, len(z) - 1)):
        pair = ok[:-lag] & ok[lag:]
        if pair.sum() < 3:
            break
        rho = float(np.sum(zc[:-lag][pair] * zc[lag:][pair]) / pair.sum() / var)
        if rho <= 0:
            break
        factor += 2.0 * (1.0 - lag / k) * rho
    return float(np.clip(k / factor, 1.0, k))


def _ncx2(p: float, dof: float, nc: float, upper: bool) -> float:
    """Quantile (lower tail p, or upper tail p) of noncentral chi-square(dof, nc)."""
    from scipy import stats  # imported where used: seconds of start-up for analyses that never get here

    if nc < 1e-12:
        return float(stats.chi2.isf(p, dof) if upper else stats.chi2.ppf(p, dof))
    if nc > _GAUSSIAN_NC:
        z = float(stats.norm.isf(p) if upper else stats.norm.ppf(p))
        return float(dof + nc + z * np.sqrt(2.0 * (dof + 2.0 * nc)))
    return float(stats.ncx2.isf(p, dof, nc) if upper else stats.ncx2.ppf(p, dof, nc))


def scale_threshold(p: float, sigma: float, nu: float, k_eff: float, upper: bool = False) -> float:
    """The window scale th with P(sigma_hat <= th) = p (or P(sigma_hat >= th) = p with `upper`) when the
    samples are Rice(nu, sigma) (Rayleigh at nu = 0), K_eff effectively independent samples."""
    q = _ncx2(p, 2.0 * k_eff, k_eff * nu * nu / (sigma * sigma), upper)
    return float(sigma * np.sqrt(max(q, 0.0) / (2.0 * k_eff)))


def scale_probability_below(th: float, sigma: float, nu: float, k: float) -> float:
    """P(sigma_hat <= th) for a window of k independent Rice(nu, sigma) samples: the false-alarm rate of
    the collapse rule at threshold th (the miss rate when sigma, nu describe spoofing, as 1 minus it)."""
    from scipy import stats

    x = 2.0 * k * th * th / (sigma * sigma)
    nc = k * nu * nu / (sigma * sigma)
    return float(stats.chi2.cdf(x, 2.0 * k) if nc < 1e-12 else stats.ncx2.cdf(x, 2.0 * k, nc))


def paper_boundary(sigma_gnss: float, sigma_s: float) -> float:
    """Rules (15), (19), (22) as printed: (sigma_GNSS - sigma_S) / 2 (the text's worked example adds the
    two, (10.06 + 0.12) / 2 = 5.09, not 4.97)."""
    return 0.5 * (sigma_gnss - sigma_s)


def scale_changepoint(x: FloatArray, lo: int, hi: int, floor: float = 1e-6) -> int:
    """Index in (lo, hi) where the Rayleigh scale of x most likely changes (two-segment maximum
    likelihood: minimise n1 log s1^2 + n2 log s2^2, the segments' ML scales floored at `floor`)."""
    x = np.asarray(x, dtype=float)[lo:hi]
    n = len(x)
    if n < 3:
        return lo
    sq = np.where(np.isfinite(x), x * x, 0.0)
    cs = np.cumsum(sq)
    m = np.arange(1, n)
    s1 = np.maximum(cs[m - 1] / (2.0 * m), floor)
    s2 = np.maximum((cs[-1] - cs[m - 1]) / (2.0 * (n - m)), floor)
    cost = m * np.log(s1) + (n - m) * np.log(s2)
    return lo + int(m[int(np.argmin(cost))])


@dataclass(frozen=True)
class Calibration:
    """Null-hypothesis parameters of a window statistic, fitted on the clean part of the log."""

    nu: float  # Rice location (0: Rayleigh)
    sigma: float  # Rice / Rayleigh scale of the clean samples
    rayleigh_sigma: float  # the paper's sigma_GNSS: Rayleigh ML scale of the clean samples
    k: int
    k_eff: float
    threshold: float  # on the window scale
    clean: BoolArray  # samples the fit used (not in any flagged window)
    iterations: int
    calibrated: bool  # False: the clean part was too short; fitted on every sample instead


def _wider_side(x: FloatArray, use: BoolArray, ratio: float = 0.5, min_side: int = 30) -> BoolArray | None:
    """The samples on the larger-scale side of the one change point of x's Rayleigh scale (two-segment
    maximum likelihood), when the other side's scale is below `ratio` of it and both sides hold at least
    `min_side` samples; else None (no collapse to start from)."""
    idx = np.flatnonzero(use & np.isfinite(x))
    if len(idx) < 2 * min_side:
        return None
    cp = scale_changepoint(x[idx], 0, len(idx))
    if min(cp, len(idx) - cp) < min_side:
        return None
    s1, s2 = rayleigh_scale(x[idx[:cp]]), rayleigh_scale(x[idx[cp:]])
    if min(s1, s2) >= ratio * max(s1, s2):
        return None
    out = np.zeros(len(x), dtype=bool)
    out[idx[:cp] if s1 > s2 else idx[cp:]] = True
    return out


def flagged_samples(alarm: BoolArray, k: int, include_current: bool) -> BoolArray:
    """The samples that make up the alarmed windows."""
    n = len(alarm)
    out = np.zeros(n, dtype=bool)
    for j in np.flatnonzero(alarm):
        end = j + (1 if include_current else 0)
        out[max(end - k, 0) : end] = True
    return out


def calibrate(
    x: FloatArray,
    k: int,
    p_false_alarm: float,
    upper: bool = False,
    rayleigh_only: bool = False,
    include_current: bool = False,
    max_iterations: int = 6,
    min_clean: int = 30,
) -> tuple[Calibration, FloatArray, BoolArray]:
    """Fit the null distribution on the clean part of `x` and return (calibration, window scale, alarm).

    The clean part is found by iteration: fit on every sample, flag the windows beyond the threshold,
    refit on the samples outside them, until the flagged set stops changing. A collapse pulls the fit
    towards zero, which only lowers the first threshold; for `upper` the first fit is read off the lowest
    quarter of the samples, since an attack there inflates the scale. A collapse test (the
    default) alarms when the window scale falls below the threshold; `upper` alarms above it (the
    baseline-error test). `rayleigh_only` fixes nu = 0 (a statistic known to be Rayleigh).
    """
    x = np.asarray(x, dtype=float)
    finite = np.isfinite(x)
    scale = windowed_scale(x, k, include_current)
    clean = finite.copy()
    cal = None
    alarm = np.zeros(len(x), dtype=bool)
    for it in range(1, max_iterations + 1):
        calibrated = int(clean.sum()) >= max(min_clean, 3 * k)
        use = clean if calibrated else finite
        if upper and it == 1:
            # an attack makes this statistic large: start from the quietest quarter (Rayleigh quantile),
            # which holds while up to three quarters of the log are attacked
            nu, sigma = 0.0, float(np.percentile(x[use], 25) / np.sqrt(-2.0 * np.log(0.75)))
        elif it == 1 and (wider := _wider_side(x, use)) is not None:
            # a collapse lasting a good part of the log (an attack from its middle to its end) pulls a fit
            # on every sample down with it, and then its windows never fall below the threshold: start
            # from the side of the scale's change point with the larger scale
            use = use & wider
            nu, sigma = (0.0, rayleigh_scale(x[use])) if rayleigh_only else rice_fit_lower_tail(x[use])
        elif rayleigh_only:
            nu, sigma = 0.0, rayleigh_scale(x[use])
        else:
            nu, sigma = rice_fit(x[use]) if upper else rice_fit_lower_tail(x[use])
        if not np.isfinite(sigma) or sigma <= 0:
            sigma = max(float(sigma) if np.isfinite(sigma) else 0.0, 1e-9)
        k_eff = effective_window(x, use, k)
        th = scale_threshold(p_false_alarm, sigma, nu, k_eff, upper)
        alarm = np.nan_to_num(scale, nan=-np.inf) > th if upper else np.nan_to_num(scale, nan=np.inf) < th
        cal = Calibration(nu, sigma, rayleigh_scale(x[use]), k, k_eff, th, use, it, calibrated)
        new_clean = finite & ~flagged_samples(alarm, k, include_current)
        if np.array_equal(new_clean, clean) or not calibrated:
            break
        clean = new_clean
    assert cal is not None
    return cal, scale, alarm


def fixed_calibration(
    x: FloatArray,
    k: int,
    p_false_alarm: float,
    nu: float,
    sigma: float,
    k_eff: float,
    upper: bool = False,
    include_current: bool = False,
) -> tuple[Calibration, FloatArray, BoolArray]:
    """As `calibrate`, with the null model given (a vehicle's baseline: fitted on its clean logs) instead of
    fitted on this log, so a log attacked throughout is still judged against a clean model."""
    x = np.asarray(x, dtype=float)
    scale = windowed_scale(x, k, include_current)
    k_eff = float(np.clip(k_eff, 1.0, k))
    th = scale_threshold(p_false_alarm, max(sigma, 1e-9), nu, k_eff, upper)
    alarm = np.nan_to_num(scale, nan=-np.inf) > th if upper else np.nan_to_num(scale, nan=np.inf) < th
    rayleigh = float(np.sqrt(nu * nu / 2.0 + sigma * sigma))  # the Rayleigh ML scale of Rice(nu, sigma) samples
    return Calibration(nu, sigma, rayleigh, k, k_eff, th, np.isfinite(x), 0, True), scale, alarm
