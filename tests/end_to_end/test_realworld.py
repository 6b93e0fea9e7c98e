"""Detection that holds on real logs: noise learned from the log, receiver evidence, RAIM, incidents
that last as long as the attack, logs that join recordings; each with a clean and an attacked case."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from paths import REAL, ROOT
from shared_inputs import read_shared

from readers import read_log
from spooflens.attacks import apply_attack, parse_attack
from spooflens.bench.realworld_bench import Run, one_run
from spooflens.detectors.receiver_evidence import run_receiver_evidence
from spooflens.geodesy import ecef_to_geodetic, geodetic_to_enu
from spooflens.pipeline.evidence import Evidence, confidence, corroborated
from spooflens.pipeline.run import analyze_table
from spooflens.simulation.sensors import ReceiverModel
from spooflens.simulation.simulate import SCENARIOS, simulate

GSI = REAL / "rinex_gsi_pair"


def test_confidence_counts_evidence_classes_not_detectors() -> None:
    assert confidence({Evidence.INERTIAL}) == "medium"
    assert confidence({Evidence.GNSS_ONLY}) == "low"
    assert confidence({Evidence.GNSS_ONLY, Evidence.RECEIVER}) == "medium"
    assert confidence({Evidence.INERTIAL, Evidence.GNSS_ONLY}) == "high"
    assert confidence({Evidence.RAW_MEASUREMENT}) == "medium"


def test_classes_corroborate_only_when_their_alarms_meet_in_time() -> None:
    # a receiver complaining at power-on and a GNSS-only glitch 34 s later (the clean husky bag)
    apart = [(Evidence.RECEIVER, 16.0, 20.8), (Evidence.GNSS_ONLY, 54.9, 54.9)]
    assert confidence(corroborated(apart)) == "low"
    near = [(Evidence.RECEIVER, 16.0, 20.8), (Evidence.GNSS_ONLY, 28.0, 29.0)]
    assert corroborated(near) == {Evidence.RECEIVER, Evidence.GNSS_ONLY}
    # a long confirmed inertial departure meets everything inside it
    departure = [(Evidence.INERTIAL, 100.0, 400.0), (Evidence.RECEIVER, 350.0, 351.0), (Evidence.GNSS_ONLY, 10.0, 11.0)]
    assert corroborated(departure) == {Evidence.INERTIAL, Evidence.RECEIVER}


@pytest.fixture(scope="module")
def multirotor() -> object:
    sc = replace(SCENARIOS["multirotor"], receiver=ReceiverModel(accuracy_factor=5.0))
    return simulate(sc, seed=11, duration_s=300.0)


def test_receiver_evidence_is_quiet_on_a_clean_log_and_sees_a_capture(multirotor) -> None:
    clean = run_receiver_evidence(multirotor.table.fixes)
    assert clean.ran and clean.evidence == Evidence.RECEIVER and not clean.alarms
    spoofed, _ = apply_attack(multirotor.table, parse_attack("capture:start=150"))
    res = run_receiver_evidence(spoofed.fixes)
    # never before the change (trailing window); within 3 s: the three accuracies are one estimate, and a second
    # indicator (the fix lost) must agree with it
    assert res.alarms and 150.0 <= res.alarms[0].start_s <= 153.0
    assert res.alarms[0].onset_s is not None and 145.0 <= res.alarms[0].onset_s <= 150.5
    text = res.findings[0].text
    assert "reported horizontal accuracy" in text and "fix lost" in text


def _receiver_log(seconds: float, attack_s: float | None, seed: int = 3) -> pd.DataFrame:
    """1 Hz fixes of one receiver whose indicators wander as real ones do, worse from `attack_s` on as
    an M8N's under an SDR spoofer (accuracies x4, noise up, satellites down, DOP up)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0)
    bad = np.zeros(len(t), bool) if attack_s is None else t >= attack_s
    wander = lambda scale: scale * rng.standard_normal(len(t))  # noqa: E731
    return pd.DataFrame(
        {
            "t_s": t,
            "receiver_id": "gps",
            "h_acc_m": np.where(bad, 6.0, 1.6) + wander(0.1),
            "v_acc_m": np.where(bad, 9.5, 2.5) + wander(0.15),
            "vel_acc_mps": np.where(bad, 4.0, 0.35) + wander(0.03),
            "hdop": np.where(bad, 2.1, 0.9) + wander(0.03),
            "vdop": np.where(bad, 3.0, 1.3) + wander(0.05),
            "noise_per_ms": np.where(bad, 141.0, 95.0) + wander(2.0),
            "sats_used": np.where(bad, 8.0, 14.0) + rng.integers(-1, 2, len(t)),
            "jamming_indicator": np.nan,
            "agc": np.nan,
            "cn0_mean_dbhz": np.nan,
            "jamming_state": np.nan,
            "spoofing_flag": 0,
        }
    )


@pytest.mark.parametrize("attack_s", [200.0, 100.0, 60.0])
def test_receiver_evidence_learns_its_baseline_before_a_takeover_that_fills_most_of_the_log(attack_s: float) -> None:
    """A takeover lasting to the log's end and filling 1/3 to 4/5 of it: the whole log's median would be
    the attack's state (the attack normal, the clean part odd). The baseline is learned before the
    change, which is found where the indicators worsen together."""
    res = run_receiver_evidence(_receiver_log(300.0, attack_s))
    assert [round(a.start_s) for a in res.alarms] == [round(attack_s)]
    onset = res.alarms[0].onset_s
    assert res.alarms[0].end_s == 299.0 and onset is not None and attack_s - 1.0 <= onset <= attack_s
    assert f"learned before {attack_s:.1f} s" in res.reason
    clean = run_receiver_evidence(_receiver_log(300.0, None))
    assert not clean.alarms and "learned before" not in clean.reason


def test_a_clean_multirotor_flight_is_clean_and_its_imu_needs_no_inflation(multirotor) -> None:
    """Climb-out, hover and cruise: the INS follows the whole flight, so the learned IMU noise stays at
    its preset and nothing is called spoofed (a multirotor tilts its thrust; it never pitches up 90
    degrees to climb vertically, which an earlier truth did and which the filter could not follow)."""
    assert np.degrees(np.abs(multirotor.truth.pitch)).max() < 15.0
    analysis = analyze_table(multirotor.table)
    assert not analysis.verdict.spoofed
    nav = analysis.results[[r.name for r in analysis.results].index("navigation")]
    assert "IMU noise 1 x preset" in nav.reason or "IMU noise 0." in nav.reason, nav.reason


def test_the_noise_is_learned_from_the_fixes_not_from_what_the_receiver_reports(multirotor) -> None:
    from spooflens.navigation.product import navigation_of
    from spooflens.pipeline.registry import AnalysisContext, AnalyzeOptions

    nav = navigation_of(AnalysisContext(multirotor.table, AnalyzeOptions()))
    learned = nav.learned.noise
    model = ReceiverModel(accuracy_factor=5.0)
    real_h = float(np.hypot(model.white_m[0], model.gm_m[0]))
    learned_h = float(np.hypot(learned.white_pos_m[0], learned.gm_pos_m[0]))
    reported = float(np.median(multirotor.table.fixes["h_acc_m"]))
    assert 0.5 * real_h < learned_h < 2.0 * real_h  # the receiver's real scatter ...
    assert reported > 3.0 * learned_h  # ... not its five times too large report
    assert nav.learned.evaluations > 10


def test_raim_excludes_and_names_a_counterfeit_satellite_on_the_real_pair() -> None:
    from readers.rinex import rinex_approx_position
    from spooflens.gnss.solved_fixes import with_solved_fixes

    table = read_shared(GSI)
    spoofed, _ = apply_attack(table, parse_attack("pr_delay:delay=100000,svs=G07,start=0"))
    analysis = analyze_table(with_solved_fixes(spoofed))
    texts = [f.text for f in analysis.verdict.findings]
    assert any("G07 inconsistent by 100 km" in t for t in texts), texts
    assert analysis.verdict.spoofed and "G07" in analysis.verdict.incidents[0].satellites
    fixes = with_solved_fixes(spoofed)
    for rid, name in (("0759", "07590920.05o"), ("3040", "30400920.05o")):
        lat, lon, h = ecef_to_geodetic(np.array([rinex_approx_position(GSI / name)]))
        fx = fixes.fixes_of(rid)
        enu = geodetic_to_enu(fx["lat_deg"], fx["lon_deg"], fx["height_m"], float(lat[0]), float(lon[0]), float(h[0]))
        # G07 left out, the fix stays on the surveyed site
        assert np.percentile(np.hypot(enu[:, 0], enu[:, 1]), 95) < 10.0
    flags = fixes.observations["fault_flag"].to_numpy()
    g07 = fixes.observations["sv_id"].to_numpy() == "G07"
    assert (flags[g07] == 1).mean() > 0.9 and (flags[~g07] == 1).mean() < 0.10
    # other satellites left out now and then (a weaker geometry without G07) are never named
    raim = next(r for r in analysis.results if r.name == "raim")
    assert {s for a in raim.alarms for s in a.satellites} == {"G07"}
    # 100 km is no reflection: nothing natural explains it
    assert any(f.range_error_m and f.range_error_m > 9e4 for f in raim.findings)
    assert not any(e.cause == "reflection" for i in analysis.verdict.incidents for e in i.explanations)


def test_one_satellite_a_reflection_long_at_a_station_is_nlos_but_a_second_receiver_still_counts() -> None:
    # the real GSI pair with G07 at station 0759 delayed 100 m from the start, its C/N0 as recorded
    # (modelled NLOS: a building's reflection at a static receiver, which RAIM excludes)
    from spooflens.gnss.solved_fixes import with_solved_fixes

    attack = "pr_delay:delay=100,svs=G07,start=0,receiver=0759"
    spoofed, _ = apply_attack(read_shared(GSI), parse_attack(attack))
    verdict = analyze_table(with_solved_fixes(spoofed)).verdict
    raim_alone, later = verdict.incidents
    # RAIM alone (an independent class, medium until now): the reflection explains it
    assert raim_alone.detectors == ("raim",) and raim_alone.confidence_of_alarms == "medium"
    assert not raim_alone.is_spoofing and [e.cause for e in raim_alone.explanations] == ["reflection"]
    assert raim_alone.explanations[0].text.startswith("G07 alone 101 m off")
    # later the moved fix also breaks the surveyed baseline: a second receiver's evidence, which no
    # reflection accounts for, keeps that incident spoofing
    assert later.is_spoofing and later.unexplained == (Evidence.SECOND_RECEIVER,)


def test_an_injected_ramp_on_the_real_husky_bag_is_an_incident_that_ends_with_the_attack(husky_bag: Path) -> None:
    table = read_shared(husky_bag)
    spoofed, _ = apply_attack(table, parse_attack("ramp:rate=2,start=200,end=300"))
    verdict = analyze_table(spoofed).verdict
    spoofing = [i for i in verdict.incidents if i.is_spoofing]
    assert len(spoofing) == 1, verdict.incidents
    inc = spoofing[0]
    assert Evidence.INERTIAL in inc.evidence and 199.0 <= inc.start_s <= 203.0
    assert abs(inc.end_s - 300.0) < 5.0 and not inc.ongoing_at_end
    assert inc.end_interval_s is not None and inc.end_interval_s[0] - 1.0 <= 300.0 <= inc.end_interval_s[1] + 1.0


def test_a_step_on_the_real_husky_bag_opens_its_own_incident_and_leaves_the_clean_start_alone(husky_bag: Path) -> None:
    """A 50 m step from 157.4 s: the fixes before it are the clean bag's. Its alarms are its incident's
    start, not the end of one confirmed from the bag's own wander at 102 s (which the coasts cut short by
    the attack left the clean envelope's long horizons too few to bound)."""
    table = read_shared(husky_bag)
    spoofed, _ = apply_attack(table, parse_attack("step:offset=50,start=157.4"))
    verdict = analyze_table(spoofed).verdict
    spoofing = [i for i in verdict.incidents if i.is_spoofing]
    assert len(spoofing) == 1, verdict.incidents
    attack = spoofing[0]
    assert abs(attack.onset_s - 157.4) <= 3.0 and attack.start_s >= 150.0, attack
    assert Evidence.INERTIAL in attack.evidence and attack.ongoing_at_end


def test_the_clean_real_husky_bag_is_not_called_spoofed(husky_bag: Path) -> None:
    verdict = analyze_table(read_shared(husky_bag)).verdict
    assert not verdict.spoofed, verdict.incidents
    # its start (SBAS converging: receiver flags, then a GNSS-only jump half a minute later) is noted
    assert verdict.incidents and all(i.confidence == "low" for i in verdict.incidents)
    # its INS tests' alarms alone whose coasts stayed within the log's clean departures all the way are no
    # anomaly: they show only as cleared coasting checks (they were 5 of its 7 anomalies)
    cleared = [c for c in verdict.coasting_checks if c["cleared"]]
    assert len(cleared) >= 3 and all(not c["confirmed"] and c["peak_ratio_over_envelope"] <= 1.0 for c in cleared)
    assert all(i.evidence for i in verdict.incidents)


def test_a_log_that_joins_two_recordings_is_analysed_as_two(tmp_path: Path) -> None:
    src = ROOT / "sample_logs" / "ground_csv"
    joined = tmp_path / "joined"
    joined.mkdir()
    for f in ("fixes.csv", "imu.csv"):
        lines = (src / f).read_text().splitlines()
        head = [x for x in lines if x.startswith("#")]
        body = [x for x in lines if not x.startswith("#")]
        (joined / f).write_text("\n".join(head + body + body[1:]) + "\n")
    table = read_log(joined)
    assert len(table.segments) == 2 and any(s.action == "segmented" for s in table.skipped)
    first, second = table.segment(0), table.segment(1)
    assert len(first.fixes) == len(second.fixes) == len(read_log(src).fixes)
    assert first.absolute_iso(0.0) == second.absolute_iso(0.0)  # both recordings start at the same clock time
    shutil.rmtree(joined)


def test_a_velocity_pull_is_confirmed_by_how_far_gnss_velocity_leaves_the_coasted_reference() -> None:
    """0.5 m/s on east and north (the benchmark's car, seed 1022): 10 m off the reference only after 15 s,
    when a consumer INS coasting no longer separates it; its velocity is off from the first pulled fix."""
    from spooflens.bench.realworld_bench import Run, _table

    table, first = _table(Run("car", "velocity pull 0.5 m/s", 1022))
    assert first is not None
    verdict = analyze_table(table).verdict
    hit = [i for i in verdict.incidents if i.is_spoofing]
    assert len(hit) == 1 and Evidence.INERTIAL in hit[0].evidence
    assert abs(hit[0].onset_s - first) <= 1.0 and hit[0].ongoing_at_end


def test_a_capture_that_stops_ends_where_gnss_jumps_back_and_a_glitch_does_not_end_one_that_goes_on() -> None:
    """A consumer car coasting for 150 s cannot tell agreement any more; the receiver's return to the real
    sky at 250 s (the transient, and GNSS jumping hundreds of metres back) ends the incident there."""
    sc = replace(SCENARIOS["ground"], receiver=ReceiverModel())
    table = simulate(sc, seed=1, duration_s=300.0).table
    stops, _ = apply_attack(table, parse_attack("capture:start=100,end=250"))
    inc = next(i for i in analyze_table(stops).verdict.incidents if i.is_spoofing)
    assert not inc.ongoing_at_end and 249.0 <= inc.end_s <= 252.0 and "returning" in inc.end_method
    goes_on, _ = apply_attack(table, parse_attack("capture:start=100"))
    inc = next(i for i in analyze_table(goes_on).verdict.incidents if i.is_spoofing)
    assert inc.ongoing_at_end and inc.end_s == pytest.approx(float(table.duration_s), abs=0.5)


def test_a_coast_into_a_turn_with_its_heading_off_is_no_false_incident() -> None:
    """A clean simulated aircraft (`bench realworld --clean-hours 100 --seed 71000`'s one false incident): a
    coast began 14 degrees off in heading (1.85 sigma) after a straight climb and entered a 1.1 g turn. Its
    error was 1.8 sigma on each axis, but along the turn's displacement the linear covariance is thin, and
    the joint NIS made it 7 times the clean envelope. The heading error's second-order term along the turn
    (`with_heading_curvature`) is in the coast's covariance now."""
    out = one_run(Run("aircraft", None, 71602))
    assert out["false_incidents"] == 0


def test_a_receiver_losing_satellites_with_its_dop_is_no_false_incident() -> None:
    """A clean simulated multirotor (`bench realworld --clean-hours 100 --seed 75000`'s one false incident):
    its receiver lost satellites over 40 s (9 -> 5, the C/N0 of the rest steady), its DOP and reported
    accuracies rose with them; receiver self-report alarmed, and one GNSS-only epoch inside it made a medium
    SPOOFING incident. Satellites blocked whole are degradation without a fall of the C/N0."""
    out = one_run(Run("multirotor", None, 75054))
    assert out["false_incidents"] == 0
