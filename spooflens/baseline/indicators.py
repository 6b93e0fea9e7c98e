"""The receiver indicators a baseline keeps, and how far a clean log's level of each may naturally lie from
another clean log's of the same vehicle: one table, read by the baseline's learning (does a quantity
agree across logs?) and by `receiver_evidence`'s level test (how far off is off?).

`prior` is the between-log spread assumed when the logs cannot tell it (one or two logs): a different
day, place and sky moves a receiver's levels by about this much (choices, see docs/baseline.md).
`resolution` is the least spread ever assumed, however well the logs agree (the indicator's quantisation
and firmware rounding). Indicators that vary by factors (noise, AGC, jamming indicator, DOP, accuracies:
one drone's jamming indicator reads 40, another's 250) are compared as logarithms, their spreads
relative; satellites used and C/N0 (already decibels) as they are. Families group indicators one natural
cause moves together: an obstructed sky moves the whole geometry family (satellites, DOP, accuracies),
more power in the band the RF-power family (noise level, AGC); the jamming indicator and C/N0 are
families of their own. A level alarm needs two families beyond three spreads, or three or more a little
off together the way an attack moves them (`receiver_evidence.joint_level`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TWO_LOG_RANGE = 1.128  # expected range of two normal samples, in standard deviations


@dataclass(frozen=True)
class IndicatorSpread:
    unit: str
    family: str  # "geometry", "rf power", "jamming" or "signal"
    direction: int  # +1 a rise is what an attack does, -1 a fall, 0 either way
    prior_abs: float
    prior_rel: float  # of the centre
    resolution_abs: float
    resolution_rel: float
    log: bool = False  # compared as log(x + resolution_abs): spreads are relative

    def prior(self, centre: float) -> float:
        return max(self.prior_abs, self.prior_rel * abs(centre))

    def resolution(self, centre: float) -> float:
        return max(self.resolution_abs, self.resolution_rel * abs(centre))

    def scale(self, x: float | np.ndarray) -> np.ndarray:
        """The values on the scale they are compared on (logarithms for factor-varying indicators)."""
        x = np.asarray(x, dtype=float)
        return np.log(np.maximum(x, 0.0) + self.resolution_abs) if self.log else x

    def prior_on_scale(self, centre: float) -> float:
        return float(np.log1p(self.prior_rel)) if self.log else self.prior(centre)

    def resolution_on_scale(self, centre: float) -> float:
        return float(np.log1p(self.resolution_rel)) if self.log else self.resolution(centre)


# direction: a capture inflates accuracies and DOP, drops satellites, raises noise; the jamming
# indicator and AGC move either way (real PX4 logs attacked throughout read a tenth of their jamming
# indicator: issue 42), and C/N0 rises (a spoofer is louder than the sky; a fall is obstruction or jamming)
INDICATORS: dict[str, IndicatorSpread] = {
    "h_acc_m": IndicatorSpread("m", "geometry", +1, 0.05, 0.25, 0.01, 0.03, log=True),
    "v_acc_m": IndicatorSpread("m", "geometry", +1, 0.05, 0.25, 0.01, 0.03, log=True),
    "vel_acc_mps": IndicatorSpread("m/s", "geometry", +1, 0.01, 0.25, 0.002, 0.03, log=True),
    "sats_used": IndicatorSpread("", "geometry", -1, 1.5, 0.0, 0.5, 0.0),
    "hdop": IndicatorSpread("", "geometry", +1, 0.05, 0.15, 0.01, 0.03, log=True),
    "vdop": IndicatorSpread("", "geometry", +1, 0.05, 0.15, 0.01, 0.03, log=True),
    "noise_per_ms": IndicatorSpread("", "rf power", +1, 2.0, 0.05, 1.0, 0.01, log=True),
    "jamming_indicator": IndicatorSpread("", "jamming", 0, 5.0, 0.25, 1.0, 0.02, log=True),
    "agc": IndicatorSpread("", "rf power", 0, 10.0, 0.05, 1.0, 0.01, log=True),
    "cn0_mean_dbhz": IndicatorSpread("dB-Hz", "signal", +1, 1.5, 0.0, 0.3, 0.0),
}
SATELLITE_CN0 = IndicatorSpread("dB-Hz", "signal", +1, 1.5, 0.0, 0.3, 0.0)
