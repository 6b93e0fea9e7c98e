"""The noise learning with a vehicle's baseline: started from its values, never above its allowance."""

from __future__ import annotations

from spooflens.navigation.noise_learning import NoisePrior, learn_noise
from spooflens.navigation.product import imu_preset, solve_navigation
from spooflens.pipeline.registry import AnalyzeOptions
from spooflens.simulation.simulate import simulate


def test_a_prior_caps_what_the_log_may_learn() -> None:
    table = simulate("ground", seed=7, duration_s=120.0).table
    options = AnalyzeOptions()
    nav = solve_navigation(table, options)
    free = nav.learned
    preset = imu_preset(options)
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
