"""Baselines for tests: measurements of made-up clean logs, aggregated as `spooflens baseline` does."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from spooflens.baseline.format import Baseline, Quantity
from spooflens.baseline.identity import Identity
from spooflens.baseline.indicators import INDICATORS
from spooflens.baseline.learn import aggregate
from spooflens.baseline.loaded import LoadedBaseline
from spooflens.baseline.measure import ClockLevel, Level, LogMeasurement, level
from spooflens.epoch_table import EpochTable
from spooflens.schema import make_frame

RID = "gps"


def measurement(
    k: int,
    levels: Mapping[str, tuple[float, float]],
    model: str | None = "u-blox ZED-F9P",
    noise: Mapping[str, float] | None = None,
    rid: str = RID,
) -> LogMeasurement:
    """Clean log k: each indicator's (median, robust scale) as given."""
    m = LogMeasurement(
        f"clean{k}.ulg", f"{k:064x}", 600.0, Identity({rid: model}, ("HPG 1.32",), ("PX4 v1.15",), ("imu",))
    )
    m.indicators[rid] = {c: Level(med, scale, 3000) for c, (med, scale) in levels.items()}
    m.clocks[rid] = ClockLevel("boot clock", True, 0.02, 30.0 + k)
    m.consistency[rid] = ("position change vs reported velocity", np.array([0.3, 0.3, 0.6]))
    if noise is not None:
        m.noise = dict(noise)
        m.navigated = (rid, "imu", "consumer_mems")
    return m


def indicator_levels(table: EpochTable, k: int) -> LogMeasurement:
    """Clean log k's receiver indicators as `spooflens baseline` measures them (nothing left out), and
    nothing else: a baseline of these caps no noise and supplies no other level."""
    ident = Identity({rid: None for rid in table.receivers()}, (), (), ())
    m = LogMeasurement(f"clean{k}", f"{k:064x}", float(table.duration_s), ident)
    for rid in table.receivers():
        fx = table.fixes_of(rid)
        levels = {c: lv for c in INDICATORS if c in fx and (lv := level(fx[c].to_numpy(dtype=float)))}
        m.indicators[rid] = levels
    return m


def px4_like(n: int = 4, seed: int = 0) -> Baseline:
    """A drone's receiver over n clean flights: noise ~95, jamming indicator ~40, C/N0 ~42 dB-Hz."""
    rng = np.random.default_rng(seed)
    ms = [
        measurement(
            k,
            {
                "noise_per_ms": (95.0 * (1 + rng.normal(0, 0.02)), 3.0),
                "jamming_indicator": (40.0 * (1 + rng.normal(0, 0.08)), 4.0),
                "cn0_mean_dbhz": (42.0 + rng.normal(0, 0.5), 0.6),
                "sats_used": (14.0 + round(rng.normal(0, 0.5)), 1.0),
                "hdop": (0.8 * (1 + rng.normal(0, 0.04)), 0.05),
            },
            noise={"w_h": 0.2, "w_v": 0.4, "b_h": 1.0 + 0.1 * k, "b_v": 2.0, "tau_p": 100.0, "imu": 1.0},
        )
        for k in range(n)
    ]
    return aggregate(ms)


def loaded(baseline: Baseline, name: str = "drone.baseline.json") -> LoadedBaseline:
    return LoadedBaseline(baseline, name, "0" * 64)


def quantity(values: list[float], unit: str = "m") -> Quantity:
    """A quantity measured on clean logs with these per-log values (they agree)."""
    from spooflens.baseline.learn import between_spread

    return Quantity(float(np.median(values)), unit, tuple(values), None, between_spread(values), True)


def receiver_fixes(
    noise: float, jamming: float, cn0: float = 42.0, hdop: float = 0.8, seconds: float = 600.0, seed: int = 1
) -> pd.DataFrame:
    """A still u-blox receiver's 5 Hz fixes with its indicators at these levels and their usual scatter
    (noise level +-3, jamming indicator +-4, mean C/N0 +-0.6 dB, HDOP +-0.03): the levels tests' log."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 0.2)
    n = len(t)
    return make_frame(
        "fixes",
        {
            "t_s": t,
            "receiver_id": np.full(n, "gps"),
            "lat_deg": np.full(n, 47.0),
            "lon_deg": np.full(n, 8.0),
            "height_m": np.full(n, 500.0),
            "fix_type": np.full(n, 2),
            "noise_per_ms": np.round(noise + rng.normal(0, 3.0, n)),
            "jamming_indicator": np.clip(np.round(jamming + rng.normal(0, 4.0, n)), 0, 255),
            "cn0_mean_dbhz": cn0 + rng.normal(0, 0.6, n),
            "sats_used": np.full(n, 14.0),
            "hdop": hdop + rng.normal(0, 0.03, n),
        },
    )
