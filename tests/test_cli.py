"""The command line on the sample logs: inspect, analyze, schema."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from paths import SAMPLE_LOGS

from spooflens.cli import main

SAMPLES = SAMPLE_LOGS


def test_inspect_lists_streams_and_supported_analyses(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(SAMPLES / "dual_receiver.mcap")]) == 0
    out = capsys.readouterr().out
    for text in (
        "/gps/fix",
        "/gps2/fix",
        "/imu/data",
        "sensor_msgs/msg/NavSatFix",
        "FLU",
        "gnss_consistency",
        "inertial",
    ):
        assert text in out


def test_analyze_the_sample_spoofed_flight(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out_json = tmp_path / "s.json"
    code = main(
        ["analyze", str(SAMPLES / "spoofed_flight.mcap"), "-o", str(tmp_path / "s.rrd"), "--json", str(out_json)]
    )
    assert code == 0
    assert "SPOOFING DETECTED" in capsys.readouterr().out
    summary = json.loads(out_json.read_text())
    truth = json.loads((SAMPLES / "spoofed_flight.mcap.attack.json").read_text())
    incident = summary["verdict"]["incidents"][0]
    assert abs(incident["onset_s"] - truth["start_s"]) < 2.0
    assert incident["onset_interval_s"][0] - 1.0 <= truth["start_s"] <= incident["onset_interval_s"][1] + 1.0
    assert incident["confidence"] == "high"
    names = {a["name"]: a for a in summary["analyses"]}
    assert set(names) >= {"gnss_consistency", "navigation", "kf_innovation", "glrt", "mlrt", "mlrt_calibrated"}


def test_analyze_a_clean_sample_finds_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", str(SAMPLES / "ground.bag"), "-o", str(tmp_path / "g.rrd")]) == 0
    assert "NO SPOOFING DETECTED" in capsys.readouterr().out


def test_unknown_topic_role_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(SAMPLES / "ground.bag"), "--topic", "gps=/fix"]) == 2
    assert "unknown topic role" in capsys.readouterr().err


def test_simulate_writes_a_log_its_truth_and_raw_observations(tmp_path: Path) -> None:
    out = tmp_path / "raw"
    assert (
        main(["simulate", "ground", "--raw", "--format", "csv", "--seconds", "30", "--seed", "4", "-o", str(out)]) == 0
    )
    from readers import read_log

    table = read_log(out)
    assert len(table.observations) > 5 * len(table.fixes) > 0
    assert len(table.truth) == 0 and (tmp_path / "raw.truth.csv").exists()
    again = tmp_path / "again"
    main(["simulate", "ground", "--raw", "--format", "csv", "--seconds", "30", "--seed", "4", "-o", str(again)])
    assert (again / "observations.csv").read_bytes() == (out / "observations.csv").read_bytes()


def test_simulate_names_the_scenarios_it_knows(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "submarine", "-o", "x.mcap"]) == 2
    assert "ground_raw" in capsys.readouterr().err
