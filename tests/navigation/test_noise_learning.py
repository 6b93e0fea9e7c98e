"""The noise learning with a vehicle's baseline: started from its values, never above its allowance."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from spooflens.navigation.imu_models import ImuGrade
from spooflens.navigation.noise_learning import LearnOptions, NoisePrior, coordinate_search, learn_noise
from spooflens.navigation.product import Navigation, imu_preset, solve_navigation
from spooflens.pipeline.registry import AnalyzeOptions
from spooflens.simulation.simulate import simulate


@cache
def car() -> tuple[Navigation, ImuGrade]:
    """A simulated car's 120 s navigated without a prior, and the IMU preset its noise search starts from."""
    options = AnalyzeOptions()
    return solve_navigation(simulate("ground", seed=7, duration_s=120.0).table, options), imu_preset(options)


def test_a_prior_caps_what_the_log_may_learn() -> None:
    nav, preset = car()
    free = nav.learned
    low = 0.5 * free.noise.white_pos_m[0]  # the simulated car's receiver: white errors of 1.5 m
    prior = NoisePrior({"w_h": low}, {"w_h": low}, "baseline test (2 logs)")
    held = learn_noise(nav.inputs, preset, nav.start, None, (), prior=prior)
    assert held.noise.white_pos_m[0] <= low * (1 + 1e-9)
    assert held.at_upper and held.at_upper[0].startswith("w_h")
    assert "started from the baseline test (2 logs)" in held.describe()
    assert "held at the allowance: w_h" in held.describe()
    # a cap well above what the log wants holds nothing
    roomy = NoisePrior({}, {"w_h": 10.0 * free.noise.white_pos_m[0]}, "baseline roomy (3 logs)")
    assert not learn_noise(nav.inputs, preset, nav.start, None, (), prior=roomy).at_upper


def test_a_prior_floors_what_the_log_may_learn() -> None:
    """Not quieter than the vehicle's quietest clean log: trusting a receiver more than any of its clean days
    did makes ordinary excursions alarms (with a baseline of 2 clean logs the simulated vehicles' clean
    logs raised 4 one-class anomalies, without one 3)."""
    nav, preset = car()
    free = nav.learned
    high = 2.0 * free.noise.white_pos_m[0]
    prior = NoisePrior({"w_h": high}, {"w_h": 4.0 * high}, "baseline test (2 logs)", lower={"w_h": high})
    held = learn_noise(nav.inputs, preset, nav.start, None, (), prior=prior)
    assert held.noise.white_pos_m[0] >= high * (1 - 1e-9)
    # a floor below what the log wants holds nothing
    low = NoisePrior({}, {}, "baseline low (3 logs)", lower={"w_h": 0.1 * free.noise.white_pos_m[0]})
    assert learn_noise(nav.inputs, preset, nav.start, None, (), prior=low).noise.white_pos_m[0] > low.lower["w_h"]


def test_a_wander_held_at_its_size_is_not_made_faster_instead() -> None:
    # a cap on a Gauss-Markov error's size alone lets the search shorten its time constant: the same size
    # moving faster is more noise. With the rate its driving noise feeds it capped (sigma^2 / tau), the
    # time constant goes no lower than the size asks
    nav, preset = car()
    free = nav.learned
    b, tau = free.noise.gm_pos_m[0], free.noise.tau_pos_s
    rate = 0.25 * b * b / tau  # the log's own wander fed four times too fast
    prior = NoisePrior({}, {}, "baseline test (2 logs)", {"b_h": ("tau_p", rate)})
    held = learn_noise(nav.inputs, preset, nav.start, None, (), prior=prior)
    n = held.noise
    assert n.gm_pos_m[0] ** 2 / n.tau_pos_s <= rate * (1 + 1e-9)
    assert any(h.startswith("b_h") and "tau_p" in h for h in held.at_upper)


def test_a_prior_that_stands_says_it_came_from_the_baseline() -> None:
    nav, preset = car()
    prior = NoisePrior({"wv_h": 0.2, "bv_h": 0.05, "tau_v": 20.0, "imu": 2.0}, {}, "baseline test (2 logs)")
    stood = learn_noise(nav.inputs, preset, nav.start, None, ((-10.0, 1e9),), prior=prior)
    assert stood.is_prior
    text = stood.describe()
    assert "from the scatter" not in text and "(defaults)" not in text
    assert "IMU noise 2 x preset" in text


class _Bowl:
    """A likelihood with its best IMU scale at `best`: what `coordinate_search` sees of a log (no filter run)."""

    def __init__(self, best: float) -> None:
        self.best = best

    def __call__(self, opts: float) -> float:
        return 100.0 * float(np.log(opts / self.best)) ** 2

    def first_better(self, candidates: list[float], best: float) -> tuple[int, float] | None:
        return next(((i, v) for i, c in enumerate(candidates) if (v := self(c)) < best), None)


@pytest.mark.parametrize(("optimum", "learned"), [(300.0, (240.0, 380.0)), (1.0 / 300.0, (1 / 27.5, 1 / 26.5))])
def test_a_noise_still_rising_at_the_top_of_the_sweeps_reach_goes_on_and_one_falling_stops_there(
    optimum: float, learned: tuple[float, float]
) -> None:
    # two sweeps of x3 and x sqrt(3) reach 27 times the start: a log noisier than that (log171's vibrating
    # IMU) is searched on; one quieter stays at 1/27 (the INS trusted less than it could be: never more
    # false alarms, and trusting it more would need the long false-alarm runs first)
    bowl, make = _Bowl(optimum), lambda p: p["imu"]
    _, params = coordinate_search(bowl, make, {"imu": 1.0}, ["imu"], LearnOptions())  # type: ignore[arg-type]
    assert learned[0] <= params["imu"] <= learned[1]
