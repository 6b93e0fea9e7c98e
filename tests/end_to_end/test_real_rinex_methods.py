"""Seeds 001 and 002 on the real GSI station pair: clean stays clean; each raw attack of the issue, injected
with `spooflens inject`, is a spoofing incident within two epochs of its start with its satellites named."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from paths import REAL

from readers import read_log
from spooflens.attacks import AttackTruth, sidecar_path
from spooflens.cli import main

GSI = REAL / "rinex_gsi_pair"
SEED_DETECTORS = {"range_rate", "pr_change_kf", "pr_change_rnn"}
EPOCH_S = 30.0


def _analyse(log: Path, tmp_path: Path, *extra: str) -> dict:
    out = tmp_path / f"{log.name}.json"
    assert main(["analyze", str(log), "-o", str(tmp_path / "x.rrd"), "--json", str(out), "--quiet", *extra]) == 0
    return json.loads(out.read_text())


def _tracked_at(log: Path, t0: float) -> dict[str, set[str]]:
    """Per receiver, the satellites observed at its first epoch at or after t0."""
    obs = read_log(log).observations
    out = {}
    for rid, rows in obs.groupby("receiver_id"):
        first = rows.loc[rows["t_s"] >= t0 - 0.01, "t_s"].min()
        out[str(rid)] = set(rows.loc[rows["t_s"] == first, "sv_id"].astype(str))
    return out


def test_clean_pair_stays_clean(tmp_path: Path) -> None:
    summary = _analyse(GSI, tmp_path)
    assert not summary["verdict"]["spoofed"]
    ran = {a["name"]: a for a in summary["analyses"]}
    for name in SEED_DETECTORS | {"range_rate_ttest"}:
        assert ran[name]["ran"] and ran[name]["evidence"] == "known_station", name
        assert ran[name]["alarms"] == [], name


@pytest.mark.parametrize(
    "attack",
    ["meaconing:east=500,start=1800", "pr_delay:delay=300,svs=G07+G08,start=1800", "spoofed_subset:start=1800"],
)
def test_each_raw_attack_is_an_incident_within_two_epochs_with_its_satellites(tmp_path: Path, attack: str) -> None:
    out = tmp_path / "spoofed"
    assert main(["inject", str(GSI), "--attack", attack, "-o", str(out)]) == 0
    truth = AttackTruth.read(sidecar_path(out))
    summary = _analyse(out, tmp_path)
    incidents = [i for i in summary["verdict"]["incidents"] if i["spoofing"]]
    assert incidents, summary["verdict"]["headline"]
    first = incidents[0]
    assert first["confidence"] in ("medium", "high") and "known_station" in first["evidence"]
    assert 1800.0 - 0.1 <= first["start_s"] <= 1800.0 + 2 * EPOCH_S
    assert set(first["detectors"]) >= SEED_DETECTORS
    # the satellites named are the attacked ones the receivers were tracking when the attack began
    tracked = set().union(*_tracked_at(out, 1800.0).values())
    named = set().union(*(i["satellites"] for i in incidents))
    attacked = set(truth.satellites) & tracked
    if attack.startswith("meaconing"):
        assert len(named) >= 6 and named <= attacked  # a meaconer relays every satellite
    else:  # RAIM also names attacked satellites that rose later in the attack
        assert attacked <= named <= set(truth.satellites)
    alarms = [a for r in summary["analyses"] if r["name"] in SEED_DETECTORS for a in r["alarms"]]
    assert {a["receiver_id"] for a in alarms} == {"0759", "3040"}


def test_station_on_the_command_line(tmp_path: Path) -> None:
    summary = _analyse(GSI, tmp_path, "--station", "0759=35.1608750,139.6138370,70.20")
    kf = next(a for a in summary["analyses"] if a["name"] == "pr_change_kf")
    assert "--station 35.1608750,139.6138370,70.20" in kf["reason"] and not kf["alarms"]
    assert main(["analyze", str(GSI), "--station", "3041=35,139,70", "-o", str(tmp_path / "y.rrd")]) == 2
    assert main(["analyze", str(GSI), "--station", "35,139", "-o", str(tmp_path / "y.rrd")]) == 2
