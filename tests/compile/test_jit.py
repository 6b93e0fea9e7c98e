"""`spooflens.compile.jit`: numba is imported at the first call of a compiled kernel, never by a log without one.

Each check runs in a new interpreter: this one has long imported numba for other tests."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from spooflens.bench.e2e_bench import write_gnss_only


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


def test_the_first_kernel_called_puts_dispatchers_in_place_of_every_wrapper() -> None:
    out = _run(
        "import sys\n"
        "import spooflens.estimation.marginalised_likelihood as mlrt\n"
        "import spooflens.estimation.kalman_update as update\n"
        "import spooflens.navigation.kernels as kernels\n"
        "from spooflens.compile.jit import LazyKernel\n"
        "assert 'numba' not in sys.modules\n"
        "assert isinstance(kernels.gravity, LazyKernel) and isinstance(kernels.update_scratch, LazyKernel)\n"
        "python_value = kernels.gravity.function(0.7, 120.0)\n"
        "value = kernels.gravity(0.7, 120.0)\n"
        "from numba.core.dispatcher import Dispatcher\n"
        "assert 'numba' in sys.modules and value == python_value\n"
        # the defining module's names and the names other modules imported from it are the dispatchers
        "assert isinstance(kernels.gravity, Dispatcher) and isinstance(update.update_scratch, Dispatcher)\n"
        "assert kernels.update_scratch is update.update_scratch is mlrt.update_scratch\n"
        "from spooflens.compile.jit import njit\n"
        "assert isinstance(njit(cache=False)(lambda x: x + 1), Dispatcher)\n"  # later kernels: dispatchers
        "print('ok')\n"
    )
    assert out.strip() == "ok"
