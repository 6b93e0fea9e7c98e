"""`spooflens bench learning`: the analysis's search beside more sweeps of it."""

from __future__ import annotations

from spooflens.bench.learning_bench import learn_with_sweeps
from spooflens.simulation.simulate import simulate


def test_more_sweeps_start_where_the_analysis_stopped_so_they_never_learn_a_worse_likelihood() -> None:
    """Without odometry, that is: with it, the odometry's own search starts from where the first ended,
    and a first search that went further may leave the second a worse start."""
    table = simulate("aircraft", seed=7, duration_s=330.0).table
    two, three = learn_with_sweeps(table, (2, 3))
    assert two["is_the_analysis"]  # the first row is the noise the analysis runs on, to the last digit
    assert three["runs"] >= two["runs"] and three["nll"] <= two["nll"]
    # this tactical-grade simulated IMU is far quieter than the consumer preset the search starts from:
    # the third sweep still moves the IMU scale down (two sweeps reach at most 1/27 of the preset)
    assert two["imu_scale"] >= 1 / 27 - 1e-12 and three["imu_scale"] < two["imu_scale"]
