"""The project's build backend: setuptools', plus compiling the numba kernels at `pip install -e`.

pyproject.toml names this module as the backend (`backend-path = ["."]`). Every hook is setuptools'
own; two are extended:
- `get_requires_for_build_editable` adds the project's runtime dependencies to the isolated build
  environment pip makes (numba, numpy and what an analysis imports);
- `build_editable` first runs `python -m spooflens.compile.warmup` in that environment, from the source tree:
  numba writes the compiled kernels to the `__pycache__` folders beside the sources, which is where the
  editable install's numba looks (its cache is keyed by the source's content, the CPU and the numba
  version, so a cache made by the same numba release on the same machine is used as it is); and the
  kernels an analysis calls are built there into one extension module (`spooflens.compile.aot`: used while
  the kernel sources, Python, numpy and the CPU are those it was built with).

A warm-up that fails or runs out of time only says so: the install goes on, and the first analysis
compiles what it needs. `SPOOFLENS_NO_WARMUP=1` skips it (and the build environment's extra
packages). A wheel (`pip install .`) is built without it (its sources move to site-packages): run
`python -m spooflens.compile.warmup` once after installing one.
"""

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
