"""What one clean log says about its vehicle: the numbers a baseline is made of, measured on an analysed
log with the stretches its analysis found anything in left out.

A log with a spoofing incident is no yardstick and is refused; a log with anomalies (one evidence class
alone) is used with each anomaly's stretch, widened by `LEFT_OUT_MARGIN_S`, left out.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.baseline.identity import Identity, identify
from spooflens.baseline.indicators import INDICATORS
from spooflens.detectors.dual_receiver import COLLAPSE, PR_COLLAPSE
from spooflens.detectors.gnss_consistency import ConsistencyOptions, residual
from spooflens.detectors.receiver_time import ReceiverTimeOptions, drift_ppm, offset_scale
from spooflens.navigation.noise_learning import LearnedNoise, noise_parameters
from spooflens.pipeline.run import Analysis
from spooflens.schema import FixType

FloatArray = NDArray[np.float64]
LEFT_OUT_MARGIN_S = 10.0
MIN_EPOCHS = 10  # an indicator with fewer finite values in a log says nothing about its level
MAX_DRIFT_ERROR_PPM = 5.0

ELEVATION_BANDS: dict[str, tuple[float, float]] = {
    "elev_00_15": (-90.0, 15.0),
    "elev_15_30": (15.0, 30.0),
    "elev_30_60": (30.0, 60.0),
    "elev_60_90": (60.0, 90.1),
}
NOISE_UNITS = {
    "w_h": "m",
    "w_v": "m",
    "b_h": "m",
    "b_v": "m",
    "tau_p": "s",
    "wv_h": "m/s",
    "wv_v": "m/s",
    "bv_h": "m/s",
    "bv_v": "m/s",
    "tau_v": "s",
    "imu": "",
}


@dataclass(frozen=True)
class Level:
    """An indicator in one log: its median, robust scale (1.4826 MAD) and how many values."""

    median: float
    scale: float
    count: int


@dataclass(frozen=True)
class ClockLevel:
    clock: str
    monotonic: bool
    scale_s: float
    drift_ppm: float


@dataclass(frozen=True)
class RiceFit:
    nu: float
    sigma: float
    k_eff_ratio: float
    window_samples: int


@dataclass
class LogMeasurement:
    name: str
    sha256: str
    duration_s: float
    identity: Identity
    left_out_s: tuple[tuple[float, float], ...] = ()
    note: str = ""
    indicators: dict[str, dict[str, Level]] = field(default_factory=dict)
    satellite_cn0: dict[str, dict[str, Level]] = field(default_factory=dict)
    fix_types: dict[str, dict[str, float]] = field(default_factory=dict)
    clocks: dict[str, ClockLevel] = field(default_factory=dict)
    noise: dict[str, float] = field(default_factory=dict)  # NOISE_UNITS names
    navigated: tuple[str, str, str] | None = None  # (receiver id, IMU id, IMU preset)
    pairs: dict[str, dict[str, RiceFit]] = field(default_factory=dict)  # "A|B" -> detector -> fit
    consistency: dict[str, tuple[str, FloatArray]] = field(default_factory=dict)  # rid -> (mode, scale ENU)
    coast_envelope: FloatArray | None = None  # per second of horizon from 0 s (the navigation's receiver)


def level(x: FloatArray) -> Level | None:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if len(x) < MIN_EPOCHS:
        return None
    med = float(np.median(x))
    return Level(med, 1.4826 * float(np.median(np.abs(x - med))), len(x))


def _outside(t: FloatArray, spans: tuple[tuple[float, float], ...]) -> NDArray[np.bool_]:
    keep = np.ones(len(t), dtype=bool)
    for a, b in spans:
        keep &= ~((t >= a) & (t <= b))
    return keep


def _noise_parameters(learned: LearnedNoise) -> dict[str, float]:
    n = learned.noise
    return {k: float(v) for k, v in noise_parameters(n, learned.imu_scale, n.has_velocity).items()}


def _satellite_levels(sats: pd.DataFrame, spans: tuple[tuple[float, float], ...]) -> dict[str, Level]:
    t = sats["t_s"].to_numpy(dtype=float)
    ok = _outside(t, spans)
    cn0 = sats["cn0_dbhz"].to_numpy(dtype=float)[ok]
    el = sats["elevation_deg"].to_numpy(dtype=float)[ok] if "elevation_deg" in sats else np.full(ok.sum(), np.nan)
    out: dict[str, Level] = {}
    if (lv := level(cn0)) is not None:
        out["all"] = lv
    for band, (lo, hi) in ELEVATION_BANDS.items():
        inside = (el >= lo) & (el < hi)
        if inside.any() and (lv := level(cn0[inside])) is not None:
            out[band] = lv
    return out


def measure(analysis: Analysis, name: str, sha256: str) -> LogMeasurement:
    """The baseline's numbers from one analysed log (one recording). Raises ValueError for a log with a
    spoofing incident (it is no yardstick: refused, the caller says why)."""
    table, verdict = analysis.table, analysis.verdict
    spoofing = [i for i in verdict.incidents if i.is_spoofing]
    if spoofing:
        i = spoofing[0]
        raise ValueError(
            f"a spoofing incident ({i.start_s:.1f}-{i.end_s:.1f} s, confidence {i.confidence}, "
            f"{', '.join(i.detectors)}): a log that may have been spoofed is no yardstick"
        )
    spans = tuple(
        (max(0.0, i.start_s - LEFT_OUT_MARGIN_S), i.end_s + LEFT_OUT_MARGIN_S)
        for i in sorted(verdict.incidents, key=lambda i: i.start_s)
    )
    note = (
        f"{len(spans)} anomaly(ies) left out: "
        + ", ".join(
            f"{a:.0f}-{b:.0f} s ({', '.join(i.detectors)})" for (a, b), i in zip(spans, verdict.incidents, strict=True)
        )
        if spans
        else ""
    )
    m = LogMeasurement(name, sha256, float(table.duration_s), identify(table), spans, note)
    receivers = table.receivers()
    for rid in receivers:
        fx = table.fixes_of(rid)
        t = fx["t_s"].to_numpy(dtype=float)
        ok = _outside(t, spans)
        levels = {c: lv for c in INDICATORS if c in fx and (lv := level(fx[c].to_numpy(dtype=float)[ok]))}
        if levels:
            m.indicators[rid] = levels
        types = fx["fix_type"].to_numpy()[ok]
        if len(types):
            m.fix_types[rid] = {
                FixType(v).name: float(np.mean(types == v)) for v in np.unique(types) if v in FixType._value2member_map_
            }
        if "time_offset_s" in fx:
            x = fx["time_offset_s"].to_numpy(dtype=float)
            good = ok & np.isfinite(x)
            if good.sum() >= MIN_EPOCHS:
                meta = table.metadata
                rate, error = drift_ppm(t[good], x[good])
                m.clocks[rid] = ClockLevel(
                    meta.get("time_offset.clock", "the log's own clock"),
                    meta.get("time_offset.monotonic") == "yes",
                    offset_scale(x[good], ReceiverTimeOptions().min_scale_s),
                    rate if error <= MAX_DRIFT_ERROR_PPM else float("nan"),  # a short log cannot tell its drift
                )
        sats = table.satellites[table.satellites["receiver_id"].astype(str) == rid]
        if len(sats):
            sat_levels = _satellite_levels(sats, spans)
            if sat_levels:
                m.satellite_cn0[rid] = sat_levels
        if ok.sum() >= MIN_EPOCHS:
            res = residual(fx[ok].reset_index(drop=True), ConsistencyOptions())
            m.consistency[rid] = (res.mode, res.scale)
    learned = analysis.learned_noise
    if learned is not None and not learned.noise.source.startswith("prior"):
        m.noise = _noise_parameters(learned)
        m.navigated = (learned.receiver_id, learned.imu_id, learned.grade.name.split(" x")[0])
        env = analysis.clean_envelope
        if env is not None and env.runs:
            m.coast_envelope = env.at(np.arange(0.0, float(env.horizon_s[-1]) + 1.0))
    labels = {f"{receivers[0]}-{b}": pair_key(receivers[0], b) for b in receivers[1:]}
    for r in analysis.results:
        if r.name not in (COLLAPSE, PR_COLLAPSE) or not r.ran:
            continue
        for label, facts in r.extras.items():
            if label not in labels or not isinstance(facts, dict) or not facts.get("calibrated_on_clean_part"):
                continue
            k = int(facts["window_samples"])
            fit = RiceFit(float(facts["rice_nu"]), float(facts["rice_sigma"]), float(facts["effective_window"]) / k, k)
            m.pairs.setdefault(labels[label], {})[r.name] = fit
    return m


def pair_key(a: str, b: str) -> str:
    """How a baseline names a receiver pair (receiver ids may hold '-')."""
    return f"{a}|{b}"
