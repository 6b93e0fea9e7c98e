"""The step a log writes its numbers with, read off the numbers themselves.

A receiver or logger rounds what it writes: NMEA to 0.0001' of latitude (18 cm) and 0.1 kn of speed (5 cm/s),
older autopilots to 1e-7 degrees or 1 cm/s. Below that step no test can ask position and velocity to agree,
so a noise scale learned from a quiet stretch (where the rounding is all there is) must not fall under it.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from spooflens.constants import KNOT_MPS, WGS84_A_M

FloatArray = NDArray[np.float64]

# the grids logs write on: a unit and its decimals (degrees or arc-minutes; m/s, knots or km/h)
_ANGLE_UNITS_DEG = (1.0, 1.0 / 60.0)
_SPEED_UNITS_MPS = (1.0, KNOT_MPS, 1.0 / 3.6)
_SI_UNITS = (1.0,)
_DECIMALS = range(0, 10)
# a value on the grid is within this fraction of a step of a grid point (a decimal read into a double and
# converted, e.g. minutes to degrees, is off by far less)
_ON_GRID = 1e-4


def written_step(x: FloatArray, units: tuple[float, ...]) -> float:
    """The coarsest step, a unit times a power of ten, that every finite value of `x` lies on; 0 when the
    values lie on none (doubles written in full). Never coarser than the smallest change between the values,
    so a log of few distinct values cannot be given a step it does not have."""
    v = np.unique(np.asarray(x, float)[np.isfinite(x)])
    if len(v) < 2:
        return 0.0
    smallest_change = float(np.min(np.diff(v)))
    best = 0.0
    for unit in units:
        for k in _DECIMALS:
            step = unit * 10.0**-k
            if step > smallest_change * (1 + _ON_GRID) or step <= best:
                continue
            r = v / step
            if np.all(np.abs(r - np.round(r)) <= _ON_GRID):
                best = step
                break
    return best


def angle_step_deg(x: FloatArray) -> float:
    """Step of a latitude or longitude in degrees (written in degrees or in degrees and minutes)."""
    return written_step(x, _ANGLE_UNITS_DEG)


def speed_step_mps(speed_mps: FloatArray) -> float:
    """Step of a speed in m/s (written in m/s, knots or km/h)."""
    return written_step(speed_mps, _SPEED_UNITS_MPS)


def decimal_step(x: FloatArray) -> float:
    """Step of a value written in decimals of its SI unit: a height in m, a velocity component in m/s (mm/s
    or cm/s integers scaled, or decimals)."""
    return written_step(x, _SI_UNITS)


def position_steps_m(lat_deg: FloatArray, lon_deg: FloatArray, height_m: FloatArray) -> FloatArray:
    """East, north and up steps of a log's fixes in metres (0 where an axis is written in full)."""
    lat0 = float(np.nanmedian(lat_deg)) if np.isfinite(lat_deg).any() else 0.0
    metres_per_deg = math.radians(1.0) * WGS84_A_M
    return np.array(
        [
            angle_step_deg(lon_deg) * metres_per_deg * math.cos(math.radians(lat0)),
            angle_step_deg(lat_deg) * metres_per_deg,
            decimal_step(height_m),
        ]
    )
