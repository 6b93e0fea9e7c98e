"""Independent pieces of an analysis side by side: same answers as one after the other."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from spooflens import threads
from spooflens.attacks import apply_attack, parse_attack
from spooflens.detectors import mlrt
from spooflens.navigation.product import solve_navigation
from spooflens.pipeline.registry import AnalyzeOptions
from spooflens.simulation.simulate import simulate


def test_two_pieces_really_run_at_once_and_come_back_in_order() -> None:
    meet = threading.Barrier(2, timeout=10)  # only passes when both calls are running together

    def piece(value: int) -> int:
        meet.wait()
        return value

    with threads.limited(2):
        assert threads.in_parallel([lambda: piece(1), lambda: piece(2)]) == [1, 2]


def test_one_thread_runs_the_pieces_in_the_caller_one_after_the_other() -> None:
    seen: list[str] = []

    def piece(value: int) -> int:
        seen.append(threading.current_thread().name)
        return value

    with threads.limited(1):
        assert threads.in_parallel([lambda: piece(1), lambda: piece(2), lambda: piece(3)]) == [1, 2, 3]
    assert seen == [threading.current_thread().name] * 3


def test_a_piece_queued_behind_busy_workers_runs_on_the_calling_thread() -> None:
    # both workers held by work started earlier (the smoother, the windowed pass): the caller does not
    # sit waiting for one of them, it runs the queued piece itself, and the answers keep their order
    release = threading.Event()
    with threads.limited(2):
        busy = [threads.started(lambda: release.wait(10)) for _ in range(2)]
        caller = threading.current_thread().name
        ran_on: list[str] = []

        def piece(value: int) -> int:
            ran_on.append(threading.current_thread().name)
            return value

        assert threads.in_parallel([lambda: piece(1), lambda: piece(2), lambda: piece(3)]) == [1, 2, 3]
        assert not release.is_set() and ran_on == [caller] * 3
        release.set()
        assert all(b.result(10) for b in busy)


def test_a_piece_on_the_pool_runs_its_own_pieces_side_by_side_and_never_waits_for_a_queued_one() -> None:
    meet = threading.Barrier(2, timeout=10)  # passes only when the two inner pieces run together

    def inner(value: int) -> int:
        meet.wait()
        return value

    def outer() -> list[int]:  # runs on a worker; the other worker is free
        return threads.in_parallel([lambda: inner(1), lambda: inner(2)])

    def nested_when_busy() -> list[int]:  # both workers taken by the outer pieces: runs its own
        return threads.in_parallel([lambda: 3, lambda: 4])

    with threads.limited(2):
        assert threads.in_parallel([lambda: 0, outer]) == [0, [1, 2]]
        assert threads.in_parallel([nested_when_busy, nested_when_busy, nested_when_busy]) == [[3, 4]] * 3


def test_the_environment_sets_the_threads_and_nonsense_is_ignored(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(threads.ENV, "1")
    assert threads.thread_count() == 1
    monkeypatch.setenv(threads.ENV, "zero")
    assert 1 <= threads.thread_count() <= 2
    with threads.limited(1):
        monkeypatch.setenv(threads.ENV, "2")
        assert threads.thread_count() == 1  # a batch worker's limit wins


def test_an_error_in_either_piece_is_raised_after_both_finish() -> None:
    finished = threading.Event()

    def slow() -> int:
        finished.wait(0.2)
        finished.set()
        return 1

    def bad() -> int:
        raise ValueError("piece failed")

    with threads.limited(2), pytest.raises(ValueError, match="piece failed"):
        threads.in_parallel([bad, slow])
    assert finished.is_set()
    with threads.limited(2), pytest.raises(ValueError, match="piece failed"):
        threads.in_parallel([slow, bad])


def test_a_piece_that_splits_again_runs_its_parts_in_its_own_thread() -> None:
    def inner() -> list[int]:
        return threads.in_parallel([lambda: 1, lambda: 2])

    with threads.limited(2):
        assert threads.in_parallel([inner, inner, inner]) == [[1, 2]] * 3


def test_a_started_call_runs_beside_the_caller_and_its_future_holds_the_answer_or_the_error() -> None:
    meet = threading.Barrier(2, timeout=10)  # only passes when the call runs while the caller goes on

    def piece() -> str:
        meet.wait()
        return threading.current_thread().name

    with threads.limited(2):
        running = threads.started(piece)
        meet.wait()
        assert running.result() != threading.current_thread().name

    def bad() -> int:
        raise ValueError("piece failed")

    for n in (1, 2):
        with threads.limited(n):
            failed = threads.started(bad)
            with pytest.raises(ValueError, match="piece failed"):
                failed.result()


def test_a_started_call_not_begun_when_its_result_is_wanted_is_made_by_the_caller() -> None:
    release = threading.Event()
    caller = threading.current_thread().name
    with threads.limited(2):
        busy = [threads.started(lambda: release.wait(10)) for _ in range(2)]
        queued = threads.started(lambda: threading.current_thread().name)
        assert threads.finished(queued, lambda: threading.current_thread().name) == caller
        assert queued.cancelled() and not release.is_set()
        release.set()
        assert all(b.result(10) for b in busy)
        begun = threads.started(lambda: threading.current_thread().name)
        assert threads.finished(begun, lambda: "made again") != caller  # begun: waited for, not made twice


def test_with_one_thread_a_started_call_is_made_at_once_in_the_caller() -> None:
    with threads.limited(1):
        done = threads.started(lambda: threading.current_thread().name)
    assert done.done() and done.result() == threading.current_thread().name


def test_side_work_begins_beside_a_compiled_stretch_once_and_is_dropped_when_none_comes() -> None:
    meet = threading.Barrier(2, timeout=10)  # passes only while the side work runs beside the stretch
    ran: list[str] = []

    def side() -> None:
        meet.wait()
        ran.append(threading.current_thread().name)

    def failing() -> None:
        raise RuntimeError("a side import that fails is left to the code that needs it")

    with threads.limited(2), threads.side_work(failing, side):
        with threads.core_idle():
            meet.wait()
        with threads.core_idle():  # the queue was emptied: nothing runs twice
            pass
    deadline = time.monotonic() + 10
    while not ran and time.monotonic() < deadline:
        time.sleep(0.01)
    assert len(ran) == 1 and ran[0] != threading.current_thread().name

    never: list[int] = []
    with threads.limited(1), threads.side_work(lambda: never.append(1)), threads.core_idle():
        pass  # one thread: no core to spare
    with threads.limited(2), threads.core_idle():  # the block ended: the queued call went with it
        pass
    assert never == [] and threads._side == []


def test_the_navigation_and_seed000_in_two_threads_answer_exactly_as_in_one() -> None:
    """Noise learning's candidate runs and seed 000's two passes side by side change nothing but the
    count of filter runs (a candidate run after one that already improved is wasted)."""
    table = simulate("aircraft", seed=3, duration_s=120.0).table
    spoofed, _ = apply_attack(table, parse_attack("ramp:rate=3,axes=en,start=70"))
    runs = []
    for n in (1, 2):
        with threads.limited(n):
            nav = solve_navigation(spoofed, AnalyzeOptions())
            runs.append((nav, mlrt.detect(nav.model)))
    (nav1, det1), (nav2, det2) = runs
    assert nav1.learned.noise == nav2.learned.noise and nav1.learned.imu_scale == nav2.learned.imu_scale
    # one thread stops at the first better candidate; two run the pair and may waste the second
    assert nav1.learned.evaluations <= nav2.learned.evaluations
    np.testing.assert_array_equal(nav1.solution.nis, nav2.solution.nis)
    np.testing.assert_array_equal(nav1.smoothed.track_llh, nav2.smoothed.track_llh)  # begun in the background
    assert any(r.alarms for r in det1)  # the onset posteriors (ramp and step side by side) ran
    for a, b in zip(det1, det2, strict=True):
        assert [(x.start_s, x.end_s, x.onset_s, x.onset_interval_s) for x in a.alarms] == [
            (x.start_s, x.end_s, x.onset_s, x.onset_interval_s) for x in b.alarms
        ]
        for sa, sb in zip(a.series, b.series, strict=True):
            np.testing.assert_array_equal(sa.values, sb.values, err_msg=f"{a.name}/{sa.name}")
        for ca, cb in zip(a.curves, b.curves, strict=True):
            np.testing.assert_array_equal(ca.y, cb.y, err_msg=f"{a.name}/{ca.name}")


def test_the_analyses_after_seed000_run_before_its_offline_pass_is_waited_for(monkeypatch: pytest.MonkeyPatch) -> None:
    """Seed 000 returns `Later`: the innovation tests run while its offline pass finishes, and every
    result still comes in the run order."""
    from dataclasses import replace

    from spooflens.detectors import innovation_tests
    from spooflens.detectors.base import DetectorResult
    from spooflens.pipeline.registry import AnalysisContext, Later, run_with_context

    order: list[str] = []
    results_of = mlrt._results

    def results(*args: object) -> list[DetectorResult]:
        order.append("seed000 finished")
        return results_of(*args)  # type: ignore[arg-type]

    run_tests = innovation_tests.ANALYSIS.run

    def tests_run(ctx: AnalysisContext) -> list[DetectorResult] | Later:
        order.append("innovation tests")
        return run_tests(ctx)

    monkeypatch.setattr(mlrt, "_results", results)
    monkeypatch.setattr(innovation_tests, "ANALYSIS", replace(innovation_tests.ANALYSIS, run=tests_run))
    table = simulate("aircraft", seed=3, duration_s=60.0).table
    steps: list[str] = []
    names = [r.name for r in run_with_context(AnalysisContext(table, AnalyzeOptions()), steps.append)]
    assert order == ["innovation tests", "seed000 finished"]
    assert steps[-1] == "finishing navigation, inertial"  # the wait for them is shown as theirs
    declared = [d.name for d in mlrt.ANALYSIS.detectors] + [d.name for d in innovation_tests.ANALYSIS.detectors]
    assert [n for n in names if n in declared] == declared


def test_a_forked_child_of_a_process_that_used_the_pool_runs_pieces_side_by_side_again(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The fuzz sandbox forks a server that has analysed a log: its pool's threads stay behind, so the
    child must make its own pool, not wait for ever on the parent's (each run timed out before)."""
    import os
    import signal

    monkeypatch.setenv(threads.ENV, "2")
    assert threads.in_parallel([lambda: 1, lambda: 2]) == [1, 2]  # the parent's pool exists now
    pid = os.fork()
    if pid == 0:  # the child: a hang is ended by the alarm, and shows as a signal below
        signal.alarm(20)
        ok = threads.in_parallel([lambda: 3, lambda: 4]) == [3, 4]
        os._exit(0 if ok else 1)
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0
