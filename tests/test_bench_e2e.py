"""`spooflens bench e2e --repeat N`: the run reported is the median one, with the spread beside it."""

from __future__ import annotations

from spooflens.bench.e2e_bench import _median_run, _spread


def test_the_median_run_is_reported_whole_and_the_lower_middle_of_an_even_count() -> None:
    runs = [{"wall_s": w, "stages": [w]} for w in (9.0, 8.0, 12.0)]
    assert _median_run(runs) == {"wall_s": 9.0, "stages": [9.0]}  # its stage table goes with it
    assert _median_run([{"wall_s": w} for w in (4.0, 1.0, 3.0, 2.0)]) == {"wall_s": 2.0}
    assert _spread(runs) == " (8.00-12.00)"
    assert _spread(runs[:1]) == ""  # one run: no spread to show
