"""Shared fixtures. Paths to the inputs are in `paths` (tests import it; `tests/` is on the path)."""

from __future__ import annotations

from pathlib import Path

import pytest
from paths import REAL, real_log


@pytest.fixture(scope="session")
def real() -> Path:
    """../shared/real, the real logs recorded by others (a test that uses it fails when it is missing)."""
    return real_log(".") if not REAL.is_dir() else REAL


@pytest.fixture(scope="session")
def husky_bag() -> Path:
    return real_log("ros1_husky_navsat/test1.bag")


END_TO_END = ("end_to_end", "expected")  # folders of tests that analyse whole logs


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Every test of the end-to-end folders is `slow` (still run in CI; `-m "not slow"` leaves them out)."""
    for item in items:
        if any(part in END_TO_END for part in item.path.parts[-3:-1]):
            item.add_marker(pytest.mark.slow)
