"""`spooflens.compile.aot`: the kernels compiled ahead of time at install answer as numba's JIT does, bit for bit,
without importing numba; anything they were not built for, or built from other sources, goes to numba.

The module is built by `python -m spooflens.compile.warmup`, which `pip install -e` runs (the README's install):
a checkout installed that way has it, and these tests say so when it is missing."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numba import typeof
from paths import ROOT

from spooflens.compile import aot

SAMPLE = ROOT / "sample_logs" / "spoofed_flight.mcap"


def _analyse(log: Path, out: Path, aot_setting: str) -> tuple[dict, bool]:
    """The JSON summary of `spooflens analyze LOG` in a new process, and whether numba was imported."""
    code = (
        "import sys\n"
        "from spooflens.cli import main\n"
        f"sys.argv = ['spooflens', 'analyze', {str(log)!r}, '-o', {str(out / 'x.rrd')!r}, "
        f"'--json', {str(out / 'x.json')!r}, '--quiet']\n"
        "try:\n    main()\nexcept SystemExit:\n    pass\n"
        "print('numba' in sys.modules)\n"
    )
    env = {**os.environ, aot.ENV: aot_setting}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=False)
    assert done.returncode == 0, done.stderr
    return json.loads((out / "x.json").read_text()), done.stdout.split()[-1] == "True"


def test_the_install_built_the_module_for_the_kernels_an_imu_log_calls() -> None:
    assert aot.MANIFEST.exists(), (
        "no ahead-of-time kernels: run `python -m spooflens.compile.warmup` (pip install -e does)"
    )
    manifest = json.loads(aot.MANIFEST.read_text())
    names = {e["kernel"] for e in manifest["exports"]}
    assert {"spooflens.navigation.kernels:filter_loop", "spooflens.estimation.kalman:_forward"} <= names
    # the kernels' files and what they import from the project (constants numba freezes into the code)
    assert {
        "spooflens/navigation/kernels.py",
        "spooflens/estimation/kalman_update.py",
        "spooflens/constants.py",
    } <= set(manifest["sources"])


def test_an_imu_log_is_analysed_without_numba_and_exactly_as_numba_analyses_it(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "j").mkdir()
    ahead, numba_ahead = _analyse(SAMPLE, tmp_path / "a", "1")
    jit, numba_jit = _analyse(SAMPLE, tmp_path / "j", "0")
    assert not numba_ahead and numba_jit
    for summary in (ahead, jit):  # the output paths differ; everything else is the same to the last bit
        summary.pop("outputs", None)
    assert ahead == jit
    assert ahead["verdict"]["spoofed"]


@pytest.mark.parametrize(
    "value",
    [
        np.zeros(3),
        np.zeros((3, 4)),
        np.zeros((3, 4))[:, 1],  # strided: 'A'
        np.asfortranarray(np.zeros((3, 4))),  # 'F'
        np.zeros((3, 4))[::2],  # rows skipped: 'A'
        np.zeros(5, dtype=np.int64),
        np.zeros(5, dtype=np.bool_),
        np.zeros(5, dtype=np.uint8),
        np.zeros(5, dtype=np.float32),
        np.broadcast_to(np.zeros(3), (4, 3)),  # read-only
        1.5,
        7,
        True,
        np.float64(2.0),
        np.int64(3),
        np.bool_(False),
        (np.zeros(2), np.zeros((2, 2)), 3),
        (1.0, 2.0, 3.0),
        ((np.zeros(2), 1), (True, np.zeros(3, dtype=np.int64))),
    ],
)
def test_the_key_of_a_value_is_the_key_of_the_type_numba_gives_it(value: object) -> None:
    assert aot.type_key(value) == aot.numba_type_key(typeof(value))


def test_values_numba_has_no_key_for_here_are_never_looked_up() -> None:
    assert aot.type_key("text") is None
    assert aot.type_key((1.0, "text")) is None
    assert aot.type_key(2**70) is None


def test_a_changed_kernel_source_or_another_numpy_leaves_every_call_to_numba(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    manifest = json.loads(aot.MANIFEST.read_text())
    assert aot._load(), "the module as installed loads"
    for change in ("sources", "numpy"):
        edited = json.loads(json.dumps(manifest))
        if change == "sources":
            first = next(iter(edited["sources"]))
            edited["sources"][first] = "0" * 64  # the source it was built from is not the one here
        else:
            edited["facts"]["numpy"] = "1.0.0"
        copy = tmp_path / f"{change}.json"
        copy.write_text(json.dumps(edited))
        monkeypatch.setattr(aot, "MANIFEST", copy)
        assert aot._load() == {}
    monkeypatch.setattr(aot, "MANIFEST", tmp_path / "missing.json")
    assert aot._load() == {}


def test_a_call_with_types_the_module_was_not_built_for_is_not_answered_by_it(monkeypatch: pytest.MonkeyPatch) -> None:
    from spooflens.navigation import kernels

    monkeypatch.setattr(aot, "_table", None)
    kernel: Any = kernels.correct_all
    function = kernel.py_func
    states, dx = np.zeros((4, 22)), np.zeros((4, 24))
    assert aot.compiled(function, (states, dx)) is not None  # as the analysis calls it
    assert aot.compiled(function, (states.astype(np.float32), dx)) is None
    assert aot.compiled(function, (np.asfortranarray(states), dx)) is None
    monkeypatch.setattr(aot, "disabled", True)
    monkeypatch.setattr(aot, "_table", None)
    assert aot.compiled(function, (states, dx)) is None
    monkeypatch.setattr(aot, "_table", None)  # the next test loads the table afresh
