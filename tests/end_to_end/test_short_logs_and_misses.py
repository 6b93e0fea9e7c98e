"""Evidence that is there is not lost (issue 39, items 4 and 5a): a real log too short to learn its noise
from or to coast a clean reference in says so and still catches a ramp, and an attack whose incident an
unrelated alarm opened a few seconds before it is still confirmed by coasting the INS."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from readers import read_log
from spooflens.attacks import apply_attack, parse_attack
from spooflens.cli import main
from spooflens.epoch_table import EpochTable
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.reconstruction import NO_CLEAN_COASTS, Placebo
from spooflens.pipeline.run import analyze_table
from spooflens.schema import FRAMES


def _first(table: EpochTable, seconds: float) -> EpochTable:
    """The log's first `seconds` (every frame cut at the same time), as a log that ended there."""
    t_end = float(table.fixes["t_s"].min()) + seconds
    cut = replace(table)
    for name in FRAMES:
        df = table.frame(name)
        setattr(cut, name, df[df["t_s"] <= t_end].reset_index(drop=True))
    return cut


@pytest.mark.parametrize("seconds", [60.0, 90.0])
def test_a_short_real_log_says_what_it_could_not_learn_and_still_catches_a_ramp(
    husky_bag: Path, seconds: float
) -> None:
    """The real husky bag (consumer IMU, wheel odometry, SBAS fixes) cut to its first minute or minute and
    a half: too short for the noise learning (300 s window) and for any clean coast (30 s settling, 60 s
    horizon), which the navigation result and the coasting check say; clean, no spoofing incident; with a
    5 m/s ramp from 30 s, spoofing from the ramp's start to the end of the log."""
    table = _first(read_log(husky_bag), seconds)
    clean = analyze_table(table)
    navigation = next(r for r in clean.results if r.name == "navigation")
    assert navigation.extras["noise_learned"] is False
    assert "noise NOT learned" in navigation.reason and "prior used" in navigation.reason
    assert not clean.verdict.spoofed, clean.verdict.incidents
    assert all(c["clean_coasts"] == 0 for c in clean.verdict.coasting_checks)
    assert any(NO_CLEAN_COASTS in i.end_method for i in clean.verdict.incidents)

    spoofed, _ = apply_attack(table, parse_attack("ramp:rate=5,start=30"))
    verdict = analyze_table(spoofed).verdict
    attack = next(i for i in verdict.incidents if i.is_spoofing)
    assert Evidence.INERTIAL in attack.evidence and attack.ongoing_at_end
    assert 29.0 <= attack.onset_s <= 31.0 and attack.start_s <= 32.0
    assert NO_CLEAN_COASTS in attack.end_method


def test_a_meaconer_is_confirmed_although_an_earlier_alarm_opened_its_incident(tmp_path: Path) -> None:
    """A simulated car logging raw observations, meaconed 300 m east from 200 s: a windowed range-rate
    t-test alarm from 186 s (its window reaching back to 133 s) merged with the attack's alarms. Its coast
    began at 133 s, and a consumer INS coasted 67 s could not see the jump (no spoofing). The coast is now
    tried again from the burst of alarms at 200 s and the incident split there."""
    assert main(["simulate", "ground_raw", "-o", str(tmp_path / "gr"), "--format", "csv"]) == 0
    attacked = tmp_path / "grm"
    assert main(["inject", str(tmp_path / "gr"), "--attack", "meaconing:east=300,start=200", "-o", str(attacked)]) == 0
    verdict = analyze_table(read_log(attacked)).verdict
    spoofing = [i for i in verdict.incidents if i.is_spoofing]
    assert len(spoofing) == 1, verdict.incidents
    attack = spoofing[0]
    assert 198.0 <= attack.onset_s <= 202.0 and 198.0 <= attack.start_s <= 202.0, attack
    assert Evidence.INERTIAL in attack.evidence and attack.ongoing_at_end
    # what alarmed before the attack stays an anomaly of its own
    assert all(not i.is_spoofing for i in verdict.incidents if i.start_s < 198.0)


def test_the_clean_envelope_leaves_out_coasts_into_incidents_not_judged_yet() -> None:
    """Three coasts, the last starting inside a later incident (an attack the loop has not reached): its
    departures are not this log's clean behaviour, not even at its first epoch."""
    grid = np.arange(0.0, 61.0)
    curves = np.vstack([np.full(len(grid), 0.5), np.full(len(grid), 0.8), np.full(len(grid), 800.0)])
    placebo = Placebo(np.array([30.0, 60.0, 150.0]), grid, curves)
    later = [(140.0, 300.0)]
    assert placebo.envelope((10.0, 20.0), [], 1.0, later=later).kappa.max() == 1.0
    assert placebo.envelope((10.0, 20.0), [], 1.0).kappa.max() == 800.0  # without: the attack's coast
    # an incident whose own span holds every coast start: none is clean, none counts
    assert placebo.envelope((0.0, 200.0), [], 1.0).runs == 0
