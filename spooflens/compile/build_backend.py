"""The project's build backend: setuptools', plus compiling the numba kernels at `pip install -e`
(docs/compile.md)."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

from setuptools import build_meta as _setuptools
from setuptools.build_meta import *  # noqa: F403 - every other hook as setuptools defines it

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT_S = 1800.0


def _runtime_requirements() -> list[str]:
    with (ROOT / "pyproject.toml").open("rb") as f:
        return list(tomllib.load(f)["project"]["dependencies"])


def get_requires_for_build_editable(config_settings: dict | None = None) -> list[str]:
    extra = [] if os.environ.get("SPOOFLENS_NO_WARMUP") else _runtime_requirements()
    return [*_setuptools.get_requires_for_build_editable(config_settings), *extra]


def build_editable(
    wheel_directory: str, config_settings: dict | None = None, metadata_directory: str | None = None
) -> str:
    _warm_up()
    return _setuptools.build_editable(wheel_directory, config_settings, metadata_directory)


def _say(text: str) -> None:
    print(f"spooflens build: {text}", file=sys.stderr, flush=True)


def _warm_up() -> None:
    if os.environ.get("SPOOFLENS_NO_WARMUP"):
        _say("SPOOFLENS_NO_WARMUP set: numba kernels not compiled now (the first analysis compiles them)")
        return
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    env.pop("NUMBA_CACHE_DIR", None)  # the cache must land beside the sources, where the install looks
    try:
        done = subprocess.run(
            [sys.executable, "-m", "spooflens.compile.warmup"],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=TIMEOUT_S,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired) as err:
        _say(f"compiling the numba kernels did not finish ({err}); the first analysis will compile them")
        return
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no output"])[-1]
        _say(f"compiling the numba kernels failed ({last}); the first analysis will compile them")
        return
    _say((done.stdout.strip().splitlines() or ["numba kernels compiled"])[-1])
