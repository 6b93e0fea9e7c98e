"""Jamming injected into real logs of every format that carries C/N0 or the front end's indicators, and into
simulated ones, is caught by the interference detector with its interval after the copy is read back;
jam_spoof gives both phases."""

from __future__ import annotations

import json
import re
import shutil
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from paths import HUSKY_BAG, real_log

from readers import read_log
from spooflens.attacks import apply_attack, parse_attack
from spooflens.cli import main
from spooflens.detectors.base import Alarm
from spooflens.detectors.interference import run_interference
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.run import analyze_table
from spooflens.pipeline.verdict import Kind
from spooflens.simulation.sensors import ReceiverModel
from spooflens.simulation.simulate import SCENARIOS, simulate
from spooflens.writers.ubx_rewrite import rewrite_ubx


def caught(path: Path, start: float, end: float, slack: float = 2.0) -> Alarm:
    """The one interference alarm of the log, its onset interval at the jammer's start and its end at the end."""
    r = run_interference(read_log(path))
    assert r.ran and len(r.alarms) == 1, (r.reason, [f.text for f in r.findings])
    a = r.alarms[0]
    assert a.onset_interval_s is not None and a.end_interval_s is not None
    assert a.onset_interval_s[0] - slack <= start <= a.onset_interval_s[1] + slack
    assert a.end_interval_s[0] - slack <= end <= a.end_interval_s[1] + slack
    return a


def inject(src: Path, attack: str, dst: Path, capsys: pytest.CaptureFixture[str]) -> str:
    assert main(["inject", str(src), "--attack", attack, "-o", str(dst)]) == 0
    return capsys.readouterr().out


def test_a_real_ublox_capture(tmp_path: Path) -> None:
    src = real_log("ubx_receivers/gpsd_ublox-zed-f9r.log")
    table = read_log(src)
    assert not run_interference(table).alarms
    jammed, _ = apply_attack(table, parse_attack("jam:start=12,end=22"))
    note = rewrite_ubx(src, tmp_path / "f9r.log", table, jammed, True)
    assert "NAV-SAT" in note and "monitor" in note
    back = read_log(tmp_path / "f9r.log")
    for column in ("agc", "noise_per_ms", "jamming_indicator", "jamming_state", "sats_used"):
        np.testing.assert_array_equal(back.fixes[column].to_numpy(float), jammed.fixes[column].to_numpy(float))
    a = caught(tmp_path / "f9r.log", 12.0, 22.0)
    assert {"GPS", "Galileo", "GLONASS", "BeiDou"} <= set(a.systems)
    text = run_interference(back).findings[0].text
    assert "AGC down 40 %" in text and "the receiver reported jamming (warning)" in text


def test_a_real_nmea_log_with_gsv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = inject(real_log("nmea_boats/gpsd_bundg_zeus_9.log"), "jam:start=60,end=120", tmp_path / "b.log", capsys)
    assert "self-reports" in out and "not in the copy" not in out
    a = caught(tmp_path / "b.log", 60.0, 120.0)
    assert a.systems == ("GLONASS", "GPS") and a.bands == ("G1", "L1")


def test_a_real_rinex_file_with_signal_strengths(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = real_log("android_gnsslogger/gnss_lib_py/pixel6.23o")
    inject(src, "jam:start=100,end=300,cn0=10", tmp_path / "p.23o", capsys)
    caught(tmp_path / "p.23o", 100.0, 300.0, slack=18.0)  # the phone's epochs are 18 s apart


def test_a_real_gnsslogger_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = real_log("android_gnsslogger/gps-measurement-tools/pseudoranges_log_2016_08_22_14_45_50.txt")
    out = inject(src, "jam:start=60,end=150,cn0=10", tmp_path / "g.txt", capsys)
    assert "Raw/Status/Agc lines with their C/N0 or AGC moved" in out and "pseudoranges moved" in out
    caught(tmp_path / "g.txt", 60.0, 150.0)
    # a counterfeit satellite 300 m late lands in its Raw lines' ReceivedSvTimeNanos: the copy reads it back
    src_table = read_log(src, {"nav": str(src.parent / "hour2350.16n")})
    inject(src, "pr_delay:delay=300,count=1,start=30", tmp_path / "d.txt", capsys)
    shutil.copy(src.parent / "hour2350.16n", tmp_path / "hour2350.16n")
    back = read_log(tmp_path / "d.txt", {"nav": str(tmp_path / "hour2350.16n")})
    moved = back.observations["pseudorange_m"].to_numpy() - src_table.observations["pseudorange_m"].to_numpy()
    assert ((np.abs(moved) < 1e-6) | (np.abs(moved - 300.0) < 0.2)).all() and (np.abs(moved - 300.0) < 0.2).sum() > 50


@pytest.mark.parametrize(("fmt", "name"), [("ulog", "sim.ulg"), ("csv", "sim_csv")])
def test_simulated_jamming_in_px4_ulog_and_csv(fmt: str, name: str, tmp_path: Path) -> None:
    out = tmp_path / name
    code = main(["simulate", "multirotor", "-o", str(out), "--format", fmt, "--seconds", "240", "--jam", "100,160,15"])
    assert code == 0
    truth = json.loads(Path(str(out) + ".attack.json").read_text())
    assert truth["kind"] == "jam" and truth["phases"][0]["start_s"] == 100.0
    a = caught(out, 100.0, 160.0)
    assert a.systems == ("GPS", "Galileo")


LOG171 = "corpus/dronekit-la-testdata/log171.bin"  # ArduCopter 3.3 (2015): UBX1 every ~2 s, no C/N0, no INS run


def analyze_json(path: Path, tmp_path: Path) -> dict[str, Any]:
    """`spooflens analyze LOG --json`'s summary."""
    report = tmp_path / f"{path.name}.json"
    assert main(["analyze", str(path), "-o", str(tmp_path / "x.rrd"), "--json", str(report), "--quiet"]) == 0
    summary: dict[str, Any] = json.loads(report.read_text())
    return summary


def events_of(summary: dict[str, Any], kind: str) -> list[dict[str, Any]]:
    return [e for e in summary["verdict"]["events"] if e["kind"] == kind]


def interference_alarms(summary: dict[str, Any]) -> list[dict[str, Any]]:
    (result,) = [a for a in summary["analyses"] if a["name"] == "interference"]
    alarms: list[dict[str, Any]] = result["alarms"]
    return alarms


def test_a_real_dataflash_log_with_ubx1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = real_log(LOG171)
    clean = analyze_json(src, tmp_path)
    assert not clean["verdict"]["spoofed"] and not events_of(clean, "jamming") and not interference_alarms(clean)
    out = inject(src, "jam:start=100,end=150", tmp_path / "jam.bin", capsys)
    assert "UBX1" in out and "not in the copy" not in out
    jammed = analyze_json(tmp_path / "jam.bin", tmp_path)
    assert not jammed["verdict"]["spoofed"] and not events_of(jammed, "spoofing")
    (event,) = events_of(jammed, "jamming")
    # the jammer's noisier fixes and inflated accuracies open the event within a second of the jammer's
    # start; a GNSS-only alarm on those fixes 8 s after its end closes it
    assert 100.0 <= event["start_s"] <= 101.0 and 150.0 <= event["end_s"] <= 160.0
    # the RF indicators alone: UBX1 comes every ~2 s and the jammer ramps up over 2 s, and the detector
    # holds each indicator's largest excursion over 5 s, so its alarm starts up to 3 s late and ends up
    # to 6 s late
    (alarm,) = interference_alarms(jammed)
    assert 100.0 <= alarm["start_s"] <= 103.0 and 150.0 <= alarm["end_s"] <= 156.0
    rf = next(f for f in jammed["verdict"]["findings"] if "front end saw more power" in str(f))
    assert "AGC down 40 %" in str(rf) and "jamming indicator 34 -> 184" in str(rf)


def test_a_jammer_that_costs_the_fix_is_seen_through_the_ubx1_reports(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # 7 of the 10 satellites lost from half power on: no fix from 101 s to 149 s, so no fix carries the
    # front end's indicators; the receiver's UBX1 reports go on every ~2 s and carry them
    src = real_log(LOG171)
    out = inject(src, "jam:start=100,end=150,lost=7", tmp_path / "lost.bin", capsys)
    assert "lost: Status 1" in out and "UBX1" in out and "not in the copy" not in out
    copy = read_log(tmp_path / "lost.bin")
    fix_t = copy.fixes["t_s"].to_numpy()
    assert not ((fix_t > 102) & (fix_t < 149)).any()
    summary = analyze_json(tmp_path / "lost.bin", tmp_path)
    assert not summary["verdict"]["spoofed"] and not events_of(summary, "spoofing")
    (event,) = events_of(summary, "jamming")
    assert 100.0 <= event["start_s"] <= 101.0 and 150.0 <= event["end_s"] <= 160.0
    # as when the fix holds: the next report after the jammer's start opens it, the 5 s hold closes it late
    (alarm,) = interference_alarms(summary)
    assert 100.0 <= alarm["start_s"] <= 103.0 and 150.0 <= alarm["end_s"] <= 156.0
    assert alarm["onset_interval_s"][0] <= 101.0 and alarm["end_interval_s"][0] <= 156.0
    (result,) = [a for a in summary["analyses"] if a["name"] == "interference"]
    (found,) = result["facts"]["events"]
    assert found["found_by"] == "front-end power" and found["fix"]["lost_s"] > 40.0
    assert found["rf"]["jamming_indicator"]["during"] == 184.0 and found["rf"]["agc"]["change_pct"] == -40.0
    # the event's own reading quotes the reports too, not the last fixes before the loss (34 -> 142 there)
    assert re.search(r"jamming indicator 3\d -> 18\d, noise level \d+ -> 14\d", json.dumps(summary["verdict"]))


def test_jam_then_capture_in_a_real_dataflash_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # the capture's drag carries its velocity with it and this log's IMU stops for 2 s at 61 s (no INS
    # runs), so the spoofing is seen where the spoofer lets go at 200 s and the receiver falls back on the
    # real sky; the verdict still puts the jamming first and the spoofing after it
    src = real_log(LOG171)
    out = inject(src, "jam_spoof:start=100,jam=30,end=200", tmp_path / "js.bin", capsys)
    assert "UBX1" in out and "lost: Status 1" in out and "not in the copy" not in out
    summary = analyze_json(tmp_path / "js.bin", tmp_path)
    verdict = summary["verdict"]
    assert verdict["spoofed"] and "after JAMMING / INTERFERENCE" in verdict["headline"]
    (jam,) = events_of(summary, "jamming")
    (spoof,) = events_of(summary, "spoofing")
    # the jammer stops at the takeover (130 s); the receiver's re-acquisition on the spoofer over the next
    # 4 s draws alarms that stay with the jamming
    assert 100.0 <= jam["start_s"] <= 102.0 and 130.0 <= jam["end_s"] <= 150.0
    assert verdict["events"][spoof["sequence"]["follows"]] == jam
    assert spoof["onset_interval_s"][0] <= 200.0 <= spoof["end_s"]


def test_a_format_without_a_place_for_it_says_what_was_not_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = inject(HUSKY_BAG, "jam:start=100,end=160", tmp_path / "h.bag", capsys)
    assert "not in the copy (the format or its writer has no place for them): reported accuracies" in out


def test_jam_then_capture_both_phases_are_seen() -> None:
    sc = replace(SCENARIOS["multirotor"], receiver=ReceiverModel(), satellite_reports=True)
    table = simulate(sc, seed=11, duration_s=360.0).table
    spoofed, truth = apply_attack(table, parse_attack("jam_spoof:start=150,jam=40"))
    analysis = analyze_table(spoofed)
    jam = [i for i in analysis.verdict.incidents if i.evidence == (Evidence.INTERFERENCE,)]
    assert len(jam) == 1 and not jam[0].is_spoofing
    assert jam[0].onset_interval_s is not None and jam[0].onset_interval_s[0] - 1 <= 150.0 <= jam[0].onset_interval_s[1]
    assert 185.0 <= jam[0].end_s <= 191.0
    facts = next(r.extras for r in analysis.results if r.name == "interference")
    assert "stronger than before" in facts["events"][0]["after"]  # type: ignore[index]
    takeover = truth.phases[1]["start_s"]
    spoofing = [i for i in analysis.verdict.incidents if i.is_spoofing]
    assert spoofing and spoofing[-1].ongoing_at_end and spoofing[-1].end_s >= takeover
    new_alarms = [
        a.start_s
        for r in analysis.results
        if r.is_detector and r.ran and r.evidence not in (None, Evidence.INTERFERENCE)
        for a in r.alarms
        if takeover - 1.0 <= a.start_s <= takeover + 30.0
    ]
    assert new_alarms  # the capture itself draws the spoofing detectors' alarms


def test_simulated_pure_jamming_is_named_jamming_not_spoofing() -> None:
    # the multirotor that drew a SPOOFING verdict from its jammed fixes alone (the inertial tests and the
    # coast weighed the noisier fixes with their clean noise): every alarm under the jamming is the jamming's
    from spooflens.bench.realworld_bench import Run, _attacked, called_kind

    table, _, truth = _attacked(Run("multirotor_sky", "jam 15 dB", 41013))
    analysis = analyze_table(table)
    jam = truth.phases[0]
    assert not analysis.verdict.spoofed
    assert called_kind(analysis, jam["start_s"], jam["end_s"]) == "jamming"
    explained = {e.cause for i in analysis.verdict.incidents for e in i.explanations}
    assert "jammed receiver's noise" in explained


def test_simulated_jam_then_capture_names_the_jamming_and_the_capture_from_its_takeover() -> None:
    # car, seed 1000: the jamming (198.4-228.4 s) drew inertial, GNSS-only and receiver alarms that were all
    # merged with the capture into one spoofing incident from 199 s; now the spoofing event begins at the
    # takeover and the jamming is an event of its own, linked to it
    from spooflens.bench.realworld_bench import Run, _attacked, called_kind

    table, _, truth = _attacked(Run("car", "jam then capture", 1000))
    analysis = analyze_table(table)
    jam, capture = truth.phases
    verdict = analysis.verdict
    assert verdict.spoofed
    assert called_kind(analysis, jam["start_s"], jam["end_s"], late_s=-1.0) == "jamming"
    assert called_kind(analysis, capture["start_s"], capture["end_s"]) == "spoofing"
    (spoof,) = verdict.events_of(Kind.SPOOFING)
    assert capture["start_s"] - 1.0 <= spoof.start_s <= capture["start_s"] + 2.0
    assert spoof.follows is not None and verdict.events[spoof.follows].kind == Kind.JAMMING
    assert verdict.headline.startswith("SPOOFING DETECTED") and "after JAMMING / INTERFERENCE" in verdict.headline
