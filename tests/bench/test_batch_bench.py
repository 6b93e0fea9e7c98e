"""`spooflens bench batch`'s measure of what the machine gives two processes at once."""

from __future__ import annotations

import os

from spooflens.bench.batch_bench import _spin, core_scaling


def test_the_loop_is_timed_on_a_clock_two_processes_share() -> None:
    start, end = _spin(200)
    assert 0.0 < end - start < 5.0


def test_two_processes_at_once_do_at_most_twice_the_work_of_one() -> None:
    ratio = core_scaling(5_000)
    # one core gives about 1 (the two take turns), two free cores about 2; never much more than 2
    low = 0.5 if (os.cpu_count() or 1) < 2 else 0.8
    assert low < ratio < 2.4
