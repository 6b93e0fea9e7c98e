"""`spooflens.compile.jit`: numba imported only for a call ahead-of-time code cannot answer, and for that call only.

The import check runs in a new interpreter: this one has long imported numba for other tests."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spooflens.bench.e2e_bench import write_gnss_only
from spooflens.compile import aot
from spooflens.compile.jit import LazyKernel, njit


def _run(code: str) -> str:
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_a_log_of_gnss_fixes_only_is_analysed_without_importing_numba(tmp_path: Path) -> None:
    log = tmp_path / "gnss_only.mcap"
    write_gnss_only(str(log))
    out = _run(
        "import sys\n"
        "from readers import read_log\n"
        "from spooflens.pipeline.run import analyze_table\n"
        f"analyses = analyze_table(read_log({str(log)!r}))\n"
        "print(analyses.verdict.spoofed, 'numba' in sys.modules)\n"
    )
    assert out.split() == ["False", "False"]


@njit(cache=False, inline="always")
def _scaled(x: float, k: float = 2.0) -> float:
    return x * k


@njit(cache=False)
def _sum_scaled(a: np.ndarray) -> float:
    total = 0.0
    for v in a:
        total += _scaled(v)  # a kernel called (and inlined) from a kernel
    return total


def test_a_kernel_calls_and_inlines_a_kernel_inside_numba() -> None:
    assert isinstance(_sum_scaled, LazyKernel) and isinstance(_scaled, LazyKernel)
    assert _sum_scaled(np.arange(4.0)) == 12.0


def test_a_call_numba_must_compile_leaves_the_other_calls_on_their_ahead_of_time_builds(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    ran: list[tuple[object, ...]] = []

    def ahead(*args: object) -> float:
        ran.append(args)
        return -1.0  # not what the kernel computes: shows which one answered

    built_for = aot.type_key((1.5, 2.0))  # the full signature: the default given
    name = aot.kernel_name(_scaled.py_func)  # type: ignore[attr-defined]
    monkeypatch.setattr(aot, "_table", {(name, built_for): ahead})
    assert _scaled(1.5, np.float32(2.0)) == 3.0  # type: ignore[arg-type]  # types it was not built for: numba
    assert _scaled(1.5, 2.0) == -1.0  # the next call with its types: the build, numba running or not
    assert _scaled(1.5) == -1.0  # the default left out: the same signature, the same build
    assert ran == [(1.5, 2.0), (1.5, 2.0)]
    monkeypatch.setattr(aot, "_table", None)  # the next test loads the table afresh
