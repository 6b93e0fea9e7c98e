"""The receiver indicators a baseline keeps, and how far a clean log's level of each may naturally lie from
another clean log's of the same vehicle: one table, read by the baseline's learning (does a quantity
agree across logs?) and by `receiver_evidence`'s level test (how far off is off?).

`prior` is the between-log spread assumed when the logs cannot tell it (one or two logs): a different day,
place and sky moves a receiver's levels by about this much (choices, see docs/baseline.md). `resolution`
is the least spread ever assumed, however well the logs agree (the indicator's quantisation and
firmware rounding). Families group indicators one natural cause moves together: an obstructed sky moves
the whole geometry family (satellites, DOP, accuracies), radio interference the RF family (noise, AGC,
jamming indicator); a level alarm needs two families.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class IndicatorSpread:
    unit: str
    family: str  # "geometry", "rf" or "signal"
    direction: int  # +1 a rise is what an attack does, -1 a fall, 0 either way
    prior_abs: float
    prior_rel: float  # of the centre
    resolution_abs: float
    resolution_rel: float

    def prior(self, centre: float) -> float:
        return max(self.prior_abs, self.prior_rel * abs(centre))

    def resolution(self, centre: float) -> float:
        return max(self.resolution_abs, self.resolution_rel * abs(centre))


# direction: a capture inflates accuracies and DOP, drops satellites, raises noise; the jamming
# indicator and AGC move either way (real PX4 logs attacked throughout read a tenth of their jamming
# indicator: issue 42), and C/N0 rises (a spoofer is louder than the sky; a fall is obstruction or jamming)
INDICATORS: dict[str, IndicatorSpread] = {
    "h_acc_m": IndicatorSpread("m", "geometry", +1, 0.05, 0.25, 0.01, 0.03),
    "v_acc_m": IndicatorSpread("m", "geometry", +1, 0.05, 0.25, 0.01, 0.03),
    "vel_acc_mps": IndicatorSpread("m/s", "geometry", +1, 0.01, 0.25, 0.002, 0.03),
    "sats_used": IndicatorSpread("", "geometry", -1, 1.5, 0.0, 0.5, 0.0),
    "hdop": IndicatorSpread("", "geometry", +1, 0.05, 0.15, 0.01, 0.03),
    "vdop": IndicatorSpread("", "geometry", +1, 0.05, 0.15, 0.01, 0.03),
    "noise_per_ms": IndicatorSpread("", "rf", +1, 2.0, 0.05, 1.0, 0.01),
    "jamming_indicator": IndicatorSpread("", "rf", 0, 5.0, 0.25, 1.0, 0.02),
    "agc": IndicatorSpread("", "rf", 0, 10.0, 0.05, 1.0, 0.01),
    "cn0_mean_dbhz": IndicatorSpread("dB-Hz", "signal", +1, 1.5, 0.0, 0.3, 0.0),
}
SATELLITE_CN0 = IndicatorSpread("dB-Hz", "signal", +1, 1.5, 0.0, 0.3, 0.0)
