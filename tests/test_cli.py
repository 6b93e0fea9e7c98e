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


def test_fail_on_jam_exits_5_when_the_receiver_reports_jamming(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from px4_support import v1_12_log

    # PX4 v1.12: from 20 s the receiver's jamming state at warning, its noise and jamming indicator up, its
    # gain down, satellites lost; no spoofing state in that release, no fix moved
    log = tmp_path / "jammed.ulg"
    v1_12_log(log)
    args = ["analyze", str(log), "-o", str(tmp_path / "j.rrd"), "--json", str(tmp_path / "j.json"), "--quiet"]
    assert main(args) == 0
    assert main([*args, "--fail-on-spoof"]) == 0
    assert main([*args, "--fail-on-jam"]) == 5
    headline = capsys.readouterr().out.splitlines()[-1]
    assert headline.startswith("NO SPOOFING DETECTED") and "JAMMING / INTERFERENCE from" in headline
    summary = json.loads((tmp_path / "j.json").read_text())
    (event,) = summary["verdict"]["events"]
    assert event["kind"] == "jamming" and any("jamming state" in x for x in event["evidence_for"])


def test_spoofing_wins_over_jamming_and_both_over_damage() -> None:
    from pipeline_support import circling_table

    from spooflens.pipeline.registry import AnalyzeOptions
    from spooflens.pipeline.run import Analysis
    from spooflens.pipeline.verdict import Event, Kind, Verdict
    from spooflens.service import EXIT_JAMMED, EXIT_OK, EXIT_SPOOFED, finish

    jam = Event(Kind.JAMMING, 10.0, 20.0, 10.0, "medium", 0, "jamming")
    spoof = Event(Kind.SPOOFING, 30.0, 40.0, 30.0, "high", 1, "spoofing")

    def analysis(spoofed: bool, *events: Event) -> Analysis:
        verdict = Verdict(spoofed, detectors_run=("x",), events=events)
        return Analysis(circling_table(seconds=20.0), AnalyzeOptions(), [], verdict)

    log = Path("x.mcap")
    assert finish(log, [analysis(True, jam, spoof)], True, True) == EXIT_SPOOFED == 4
    assert finish(log, [analysis(True, jam, spoof)], False, True) == EXIT_JAMMED == 5
    assert finish(log, [analysis(False, jam)], True, False) == EXIT_OK
    assert finish(log, [analysis(False)], True, True) == EXIT_OK


def test_a_natural_events_line_names_both_confidences(capsys: pytest.CaptureFixture[str]) -> None:
    """A receiver fault's incident said "confidence low" (of spoofing) while its event said "confidence medium"
    (of the fault): the console names which is which."""
    from spooflens.service import print_analysis

    incident = {
        "kind": "receiver_fault", "confidence": "low", "confidence_of_alarms": "low", "spoofing": False,
        "onset_s": 79.6, "start_s": 80.6, "end_s": 80.6, "ongoing_at_end": True, "evidence": ["gnss_only"],
        "corroborating_evidence": ["gnss_only"], "detectors": ["gnss_consistency"], "explanations": [],
    }  # fmt: skip
    event = {"kind": "receiver_fault", "confidence": "medium", "incident": 0, "sequence": None}
    verdict = {"spoofed": False, "headline": "NO SPOOFING", "incidents": [incident], "events": [event], "findings": []}
    print_analysis({"verdict": verdict, "analyses": [], "skipped": []}, None, None)
    out = " ".join(capsys.readouterr().out.split())
    assert "confidence of spoofing low, of receiver fault medium" in out
