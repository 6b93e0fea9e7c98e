"""Independent pieces of one analysis on the machine's cores.

In depth: docs/install.md."""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager, suppress
from typing import TypeVar

T = TypeVar("T")

ENV = "SPOOFLENS_THREADS"
_MAX_DEFAULT = 2

_lock = threading.Lock()
_pool: ThreadPoolExecutor | None = None
_pool_size = 0
# set in the pool's threads: work `started` there runs at once (its future may be waited for while every
# worker is busy); `in_parallel` may nest, since it never waits for a call that has not begun
_inside = threading.local()
_limit: int | None = None  # set by `limited`
_side: list[Callable[[], object]] = []  # queued by `side_work`, begun by `core_idle`


def thread_count() -> int:
    """Threads an analysis may use: `SPOOFLENS_THREADS` when it is a positive integer, else the cores (<= 2)."""
    if _limit is not None:
        return _limit
    value = os.environ.get(ENV, "").strip()
    if value.isdigit() and int(value) >= 1:
        return int(value)
    return max(1, min(_MAX_DEFAULT, os.cpu_count() or 1))


@contextmanager
def limited(threads: int) -> Iterator[None]:
    """Within the block, analyses use at most `threads` threads (a batch worker: the cores are full)."""
    global _limit
    before = _limit
    _limit = max(1, threads)
    try:
        yield
    finally:
        _limit = before


def _executor(size: int) -> ThreadPoolExecutor:
    global _pool, _pool_size
    with _lock:
        if _pool is None or _pool_size != size:
            if _pool is not None:
                _pool.shutdown(wait=False)
            _pool = ThreadPoolExecutor(max_workers=size, thread_name_prefix="spooflens", initializer=_mark)
            _pool_size = size
        return _pool


def _mark() -> None:
    _inside.active = True


def _forget_pool() -> None:
    """In a forked child: the pool's threads did not come along, so work handed to it would wait for
    ever (the fuzz sandbox forks a process that has analysed a log); the child makes its own."""
    global _lock, _pool, _pool_size
    _lock = threading.Lock()
    _pool, _pool_size = None, 0


os.register_at_fork(after_in_child=_forget_pool)


def in_parallel(calls: Sequence[Callable[[], T]]) -> list[T]:
    """Every call's result, in order; side by side when more than one thread is allowed (an exception is
    raised as the sequential run would have raised it, after the others finish). A call still queued when
    this thread is done with the first (the pool busy with work `started` earlier, or with the pieces of
    the call this one is part of) runs on this thread rather than being waited for: so a piece may run
    pieces of its own side by side, and no thread ever waits for work that has not begun."""
    size = thread_count()
    if size < 2 or len(calls) < 2:
        return [call() for call in calls]
    pool = _executor(size)
    futures = [pool.submit(call) for call in calls[1:]]
    try:
        first = calls[0]()
    finally:
        for k, future in enumerate(futures):
            if future.cancel():  # not begun: nothing is gained by waiting for a worker
                futures[k] = _run_now(calls[k + 1])
        rest = [f.exception() for f in futures]  # wait for all before anything is raised
    for error in rest:
        if error is not None:
            raise error
    return [first, *(f.result() for f in futures)]


def started(call: Callable[[], T]) -> Future[T]:
    """`call` begun on another thread when more than one is allowed, its result (or exception) waiting in
    the future; else made now, the future already done."""
    size = thread_count()
    if size >= 2 and not getattr(_inside, "active", False):
        return _executor(size).submit(call)
    return _run_now(call)


def finished(future: Future[T], call: Callable[[], T]) -> T:
    """The result of `call`, begun with `started` as `future`: made on this thread when it has not begun
    yet (every worker busy), so no thread waits for work that has not begun; else waited for."""
    if future.cancel():
        return call()
    return future.result()


def _run_now(call: Callable[[], T]) -> Future[T]:
    """`call` made on this thread, its result (or exception) in a future that is done."""
    done: Future[T] = Future()
    try:
        done.set_result(call())
    except Exception as err:  # noqa: BLE001 - kept for `result()` to raise, as a background run's would be
        done.set_exception(err)
    return done


A = TypeVar("A")
B = TypeVar("B")


@contextmanager
def side_work(*calls: Callable[[], object]) -> Iterator[None]:
    """Within the block, `calls` wait for the first stretch that leaves a core idle (`core_idle`); those
    not begun by the block's end are dropped (their work is done where it is needed: each call only
    prepares what later code makes for itself when it is missing, and its errors are ignored)."""
    with _lock:
        _side.extend(calls)
    try:
        yield
    finally:
        with _lock:
            _side[:] = [call for call in _side if call not in calls]


@contextmanager
def core_idle() -> Iterator[None]:
    """Around a compiled call that runs alone and releases the GIL: the queued side work begins on
    another thread meanwhile (when more than one thread is allowed)."""
    if thread_count() >= 2 and not getattr(_inside, "active", False):
        with _lock:
            queued = list(_side)
            _side.clear()
        for call in queued:
            _executor(thread_count()).submit(_quietly, call)
    yield


def _quietly(call: Callable[[], object]) -> None:
    with suppress(Exception):  # side work only prepares: the code that needs it fails in place
        call()


def both(first: Callable[[], A], second: Callable[[], B]) -> tuple[A, B]:
    """`in_parallel` of two calls of different result types."""
    a, b = in_parallel([first, second])  # type: ignore[list-item]
    return a, b  # type: ignore[return-value]
