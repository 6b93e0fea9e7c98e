"""The analysis runner: every registered analysis in order, a missing input or an error as its reason,
and an analysis that finishes later (the navigation's smoothed track) in its place."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from spooflens import threads
from spooflens.detectors.base import DetectorResult
from spooflens.errors import AnalysisError
from spooflens.pipeline import registry
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, AnalyzeOptions, DetectorInfo, Later, run_analyses
from spooflens.simulation.simulate import simulate


def _spec(name: str, run: object) -> AnalysisSpec:
    return AnalysisSpec(name, name, (), run, (DetectorInfo(name, None, name),))  # type: ignore[arg-type]


def _done(name: str) -> DetectorResult:
    return DetectorResult(name, True, "ran")


def test_an_analysis_that_finishes_later_takes_its_place_and_the_ones_after_it_run_meanwhile(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    order: list[str] = []
    gate = threading.Event()  # the background work is held until the analyses after it have run

    def slow_product(ctx: AnalysisContext) -> Later:
        work = threads.started(lambda: gate.wait(10) and "track")
        return Later(lambda: [DetectorResult("product", True, str(work.result()))])

    def after(ctx: AnalysisContext) -> list[DetectorResult]:
        order.append("after")
        assert [r.name for r in ctx.results] == ["first"]  # the later one has not joined yet
        gate.set()
        return [_done("after")]

    def failing_later(ctx: AnalysisContext) -> Later:
        def finish() -> list[DetectorResult]:
            raise AnalysisError("the smoother met a covariance it cannot invert")

        return Later(finish)

    specs = [
        _spec("first", lambda ctx: [_done("first")]),
        _spec("product", slow_product),
        _spec("after", after),
        _spec("broken", failing_later),
        _spec("last", lambda ctx: [_done("last")]),
    ]
    monkeypatch.setattr(registry, "analyses", lambda: specs)
    table = simulate("ground", seed=1, duration_s=5.0).table
    for n in (1, 2):
        order.clear()
        gate.clear()
        if n == 1:
            gate.set()  # one thread: the work is made at once, before the analyses after it
        with threads.limited(n):
            results = run_analyses(table, AnalyzeOptions())
        assert [r.name for r in results] == ["first", "product", "after", "broken", "last"]
        assert order == ["after"]
        assert results[1].ran and results[1].reason == "track"
        assert not results[3].ran and "cannot invert" in results[3].reason  # its error: its reason


def test_the_navigation_result_is_in_its_registered_place_with_its_smoothed_track() -> None:
    table = simulate("aircraft", seed=2, duration_s=60.0).table
    results = run_analyses(table)
    names = [r.name for r in results]
    assert names.index("navigation") < names.index("kf_innovation")
    nav = results[names.index("navigation")]
    assert nav.ran and nav.tracks and np.isfinite(nav.tracks[0].lat_deg).all()
