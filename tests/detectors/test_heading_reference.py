"""GNSS against a vessel's compass and speed log (heading reference): a real chartplotter log, clean and
attacked, and synthetic vessels for what the real log does not hold (no speed log, glitches, GNSS
headings)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from paths import real_log

from readers import read_log
from spooflens.attacks import apply_attack, parse_attack
from spooflens.detectors.base import DetectorResult, Track
from spooflens.detectors.heading_reference import run_heading_reference
from spooflens.geodesy import enu_to_geodetic
from spooflens.pipeline.departure import gnss_departure, reconstructed_tracks
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.run import analyze_table
from spooflens.pipeline.verdict import Verdict
from spooflens.simulation.sensors import (
    TIDE_PERIOD_S,
    CompassModel,
    compass_readings,
    realistic_compass,
    realistic_receiver,
)
from spooflens.simulation.simulate import SCENARIOS, simulate


@pytest.fixture(scope="module")
def bundg():
    return read_log(real_log("nmea_boats/gpsd_bundg_zeus_9.log"))


def _strength(result) -> np.ndarray:
    return next(s for s in result.series if s.name.endswith("/strength")).values


def test_the_real_sailing_log_is_quiet_with_a_wide_margin(bundg) -> None:
    # 148 s on the IJsselmeer at 3 m/s, SDHDG compass at 10 Hz and SDVHW speed log at 1 Hz
    result = run_heading_reference(bundg.fixes, bundg.headings)
    assert result.ran and result.evidence == Evidence.HEADING and not result.alarms
    assert "SDHDG" in result.reason and "speed log" in result.reason
    assert np.nanmax(_strength(result)) < 0.6  # measured 0.47 of the alarm level
    # the residual the compass and log leave is the chartplotter's scatter: tenths of a m/s
    track = next(s for s in result.series if s.name.endswith("/track_residual")).values
    assert np.nanmax(np.abs(track)) < 0.5


@pytest.mark.parametrize("offset_m", [30.0, 3000.0])
def test_a_jump_of_the_real_log_is_spoofing_with_the_heading_class(bundg, offset_m: float) -> None:
    spoofed, _ = apply_attack(bundg, parse_attack(f"step:offset={offset_m:g},start=70"))
    result = run_heading_reference(spoofed.fixes, spoofed.headings)
    assert len(result.alarms) == 1
    alarm = result.alarms[0]
    assert 70.0 <= alarm.start_s <= 71.5 and alarm.onset_s is not None and 67.0 <= alarm.onset_s <= 70.5
    analysis = analyze_table(spoofed)
    verdict = analysis.verdict
    assert verdict.spoofed
    first = verdict.deciding_incident
    assert first is not None and Evidence.HEADING in first.corroborating
    # 3 km is held to the last fix: the incident lasted to the end of the log, not to its last alarm
    assert first.ongoing_at_end == (offset_m == 3000.0)
    # where the vessel was: dead reckoned by its compass and log from the last quiet fix; GNSS went the
    # jump's sqrt(2) x offset (east and north) away from it, give or take the dead reckoning's own
    # error over the half minute it is held and the fixes' scatter
    (departure,) = gnss_departure(spoofed, analysis.results, analysis.verdict, first)
    assert departure.track.startswith("reconstructed (compass")
    assert departure.peak_m == pytest.approx(np.sqrt(2) * offset_m, rel=0.05, abs=5.0)


def test_a_drag_of_a_third_of_the_real_log_is_found_to_its_end(bundg) -> None:
    spoofed, _ = apply_attack(bundg, parse_attack("ramp:rate=2,start=100"))
    result = run_heading_reference(spoofed.fixes, spoofed.headings)
    assert len(result.alarms) == 1
    alarm = result.alarms[0]
    # the track's 10 s window fills with the drag before it passes the alarm level; the onset is where
    # its rise began
    assert 100.0 <= alarm.start_s <= 110.0 and alarm.end_s == pytest.approx(spoofed.fixes["t_s"].max())
    assert alarm.onset_s is not None and 97.0 <= alarm.onset_s <= 101.0


def _vessel(
    seconds: float = 900.0,
    heading_deg: float = 70.0,
    water_mps: float = 5.0,
    current: tuple[float, float] = (0.4, -0.3),
    speed_log: bool = True,
    talker: str = "HE",
    seed: int = 3,
) -> tuple[pd.DataFrame, pd.DataFrame, np.ndarray, np.ndarray]:
    """A ship on a zig-zag course (heading swinging 30 degrees every 5 min) at `water_mps` through water
    that flows at `current`: 1 Hz GNSS fixes (1 m noise, Doppler velocity 0.05 m/s), 1 Hz gyro heading
    (0.3 degrees) with the speed log. Returns fixes, headings and the true east/north track."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0)
    h = np.radians(heading_deg + 30.0 * (np.floor(t / 300.0) % 2))
    v = np.c_[water_mps * np.sin(h) + current[0], water_mps * np.cos(h) + current[1]]
    p = np.cumsum(v, axis=0)
    return (*_frames(t, p, v, h, rng, speed_log, talker, water_mps), t, p)


def _frames(t, p, v, h, rng, speed_log, talker, water_mps) -> tuple[pd.DataFrame, pd.DataFrame]:
    n = len(t)
    enu = np.c_[p + rng.normal(0.0, 1.0, p.shape), np.zeros(n)]
    lat, lon, _ = enu_to_geodetic(enu, 54.0, 10.0, 0.0)
    fixes = pd.DataFrame(
        {
            "t_s": t,
            "receiver_id": "GP",
            "lat_deg": lat,
            "lon_deg": lon,
            "vel_e_mps": v[:, 0] + rng.normal(0.0, 0.05, n),
            "vel_n_mps": v[:, 1] + rng.normal(0.0, 0.05, n),
        }
    )
    headings = pd.DataFrame(
        {
            "t_s": t + 0.3,
            "heading_id": f"{talker}HDT",
            "heading_deg": np.degrees(h + rng.normal(0.0, np.radians(0.3), n)) % 360.0,
            "talker": talker,
            "water_speed_mps": np.where(speed_log, water_mps + rng.normal(0.0, 0.05, n), np.nan),
        }
    )
    return fixes, headings


def _shift(fixes: pd.DataFrame, offset_enu: np.ndarray, velocity: np.ndarray | None = None) -> pd.DataFrame:
    """The fixes moved by a per-fix east/north offset (and their velocity by `velocity`), as a spoofer does."""
    out = fixes.copy()
    mlat = 6_371_000.0
    out["lat_deg"] += np.degrees(offset_enu[:, 1] / mlat)
    out["lon_deg"] += np.degrees(offset_enu[:, 0] / (mlat * np.cos(np.radians(out["lat_deg"]))))
    if velocity is not None:
        out["vel_e_mps"] += velocity[:, 0]
        out["vel_n_mps"] += velocity[:, 1]
    return out


def test_a_clean_zigzag_through_a_current_raises_nothing() -> None:
    fixes, headings, _, _ = _vessel()
    result = run_heading_reference(fixes, headings)
    assert result.ran and not result.alarms
    assert np.nanmax(_strength(result)) < 0.6
    # the current is what is fitted, not an alarm: 0.4 m/s east, -0.3 m/s north
    assert "+0.4 E" not in result.reason  # findings only come with alarms
    assert not result.findings


def test_a_drag_across_the_bow_with_a_consistent_velocity_is_found_at_its_onset() -> None:
    fixes, headings, t, _ = _vessel()
    # 3 m/s: at 5 m/s through the water the floor is 0.27 m/s (0.2 m/s and 2 degrees), so a drag needs
    # 2.2 m/s to pass 8 sigma
    rate = 3.0
    across = np.array([np.cos(np.radians(70.0)), -np.sin(np.radians(70.0))])  # starboard of 070
    on = np.clip(t - 600.0, 0.0, None)
    spoofed = _shift(fixes, on[:, None] * rate * across, np.where(t[:, None] >= 600.0, rate * across, 0.0))
    result = run_heading_reference(spoofed, headings)
    assert len(result.alarms) == 1
    alarm = result.alarms[0]
    assert 600.0 <= alarm.start_s <= 602.0 and alarm.end_s == pytest.approx(t[-1])
    assert alarm.onset_s is not None and 596.0 <= alarm.onset_s <= 601.0
    assert result.findings and "across" in result.findings[0].text


def test_without_a_speed_log_only_motion_across_the_bow_is_judged() -> None:
    fixes, headings, t, _ = _vessel(speed_log=False)
    heading = np.radians(70.0)
    along = np.array([np.sin(heading), np.cos(heading)])
    across = np.array([np.cos(heading), -np.sin(heading)])
    drag = np.clip(t - 600.0, 0.0, 120.0)[:, None] * 3.0  # a 3 m/s drag from 600 to 720 s, then held
    on = ((t >= 600.0) & (t < 720.0))[:, None] * 3.0
    hidden = run_heading_reference(_shift(fixes, drag * along, on * along), headings)
    assert hidden.ran and "across the bow only" in hidden.reason and not hidden.alarms
    seen = run_heading_reference(_shift(fixes, drag * across, on * across), headings)
    assert len(seen.alarms) == 1 and 600.0 <= seen.alarms[0].start_s <= 602.0
    # the drag stops at 720 s and the vessel moves as its compass says again: the alarm ends there
    assert 719.0 <= seen.alarms[0].end_s <= 731.0


def test_a_few_seconds_of_bad_fixes_are_no_alarm() -> None:
    fixes, headings, t, _ = _vessel()
    glitch = ((t >= 400.0) & (t < 403.0))[:, None] * np.array([25.0, -15.0])  # 3 s of multipath, 29 m
    result = run_heading_reference(_shift(fixes, glitch), headings)
    assert not result.alarms
    assert np.nanmax(_strength(result)) > 1.0  # seen, but not for the 5 s an alarm needs


def test_a_gnss_receiver_heading_is_no_reference() -> None:
    fixes, headings, _, _ = _vessel(talker="GP")  # a dual-antenna receiver's HDT: the spoofer moves it too
    result = run_heading_reference(fixes, headings)
    assert not result.ran
    # the note names the headings it set aside, never "no compass heading in the log"
    assert result.reason.startswith(f"headings from GNSS talkers only (GPHDT ({len(headings)} rows))")
    assert "no reference independent of GNSS" in result.reason


def test_the_track_alone_finds_a_jump_across_the_bow_without_log_or_receiver_velocity() -> None:
    fixes, headings, t, _ = _vessel(speed_log=False)
    fixes[["vel_e_mps", "vel_n_mps"]] = np.nan  # GGA only: no Doppler velocity
    across = np.array([np.cos(np.radians(70.0)), -np.sin(np.radians(70.0))])
    result = run_heading_reference(_shift(fixes, (t >= 450.0)[:, None] * 60.0 * across), headings)
    assert [s.name for s in result.series] == ["GP/strength", "GP/level", "GP/track_residual"]
    assert len(result.alarms) == 1
    # the jump is in the 10 s window's displacement until the window has passed it
    assert 450.0 <= result.alarms[0].start_s <= 451.0 and 455.0 <= result.alarms[0].end_s <= 460.0


def test_a_jump_is_held_while_its_offset_lasts_and_ends_when_gnss_comes_back(bundg) -> None:
    # the track sees a jump only while its 10 s window holds it; the offset from where the compass and
    # log put the vessel lasts, and holds the incident until GNSS comes back or the dead reckoning's own
    # growing error covers the offset
    last = float(bundg.fixes["t_s"].max())
    for attack, end in [("step:offset=3000,start=70", last), ("step:offset=3000,start=70,end=110", 110.0)]:
        spoofed, _ = apply_attack(bundg, parse_attack(attack))
        result = run_heading_reference(spoofed.fixes, spoofed.headings)
        assert len(result.alarms) == 1, attack  # the jump back at 110 s is the end, not a second attack
        assert result.alarms[0].end_s == pytest.approx(end, abs=1.0), attack
    # 30 m: held for as long as 5 sigma of the dead reckoning stays below it, about half a minute here
    spoofed, _ = apply_attack(bundg, parse_attack("step:offset=30,start=70"))
    (alarm,) = run_heading_reference(spoofed.fixes, spoofed.headings).alarms
    assert 95.0 <= alarm.end_s <= 120.0


def test_the_simulated_compass_and_log_explain_the_ground_track() -> None:
    # a perfect compass and log: heading and speed through the water plus the current are the ground
    # velocity (the tide at its phase, no leeway)
    t = np.arange(0.0, 600.0, 1.0)
    v = np.c_[3.0 * np.sin(t / 100.0), 3.0 * np.cos(t / 100.0) + 1.0]
    model = CompassModel(noise_deg=0.0, log_noise_mps=0.0, current_mps=(0.3, -0.2), tide_mps=(0.2, 0.1))
    heading, log = compass_readings(t, v, model, np.random.default_rng(0))
    h = np.radians(heading)
    tide = np.sin(2 * np.pi * t / TIDE_PERIOD_S)[:, None] * np.array([0.2, 0.1])
    rebuilt = log[:, None] * np.c_[np.sin(h), np.cos(h)] + np.array([0.3, -0.2]) + tide
    assert np.abs(rebuilt - v).max() < 1e-9


def test_simulated_voyages_with_realistic_compasses_are_quiet_and_a_capture_is_found() -> None:
    # voyage records as `bench realworld --vehicle ship_nmea` draws them: gyro or magnetic compass with
    # deviation, a speed log off by up to 8 %, currents and tides, leeway; GNSS with correlated errors
    for seed in range(3):
        rng = np.random.default_rng(seed)
        sc = replace(SCENARIOS["ship"], receiver=realistic_receiver(rng), compass=realistic_compass(rng))
        table = simulate(sc, seed=seed, duration_s=1200.0).table
        clean = run_heading_reference(table.fixes, table.headings)
        assert clean.ran and not clean.alarms and np.nanmax(_strength(clean)) < 0.5, seed
        spoofed, _ = apply_attack(table, parse_attack("ramp:rate=5,vel=1,start=600"))
        (alarm,) = run_heading_reference(spoofed.fixes, spoofed.headings).alarms
        assert 600.0 <= alarm.start_s <= 602.0 and alarm.end_s == pytest.approx(1199.0, abs=1.0), seed


def test_a_stuck_speed_log_is_not_used_rather_than_turning_every_turn_into_an_alarm(monkeypatch) -> None:
    # a fouled paddle wheel reading 0 while the ship makes 5 m/s: taken at its word, the 5 m/s the log
    # misses would look like a current along the bow that swings with every turn of the zig-zag
    fixes, headings, _, _ = _vessel()
    headings["water_speed_mps"] = 0.0
    result = run_heading_reference(fixes, headings)
    assert result.ran and not result.alarms
    assert "speed log not used: it reads 0.00 x the GNSS speed along the heading" in result.reason
    monkeypatch.setattr("spooflens.detectors.heading_reference.LOG_SCALE", (0.0, np.inf))
    assert run_heading_reference(fixes, headings).alarms  # believed, the stuck log raises alarms at the turns


def test_where_a_log_has_an_imu_its_ins_reconstruction_comes_before_the_dead_reckoning() -> None:
    # the verdict measures how far GNSS went against the first reconstructed track; a vessel with an IMU
    # and a compass has both, and the INS (noise learned from the log) beats a current-fitted reckoning
    def result(name: str, track: str) -> DetectorResult:
        z = np.zeros(2)
        return DetectorResult(name, True, tracks=[Track(f"reconstructed ({track})", z, z, z, z)])

    heading = result("heading_reference", "compass")
    z = np.zeros(2)
    verdict = Verdict(True, reconstructed=(Track("reconstructed (INS)", z, z, z, z),))
    assert [t.name for t in reconstructed_tracks([heading], verdict)] == [
        "reconstructed (INS)",
        "reconstructed (compass)",
    ]
