"""The level test against a vehicle's baseline (`receiver_levels`): a receiver whose indicators all sit a
little off its vehicle's clean days, the way a takeover moves them, is flagged over the whole log; a clean
day of the vehicle, or the same shifts with the C/N0 fallen as a jammer's or an obstructed sky's, is not."""

from __future__ import annotations

import numpy as np
import pytest
from baseline_support import indicator_levels, px4_like, receiver_fixes

from spooflens.baseline.format import Baseline, Quantity
from spooflens.baseline.indicators import INDICATORS
from spooflens.baseline.learn import aggregate
from spooflens.baseline.use import level_z
from spooflens.bench.baseline_sim import LogSpec, simulate_log
from spooflens.detectors.receiver_evidence import run_receiver_levels


@pytest.mark.parametrize("n", [3, 4, 8])
def test_a_clean_logs_level_z_is_a_standard_normal_deviate_whatever_the_number_of_logs(n: int) -> None:
    # a new clean day's level against n earlier ones: beyond 2 as often as a normal deviate is (2.3 %),
    # so deviates of several indicators add up; a spread taken at its upper 95 % confidence bound made it
    # 0.5 % (three to eight logs). Days 5 dB apart: the indicator's resolution (0.3 dB) plays no part
    spec = INDICATORS["cn0_mean_dbhz"]
    rng = np.random.default_rng(n)
    z = []
    for _ in range(4000):
        days = 40.0 + rng.normal(0.0, 5.0, n + 1)
        q = Quantity(float(np.median(days[:n])), "dB-Hz", tuple(days[:n].tolist()), 0.5, None, True)
        z.append(level_z(q, spec, np.array([days[n]]), np.array([3000.0])).item())
    beyond = float(np.mean(np.array(z) > 2.0))
    assert 0.015 < beyond < 0.035
    assert abs(float(np.median(z))) < 0.1


def _vehicle(vehicle: str, seed: int) -> Baseline:
    """The bench's baseline of a simulated vehicle from its eight clean logs (their indicator levels)."""
    return aggregate([indicator_levels(simulate_log(LogSpec(vehicle, seed, 1000 * seed + k))[0], k) for k in range(8)])


@pytest.mark.parametrize(("vehicle", "seed", "log"), [("car", 1, 1600), ("aircraft", 1, 1601)])
def test_a_capture_from_the_first_fix_is_off_its_vehicles_levels_all_log_long(
    vehicle: str, seed: int, log: int
) -> None:
    # `spooflens bench baseline`'s two captures flagged over a tenth of the log at most, with and without
    # eight clean logs: their noise, AGC, jamming indicator and C/N0 each sat two to three spreads of the
    # vehicle's clean days off, the way a takeover moves them, and no two families beyond three
    baseline = _vehicle(vehicle, seed)
    table, _ = simulate_log(LogSpec(vehicle, seed, log, "capture"))
    t = table.fixes["t_s"].to_numpy(dtype=float)
    result = run_receiver_levels(table.fixes, baseline)
    covered = sum(a.end_s - a.start_s for a in result.alarms) / float(t[-1] - t[0])
    assert covered > 0.95
    (finding,) = result.findings
    assert "families together" in finding.text and "mean C/N0" in finding.text
    for clean in range(1000 * seed + 500, 1000 * seed + 503):  # the bench's clean test logs of the vehicle
        assert not run_receiver_levels(simulate_log(LogSpec(vehicle, seed, clean))[0].fixes, baseline).alarms


def test_families_a_little_off_together_are_flagged_the_attacks_way_only() -> None:
    baseline = px4_like()
    # each family two or three of the clean flights' spreads off: noise, jamming indicator, HDOP up and the
    # C/N0 up (a signal louder than the sky), none far enough alone
    louder = run_receiver_levels(receiver_fixes(noise=104.0, jamming=50.0, cn0=44.0, hdop=0.86), baseline)
    (alarm,) = louder.alarms
    assert alarm.start_s < 70.0 and alarm.end_s > 590.0
    # the same with the C/N0 fallen as much: what a jammer or an obstructed sky does, not a takeover
    assert not run_receiver_levels(receiver_fixes(noise=104.0, jamming=50.0, cn0=40.0, hdop=0.86), baseline).alarms
    # two families alone are the two-family test's to judge: not beyond three each, no alarm
    assert not run_receiver_levels(receiver_fixes(noise=104.0, jamming=50.0, cn0=42.0, hdop=0.79), baseline).alarms
