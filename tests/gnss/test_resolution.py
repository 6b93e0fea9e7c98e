"""The step a log writes its numbers with, read off the numbers."""

from __future__ import annotations

import numpy as np

from spooflens.constants import KNOT_MPS
from spooflens.gnss.resolution import angle_step_deg, decimal_step, position_steps_m, speed_step_mps


def test_nmea_minutes_and_knots_are_found() -> None:
    minutes = np.array([9.2031, 9.2030, 9.2031, 9.2034])
    assert np.isclose(angle_step_deg(60.0 + minutes / 60.0) * 60.0, 1e-4)
    assert np.isclose(speed_step_mps(np.array([0.0, 0.4, 0.2, 0.3]) * KNOT_MPS) / KNOT_MPS, 0.1)
    assert np.isclose(speed_step_mps(np.array([3.6, 7.2, 12.5]) / 3.6) * 3.6, 0.1)  # km/h with one decimal


def test_integer_scaled_degrees_and_centimetres() -> None:
    assert np.isclose(angle_step_deg(np.array([471234567, 471234569, 471234999]) * 1e-7), 1e-7)
    assert np.isclose(decimal_step(np.array([1234, -5, 17]) * 0.01), 0.01)


def test_doubles_written_in_full_have_no_step() -> None:
    rng = np.random.default_rng(3)
    assert angle_step_deg(47.0 + rng.random(50) * 1e-3) == 0.0
    assert speed_step_mps(rng.random(50) * 10) == 0.0
    assert angle_step_deg(np.array([47.5])) == 0.0  # one value: no change to read a step from


def test_a_step_is_never_coarser_than_the_smallest_change() -> None:
    # two values 0.0002' apart also lie on a 0.0002' grid, which no unit writes: the 0.0001' one is taken,
    # never more than the change itself
    step = angle_step_deg(60.0 + np.array([9.2030, 9.2032]) / 60.0) * 60.0
    assert 1e-4 - 1e-9 <= step <= 2e-4 + 1e-9


def test_position_steps_in_metres() -> None:
    lat = 60.0 + np.array([9.2031, 9.2030, 9.2031]) / 60.0
    lon = 24.0 + np.array([53.6519, 53.6520, 53.6525]) / 60.0
    east, north, up = position_steps_m(lat, lon, np.array([12.3, 12.4, 12.3]))
    assert 0.18 < north < 0.19 and 0.09 < east < 0.095 and np.isclose(up, 0.1)
