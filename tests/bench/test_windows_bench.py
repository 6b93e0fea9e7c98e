"""`spooflens bench windows`: stretches of real clean logs cut at random, each analysed as a log of its own."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from paths import REAL

from spooflens.bench.windows_bench import starts
from spooflens.cli import main


def test_the_same_seed_log_and_length_give_the_same_starts_inside_the_span() -> None:
    first = starts(3, "corpus/x.log", (10.0, 610.0), 150.0, 4)
    assert first == starts(3, "corpus/x.log", (10.0, 610.0), 150.0, 4)
    assert first != starts(4, "corpus/x.log", (10.0, 610.0), 150.0, 4)
    assert all(10.0 <= s <= 460.0 for s in first) and len(first) == 4
    assert starts(3, "corpus/x.log", (10.0, 100.0), 150.0, 4) == []  # a log shorter than the stretch


def test_stretches_of_a_real_boat_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Signal K's 20 minutes near Amsterdam, two stretches of 60 s: each inside the log, each analysed."""
    out = tmp_path / "w.json"
    args = ["bench", "windows", str(REAL), "--only", "corpus/signalk/gps.log", "--length", "60", "--draws", "2"]
    assert main([*args, "--jobs", "1", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    stretches = report["stretches"]
    assert [s["outcome"] for s in stretches] == ["analysed", "analysed"]
    assert all(s["length_s"] == 60.0 and s["headline"] for s in stretches)
    assert report["table"][-1]["stretches"] == 2 and report["false_spoofing"] == []
    assert "false SPOOFING" in capsys.readouterr().out


def test_a_folder_that_does_not_exist_is_a_usage_error(tmp_path: Path) -> None:
    assert main(["bench", "windows", str(tmp_path / "nowhere")]) == 2
