"""Shared benchmark plumbing: run a function in a fresh interpreter and read its time and peak memory."""

from __future__ import annotations

import json
import resource
import subprocess
import sys
from pathlib import Path
from typing import Any

_CHILD = """
import json, sys, time, importlib
from spooflens.bench.common import peak_rss_mb
module, func, args = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
fn = getattr(importlib.import_module(module), func)
t0 = time.perf_counter()
extra = fn(*args)
wall = time.perf_counter() - t0
print(json.dumps({"wall_s": wall, "peak_rss_mb": peak_rss_mb(), "result": extra}))
"""


def peak_rss_mb() -> float:
    """This process's peak resident memory (MB). Linux's VmHWM, of the process's own memory since it
    began its program: `ru_maxrss` is not, since it keeps the high water of the process it was forked
    from (a child started by a benchmark that holds 600 MB reported at least 600 MB)."""
    try:
        with Path("/proc/self/status").open() as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def measure_in_child(module: str, func: str, *args: Any, memory_limit_mb: float | None = None) -> dict[str, Any]:
    """Call module.func(*args) in a new Python process; its wall time, peak RSS and JSON-able result.

    `memory_limit_mb` caps the child's data segment (RLIMIT_DATA: heap and anonymous mappings), so a
    run that would take more fails with a MemoryError (CalledProcessError here) instead of pressing on a
    shared machine.
    """

    def limit() -> None:
        if memory_limit_mb is not None:
            cap = int(memory_limit_mb * 1024 * 1024)
            resource.setrlimit(resource.RLIMIT_DATA, (cap, cap))

    out = subprocess.run(
        [sys.executable, "-c", _CHILD, module, func, json.dumps(list(args))],
        check=True,
        capture_output=True,
        text=True,
        preexec_fn=limit if memory_limit_mb is not None else None,
    )
    result: dict[str, Any] = json.loads(out.stdout.strip().splitlines()[-1])
    return result
