"""Noise scales and thresholds read off the log itself, for statistics whose noise no data sheet gives.

A forensic log has no clean twin: a detector's noise scale must come from the log, robustly to the
attack it may contain, and its threshold must allow for that scale being an estimate.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spooflens.estimation.quantiles import f_isf, halfnorm_ppf, norm_cdf, norm_pdf

FloatArray = NDArray[np.float64]

_CLIP = 3.0
_CLIPPED_VARIANCE = 1.0 - 2.0 * _CLIP * norm_pdf(_CLIP) / (2.0 * norm_cdf(_CLIP) - 1.0)


def robust_scale(x: FloatArray, floor: float = 0.0) -> float:
    """Standard deviation of a zero-mean residual that outliers (attacks) may contaminate.

    Started from the quietest quarter (25th percentile of |x|, right while up to three quarters of the
    samples are disturbed), then refined to the RMS of the samples within 3 scales (corrected for the
    clipping) until it settles: the quietest quarter alone is noisy for a smooth, time-correlated residual
    (an INS drift), which picks its quietest stretch. Exact zeros are left out.
    """
    a = np.abs(np.asarray(x, float))
    a = a[np.isfinite(a) & (a > 1e-12)]
    if not len(a):
        return floor
    s = float(np.percentile(a, 25) / halfnorm_ppf(0.25))
    for _ in range(100):
        inside = a[a < _CLIP * s]
        if len(inside) < 3:
            break
        new = float(np.sqrt(np.mean(inside**2) / _CLIPPED_VARIANCE))
        if abs(new - s) <= 1e-6 * s:
            s = new
            break
        s = new
    return max(s, floor)


def lag1_autocorrelation(z: FloatArray, clip: float = 5.0) -> float:
    """Lag-1 autocorrelation of normalised components (E, k), averaged over the components, from the pairs of
    consecutive epochs both inside +-`clip` (an attack's outliers would make any series look smooth)."""
    values = []
    for i in range(z.shape[1]):
        a, b = z[:-1, i], z[1:, i]
        ok = np.isfinite(a) & np.isfinite(b) & (np.abs(a) <= clip) & (np.abs(b) <= clip)
        if ok.sum() >= 8:
            a, b = a[ok] - a[ok].mean(), b[ok] - b[ok].mean()
            den = np.sqrt(np.sum(a * a) * np.sum(b * b))
            values.append(float(np.sum(a * b) / den) if den > 0 else 0.0)
    return float(np.mean(values)) if values else float("nan")


def threshold(p_false_alarm: float, n_samples: int, rho: float, dof: int = 3) -> tuple[float, float]:
    """Threshold on the sum of `dof` squared components whose scales were estimated from `n_samples`
    epochs with lag-1 autocorrelation `rho`: dof x F(dof, n_eff) at `p_false_alarm`, n_eff = n (1 - rho) /
    (1 + rho) (at least 5). Chi-square(dof) when the scale is known; the F tail adds the uncertainty of a
    scale read off a short or smooth series. Returns (threshold, n_eff)."""
    r = float(np.clip(np.nan_to_num(rho), 0.0, 0.99))
    n_eff = max(n_samples * (1.0 - r) / (1.0 + r), 5.0)
    return float(dof * f_isf(p_false_alarm, dof, n_eff)), n_eff
