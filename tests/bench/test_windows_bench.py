"""`spooflens bench windows`: stretches of real clean logs cut at random, each analysed as a log of its own."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from paths import REAL

from spooflens.bench.natural_changes import changed
from spooflens.bench.windows_bench import starts
from spooflens.cli import main
from spooflens.service import read_table


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


def test_natural_changes_change_what_they_say_and_only_logs_they_apply_to(husky_bag: Path) -> None:
    table = read_table(husky_bag, {}, False)
    rate = lambda t: (len(np.unique(t)) - 1) / float(np.ptp(t))  # noqa: E731
    half = changed(table, "imu-half-rate")
    assert half is not None and rate(half.imu["t_s"]) == pytest.approx(rate(table.imu["t_s"]) / 2, rel=0.05)
    one_hz = changed(table, "fixes-1hz")
    assert one_hz is not None and rate(one_hz.fixes["t_s"]) == pytest.approx(1.0, rel=0.05)
    late = changed(table, "fixes-late")
    assert late is not None and np.allclose(late.fixes["t_s"] - table.fixes["t_s"], 0.2)
    biased = changed(table, "gyro-bias")
    assert biased is not None and np.allclose(biased.imu["wz_radps"] - table.imu["wz_radps"], 0.01)
    scaled = changed(table, "accelerometer-scale")
    assert scaled is not None and np.allclose(scaled.imu["az_mps2"], 1.03 * table.imu["az_mps2"])
    # every stream counted again over what is left
    (imu_stream,) = [s for s in half.streams if s.role == "imu"]
    assert imu_stream.count == len(half.imu)
    boat = read_table(REAL / "nmea_boats" / "gpsd_bundg_zeus_9.log", {}, False)
    assert changed(boat, "imu-half-rate") is None and changed(boat, "gyro-bias") is None


def test_stretches_of_a_naturally_changed_log_are_analysed_and_say_the_change(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "w.json"
    args = ["bench", "windows", str(REAL), "--only", "ros1_husky_navsat/*", "--length", "90", "--draws", "2"]
    assert main([*args, "--natural", "fixes-late", "--jobs", "1", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["settings"]["natural"] == "fixes-late"
    assert [s["outcome"] for s in report["stretches"]] == ["analysed", "analysed"]
    assert report["false_spoofing"] == []
    assert "each log changed first (fixes-late): Fixes stamped" in capsys.readouterr().out
