"""Where the tests find their inputs: the repository, its sample logs, and the real logs recorded by others
in ../shared/real (never copied into the repository)."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SAMPLE_LOGS = ROOT / "sample_logs"
REAL = ROOT.parent / "shared" / "real"
HUSKY_BAG = REAL / "ros1_husky_navsat" / "test1.bag"


def real_log(relative: str) -> Path:
    """A real log under ../shared/real; a test that needs one fails (never skips) when it is missing."""
    path = REAL / relative
    if not path.exists():
        pytest.fail(f"real log missing: {path} (tests expect ../shared/real beside the checkout)")
    return path
