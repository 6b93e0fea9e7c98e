"""A fresh analysis of every sample log and real log equals its expected output (tests/expected/*.json).

A change that moves what spooflens reports fails here; if the change is meant, rerun
`python tests/support/expected_outputs.py [NAME ...]` and review the diff of the expected
files in the commit.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
from expected_outputs import expected_path, logs, summary_of

REL_TOL = 1e-7  # the same machine gives the same bits; a CPU with other vector units may move the last ones


def differences(expected: Any, got: Any, where: str = "") -> list[str]:
    """Where two summaries differ (floats within REL_TOL are equal)."""
    if isinstance(expected, dict) and isinstance(got, dict):
        out = [f"{where}/{k}: missing" for k in expected.keys() - got.keys()]
        out += [f"{where}/{k}: unexpected" for k in got.keys() - expected.keys()]
        for k in expected.keys() & got.keys():
            out += differences(expected[k], got[k], f"{where}/{k}")
        return out
    if isinstance(expected, list) and isinstance(got, list):
        if len(expected) != len(got):
            return [f"{where}: {len(expected)} items expected, {len(got)} found"]
        return [
            d for k, (a, b) in enumerate(zip(expected, got, strict=True)) for d in differences(a, b, f"{where}[{k}]")
        ]
    numbers = (int, float)
    if isinstance(expected, numbers) and isinstance(got, numbers) and not isinstance(expected, bool):
        return (
            [] if math.isclose(expected, got, rel_tol=REL_TOL, abs_tol=1e-9) else [f"{where}: {expected!r} -> {got!r}"]
        )
    return [] if expected == got else [f"{where}: {expected!r} -> {got!r}"]


@pytest.mark.parametrize("name", list(logs()))
def test_the_analysis_gives_the_expected_output(name: str) -> None:
    log: Path = logs()[name]
    if not log.exists():
        pytest.fail(f"log missing: {log} (tests expect ../shared/real beside the checkout)")
    expected = json.loads(expected_path(name).read_text())
    found = differences(expected, summary_of(log))
    assert not found, f"{name}: {len(found)} difference(s) from tests/expected:\n" + "\n".join(found[:30])


def test_a_moved_number_is_a_difference() -> None:
    a = {"verdict": {"spoofed": False, "incidents": [{"onset_s": 12.5}]}}
    assert differences(a, a) == []
    assert differences(a, {"verdict": {"spoofed": False, "incidents": [{"onset_s": 12.6}]}}) == [
        "/verdict/incidents[0]/onset_s: 12.5 -> 12.6"
    ]
    assert sorted(differences(a, {"verdict": {"spoofed": True, "incidents": []}})) == [
        "/verdict/incidents: 1 items expected, 0 found",
        "/verdict/spoofed: False -> True",
    ]
