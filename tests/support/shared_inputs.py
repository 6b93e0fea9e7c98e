"""Inputs several tests build the same way, made once per test process and handed out as deep copies.

Reading the husky bag takes seconds, simulating ten minutes of a multirotor ten; several tests in several
files start from the very same table. Each call returns a deep copy of the one made first, so a test that
changes its table (drops fixes, holes the IMU) changes its own copy only: every test gets what a fresh
`read_log` / `simulate` gives (both are deterministic), and no test sees another's changes."""

from __future__ import annotations

import copy
from functools import cache
from pathlib import Path

from readers import read_log
from spooflens.epoch_table import EpochTable
from spooflens.simulation.simulate import Simulated, simulate


@cache
def _read(path: Path) -> EpochTable:
    return read_log(path)


@cache
def _simulated(scenario: str, seed: int, duration_s: float | None) -> Simulated:
    return simulate(scenario, seed=seed, duration_s=duration_s)


def read_shared(path: Path) -> EpochTable:
    """`read_log(path)`, read once per process: a deep copy of that table."""
    return copy.deepcopy(_read(Path(path)))


def simulated(scenario: str, seed: int, duration_s: float | None = None) -> Simulated:
    """`simulate(scenario, seed=seed, duration_s=duration_s)`, simulated once per process: a deep copy."""
    return copy.deepcopy(_simulated(scenario, seed, duration_s))
