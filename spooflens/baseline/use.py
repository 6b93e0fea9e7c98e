"""What each detector takes from a baseline, in one place.

One rule runs through it: the baseline caps what a log may teach a detector about its own noise. A
log attacked from its first fix to its last would otherwise teach every detector that the attack is
the receiver's normal behaviour. So a scale a detector learns from the log may be at most `ALLOWANCE`
times the largest the vehicle's clean logs showed (twice as noisy as its noisiest clean log; for the
IMU's variance scale its square; for a Gauss-Markov error both its size and the rate its driving noise
feeds it, sigma^2 / tau, the latter the square: `rate_cap`), and a level (an indicator's typical value,
the distance between two receivers) comes from the clean logs instead of the log. A clean log of the
vehicle learns what it learned before, inside the allowance: a baseline makes no clean log noisier than
it was.

A cap needs evidence of what is normal: at least `MIN_LOGS_TO_CAP` clean logs that agree on the
quantity (`learn`: within a factor of three). One log cannot tell a vehicle's normal from one day's
conditions (two clean logs of one phone differ fourteenfold in `gnss_consistency`'s scale, a car's
drive against a walk), so with one log, or logs that disagree, the quantity is recorded and the log
learns it freely.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from spooflens.baseline.format import Baseline, Quantity
from spooflens.baseline.indicators import TWO_LOG_RANGE, IndicatorSpread
from spooflens.baseline.loaded import LoadedBaseline
from spooflens.detectors.base import DetectorResult
from spooflens.epoch_table import EpochTable
from spooflens.estimation.quantiles import t_as_normal

if TYPE_CHECKING:
    from spooflens.navigation.noise_learning import NoisePrior

FloatArray = NDArray[np.float64]
ALLOWANCE = 2.0  # a log's learned noise scale may be this many times the noisiest clean log's
MIN_LOGS_FOR_SPREAD = 3  # an indicator's between-log spread measured on fewer logs is the prior's


def note(result: DetectorResult, text: str) -> None:
    """Say in a result what it took from the baseline (collected into the JSON's `baseline` block)."""
    before = result.extras.get("from_baseline")
    result.extras["from_baseline"] = f"{before}; {text}" if before else text


MIN_LOGS_TO_CAP = 2


def usable(q: Quantity | None) -> bool:
    """Whether a scale is known well enough to cap a log's: enough clean logs, and they agree on it."""
    return q is not None and q.n_logs >= MIN_LOGS_TO_CAP and q.agree is True


def floor(q: Quantity | None) -> float:
    """The smallest value a log may learn for this noise scale: its quietest clean log's (0 when the
    baseline cannot tell: `usable`). A receiver or IMU is not quieter on one day than on every clean day."""
    return float(min(q.values)) if q is not None and usable(q) else 0.0


def cap(q: Quantity | None, allowance: float = ALLOWANCE) -> float:
    """The largest value a log may learn for this scale (inf when the baseline cannot tell: `usable`)."""
    return float(max(q.values) * allowance) if q is not None and usable(q) else float("inf")


# a Gauss-Markov error's size and the time constant its driving noise is measured with (2 sigma^2 / tau)
MARKOV = {"b_h": "tau_p", "b_v": "tau_p", "bv_h": "tau_v", "bv_v": "tau_v"}


def rate_cap(sigma: Quantity | None, tau: Quantity | None) -> float:
    """The largest sigma^2 / tau a log may learn for a Gauss-Markov error (inf when the baseline cannot
    tell: `usable`, for both). Its driving noise is a noise scale too: a size capped alone would let the
    search shorten the time constant instead, and a wander of the allowed size that moves ten times
    faster swallows a drag the clean logs' slow wander never could."""
    if sigma is None or tau is None or not (usable(sigma) and usable(tau)):
        return float("inf")
    rates = [s * s / t for s, t in zip(sigma.per_log, tau.per_log, strict=True) if s is not None and t]
    return float(max(rates) * ALLOWANCE**2) if len(rates) >= MIN_LOGS_TO_CAP else float("inf")


def level_scale(q: Quantity, spec: IndicatorSpread) -> float:
    """How far a clean log's level of an indicator may naturally lie from the baseline's centre (one
    sigma, on the indicator's comparison scale: `IndicatorSpread.scale`): with three logs or more, the
    standard deviation of their levels times sqrt(1 + 1/n), a new log's prediction error (`level_z` reads
    it with the n - 1 degrees of freedom it was estimated with); with fewer, the indicator's prior spread
    (`indicators.INDICATORS`); never below its resolution."""
    v = spec.scale(np.asarray(q.values, dtype=float))
    n = len(v)
    floor = spec.resolution_on_scale(q.centre)
    if n >= MIN_LOGS_FOR_SPREAD:
        return float(max(float(np.std(v, ddof=1)) * np.sqrt(1.0 + 1.0 / n), floor))
    spread = float(abs(v[1] - v[0]) / TWO_LOG_RANGE * np.sqrt(1.5)) if n == 2 else 0.0
    return float(max(spread, spec.prior_on_scale(q.centre), floor))


def level_z(q: Quantity, spec: IndicatorSpread, level: FloatArray, count: FloatArray) -> FloatArray:
    """An indicator's level (median over `count` values) against the baseline, in the direction an attack
    moves it (either way for direction 0: then |z|): (level - centre) over `level_scale` and the level's
    own sampling error. With a spread measured on n logs this is a t of n - 1 degrees of freedom, given as
    the normal deviate of the same tail probability: a standard normal deviate for a clean log, whatever
    n, so levels judged on 3 logs and on 8 read on one scale (and can be added across indicators:
    `receiver_evidence`'s joint test). An upper confidence bound of the spread in its place shrinks every
    deviation by one factor (2.9 with four logs, at 95%): a level five prediction errors off, which a
    clean log shows less than once in a hundred, would read as 1.7."""
    values = spec.scale(np.asarray(q.values, dtype=float))
    centre = float(np.median(values))
    within = (q.within or 0.0) / (abs(q.centre) + spec.resolution_abs) if spec.log else (q.within or 0.0)
    scale = np.sqrt(level_scale(q, spec) ** 2 + (1.2533 * within) ** 2 / np.maximum(count, 1.0))
    z = (spec.scale(level) - centre) / scale
    if len(values) >= MIN_LOGS_FOR_SPREAD:
        z = t_as_normal(z, len(values) - 1)
    return np.asarray(np.abs(z) if spec.direction == 0 else spec.direction * z, dtype=float)


def consistency_caps(baseline: Baseline, table: EpochTable) -> dict[str, tuple[str, FloatArray]]:
    """receiver id -> (mode, per-axis cap on `gnss_consistency`'s scale)."""
    out = {}
    for rid in table.receivers():
        rx = baseline.receivers.get(rid)
        if rx is None or rx.consistency_mode is None or not rx.consistency_scale:
            continue
        caps = np.array([cap(rx.consistency_scale.get(a)) for a in ("east", "north", "up")])
        if np.isfinite(caps).any():
            out[rid] = (rx.consistency_mode, caps)
    return out


def noise_prior(loaded: LoadedBaseline, receiver_id: str, imu_id: str, preset: str) -> NoisePrior | None:
    """The navigation's noise search started from the baseline's values and capped by its allowance, when
    the baseline's navigation ran on this receiver and IMU (None otherwise: the log's own learning)."""
    from spooflens.navigation.noise_learning import NoisePrior

    nav = loaded.content.navigation
    if nav is None or nav.receiver_id != receiver_id or nav.imu_id != imu_id:
        return None
    params = {k: q for k, q in nav.parameters.items() if k != "imu" or nav.imu_grade == preset}
    start = {k: q.centre for k, q in params.items()}
    # a variance scale (the IMU's) gets the square of a standard deviation's allowance; time constants none
    upper = {
        k: cap(q, ALLOWANCE**2 if k == "imu" else ALLOWANCE)
        for k, q in params.items()
        if not k.startswith("tau") and usable(q)
    }
    rates = {s: (tau, r) for s, tau in MARKOV.items() if np.isfinite(r := rate_cap(params.get(s), params.get(tau)))}
    lower = {k: floor(q) for k, q in params.items() if not k.startswith("tau") and floor(q) > 0.0}
    n = max((q.n_logs for q in params.values()), default=0)
    free = [k for k in params if not k.startswith("tau") and k not in upper]
    limits = (
        f"capped at {ALLOWANCE:g} x its noisiest clean log, not below its quietest"
        + (" (its wanders' driving noise too)" if rates else "")
        + (f" but {', '.join(free)} (one log, or its logs disagree)" if free else "")
        if upper
        else "nothing capped (one log, or its logs disagree)"
    )
    return NoisePrior(start, upper, f"baseline {loaded.file} ({n} log{'s' if n != 1 else ''}; {limits})", rates, lower)


def coast_envelope_limit(loaded: LoadedBaseline | None, receiver_id: str, imu_id: str) -> tuple[FloatArray, str] | None:
    """The largest clean-coast envelope (per second of horizon) the vehicle's baseline allows the INS of
    this IMU and receiver, and the words saying so; None when the baseline has none for them."""
    known = loaded.content.navigation if loaded is not None else None
    if known is None or not known.coast_envelope or (known.receiver_id, known.imu_id) != (receiver_id, imu_id):
        return None
    if not usable(known.coast_envelope_peak):
        return None
    limit = ALLOWANCE * np.asarray(known.coast_envelope, dtype=float)
    return limit, f"clean coasts' envelope at most {ALLOWANCE:g} x the clean logs' (peak {limit.max():.3g})"
