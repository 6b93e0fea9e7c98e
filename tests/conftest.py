"""Shared fixtures: where the real logs recorded by others live (never copied into the repo)."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "real"
HUSKY_BAG = REAL / "ros1_husky_navsat" / "test1.bag"
SAMPLE_LOGS = ROOT / "sample_logs"


def real_log(relative: str) -> Path:
    """A real log under ../shared/real; a test that needs one fails (never skips) when it is missing."""
    path = REAL / relative
    if not path.exists():
        pytest.fail(f"real log missing: {path} (tests expect ../shared/real beside the checkout)")
    return path


@pytest.fixture(scope="session")
def husky_bag() -> Path:
    return real_log("ros1_husky_navsat/test1.bag")
