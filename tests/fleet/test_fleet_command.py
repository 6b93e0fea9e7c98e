"""Seed 004: the homology index (Algorithm 1), attack simulation on real pseudoranges, and `spooflens fleet`."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from paths import REAL, ROOT, SAMPLE_LOGS

from spooflens.cli import main
from spooflens.fleet import attack_simulation as sim
from spooflens.fleet.homology import homology_batch, homology_index, null_quantile

GSI = REAL / "rinex_gsi_pair"

A = np.array([[1.0, 10.0], [-0.8, 9.8]])
B = np.array([[6.50, 7.63], [7.77, 6.36]])


def test_the_papers_worked_example_is_wrong_without_rotation():
    # "without rotation A's homology is smaller than B's": it is larger; B is A turned by about 45 degrees
    assert homology_index(A, ddof=0, rotate=False) == pytest.approx(99.11, abs=0.01)
    assert homology_index(B, ddof=0, rotate=False) == pytest.approx(22.25, abs=0.01)
    assert homology_index(A, ddof=0) == pytest.approx(22.36, abs=0.01)
    assert homology_index(B, ddof=0) == pytest.approx(22.26, abs=0.01)
    # the sample deviation (ddof 1, our default) scales theta by sqrt((n-1)/n)
    assert homology_index(A) == pytest.approx(homology_index(A, ddof=0) * np.sqrt(1 / 2), rel=1e-12)


def test_homology_guards_and_invariances():
    rng = np.random.default_rng(1)
    pov = rng.normal([30.0, -20.0], 2.0, (12, 2))
    theta = homology_index(pov)
    for angle in (0.3, 2.0, -1.2):
        c, s = np.cos(angle), np.sin(angle)
        assert homology_index(pov @ np.array([[c, -s], [s, c]]).T) == pytest.approx(theta, rel=1e-10)
    assert homology_index(pov * 1e3) == pytest.approx(theta, rel=1e-10)  # scale-free: amplitude invariance
    assert homology_index(np.zeros((5, 2))) == 0.0  # step 1: no offset, no homology
    assert homology_index(np.full((5, 2), 1e-4)) == 0.0  # within the solver's tolerance
    assert homology_index(np.tile([3.0, 4.0], (4, 1))) == float("inf")  # identical offsets
    batch = homology_batch(np.stack([pov, pov * 2, np.zeros((12, 2))]))
    assert batch == pytest.approx([theta, theta, 0.0], rel=1e-10)
    assert null_quantile(5, 0.01, runs=50_000) > null_quantile(30, 0.01, runs=50_000)


@pytest.fixture(scope="module")
def snapshot():
    from readers import read_log

    return sim.snapshot_from_table(read_log(GSI))


def test_attack_simulation_on_the_real_pair(snapshot):
    snap = snapshot
    assert snap.receivers == ("0759", "3040") and snap.n_satellites >= 8
    rng = np.random.default_rng(2)
    N = snap.n_satellites
    full = sim.solve_sets(snap, np.ones((1, 2, N), bool))[0]
    # each station's all-satellite solution is within a few metres of its surveyed site
    from readers.rinex import rinex_approx_position

    site = np.array(rinex_approx_position(GSI / "07590920.05o"))
    assert np.linalg.norm(full[0] - site) < 5.0
    every = sim.bias_injection(snap, N, 20, rng, 300.0, full)
    assert np.abs(every.pov).max() < 1e-3  # a common delay on every satellite is a clock change
    assert homology_batch(every.pov) == pytest.approx(np.zeros(20))
    few = sim.bias_injection(snap, 3, 200, np.random.default_rng(3), 300.0, full)
    big = sim.bias_injection(snap, 3, 200, np.random.default_rng(3), 3000.0, full)
    assert np.abs(big.pov).mean() == pytest.approx(10 * np.abs(few.pov).mean(), rel=0.01)
    ok = np.linalg.norm(few.pov, axis=2).min(axis=1) > 1.0
    # theta is amplitude-invariant (linear solution, c_v scale-free) up to the solver's nonlinearity, which
    # matters here: two receivers 3.3 km apart differ by centimetres, the second-order term by millimetres
    ratio = homology_batch(big.pov)[ok] / homology_batch(few.pov)[ok]
    assert np.median(ratio) == pytest.approx(1.0, abs=0.05)
    blocked = sim.blocking(snap, 2, 200, rng, full)
    spoofed = sim.spoofing(snap, 1, 200, rng, 300.0)
    assert np.nanmedian(np.linalg.norm(blocked.pov, axis=2)) < 3.0  # blocking moves a fix by its noise only
    assert np.nanmedian(np.linalg.norm(spoofed.pov, axis=2)) > 30.0  # a counterfeit 300 m late
    assert np.nanmean(homology_batch(spoofed.pov)) > 10 * np.nanmean(homology_batch(blocked.pov))


def _attacked_copy(tmp: Path, station: str) -> Path:
    out = tmp / f"{station}0920.05o"
    shutil.copy(GSI / f"{station}0920.05n", tmp / f"{station}0920.05n")
    code = main(
        [
            "inject",
            str(GSI / f"{station}0920.05o"),
            "--attack",
            "pr_delay:svs=G07+G11,delay=300,start=1800",
            "-o",
            str(out),
        ]
    )
    assert code == 0
    return out


def test_fleet_command_on_the_real_pair(tmp_path: Path):
    logs = [str(GSI / "07590920.05o"), str(GSI / "30400920.05o"), str(ROOT / "sample_logs" / "ground_ros2.mcap")]
    assert main(["fleet", *logs, "-o", str(tmp_path / "clean"), "--quiet"]) == 0
    clean = json.loads((tmp_path / "clean" / "fleet.json").read_text())
    assert (tmp_path / "clean" / "fleet.rrd").stat().st_size > 0
    assert clean["homology"]["common_attack"] == []
    assert any("ground_ros2.mcap" in n and "does not overlap" in n for n in clean["notes"])
    for v in clean["vehicles"][:2]:
        assert v["reference"].startswith("surveyed site")
        assert not v["summary"]["verdict"]["spoofed"]
        fleet = next(a for a in v["summary"]["analyses"] if a["name"] == "fleet_homology")
        assert fleet["ran"] and not fleet["alarms"]

    attacked = tmp_path / "attacked"
    attacked.mkdir()
    logs = [str(_attacked_copy(attacked, s)) for s in ("0759", "3040")]
    assert main(["fleet", *logs, "-o", str(tmp_path / "out"), "--quiet"]) == 0
    out = json.loads((tmp_path / "out" / "fleet.json").read_text())
    (common,) = out["homology"]["common_attack"]
    assert common["vehicles"] == ["07590920.05o", "30400920.05o"]
    assert "2005-04-02T00:29:47" <= common["start_utc"] <= "2005-04-02T00:40:00"  # attack from 00:29:47
    for v in out["vehicles"]:
        verdict = v["summary"]["verdict"]
        assert verdict["spoofed"]
        assert any("fleet" in i["evidence"] and i["spoofing"] for i in verdict["incidents"])
        assert any(f["text"].startswith("common attack with") for f in verdict["findings"])


def test_single_log_analysis_lists_the_fleet_detector_as_not_run(tmp_path: Path, capsys):
    assert main(["inspect", str(ROOT / "sample_logs" / "ground_ros2.mcap")]) == 0
    text = capsys.readouterr().out
    assert "fleet_homology" in text and "spooflens fleet" in text


def test_a_vehicles_verdict_after_the_fleet_keeps_what_its_own_analysis_confirmed() -> None:
    """The fleet adds its evidence and decides each vehicle's verdict again through the analysis' own
    assessment: the coasting check's confirmed end and the distance GNSS went from the reconstructed
    track are kept (re-deciding from the alarms alone lost both)."""
    from spooflens.fleet.command import run_fleet
    from spooflens.fleet.offsets import FleetOptions
    from spooflens.pipeline.run import analyze_table
    from spooflens.service import read_table

    logs = [SAMPLE_LOGS / "spoofed_flight.mcap", SAMPLE_LOGS / "ground.bag"]
    vehicles, _, _ = run_fleet(logs, FleetOptions())
    alone = analyze_table(read_table(logs[0], {}, False)).verdict
    in_fleet = vehicles[0].verdict
    assert alone.spoofed and in_fleet.spoofed
    (a,), (f,) = [i for i in alone.incidents if i.is_spoofing], [i for i in in_fleet.incidents if i.is_spoofing]
    assert f.end_method == a.end_method == "GNSS never agreed again with the coasted INS reference"
    assert a.offset_peak_m is not None and a.offset_peak_m > 100.0
    assert f.offset_peak_m == pytest.approx(a.offset_peak_m)
    assert len(in_fleet.reconstructed) == len(alone.reconstructed) == 1
