"""Shared fixtures: where the real logs recorded by others live (never copied into the repo)."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "real"
HUSKY_BAG = REAL / "ros1_husky_navsat" / "test1.bag"
SAMPLE_LOGS = ROOT / "sample_logs"


@pytest.fixture(scope="session")
def husky_bag() -> Path:
    if not HUSKY_BAG.exists():
        pytest.fail(f"real log missing: {HUSKY_BAG} (tests expect ../shared/real beside the checkout)")
    return HUSKY_BAG
