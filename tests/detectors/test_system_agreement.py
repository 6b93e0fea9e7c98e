"""system_agreement: a GPS-only spoofer before a GPS + Galileo receiver, seen as the two systems' own
positions moving apart, on a simulated car whose receiver logs raw observations of both systems."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from spooflens.attacks import apply_attack, parse_attack
from spooflens.detectors.base import DetectorResult
from spooflens.detectors.system_agreement import SystemAgreementOptions, run_system_agreement
from spooflens.epoch_table import EpochTable
from spooflens.pipeline.registry import AnalysisContext, AnalyzeOptions
from spooflens.simulation.simulate import SCENARIOS, simulate


def _car(constellation: str = "synthetic_gps_galileo") -> EpochTable:
    sc = replace(SCENARIOS["ground_raw"], constellation=constellation)
    return simulate(sc, seed=3, duration_s=300.0).table


@pytest.fixture(scope="module")
def car() -> EpochTable:
    return _car()


def _run(table: EpochTable) -> DetectorResult:
    return run_system_agreement(AnalysisContext(table, AnalyzeOptions()))


def test_honest_systems_agree_within_metres(car: EpochTable) -> None:
    r = _run(car)
    assert r.ran and not r.alarms and not r.findings
    (sep,) = [s for s in r.series if s.name.endswith("_separation")]
    assert sep.name == "/gps/fix/GE_separation" and len(sep.t) == 301
    assert float(np.median(sep.values)) < 5.0 and float(np.max(sep.values)) < 20.0
    assert "GPS vs Galileo at 301 epochs" in r.reason


@pytest.mark.parametrize(
    ("attack", "latest_s"),
    [("ramp:rate=3,systems=G,start=150", 165.0), ("step:offset=100,systems=G,start=150", 151.0)],
)
def test_a_gps_only_spoofer_moves_the_gps_position_away_from_galileos(
    car: EpochTable, attack: str, latest_s: float
) -> None:
    spoofed, truth = apply_attack(car, parse_attack(attack))
    assert sorted({s[0] for s in truth.satellites}) == ["G"]
    r = _run(spoofed)
    (alarm,) = r.alarms
    # a 3 m/s ramp on east and north is 50 m off after 12 s; a 141 m step at once
    assert 150.0 <= alarm.start_s <= latest_s and alarm.end_s == 300.0
    assert alarm.onset_interval_s is not None
    lo, hi = alarm.onset_interval_s
    assert lo <= 150.0 <= hi + 1.0 and hi - lo <= 10.0 and alarm.onset_s == hi
    (finding,) = r.findings
    assert "its GPS and Galileo satellites gave positions up to" in finding.text
    assert alarm.peak_statistic > 130.0


def test_one_bad_galileo_satellite_is_no_system_disagreement(car: EpochTable) -> None:
    gal = sorted(s for s in car.observations["sv_id"].astype(str).unique() if s.startswith("E"))
    spoofed, _ = apply_attack(car, parse_attack(f"pr_delay:svs={gal[0]},delay=3000,start=100"))
    assert not _run(spoofed).alarms  # RAIM inside each system's solution leaves it out


def test_a_log_spoofed_from_its_first_fix_still_shows_it(car: EpochTable) -> None:
    """The separation's scale is capped at what two honest systems show, so an attack filling the log
    cannot teach the detector that kilometres are normal."""
    spoofed, _ = apply_attack(car, parse_attack("step:offset=300,systems=G,start=0"))
    (alarm,) = _run(spoofed).alarms
    assert alarm.start_s <= 1.0 and alarm.end_s == 300.0
    loose = run_system_agreement(AnalysisContext(spoofed, AnalyzeOptions()), SystemAgreementOptions(max_scale_m=1e6))
    assert not loose.alarms  # without the cap the scale is the attack's


def test_one_system_is_nothing_to_compare() -> None:
    r = _run(_car("synthetic"))
    assert not r.ran and "two satellite systems" in r.reason
