"""The warm-up writes the project's bytecode even where PYTHONDONTWRITEBYTECODE forbids Python to."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from typing import Any

import pytest

from spooflens.compile import warmup


def _package(root: Path, source: str) -> Path:
    folder = root / "pkg"
    folder.mkdir(parents=True)
    (folder / "__init__.py").write_text("")
    (folder / "mod.py").write_text(source)
    return folder


def test_the_bytecode_is_written_though_python_is_told_not_to(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    folder = _package(tmp_path, "X = 1\n")
    assert warmup.compile_bytecode((folder,))
    assert Path(importlib.util.cache_from_source(str(folder / "mod.py"))).is_file()


def test_a_module_that_does_not_compile_is_said_and_the_next_package_still_compiles(tmp_path: Path) -> None:
    broken = _package(tmp_path / "a", "def broken(:\n")
    sound = _package(tmp_path / "b", "X = 1\n")
    assert not warmup.compile_bytecode((broken, sound))
    assert Path(importlib.util.cache_from_source(str(sound / "mod.py"))).is_file()


def test_the_project_packages_are_the_ones_an_analysis_imports() -> None:
    assert {p.name for p in warmup.PACKAGES} == {"spooflens", "readers"}
    assert all((p / "__init__.py").is_file() for p in warmup.PACKAGES)


def test_the_warm_up_reaches_both_forms_of_the_offline_pass() -> None:
    # the kept form (two filters side by side) on a short log, the bounded form a day-long log takes
    from spooflens.estimation import marginalised_likelihood

    car = warmup.SAMPLES / "ground_ros2.mcap"
    names = [name for name, _ in warmup.warm([car])]
    assert names == ["ground_ros2.mcap", "ground_ros2.mcap (long-log offline pass)"]
    assert marginalised_likelihood.OFFLINE_KEEP_BYTES == 64_000_000  # put back
    kernels: list[Any] = [marginalised_likelihood._forward_kept, marginalised_likelihood._two_filter_offline]
    for kernel in kernels:  # the warm-up runs numba, never the ahead-of-time builds: each compiled a signature
        assert kernel.numba_dispatcher().signatures, kernel
