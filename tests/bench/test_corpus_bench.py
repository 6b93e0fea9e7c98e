"""`spooflens bench corpus` on a tiny fake corpus: which paths are logs, how each command's end is
classified, how an attacked copy is scored, and the tables and lists the bench prints."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import pytest
from paths import SAMPLE_LOGS

from spooflens.bench.corpus_bench import (
    BATTERY,
    attack_start,
    false_verdicts,
    grouped,
    interference,
    print_report,
    refusal_reason,
    refusals,
    report_json,
    run_corpus,
)
from spooflens.bench.corpus_logs import discover, is_truth_of_another, tags_of
from spooflens.bench.corpus_runs import (
    DAMAGED,
    INTERNAL,
    READ,
    REFUSED,
    TIMEOUT,
    LogFacts,
    command_result,
    hours,
    score,
)
from spooflens.bench.sandbox import RunResult

HEADER = "path\tformat\tvehicle\tduration_s\tsource_repo\tcommit\tsource_path\tlicence\tnotes\n"


def _fake_corpus(root: Path) -> Path:
    """real/corpus/ with a manifest (a clean drive, a spoofed flight listed as clean, a garbage file tagged
    SYNTHETIC, the drive's truth), and real/extra/ beside it, described by real/README.md's table."""
    corpus = root / "corpus" / "logs"
    corpus.mkdir(parents=True)
    shutil.copyfile(SAMPLE_LOGS / "ground_ros2.mcap", corpus / "drive.mcap")
    shutil.copyfile(SAMPLE_LOGS / "spoofed_flight.mcap", corpus / "flight.mcap")
    (corpus / "garbage.bin").write_bytes(bytes(range(256)) * 8)
    (corpus / "drive_truth.csv").write_text("t_s,lat_deg,lon_deg\n0,1,2\n")
    rows = [
        "logs/drive.mcap\tmcap\tcar\t120\tr\tc\ts\tMIT\ta drive; LOSS-OF-FIX near the end\n",
        "logs/flight.mcap\tmcap\tfixed-wing\t240\tr\tc\ts\tMIT\ta flight\n",
        "logs/garbage.bin\tother\tunknown\t\tr\tc\ts\tMIT\tSYNTHETIC: random bytes, NO-GNSS-RAW\n",
        "logs/drive_truth.csv\tother\tcar\t\tr\tc\ts\tMIT\tground truth for drive.mcap\n",
    ]
    (root / "corpus" / "MANIFEST.tsv").write_text(HEADER + "".join(rows))
    (root / "extra").mkdir()
    shutil.copyfile(SAMPLE_LOGS / "ground_ros1.mcap", root / "extra" / "car.mcap")
    (root / "README.md").write_text("| folder | what |\n|---|---|\n| `extra/` | a simulated car, ROS1 MCAP |\n")
    return root


def test_manifest_rows_are_logs_and_the_rest_is_sniffed(tmp_path: Path) -> None:
    corpus = discover(_fake_corpus(tmp_path / "real"))
    logs = {c.name: c for c in corpus.logs}
    assert sorted(logs) == [
        "corpus/logs/drive.mcap",
        "corpus/logs/flight.mcap",
        "corpus/logs/garbage.bin",
        "extra/car.mcap",
    ]
    drive, garbage, car = logs["corpus/logs/drive.mcap"], logs["corpus/logs/garbage.bin"], logs["extra/car.mcap"]
    assert drive.tags == ("LOSS-OF-FIX",) and drive.clean and drive.vehicle == "car" and drive.reader == "mcap"
    assert garbage.tags == ("SYNTHETIC",) and not garbage.clean and garbage.reader is None
    assert not car.listed and car.vehicle == "unknown" and car.notes == "a simulated car, ROS1 MCAP"
    why = {n.name: n.why for n in corpus.not_logs}
    assert "ground truth" in why["corpus/logs/drive_truth.csv"] and "README.md" in why


def test_tags_are_whole_tokens_and_truth_rows_are_told_apart() -> None:
    assert tags_of("RECEIVER-RESET/COLD-START; NO-GNSS-RAW, EDITED: x, LEAP-SECONDS") == (
        "RECEIVER-RESET",
        "COLD-START",
        "EDITED",
        "LEAP-SECONDS",
    )
    assert tags_of("ZED-F9P, NAV-PVT") == ()
    assert is_truth_of_another("NovAtel SPAN ground truth (csv) for x.txt")
    assert is_truth_of_another("reference trajectory (GGA only) for the drive; use as ground truth")
    assert not is_truth_of_another("Pixel 4 GnssLogger in a car; truth in x_ground_truth.csv")
    assert not is_truth_of_another("u-blox NMEA; reference truth for the same drive in y.gga")


@pytest.mark.parametrize(
    ("run", "outcome"),
    [
        (RunResult(0, None, 100.0, 1.0, ""), READ),
        (RunResult(3, None, 100.0, 1.0, "spooflens: x: input damaged"), DAMAGED),
        (RunResult(2, None, 100.0, 1.0, "spooflens: error: x: unknown format"), REFUSED),
        (RunResult(1, None, 100.0, 1.0, "spooflens: internal error: KeyError"), INTERNAL),
        (RunResult(4, None, 100.0, 1.0, ""), INTERNAL),  # --fail-on-spoof is never given: 4 is unexpected
        (RunResult(None, "signal 11", 100.0, 1.0, ""), INTERNAL),
        (RunResult(None, "rss", 9000.0, 1.0, ""), INTERNAL),
        (RunResult(None, "timeout", 100.0, 120.0, ""), TIMEOUT),
    ],
)
def test_each_way_a_command_ends_is_classified(run: RunResult, outcome: str) -> None:
    result = command_result(run)
    assert result.outcome == outcome
    assert (result.error == "") == (outcome == READ)


def test_a_refusal_reason_loses_the_path_and_its_details() -> None:
    log = Path("/r/corpus/a.log")
    assert refusal_reason("spooflens: error: /r/corpus/a.log [nmea]: no usable NMEA sentence (x): GP", log) == (
        "no usable NMEA sentence"
    )
    assert refusal_reason("spooflens: error: /r/corpus/a.log: unknown format (starts with b'#'); supported", log) == (
        "unknown format"
    )


def _summary(*incidents: dict, spoofed: bool) -> dict:
    t0 = 1_000_000_000_000
    return {"t0_abs_ns": t0, "duration_s": 100.0, "verdict": {"spoofed": spoofed, "incidents": list(incidents)}}


def _incident(onset: float, alarm: float, end: float, spoofing: bool = True, **extra: object) -> dict:
    t0 = 1_000_000_000_000
    return {
        "spoofing": spoofing,
        "confidence": "high" if spoofing else "low",
        "onset_s": onset,
        "start_s": alarm,
        "end_s": end,
        "start_abs_ns": t0 + int(alarm * 1e9),
        "end_abs_ns": t0 + int(end * 1e9),
        "onset_interval_s": [onset - 1.0, onset + 1.0],
        "evidence": ["gnss_only"],
        "detectors": ["gnss_consistency"],
        **extra,
    }


def test_an_attack_is_caught_by_a_spoofing_incident_from_its_start() -> None:
    truth = {"t0_abs_ns": 1_000_000_000_000, "start_s": 50.0, "end_s": 100.0}
    early_false = _incident(5.0, 6.0, 8.0)
    hit = _incident(50.5, 52.0, 100.0, ongoing_at_end=True)
    s = score(truth, _summary(early_false, hit, spoofed=True), fix_rate_hz=1.0)
    assert s.caught and s.delay_s == pytest.approx(2.0) and s.onset_covered and s.to_end
    assert s.end_error_s == pytest.approx(0.0) and s.incident["start_s"] == 52.0
    late_onset = _incident(60.0, 61.0, 70.0)
    s = score(truth, _summary(late_onset, spoofed=True), fix_rate_hz=1.0)
    assert s.caught and s.onset_covered is False and s.to_end is False and s.end_error_s == pytest.approx(-30.0)


def test_a_miss_says_why() -> None:
    truth = {"t0_abs_ns": 1_000_000_000_000, "start_s": 50.0, "end_s": 100.0}
    assert score(truth, _summary(spoofed=False), 1.0).reason == "no alarm at or after the attack start"
    anomaly = _incident(50.0, 51.0, 60.0, spoofing=False)
    missed = score(truth, _summary(anomaly, spoofed=False), 1.0)
    assert (
        not missed.caught
        and missed.reason.startswith("only one-class anomalies")
        and "gnss_consistency" in missed.reason
    )
    before = _incident(5.0, 6.0, 8.0)
    assert score(truth, _summary(before, spoofed=True), 1.0).reason == "spoofing incident only before the attack"


def test_attacks_start_in_the_middle_third_the_same_every_run() -> None:
    starts = [attack_start(f"log{k}", kind.name, (10.0, 310.0)) for k in range(20) for kind in BATTERY]
    assert all(110.0 <= s <= 210.0 for s in starts) and len(set(starts)) > 50
    assert attack_start("a", "ramp 2 m/s", (0.0, 90.0)) == attack_start("a", "ramp 2 m/s", (0.0, 90.0))


def test_the_bench_on_a_tiny_corpus(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Both passes through the CLI on the manifest's logs: the drive read and attacked, the flight a
    SPOOFING verdict on a log listed as clean, the garbage refused; the tables and lists follow."""
    root = _fake_corpus(tmp_path / "real")
    report = run_corpus([root], jobs=1, only=("corpus/*",))
    by_name = {r.log.name: r for r in report.results}
    drive, flight, garbage = (by_name[f"corpus/logs/{n}"] for n in ("drive.mcap", "flight.mcap", "garbage.bin"))
    assert (drive.outcome, flight.outcome, garbage.outcome) == (READ, READ, REFUSED)
    assert [f["log"] for f in false_verdicts(report.results)] == ["corpus/logs/flight.mcap"]
    assert refusals(report.results) == {"unknown format": ["corpus/logs/garbage.bin"]}
    assert flight.not_attacked == "clean verdict already SPOOFING: a catch cannot be shown"
    assert garbage.not_attacked == "clean pass: refused"
    # one receiver with logged fixes and no raw observations: the fix-level kinds only
    assert [i.kind for i in drive.injected] == ["ramp 2 m/s", "step 50 m", "capture"]
    assert set(drive.not_injected) == {"counterfeit satellite", "single antenna"}
    assert all(i.made and i.score is not None for i in drive.injected)
    assert any(i.score is not None and i.score.caught for i in drive.injected)
    by_tag = {row.group: row for row in grouped(report.results, lambda r: list(r.log.tags) or ["(no tag)"])}
    assert by_tag["LOSS-OF-FIX"].attacks == 3 and by_tag["SYNTHETIC"].outcomes[REFUSED] == 1
    assert by_tag["all"].logs == 3 and by_tag["all"].false_spoofing == 1
    json.dumps(report_json(report), default=str)
    print_report(report)
    printed = capsys.readouterr().out
    assert "False SPOOFING verdicts on clean-sky logs: 1" in printed and "1 x unknown format" in printed
    assert "Interference alarms on the clean pass: 0" in printed  # no C/N0 or RF indicator in these logs
    assert report_json(report)["interference"]["logs"] == 0


def test_interference_on_the_clean_pass_lists_alarms_with_what_the_receiver_said() -> None:
    from typing import Any, cast

    from spooflens.bench.corpus_bench import LogResult

    class Clean:
        def __init__(self, name: str, facts: dict[str, Any], alarms: list[Any]) -> None:
            self.log = type("Log", (), {"name": name, "clean": True, "tags": ()})()
            analysis = {"name": "interference", "ran": True, "alarms": alarms, "facts": facts}
            text = "ubx: C/N0 of all 9 GPS L1 satellites fell by 15 dB together"
            analysis["findings"] = [{"text": text}] * len(alarms)
            self.summary = {"duration_s": 1800.0, "analyses": [analysis]}

    monitor = {"ubx": {"jamming_monitor": {"reported": "interference reported"}}}
    quiet = {"receivers": {"GP": {"jamming_monitor": {"reported": "not logged"}}}, "rejected": [{"start_s": 5.0}]}
    results = cast(list[LogResult], [Clean("a.ubx", {"receivers": monitor}, [{}]), Clean("b.nmea", quiet, [])])
    found = interference(results)
    assert found["logs"] == 2 and found["hours"] == 1.0 and len(found["rejected_losses"]) == 1
    assert [a["log"] for a in found["alarms"]] == ["a.ubx"]
    assert found["alarms"][0]["receiver_said"]["ubx"]["reported"] == "interference reported"
    assert found["jamming_monitor"] == {"interference reported": ["a.ubx"], "not logged": ["b.nmea"]}


def test_an_attack_reaching_fewer_epochs_than_an_alarm_needs_is_not_counted() -> None:
    # georinex 14601736.18o: 15 s epochs over 30 s, the attack from 14.6 s reaches 2 of them
    from spooflens.bench.corpus_bench import MIN_ATTACKED_EPOCHS, attacked_epochs

    truth = {
        "start_s": 14.6,
        "end_s": 30.0,
        "offsets": {"st": [[0.0, 0, 0, 0], [15.0, 38, 17, 181], [30.0, 38, 16, 181]]},
    }
    assert attacked_epochs(truth) == 2 < MIN_ATTACKED_EPOCHS
    assert attacked_epochs({"start_s": 0.0, "offsets": {}}) is None


def test_a_counterfeit_satellite_counts_as_seen_only_where_raim_or_the_systems_comparison_ran() -> None:
    # satellite_horizon shares RAIM's evidence class but cannot see a delayed satellite: a log where it
    # alone of that class ran (CEDA, whose time tags keep RAIM from judging it) has no reference for it
    kind = next(k for k in BATTERY if k.name == "counterfeit satellite")
    facts = LogFacts(1, (), ("rx",), ("rx",), (0.0, 1.0), (0.0, 1.0), 1.0, frozenset({"raw_measurement"}))
    assert not kind.seen_in(replace(facts, analyses_run=frozenset({"satellite_horizon"})))
    assert kind.seen_in(replace(facts, analyses_run=frozenset({"satellite_horizon", "raim"})))
    ramp = next(k for k in BATTERY if k.name == "ramp 2 m/s")
    assert not ramp.seen_in(facts) and ramp.seen_in(replace(facts, classes_run=frozenset({"inertial"})))


def test_a_log_stitched_from_sessions_years_apart_counts_the_time_its_fixes_cover() -> None:
    # one fix 78 million seconds after the rest (pynmeagps' Unicore sample): a minute, not 2.5 years; a day
    # of 30 s RINEX epochs counts whole, a log without GNSS streams counts its duration
    stitched = {"duration_s": 78e6, "streams": [{"role": "fix", "count": 1, "first_s": 78e6, "last_s": 78e6}]}
    assert hours(stitched) == pytest.approx(60.0 / 3600.0)
    rinex = {
        "duration_s": 86370.0,
        "streams": [{"role": "observations", "count": 2880, "first_s": 0.0, "last_s": 86370.0}],
    }
    assert hours(rinex) == pytest.approx(86370.0 / 3600.0)
    gappy = {"duration_s": 7200.0, "streams": [{"role": "fix", "count": 11, "first_s": 0.0, "last_s": 7200.0}]}
    assert hours(gappy) == pytest.approx(11 * 60.0 / 3600.0)
    assert hours({"duration_s": 600.0, "streams": []}) == pytest.approx(600.0 / 3600.0)
