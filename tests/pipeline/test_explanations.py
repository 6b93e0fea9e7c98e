"""Natural explanations of an incident's evidence, each on a real log that shows it (or, where no readable
real log does, on a real log with the fault modelled, said so in the test's name)."""

from __future__ import annotations

from dataclasses import replace
from functools import cache

import numpy as np
import pandas as pd
import pytest
from paths import REAL, real_log

from spooflens.attacks import apply_attack
from spooflens.attacks.spec import parse_attack
from spooflens.detectors.base import Alarm, DetectorResult
from spooflens.detectors.gnss_consistency import ConsistencyOptions, run_gnss_consistency
from spooflens.detectors.receiver_time import run_receiver_time
from spooflens.epoch_table import EpochTable
from spooflens.pipeline.events import classify
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.explanations import ROLLOVER_S, explain, scene_of, spoofer_marks
from spooflens.pipeline.run import Analysis, analyze_table
from spooflens.pipeline.verdict import Kind, Verdict, decide
from spooflens.service import read_table


@cache
def analysed(relative: str) -> Analysis:
    return analyze_table(read_table(real_log(relative), {}, False))


@cache
def table_of(relative: str) -> EpochTable:
    return read_table(real_log(relative), {}, False)


def causes(verdict: Verdict) -> set[str]:
    return {e.cause for inc in verdict.incidents for e in inc.explanations}


def test_a_weakened_sky_is_degradation_not_spoofing() -> None:
    # a receiver by a window: C/N0 12 dB down, HDOP and reported accuracy up, satellites lost, the fix moving
    # by metres; GNSS-only and receiver self-report agreed (medium until this stage)
    a = analysed("corpus/gpsd/navisys-gr8013.log")
    (inc,) = a.verdict.incidents
    assert inc.confidence_of_alarms == "medium" and not a.verdict.spoofed
    assert inc.kind == Kind.DEGRADATION and inc.confidence == "low"
    (e,) = inc.explanations
    assert e.cause == "degradation" and set(e.detectors) == {"gnss_consistency", "receiver_evidence"}
    assert any("C/N0 fell" in f for f in e.facts) and any("satellites used 10 -> 6" in f for f in e.facts)
    assert "while the fix jumped: degradation (multipath, obstruction), not spoofing" in e.text
    assert "NO SPOOFING DETECTED" in a.verdict.headline and "signal degradation" in a.verdict.headline


def test_a_sky_drowned_until_the_fix_is_lost_is_degradation() -> None:
    # every satellite 26 dB down, 29 -> 12 used, the fix lost for 5 s, then back
    a = analysed("corpus/gpsd/unicore-um621.log")
    (inc,) = a.verdict.incidents
    assert not a.verdict.spoofed and inc.kind == Kind.DEGRADATION
    assert any("fix lost" in f for e in inc.explanations for f in e.facts)


def test_a_weak_sky_all_along_is_degradation() -> None:
    # a phone modem indoors: C/N0 about 20 dB-Hz from the start, its fix wandering by tens of metres (its GP
    # and GN talkers are one receiver: the dual-receiver tests' precondition keeps them from running)
    a = analysed("corpus/gpsd/quectel-eg25-g.log")
    (inc,) = a.verdict.incidents
    assert inc.confidence_of_alarms == "medium" and not a.verdict.spoofed
    assert "degradation" in causes(a.verdict)
    assert any("a weak sky all along" in f for e in inc.explanations for f in e.facts)


def test_the_first_fixes_of_a_cold_start_are_convergence() -> None:
    # a SiRF receiver's first fix: 2D, HDOP 21, satellites being acquired
    a = analysed("corpus/gpsd/haicom-305N.log")
    (inc,) = a.verdict.incidents
    assert not a.verdict.spoofed and inc.kind == Kind.RECEIVER_FAULT
    (e,) = inc.explanations
    assert e.cause == "convergence" and "converging after a cold start" in e.text
    assert "HDOP 21.1" in e.text and "2D -> 3D" in e.text


def test_one_receivers_talkers_are_no_second_receiver() -> None:
    # SiRFstarV NMEA: GP, GL and GN sentences of one receiver give the same numbers; baseline_collapse read
    # them as two antennas fed by one spoofer. Relayed duplicates are weighed before the dual-receiver
    # tests run (their precondition), so no alarm of a second receiver is left to explain
    a = analysed("corpus/gpsd/sirfstarv-nmea.log")
    assert not a.verdict.spoofed
    collapse = next(r for r in a.results if r.name == "baseline_collapse")
    assert not collapse.ran and collapse.precondition is not None
    assert "one receiver" in collapse.reason


@pytest.fixture(scope="module")
def mtv() -> Analysis:
    # a u-blox ZED-F9K in a car, 29 min: RTK fixed, float, DGNSS in turn; R10 never in its fix
    return analysed("corpus/gps-measurement-tools/MTV.Local1.ublox-F9K.20200206-181434.nmea")


def test_a_satellite_the_receiver_never_used_corroborates_no_jump_of_its_fix(mtv: Analysis) -> None:
    """The urban drive's GNSS-only test at its nominal threshold (before it learned this receiver's heavy
    tail): its fix jumps coincide with a satellite's alarms, six incidents of two classes, and the satellite,
    R10, is one the receiver never used."""
    assert not mtv.verdict.spoofed
    nominal = run_gnss_consistency(mtv.table.fixes, ConsistencyOptions(min_bursts_to_recalibrate=10**9))
    results = [nominal, *(r for r in mtv.results if r.name != nominal.name)]
    incidents = decide(results).incidents
    before = [i for i in incidents if i.confidence_of_alarms != "low"]
    assert len(before) >= 6  # GNSS-only + receiver self-report at the same time: six SPOOFING incidents before
    never = [
        e for i in before for e in explain(mtv.table, results, i).explanations if e.cause == "satellite never used"
    ]
    assert never and all("R10" in e.text for e in never)


def test_a_switch_of_the_fix_mode_where_the_fix_moved_is_a_receiver_mode_switch(mtv: Analysis) -> None:
    switched = [i for i in mtv.verdict.incidents if any(e.cause == "mode switch" for e in i.explanations)]
    assert switched
    e = next(e for i in switched for e in i.explanations if e.cause == "mode switch")
    assert e.kind == Kind.RECEIVER_FAULT and "RTK" in e.text
    # a GNSS-only alarm where nothing switched is not one
    quiet = Alarm(200.0, 210.0, 50.0, 205.0, onset_s=199.0, receiver_id="GN")
    result = DetectorResult("gnss_consistency", True, alarms=[quiet], evidence=Evidence.GNSS_ONLY)
    (inc,) = decide([result]).incidents
    assert "mode switch" not in {e.cause for e in explain(mtv.table, [result], inc).explanations}


def test_a_sky_back_to_its_usual_strength_after_an_obstruction_is_no_spoofers_signal(mtv: Analysis) -> None:
    """The same drive cut to 1062-1462 s, as an investigator might export it: the minute before the receiver's
    alarm at 1147 s (onset 1101 s, its fix back at 1143 s) is obstructed, its satellites' C/N0 4 dB below the
    alarm's, yet no higher than their usual level in the log. Against the minute alone that rise read as a
    spoofer's stronger signal, vetoed the RTK mode switch that explains the alarm, and the cut was SPOOFING
    (medium)."""
    cut = mtv.table.between(1062.2, 1462.2)
    analysis = analyze_table(cut)
    assert not analysis.verdict.spoofed
    (inc,) = [i for i in analysis.verdict.incidents if i.start_s == 1147.0]
    assert "mode switch" in {e.cause for e in inc.explanations} and inc.kind == Kind.RECEIVER_FAULT
    # the receiver's alarm as it was then (1147-1177 s from 1101 s), read against the minute before its onset
    then = Alarm(1147.0, 1177.0, 20.0, 1155.0, onset_s=1101.0, receiver_id="GN")
    scene = scene_of(cut, analysis.results)
    w = scene.window(then, "GN")
    assert np.nanmax(w.satellite_cn0_change()) >= 3.0 > np.nanmax(w.satellite_cn0_change(above_typical=True))
    assert not spoofer_marks(w, scene.opts)


AAVA = "corpus/signalk/aava-n2k.data"


def test_a_fix_dropped_by_a_gateways_own_cycle_is_a_receiver_fault() -> None:
    """The Aava's NMEA 2000 gateway sends 129029 every 1.005 s of 1 Hz fixes: every 190 s one fix is
    dropped and the position moves two fix periods' travel in one (3.3 m at 6.5 kn), the GNSS-only check's
    four alarms (its time saws the same way, receiver_time). A spoofer's 50 m step on the same log, or a
    ramp, is no dropped fix."""
    verdict = analysed(AAVA).verdict
    assert not verdict.spoofed and len(verdict.incidents) == 4
    for inc in verdict.incidents:
        assert inc.kind == Kind.RECEIVER_FAULT and [e.cause for e in inc.explanations] == ["skipped fix"]
        text = inc.explanations[0].text
        assert "dropped 1 fix(es)" in text and "saws by its 1 s resolution" in text
    table = table_of(AAVA)
    for attack in ("step:start=300,offset=50", "ramp:start=300,end=340,rate=1"):
        spoofed, _ = apply_attack(table, parse_attack(attack))
        (inc,) = [i for i in analyze_table(spoofed).verdict.incidents if i.start_s < 345.0 and i.end_s > 300.0]
        assert inc.kind == Kind.UNKNOWN and "skipped fix" not in causes(replace(verdict, incidents=(inc,))), attack


def _time_stepped(step_s: float, from_s: float = 25.0) -> tuple[EpochTable, list[DetectorResult], Verdict]:
    """The real ArduPilot flight with its receiver's time moved `step_s` against the autopilot's clock
    from `from_s` on (modelled: no readable real log has a rollover against a log clock)."""
    table = table_of("ardupilot_dataflash/flightdata_center_0003.bin")
    fixes = table.fixes.copy()
    later = fixes["t_s"] >= from_s
    fixes.loc[later, "time_offset_s"] += step_s
    table = replace(table, fixes=fixes)
    results = [run_receiver_time(table.fixes, monotonic=True)]
    return table, results, decide(results)


@pytest.mark.parametrize(
    ("step_s", "cause"),
    [(-ROLLOVER_S, "week rollover"), (-ROLLOVER_S + 3600.0, None), (18.0, "leap seconds"), (-3.0, "leap seconds")],
)
def test_a_time_step_of_whole_week_epochs_or_leap_seconds_is_a_receiver_fault(step_s: float, cause: str | None) -> None:
    table, results, verdict = _time_stepped(step_s)
    (inc,) = verdict.incidents
    assert inc.confidence == "medium"  # the log's clock alone: an independent class
    weighed = explain(table, results, inc)
    assert {e.cause for e in weighed.explanations} == ({cause} if cause else set())


def test_a_spoofers_clock_is_no_time_fault() -> None:
    table, results, verdict = _time_stepped(7.3)
    after = classify(table, results, verdict)
    assert after.spoofed and after.incidents[0].kind == Kind.SPOOFING
    assert any("no whole leap second" in a for a in after.events[0].evidence_against)


def test_a_stronger_signal_is_no_degradation() -> None:
    # the navisys window's fall of the sky modelled the other way: every satellite 6 dB louder during it
    a = analysed("corpus/gpsd/navisys-gr8013.log")
    sats = a.table.satellites.copy()
    during = sats["t_s"].between(15.0, 40.0)
    sats.loc[during, "cn0_dbhz"] = sats.loc[during, "cn0_dbhz"] + 16.0
    table = replace(a.table, satellites=sats)
    verdict = classify(table, a.results, decide(a.results))
    assert verdict.spoofed and verdict.incidents[0].kind == Kind.SPOOFING
    against = verdict.events[0].evidence_against
    assert any("rose" in x and "a stronger signal than the sky's" in x for x in against)


def test_a_sky_uncovered_to_an_open_skys_level_is_no_spoofers_signal() -> None:
    """A skydiver's receiver (a real log from outside the corpus): 17 s inside the aircraft at 21-24 dB-Hz, then
    out of the door at 36-43 dB-Hz, the same 12 satellites used. The rise above its level before and its usual
    level (the aircraft's, most of the log) was named a spoofer's stronger signal. Modelled on the navisys
    receiver: its sky flat and covered until 25 s, then 14 dB louder with nothing lost from the fix."""
    a = analysed("corpus/gpsd/navisys-gr8013.log")
    sats, fixes = a.table.satellites.copy(), a.table.fixes.copy()
    covered = sats.groupby("sv_id")["cn0_dbhz"].transform("median")
    sats["cn0_dbhz"] = covered + np.where(sats["t_s"] >= 25.0, 14.0, 0.0)
    fixes["sats_used"] = 10.0
    alarm = Alarm(26.0, 30.0, 20.0, 27.0, onset_s=25.0, receiver_id="ubx")

    def marks(satellites: pd.DataFrame, fix_rows: pd.DataFrame) -> list[str]:
        scene = scene_of(replace(a.table, satellites=satellites, fixes=fix_rows), a.results)
        return spoofer_marks(scene.window(alarm, "ubx"), scene.opts)

    assert not marks(sats, fixes)
    # the same rise from a sky that was open before and usually, or with satellites lost from the fix: marks
    assert any(
        "a stronger signal than the sky's" in m for m in marks(sats.assign(cn0_dbhz=sats["cn0_dbhz"] + 12.0), fixes)
    )
    lost = fixes.assign(sats_used=np.where(fixes["t_s"] >= 25.0, 6.0, 10.0))
    assert any("a stronger signal than the sky's" in m for m in marks(sats, lost))


def _blocked_whole(sats_used: bool) -> EpochTable:
    """The navisys window with its satellites blocked whole: those it stopped using gone from its sky, the
    others at their C/N0 before (`sats_used` False: its satellites-used count held at its level too)."""
    a = analysed("corpus/gpsd/navisys-gr8013.log")
    sats, fixes = a.table.satellites.copy(), a.table.fixes.copy()
    before, during = sats["t_s"] < 6.0, sats["t_s"] >= 6.0
    level = sats[before].groupby("sv_id")["cn0_dbhz"].median()
    used_during = set(sats.loc[during & (sats["used"] > 0), "sv_id"])
    sats = sats[before | sats["sv_id"].isin(used_during)].copy()
    later = sats["t_s"] >= 6.0
    sats.loc[later, "cn0_dbhz"] = sats.loc[later, "sv_id"].map(level).fillna(sats.loc[later, "cn0_dbhz"])
    if not sats_used:
        fixes["sats_used"] = 10.0
    return replace(a.table, satellites=sats, fixes=fixes)


def test_satellites_blocked_whole_are_degradation_without_a_fall_of_the_c_n0() -> None:
    # terrain or a structure hides satellites whole: the receiver loses them (10 -> 6) and its DOP rises,
    # while those it still tracks keep their C/N0; no spoofer's mark, the receiver's interference signs quiet
    a = analysed("corpus/gpsd/navisys-gr8013.log")
    table = _blocked_whole(sats_used=True)
    verdict = classify(table, a.results, decide(a.results))
    assert not verdict.spoofed and verdict.incidents[0].kind == Kind.DEGRADATION
    (e,) = verdict.incidents[0].explanations
    assert "fewer satellites in view" in e.text and "the C/N0 steady" in e.text
    assert any("satellites used 10 -> 6" in f for f in e.facts)
    assert any("C/N0 of the satellites still tracked steady" in f for f in e.facts)


def test_dop_up_alone_without_a_fall_of_the_c_n0_is_no_degradation() -> None:
    # the same window with no satellite lost: the DOP and the reported accuracy rose with the sky unchanged,
    # which no blocked sky explains
    a = analysed("corpus/gpsd/navisys-gr8013.log")
    verdict = classify(_blocked_whole(sats_used=False), a.results, decide(a.results))
    assert verdict.spoofed and verdict.incidents[0].kind == Kind.SPOOFING
    assert any("the C/N0 did not fall" in x for x in verdict.events[0].evidence_against)


def test_the_receivers_own_jamming_state_makes_the_event_jamming() -> None:
    # the navisys window with the receiver's jamming state modelled at 'critical' while its sky fell
    a = analysed("corpus/gpsd/navisys-gr8013.log")
    fixes = a.table.fixes.copy()
    fixes.loc[fixes["t_s"].between(16.0, 34.0), "jamming_state"] = 3.0
    table = replace(a.table, fixes=fixes)
    verdict = classify(table, a.results, decide(a.results))
    assert not verdict.spoofed and verdict.incidents[0].kind == Kind.JAMMING
    assert verdict.headline.startswith("NO SPOOFING DETECTED") and "JAMMING / INTERFERENCE from" in verdict.headline
    assert any("jamming state" in x for x in verdict.events[0].evidence_for)


def test_the_receivers_indicators_are_arrays_of_their_own_epochs() -> None:
    # a guard for the indicators module: a window with no fix gives no level and no sign
    from spooflens.pipeline.indicators import Receiver, Window

    rx = Receiver.of(table_of("corpus/gpsd/navisys-gr8013.log"), "ubx")
    w = Window.of(rx, 1000.0, 1010.0)
    assert w.fixes == 0 and np.isnan(w.worst("hdop", +1))


# --- the vehicle's own IMU: a crash ------------------------------------------------------------------------

CRASH = "corpus/dronekit-la-testdata/log171.bin"  # ArduCopter 3.3 in ACRO, tumbles at 227.7 s and lands


def _unnavigable(table: EpochTable) -> EpochTable:
    """The log with its IMU stopping for 1 s every 40 s: no stretch between the gaps is long enough to
    navigate, so the autopilot's filter is the only inertial reference, as in a log whose IMU spooflens
    cannot mechanise; the tumble (227.7-228.4 s) stays whole. (Navigated, log171 judges its crash by
    coasting its own INS: tests/navigation/test_imu_gaps.py.)"""
    t = table.imu["t_s"].to_numpy(dtype=float)
    return replace(table, imu=table.imu[t % 40.0 < 39.0].reset_index(drop=True))


def _ekf_dragged(table: EpochTable, start_s: float, rate_mps: float = 2.0, tau_s: float = 5.0) -> EpochTable:
    """The autopilot's filter as it shows a GNSS drag north from `start_s` it follows with time constant
    `tau_s` (as tests/detectors/test_autopilot_ekf.py models it): modelled, not a recorded attack."""
    ekf = table.frame("autopilot_ekf").copy()
    t = ekf["t_s"].to_numpy(dtype=float)
    on, dt = t >= start_s, np.clip(t - start_s, 0.0, None)
    ekf.loc[on, "vel_innov_n_mps"] -= rate_mps * np.exp(-dt[on] / tau_s)
    ekf.loc[on, "pos_innov_n_m"] -= rate_mps * tau_s * (1.0 - np.exp(-dt[on] / tau_s))
    return replace(table, autopilot_ekf=ekf)


def test_a_crash_the_imu_read_explains_the_autopilot_filters_departure() -> None:
    # a multirotor in ACRO at 8 m/s tumbles into the ground: all three IMUs at their gyros' full scale
    # (2000 deg/s) and 11-17 g for 0.7 s; the autopilot's filter, integrating through it, loses its attitude
    # and rejects GNSS (velocity test ratio 3.1) for 5 s. Its GNSS stayed where the vehicle was: at rest
    a = analyze_table(_unnavigable(table_of(CRASH)))
    assert not a.verdict.spoofed and "NO SPOOFING DETECTED" in a.verdict.headline
    assert not next(r for r in a.results if r.name == "navigation").ran
    (inc,) = [i for i in a.verdict.incidents if "autopilot_ekf" in i.detectors]
    assert inc.confidence_of_alarms == "high" and inc.confidence == "low"
    assert Evidence.INERTIAL not in inc.unexplained  # what is left is one GNSS-only anomaly
    (e,) = inc.explanations
    assert e.cause == "inertial shock" and e.detectors == ("autopilot_ekf",)
    assert "2,042 deg/s" in e.text and "227.7 s to 228.4 s" in e.text
    assert any("quiet until 227.5" in f for f in e.facts)


def test_an_autopilot_filter_dragged_before_the_crash_is_still_spoofing() -> None:
    # the drag holds to the end of the log, over the tumble at 227.7 s: from 150 s, or from 215 s (12 s
    # before it); either departure began before the IMU read the shock, which does not take it away
    for start_s in (150.0, 215.0):
        v = analyze_table(_ekf_dragged(_unnavigable(table_of(CRASH)), start_s)).verdict
        assert v.spoofed
        (inc,) = [i for i in v.incidents if i.is_spoofing]
        assert Evidence.INERTIAL in inc.unexplained and start_s - 0.5 <= inc.onset_s <= start_s + 3.0
        assert "inertial shock" not in causes(v)
        (event,) = [e for e in v.events if e.kind == Kind.SPOOFING]
        assert any("ruled out inertial shock: the inertial alarm rose from" in x for x in event.evidence_against)


def test_a_capture_injected_through_the_crash_is_still_spoofing(tmp_path) -> None:
    # the spoofer's clock 0.6 s off GNSS time (log clock: a reference the crash does not touch), from 215 s
    # to the end of the log, over the tumble at 227.7 s
    from spooflens.cli import main

    out = tmp_path / "log171_capture.bin"
    assert main(["inject", str(real_log(CRASH)), "--attack", "capture:clock=0.6,start=215", "-o", str(out)]) == 0
    v = analyze_table(read_table(out, {}, False)).verdict
    assert v.spoofed
    (inc,) = [i for i in v.incidents if i.is_spoofing]
    assert Evidence.LOG_CLOCK in inc.unexplained and 214.0 <= inc.start_s <= 220.0


PIXEL4XL = "corpus/gnss_lib_py/gsdc2021_Pixel4XL_derived.csv"  # GSDC 2021, a Pixel 4 XL in a car, clean sky


def _pixel4xl() -> EpochTable:
    if not (REAL / PIXEL4XL).exists():
        pytest.skip(f"real log absent: {REAL / PIXEL4XL}")
    return read_table(REAL / PIXEL4XL, {}, False, solve_fixes=False)


def test_a_phone_satellite_excluded_in_a_run_a_reflections_length_off_is_no_spoofing() -> None:
    # a car's phone passes reflections: RAIM excludes its noisy GLONASS R13 (residuals of +-25 m sigma
    # over the log, sign changing, at 73 deg elevation) in one run of 4 of 6 epochs, 79.8-104.8 s, 33-50 m
    # off; R13 is excluded at 35 of its 200 epochs, no finding. RAIM alone gave medium; the alarm's own size
    # is a reflection's
    from spooflens.gnss.solved_fixes import with_solved_fixes

    a = analyze_table(with_solved_fixes(_pixel4xl()))
    assert not a.verdict.spoofed, a.verdict.headline
    raim = [i for i in a.verdict.incidents if "raim" in i.detectors]
    assert raim and all(i.confidence_of_alarms == "medium" and not i.is_spoofing for i in raim)
    (alarm,) = next(r for r in a.results if r.name == "raim").alarms
    assert alarm.satellites == ("R13",) and alarm.range_error_m is not None and 30.0 < alarm.range_error_m < 60.0
    assert alarm.peak_statistic < 60.0  # the run's own largest, not the satellite's over the whole log (98 m)
    (e,) = raim[0].explanations
    assert e.cause == "reflection" and e.kind == Kind.DEGRADATION and e.text.startswith("R13 alone 41 m off")


def test_satellites_reflected_one_after_another_are_not_a_bias() -> None:
    """The same phone drive cut to 31.3-931.3 s (its solution learns another scale): RAIM excludes R14 over
    64.8-84.8 s, 53 m off, then R13 over 79.8-104.8 s, 41 m off, overlapping 5 s. The incident named both, and
    a reflection must be alone: SPOOFING (medium). A bias moves satellites at the same time; these were off
    one after another, as a car passes buildings."""
    from spooflens.gnss.solved_fixes import with_solved_fixes

    a = analyze_table(with_solved_fixes(_pixel4xl()).between(31.3, 931.3))
    assert not a.verdict.spoofed, a.verdict.headline
    (inc,) = [i for i in a.verdict.incidents if "raim" in i.detectors]
    assert set(inc.satellites) == {"R13", "R14"} and [e.cause for e in inc.explanations] == ["reflection"]


def test_two_satellites_reflected_at_once_are_no_bias_but_one_a_spoofers_length_off_beside_them_is() -> None:
    """The same drive cut to 740.9-980.9 s (`bench windows --seed 35`): RAIM excludes R13 over 761-792 s, 37 m
    off, and G09 over 766-787 s, 40 m off, at the same time (a street's buildings on both sides). "Not alone"
    made it SPOOFING (medium). Two satellites each within a reflection's length are two reflections; with G09
    a counterfeit 300 m late beside R13's reflection it stays spoofing."""
    from spooflens.attacks import apply_attack, parse_attack
    from spooflens.gnss.solved_fixes import with_solved_fixes

    clean = analyze_table(with_solved_fixes(_pixel4xl()).between(740.9, 980.9))
    assert not clean.verdict.spoofed, clean.verdict.headline
    inc = next(i for i in clean.verdict.incidents if set(i.satellites) == {"G09", "R13"})
    assert [e.cause for e in inc.explanations] == ["reflection"] and inc.kind == Kind.DEGRADATION
    assert "R13 37 m off, with G09 40 m off at the same time" in inc.explanations[0].text
    spoofed, _ = apply_attack(_pixel4xl(), parse_attack("pr_delay:svs=G09,delay=300,start=760"))
    attacked = analyze_table(with_solved_fixes(spoofed).between(740.9, 980.9))
    assert attacked.verdict.spoofed, attacked.verdict.headline
    hit = next(i for i in attacked.verdict.incidents if i.is_spoofing)
    assert "G09" in hit.satellites and not any(e.cause == "reflection" for e in hit.explanations)


def test_a_weak_satellite_gaining_a_few_db_is_still_a_reflection() -> None:
    """A 2016 phone log (GnssLogger 1.4) cut to 123.1-168.1 s, where `bench windows` cut it: RAIM excludes G05
    over 127-137 s, 30 m off, and G05's C/N0 goes from 14.8 to 18-20 dB-Hz. "Its C/N0 rose 5 dB: no
    reflection does that" made it SPOOFING (medium). A spoofer's signal rises above the sky's usual strength
    (30 dB-Hz here); a satellite near its tracking threshold gaining a few dB is still a weak one."""
    log = real_log("android_gnsslogger/gps-measurement-tools/pseudoranges_log_2016_08_22_14_45_50.txt")
    a = analyze_table(read_table(log, {}, False).between(123.1, 168.1))
    assert not a.verdict.spoofed, a.verdict.headline
    (inc,) = [i for i in a.verdict.incidents if "raim" in i.detectors]
    assert inc.satellites == ("G05",) and [e.cause for e in inc.explanations] == ["reflection"]
    assert inc.explanations[0].text.startswith("G05 alone 30 m off")


@pytest.mark.parametrize("delay_m", [2000.0, 300.0])
def test_a_satellite_a_spoofers_length_off_in_the_same_phone_log_is_still_spoofing(delay_m: float) -> None:
    # the same log with G09 (82 deg, every epoch) a counterfeit delay_m late from 200 s: RAIM's alarm carries
    # its size, more than any reflection, and nothing natural explains it
    from spooflens.attacks import apply_attack, parse_attack
    from spooflens.gnss.solved_fixes import with_solved_fixes

    spoofed, _ = apply_attack(_pixel4xl(), parse_attack(f"pr_delay:svs=G09,delay={delay_m:g},start=200"))
    a = analyze_table(with_solved_fixes(spoofed))
    assert a.verdict.spoofed, a.verdict.headline
    inc = next(i for i in a.verdict.incidents if i.is_spoofing)
    assert "G09" in inc.satellites and "raim" in inc.detectors and 195.0 <= inc.start_s <= 215.0
    assert not any(e.cause == "reflection" for e in inc.explanations)
    sizes = [x.range_error_m for x in next(r for r in a.results if r.name == "raim").alarms if x.satellites == ("G09",)]
    assert sizes and all(s is not None and 0.9 * delay_m < s < 1.1 * delay_m for s in sizes)


def test_a_cold_start_settles_where_its_first_fixes_do_not_at_jamming_minutes_later() -> None:
    # log171's receiver settles within its first minute; a jammer at 100-150 s inflates its HDOP and
    # accuracies again inside the minutes a convergence may last. That second stretch is the jamming's, not
    # a longer convergence: read as one, it explained alarms up to 149 s as a cold start
    # (its first minute alone raises no receiver alarm since its three accuracies count as one estimate)
    jammed, _ = apply_attack(table_of(CRASH), parse_attack("jam:start=100,end=150"))
    incidents = analyze_table(jammed).verdict.incidents
    settled = [
        float(f.removeprefix("settled by ").removesuffix(" s"))
        for i in incidents
        for e in i.explanations
        if e.cause == "convergence"
        for f in e.facts
        if f.startswith("settled by ")
    ]
    assert max(settled, default=0.0) < 100.0
    (jam,) = [i for i in incidents if i.start_s <= 101.0 <= i.end_s and "receiver_evidence" in i.detectors]
    assert [e.cause for e in jam.explanations] == ["interference"]


HUSKY = "ros1_husky_navsat/test1.bag"


@pytest.mark.parametrize(
    ("attack", "glitch"),
    [
        ("step:start=300,end=303,offset=10", True),  # 3 s, 10 m: multipath's size and length
        ("step:start=200,end=208,offset=25", True),
        ("step:start=300,end=315,offset=10", False),  # 15 s away: longer than an autopilot rides out
    ],
)
def test_gnss_that_leaves_the_ins_for_seconds_and_comes_back_is_a_glitch(attack: str, glitch: bool) -> None:
    """The real husky bag's fixes moved for a few seconds and back, nothing else touched: a multipath or NLOS
    excursion looks exactly like this, and ArduPilot's EKF3 rejects GNSS up to 7-10 s before it takes it back as
    true. It was SPOOFING (high: the GNSS jump and the INS agreeing on it); a glitch now. One that stays away
    longer is still spoofing."""
    spoofed, _ = apply_attack(table_of(HUSKY), parse_attack(attack))
    start = float(attack.split("start=")[1].split(",")[0])
    verdict = analyze_table(spoofed).verdict
    ((k, inc),) = [(k, i) for k, i in enumerate(verdict.incidents) if i.start_s <= start + 1.0 <= i.end_s]
    (event,) = [e for e in verdict.events if e.incident == k]
    if glitch:
        assert not inc.is_spoofing and inc.kind == Kind.DEGRADATION, attack
        (e,) = inc.explanations
        assert e.cause == "glitch" and "came back onto it" in e.text
        assert inc.confidence_of_alarms == "high"  # the alarms alone: what the explanation weighed
    else:
        assert inc.is_spoofing and inc.kind == Kind.SPOOFING, attack
        assert any("ruled out glitch" in x and "longer than a glitch" in x for x in event.evidence_against)


def _station_motion(motion: np.ndarray, odd_satellite_mps: float = 0.0) -> tuple[DetectorResult, Verdict]:
    """range_rate against a known station over 48 s at 1 Hz: the receiver's velocity against it (`motion`,
    east/north/up per epoch) and 8 satellites' rates after the fit of one common motion (3 mm/s of noise, and
    `odd_satellite_mps` more on one of them while the receiver moves)."""
    from spooflens.detectors.base import Series

    t = np.arange(48.0)
    rng = np.random.default_rng(4)
    residual = rng.normal(0.0, 0.003, (len(t), 8))
    moving = np.linalg.norm(motion, axis=1) > 0.05
    residual[moving, 3] += odd_satellite_mps
    alarm = Alarm(3.0, 6.0, 20.7, 3.0, onset_s=3.0, receiver_id="rover", satellites=("G05",))
    sats = tuple(f"G{k:02d}" for k in range(1, 9))
    series = [
        Series("rover/velocity_error", t, motion, "m/s", None, ("east", "north", "up")),
        Series("rover/rate_residual", t, residual, "m/s", None, sats),
    ]
    result = DetectorResult("range_rate", True, alarms=[alarm], evidence=Evidence.KNOWN_STATION, series=series)
    return result, decide([result])


def _out_and_back(speed_mps: float, back: bool = True) -> np.ndarray:
    v = np.zeros((48, 3))
    v[3:5, 0] = -speed_mps  # 2 s west-south-west at 0.4 m/s, as a rover's antenna handled in a real log
    v[3:5, 1] = -0.5 * speed_mps
    if back:
        v[5:7, 0], v[5:7, 1] = speed_mps, 0.5 * speed_mps
    return v


def test_a_stations_antenna_moved_and_put_back_is_no_spoofing() -> None:
    """A walking rover's RINEX, its header position taken for a station while it stood: its antenna handled,
    0.8 m west and back in 4 s, every satellite's carrier rate following, read as a medium SPOOFING incident
    naming one satellite. A station that leaves and stays away, or one satellite off on its own, stays
    evidence."""
    table = table_of("rinex_gsi_pair")
    result, verdict = _station_motion(_out_and_back(0.4))
    (inc,) = verdict.incidents
    (moved,) = [e for e in explain(table, [result], inc).explanations if e.cause == "antenna moved"]
    assert moved.kind == Kind.RECEIVER_FAULT and "moved 0.7 m from its known position and came back" in moved.text
    result, verdict = _station_motion(_out_and_back(0.4, back=False))
    weighed = explain(table, [result], verdict.incidents[0])
    assert "antenna moved" not in {e.cause for e in weighed.explanations}
    assert any("did not come back" in r for r in weighed.ruled_out)
    result, verdict = _station_motion(_out_and_back(0.4), odd_satellite_mps=0.4)
    weighed = explain(table, [result], verdict.incidents[0])
    assert "antenna moved" not in {e.cause for e in weighed.explanations}
    assert any("left the receiver's one motion" in r for r in weighed.ruled_out)


def _held_fix(table: EpochTable, at_s: float, offset_m: float = 0.0) -> EpochTable:
    """The receiver's fix held for 2 s from `at_s` (its position frozen, 0 satellites used), then where the car
    was; `offset_m` north from there on (a spoofer's jump out of the hold)."""
    fx = table.fixes.copy()
    held = fx.index[fx["t_s"].between(at_s, at_s + 1.5)]
    before = fx.index[fx["t_s"] < at_s][-1]
    fx.loc[held, ["lat_deg", "lon_deg"]] = fx.loc[before, ["lat_deg", "lon_deg"]].to_numpy(float)
    fx.loc[held, "sats_used"] = 0.0
    fx.loc[fx["t_s"] >= at_s + 2.0, "lat_deg"] += offset_m / 110_540.0
    return replace(table, fixes=fx)


def test_a_fix_held_through_an_outage_then_caught_up_is_degradation(mtv: Analysis) -> None:
    """A car's receiver under an overpass (a real Denver drive from outside the corpus) wrote its last position
    for 2 s with 0 satellites used, then jumped 87 m to where its 27 m/s took it: it was told as a 3D->2D mode
    switch "moving 27 m". The same hold ending 300 m off the car's track is no outage."""
    cut = mtv.table.between(600.0, 900.0)
    held = analyze_table(_held_fix(cut, 725.0))
    (inc,) = [i for i in held.verdict.incidents if any(e.cause == "held fix" for e in i.explanations)]
    (e,) = [e for e in inc.explanations if e.cause == "held fix"]
    assert e.text.startswith("the receiver held its fix for 2.0 s from 725.0 s (0 satellites used")
    assert "what its speed covered: an outage" in e.text and inc.kind == Kind.DEGRADATION
    jumped = analyze_table(_held_fix(cut, 725.0, offset_m=300.0))
    assert not any(e.cause == "held fix" for i in jumped.verdict.incidents for e in i.explanations)
