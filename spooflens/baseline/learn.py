"""From the measurements of a vehicle's clean logs to its baseline: per quantity the typical level, the
spread inside a log and across logs, and whether the logs agree on it.

When logs disagree: an indicator's logs disagree when their levels lie further apart than three times
what the indicator moves inside a log or naturally between clean logs (`indicators.INDICATORS`); a
learned noise parameter's (a positive scale) when the largest is more than three times the smallest (ten
for a time constant, which the likelihood hardly determines); a clock drift's when the logs differ by
more than 20 ppm. A quantity the logs disagree on is kept and said, and `receiver_evidence` does not use
it as a level (the vehicle has no one normal level of it).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from datetime import UTC, datetime

import numpy as np

from spooflens import __version__
from spooflens.baseline.format import (
    FORMAT,
    VERSION,
    Baseline,
    BaselineError,
    ClockBaseline,
    LogEntry,
    NavigationBaseline,
    PairBaseline,
    Quantity,
    ReceiverBaseline,
    RefusedLog,
    RicePair,
)
from spooflens.baseline.identity import same_model
from spooflens.baseline.indicators import INDICATORS, SATELLITE_CN0, TWO_LOG_RANGE, IndicatorSpread
from spooflens.baseline.measure import NOISE_UNITS, Level, LogMeasurement, RiceFit
from spooflens.detectors.dual_receiver import COLLAPSE, PR_COLLAPSE

DISAGREE_FACTOR = 3.0  # an indicator's log levels this many spreads apart disagree
DISAGREE_RATIO = 3.0  # a positive scale's largest over its smallest
DISAGREE_RATIO_TAU = 10.0
DISAGREE_DRIFT_PPM = 20.0


def between_spread(values: Sequence[float]) -> float | None:
    """Spread of per-log values across logs: 1.4826 MAD (three logs or more), range / 1.128 (two)."""
    v = np.asarray(values, dtype=float)
    if len(v) < 2:
        return None
    if len(v) == 2:
        return float(abs(v[1] - v[0]) / TWO_LOG_RANGE)
    return float(1.4826 * np.median(np.abs(v - np.median(v))))


def _per_log(values: Sequence[float | None]) -> tuple[float | None, ...]:
    return tuple(None if v is None or not np.isfinite(v) else float(v) for v in values)


def level_quantity(spec: IndicatorSpread, levels: Sequence[Level | None]) -> Quantity | None:
    per_log = _per_log([lv.median if lv else None for lv in levels])
    finite = [v for v in per_log if v is not None]
    if not finite:
        return None
    centre = float(np.median(finite))
    within = float(np.median([lv.scale for lv in levels if lv]))
    between = between_spread(finite)
    agree = None if between is None else between <= DISAGREE_FACTOR * max(within, spec.prior(centre))
    return Quantity(centre, spec.unit, per_log, within, between, agree)


def scale_quantity(values: Sequence[float | None], unit: str, agrees: Callable[[list[float]], bool]) -> Quantity | None:
    """A quantity with one value per log (a learned parameter, a fitted model's)."""
    per_log = _per_log(values)
    finite = [v for v in per_log if v is not None]
    if not finite:
        return None
    between = between_spread(finite)
    return Quantity(float(np.median(finite)), unit, per_log, None, between, None if between is None else agrees(finite))


def ratio_agrees(limit: float) -> Callable[[list[float]], bool]:
    return lambda v: min(v) > 0 and max(v) / min(v) <= limit


def range_agrees(limit: float) -> Callable[[list[float]], bool]:
    return lambda v: max(v) - min(v) <= limit


def receiver_models(measurements: Sequence[LogMeasurement]) -> dict[str, str | None]:
    """Per receiver id the model the logs name; BaselineError when two logs name different models (a
    baseline is of one receiver model and installation)."""
    out: dict[str, str | None] = {}
    seen: dict[str, tuple[str, str]] = {}  # rid -> (model, log that named it)
    for m in measurements:
        for rid, model in m.identity.receivers.items():
            out.setdefault(rid, None)
            if model is None:
                continue
            if rid in seen and not same_model(seen[rid][0], model):
                raise BaselineError(
                    f"{m.name}: receiver {rid} is a {model}, in {seen[rid][1]} a {seen[rid][0]}: a baseline is "
                    "learned from logs of one receiver model (and antenna installation)"
                )
            if rid not in seen or len(model) > len(seen[rid][0]):
                seen[rid] = (model, m.name)
            out[rid] = seen[rid][0]
    return out


def _receiver(rid: str, model: str | None, ms: Sequence[LogMeasurement]) -> ReceiverBaseline:
    indicators = {}
    for column, spec in INDICATORS.items():
        q = level_quantity(spec, [m.indicators.get(rid, {}).get(column) for m in ms])
        if q is not None:
            indicators[column] = q
    bands = sorted({b for m in ms for b in m.satellite_cn0.get(rid, {})})
    satellite_cn0 = {}
    for band in bands:
        q = level_quantity(SATELLITE_CN0, [m.satellite_cn0.get(rid, {}).get(band) for m in ms])
        if q is not None:
            satellite_cn0[band] = q
    types = sorted({k for m in ms for k in m.fix_types.get(rid, {})})
    fix_types = {}
    for name in types:
        values = [m.fix_types[rid].get(name, 0.0) if rid in m.fix_types else None for m in ms]
        q = scale_quantity(values, "", range_agrees(0.5))
        if q is not None:
            fix_types[name] = q
    clocks = [m.clocks.get(rid) for m in ms]
    clock = None
    known = [c for c in clocks if c is not None]
    if known:
        scale = scale_quantity([c.scale_s if c else None for c in clocks], "s", ratio_agrees(DISAGREE_RATIO))
        drift = scale_quantity([c.drift_ppm if c else None for c in clocks], "ppm", range_agrees(DISAGREE_DRIFT_PPM))
        if scale is not None:
            clock = ClockBaseline(known[0].clock, all(c.monotonic for c in known), scale, drift)
    modes = [m.consistency[rid][0] for m in ms if rid in m.consistency]
    mode = max(set(modes), key=modes.count) if modes else None
    consistency = {}
    for k, axis in enumerate(("east", "north", "up")):
        values = [
            m.consistency[rid][1][k] if rid in m.consistency and m.consistency[rid][0] == mode else None for m in ms
        ]
        unit = "m" if mode and mode.startswith("position") else "m/s^2"
        q = scale_quantity(values, unit, ratio_agrees(DISAGREE_RATIO))
        if q is not None:
            consistency[axis] = q
    firmware = tuple(dict.fromkeys(f for m in ms if rid in m.identity.receivers for f in m.identity.receiver_firmware))
    return ReceiverBaseline(model, firmware, indicators, satellite_cn0, fix_types, clock, mode, consistency)


def _navigation(ms: Sequence[LogMeasurement]) -> NavigationBaseline | None:
    navigated = [m.navigated for m in ms if m.navigated is not None]
    if not navigated:
        return None
    rid, imu, grade = max(set(navigated), key=navigated.count)
    same = [m if m.navigated == (rid, imu, grade) else None for m in ms]
    parameters = {}
    for name, unit in NOISE_UNITS.items():
        limit = DISAGREE_RATIO_TAU if name.startswith("tau") else DISAGREE_RATIO
        q = scale_quantity([m.noise.get(name) if m else None for m in same], unit, ratio_agrees(limit))
        if q is not None:
            parameters[name] = q
    curves = [m.coast_envelope for m in same if m is not None and m.coast_envelope is not None]
    envelope: tuple[float, ...] = ()
    peak = None
    if curves:
        length = min(len(c) for c in curves)
        envelope = tuple(float(x) for x in np.max([c[:length] for c in curves], axis=0))
        peaks = [
            float(np.max(m.coast_envelope)) if m is not None and m.coast_envelope is not None else None for m in same
        ]
        peak = scale_quantity(peaks, "", ratio_agrees(DISAGREE_RATIO))
    return NavigationBaseline(rid, imu, grade, parameters, envelope, peak)


def _rice(fits: Sequence[RiceFit | None]) -> RicePair | None:
    known = [f for f in fits if f is not None]
    if not known:
        return None
    k = max({f.window_samples for f in known}, key=[f.window_samples for f in known].count)
    fits = [f if f is not None and f.window_samples == k else None for f in fits]
    sigma = scale_quantity([f.sigma if f else None for f in fits], "m", ratio_agrees(DISAGREE_RATIO))
    assert sigma is not None
    nu = scale_quantity([f.nu if f else None for f in fits], "m", range_agrees(max(3.0 * sigma.centre, 0.5)))
    ratio = scale_quantity([f.k_eff_ratio if f else None for f in fits], "", ratio_agrees(DISAGREE_RATIO))
    assert nu is not None and ratio is not None
    return RicePair(nu, sigma, ratio, k)


def _pairs(ms: Sequence[LogMeasurement]) -> dict[str, PairBaseline]:
    out = {}
    for key in sorted({k for m in ms for k in m.pairs}):
        distance = _rice([m.pairs.get(key, {}).get(COLLAPSE) for m in ms])
        if distance is None:
            continue
        out[key] = PairBaseline(distance, _rice([m.pairs.get(key, {}).get(PR_COLLAPSE) for m in ms]))
    return out


def aggregate(measurements: Sequence[LogMeasurement], refused: Sequence[RefusedLog] = ()) -> Baseline:
    """The baseline of these clean logs' measurements (BaselineError when there are none, or when they
    name different receiver models)."""
    if not measurements:
        why = "; ".join(f"{r.name}: {r.reason}" for r in refused) or "no logs given"
        raise BaselineError(f"no clean log to learn a baseline from ({why})")
    models = receiver_models(measurements)
    return Baseline(
        format=FORMAT,
        version=VERSION,
        created_utc=datetime.now(UTC).isoformat(timespec="seconds"),
        spooflens_version=__version__,
        logs=tuple(LogEntry(m.name, m.sha256, m.duration_s, m.left_out_s, m.note) for m in measurements),
        refused=tuple(refused),
        firmware=tuple(dict.fromkeys(f for m in measurements for f in m.identity.firmware)),
        imus=tuple(dict.fromkeys(i for m in measurements for i in m.identity.imus)),
        receivers={rid: _receiver(rid, model, measurements) for rid, model in models.items()},
        navigation=_navigation(measurements),
        pairs=_pairs(measurements),
    )
