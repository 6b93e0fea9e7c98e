"""The `jam` and `jam_spoof` attacks on a simulated receiver that reports its sky: every satellite's C/N0
down by the same dB, the weakest lost, the fix lost below four, the front end's indicators, one truth
file with both phases."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from spooflens.attacks import AttackError, apply_attack, parse_attack
from spooflens.epoch_table import EpochTable
from spooflens.simulation.sensors import ReceiverModel
from spooflens.simulation.simulate import SCENARIOS, simulate


@pytest.fixture(scope="module")
def sky_log() -> EpochTable:
    sc = replace(SCENARIOS["multirotor"], receiver=ReceiverModel(), satellite_reports=True)
    return simulate(sc, seed=3, duration_s=240.0).table


def test_parameters_are_checked() -> None:
    spec = parse_attack("jam:start=10,end=70,cn0=12,lost=3,systems=GE")
    assert spec.params["cn0"] == 12.0 and spec.params["lost"] == 3 and spec.params["fix_lost_below"] == 20.0
    for bad in ("jam:cn0=-3", "jam:agc=1.5", "jam:acc=0.5", "jam_spoof:start=10,end=30,jam=30", "jam_spoof:jam=0"):
        with pytest.raises(AttackError):
            parse_attack(bad)


def test_every_satellite_falls_alike_the_weakest_are_lost_and_the_front_end_reacts(sky_log: EpochTable) -> None:
    jammed, truth = apply_attack(sky_log, parse_attack("jam:start=100,end=160,cn0=15,ramp=0"))
    before, after = sky_log.satellites, jammed.satellites
    inside = ((before["t_s"] >= 100) & (before["t_s"] <= 160)).to_numpy()
    drop = (before["cn0_dbhz"] - after["cn0_dbhz"]).to_numpy(float)
    assert np.allclose(drop[inside & np.isfinite(drop)], 15.0) and np.allclose(drop[~inside], 0.0)
    lost = inside & np.isnan(after["cn0_dbhz"].to_numpy(float))
    assert lost.any() and (before["cn0_dbhz"].to_numpy(float)[lost] - 15.0 < 20.0 + 3.0).all()
    assert (after["used"].to_numpy(float)[lost] == 0).all()
    fx0, fx1 = sky_log.fixes, jammed.fixes
    on = ((fx1["t_s"] >= 101) & (fx1["t_s"] <= 159)).to_numpy()
    same = fx0.set_index("t_s").loc[fx1["t_s"]]
    assert (fx1["agc"].to_numpy()[on] / same["agc"].to_numpy()[on]) == pytest.approx(0.6, abs=0.01)
    assert (fx1["h_acc_m"].to_numpy()[on] > 5.0 * same["h_acc_m"].to_numpy()[on]).all()
    assert (fx1["sats_used"].to_numpy()[on] < same["sats_used"].to_numpy()[on]).all()
    assert fx1["jamming_state"].isna().all()  # the receiver logs no jamming monitor: none is invented
    assert truth.phases[0]["kind"] == "jam" and truth.phases[0]["fix_lost_s"] == [] and truth.satellites


def test_a_deep_jam_loses_the_fix_and_a_monitor_that_is_on_says_critical(sky_log: EpochTable) -> None:
    monitored = replace(sky_log, fixes=sky_log.fixes.assign(jamming_state=1.0))
    jammed, truth = apply_attack(monitored, parse_attack("jam:start=100,end=160,cn0=35"))
    t = jammed.fixes["t_s"].to_numpy()
    (lost_from, lost_to), *_ = truth.phases[0]["fix_lost_s"]
    assert 100 <= lost_from < 110 and 150 < lost_to <= 160
    assert not ((t > lost_from) & (t < lost_to)).any()
    state = jammed.fixes.set_index("t_s")["jamming_state"]
    assert state.loc[:99].eq(1).all() and state.loc[lost_from - 5 : lost_from].max() >= 2
    off = replace(sky_log, fixes=sky_log.fixes.assign(jamming_state=0.0))  # monitor off: stays "unknown"
    assert apply_attack(off, parse_attack("jam:start=100,end=160"))[0].fixes["jamming_state"].eq(0).all()


def test_jam_then_capture_has_both_phases_and_the_spoofer_is_louder_and_alike(sky_log: EpochTable) -> None:
    spoofed, truth = apply_attack(sky_log, parse_attack("jam_spoof:start=80,jam=40,louder=5"))
    assert [p["kind"] for p in truth.phases] == ["jam", "capture"]
    assert truth.phases[0]["end_s"] == truth.phases[1]["start_s"] == 120.0 and truth.end_s == sky_log.duration_s
    sky = spoofed.satellites
    captured = sky[(sky["t_s"] > 130) & sky["cn0_dbhz"].notna()]
    clean = sky_log.satellites[sky_log.satellites["t_s"] < 80]
    assert captured["cn0_dbhz"].median() == pytest.approx(clean["cn0_dbhz"].median() + 5.0, abs=0.5)
    assert captured.groupby("t_s")["cn0_dbhz"].std().median() < 1.5  # one antenna sends them all
    moved = np.hypot(*np.array([r[1:3] for r in truth.offsets["/gps/fix"] if r[0] > 200]).T)
    assert moved.min() > 100.0  # the drag: 3 m/s per axis since the takeover
    assert truth.from_json(truth.to_json()).phases == truth.phases
