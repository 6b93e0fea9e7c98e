"""`spooflens bench e2e`: the median run of `--repeat N` with the spread beside it; what a product holds."""

from __future__ import annotations

from pathlib import Path

import pytest

from spooflens.bench.common import measure_in_child
from spooflens.bench.e2e_bench import SAMPLE, _median_run, _spread, held_bytes
from spooflens.bench.e2e_plot import E2EFigures, plot_e2e


def test_the_median_run_is_reported_whole_and_the_lower_middle_of_an_even_count() -> None:
    runs = [{"wall_s": w, "stages": [w]} for w in (9.0, 8.0, 12.0)]
    assert _median_run(runs) == {"wall_s": 9.0, "stages": [9.0]}  # its stage table goes with it
    assert _median_run([{"wall_s": w} for w in (4.0, 1.0, 3.0, 2.0)]) == {"wall_s": 2.0}
    assert _spread(runs) == " (8.00-12.00)"
    assert _spread(runs[:1]) == ""  # one run: no spread to show


def test_what_a_product_holds_counts_each_array_once_through_fields_dicts_and_finished_futures() -> None:
    from concurrent.futures import Future
    from dataclasses import dataclass

    import numpy as np

    @dataclass
    class Product:
        big: np.ndarray
        again: np.ndarray  # the same array under a second path
        smoothing: Future[dict[str, np.ndarray]]

    track = np.zeros(250_000)  # 2 MB
    done: Future[dict[str, np.ndarray]] = Future()
    done.set_result({"track": track})
    big = np.zeros(500_000)
    failed: Future[np.ndarray] = Future()
    failed.set_exception(ValueError("no smoothing"))
    held = held_bytes({"nav": Product(big, big, done), "broken": failed, "pending": Future()})
    assert held == {"nav.big": 4.0, "nav.smoothing.result()[track]": 2.0}


def test_the_first_run_by_part_never_starts_numba_and_the_second_analysis_answers_the_same(tmp_path: Path) -> None:
    parts = measure_in_child("spooflens.bench.e2e_bench", "first_run_parts", str(SAMPLE), str(tmp_path))["result"]
    names = [s["stage"] for s in parts["stages"]]
    assert names == [
        "imports of spooflens analyze",
        "read",
        "analysis (first)",
        "recording + JSON",
        "analysis (again, same process)",
        "recording + JSON (again)",
    ]
    first, again = parts["verdicts"]
    assert first == again and first[0].startswith("SPOOFING DETECTED")
    assert parts["numba_imported"] is False  # every kernel it calls was compiled ahead of time at install
    assert all((tmp_path / f"parts{k}.rrd").stat().st_size > 0 for k in (0, 1))


def _figures() -> E2EFigures:
    """The eleventh session's `bench e2e --repeat 5`, as the command collects it."""
    return E2EFigures(
        hour_stages=[("import", 0.20), ("read", 0.84), ("analysis: navigation", 1.55), ("recording + JSON", 0.26)],
        hour_wall_s=4.71,
        hour_goal_by_loop_s=5.0 / 7.9 * 6.55,
        voyage=[(1.0, 2.2, 3.5, 376.0), (4.0, 5.9, 7.6, 502.0), (24.0, 35.5, 43.0, 1748.0)],
        first_runs=[("compiled ahead of time", [1.69, 1.70, 1.72, 1.74, 1.71]), ("empty numba cache", [68.9])],
    )


def test_the_plot_draws_each_measured_part_beside_its_goal(tmp_path: Path) -> None:
    path = tmp_path / "e2e.svg"
    plot_e2e(_figures(), path)
    svg = path.read_text()
    expected = ("1 h aircraft log end to end: 4.71 s", "goal 5 s", "ratio to the rosbags loop: 4.15 s", "voyage length")
    for text in expected:
        assert text in svg, text
    assert "1.71 s" in svg and "68.90 s" in svg  # each first run's median, written on its bar
    only_voyage = E2EFigures(voyage=_figures().voyage)
    plot_e2e(only_voyage, tmp_path / "voyage.png")
    assert (tmp_path / "voyage.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_plot_of_nothing_measured_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="nothing measured"):
        plot_e2e(E2EFigures(), tmp_path / "e2e.svg")


def test_a_child_reports_its_own_peak_memory_not_that_of_the_process_it_was_started_from() -> None:
    """ru_maxrss of a child keeps the high water of the process it was forked from: a benchmark holding
    half a gigabyte made every child it measured look at least that large."""
    import numpy as np

    from spooflens.bench.common import measure_in_child

    held = np.ones(500_000_000 // 8)  # touched: resident
    run = measure_in_child("math", "sqrt", 4.0)
    assert run["result"] == 2.0 and held.sum() > 0
    assert run["peak_rss_mb"] < 200, run
