"""`spooflens bench batch`'s measure of what the machine gives two processes at once."""

from __future__ import annotations

from spooflens.bench.batch_bench import _spin, core_scaling


def test_the_loop_is_timed_on_a_clock_two_processes_share() -> None:
    start, end = _spin(200)
    assert 0.0 < end - start < 5.0


def test_two_processes_at_once_do_at_most_twice_the_work_of_one() -> None:
    ratio = core_scaling(5_000)
    # two free cores give about 2, one core or a loaded machine less (the machine's own state, which
    # `bench batch` reports and a test cannot assume); never much more than 2: each does its own share
    assert 0.0 < ratio < 2.4
