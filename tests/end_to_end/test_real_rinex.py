"""Real pseudoranges end to end: the GSI station pair solved, attacked with `spooflens inject`, analysed."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from paths import REAL
from shared_inputs import read_shared

from readers import read_log
from readers.rinex import rinex_approx_position
from spooflens.attacks import AttackTruth, sidecar_path
from spooflens.cli import main
from spooflens.geodesy import ecef_to_geodetic, geodetic_to_ecef, geodetic_to_enu
from spooflens.gnss.solved_fixes import with_solved_fixes
from spooflens.simulation.simulate import SCENARIOS, simulate

GSI = REAL / "rinex_gsi_pair"
STATIONS = {"0759": "07590920.05o", "3040": "30400920.05o"}


def _surveyed(receiver: str) -> np.ndarray:
    xyz = rinex_approx_position(GSI / STATIONS[receiver])
    assert xyz is not None
    return np.array(xyz)


def test_solved_fixes_sit_on_the_surveyed_stations() -> None:
    table = with_solved_fixes(read_shared(GSI))
    assert table.ionosphere is not None  # the nav file's Klobuchar coefficients travel with the table
    means = {}
    for rid in STATIONS:
        fx = table.fixes_of(rid)
        assert len(fx) == 120
        lat, lon, h = ecef_to_geodetic(_surveyed(rid))
        enu = geodetic_to_enu(fx["lat_deg"], fx["lon_deg"], fx["height_m"], float(lat), float(lon), float(h))
        assert np.sqrt(np.mean(np.sum(enu[:, :2] ** 2, axis=1))) < 1.5
        assert abs(np.mean(enu[:, 2])) < 2.0
        means[rid] = geodetic_to_ecef(fx["lat_deg"], fx["lon_deg"], fx["height_m"]).mean(axis=0)
    surveyed = np.linalg.norm(_surveyed("0759") - _surveyed("3040"))
    assert np.linalg.norm(means["0759"] - means["3040"]) == pytest.approx(surveyed, abs=2.0)


def test_inject_on_real_pseudoranges_moves_the_solution_and_is_caught(tmp_path: Path) -> None:
    out = tmp_path / "gsi_spoofed"
    attack = "pr_delay:delay=500,svs=G07+G28,start=1800"
    assert main(["inject", str(GSI), "--attack", attack, "-o", str(out)]) == 0
    truth = AttackTruth.read(sidecar_path(out))
    assert truth.satellites == ["G07", "G28"] and set(truth.receivers) == set(STATIONS)
    clean, spoofed = read_shared(GSI), read_log(out)
    obs = clean.observations
    hit = obs["sv_id"].isin(truth.satellites) & (obs["t_s"] >= 1800.0)
    d_pr = spoofed.observations["pseudorange_m"] - obs["pseudorange_m"]
    np.testing.assert_allclose(d_pr[hit], 500.0, atol=1e-3)  # RINEX keeps 1 mm
    np.testing.assert_allclose(d_pr[~hit], 0.0, atol=0.0)
    for rid in STATIONS:
        off = np.array(truth.offsets[rid])
        assert np.abs(off[off[:, 0] < 1800.0, 1:]).max() < 1e-6
        assert np.linalg.norm(off[off[:, 0] >= 1800.0, 1:], axis=1).min() > 50.0
    summary_path = tmp_path / "s.json"
    main(["analyze", str(out), "-o", str(tmp_path / "s.rrd"), "--json", str(summary_path)])
    summary = json.loads(summary_path.read_text())
    alarms = [a for r in summary["analyses"] if r["name"] == "gnss_consistency" for a in r["alarms"]]
    # epochs are stamped in each receiver's clock, a few ms off GPS time; nothing before the attack
    assert alarms and 1799.9 <= min(a["start_s"] for a in alarms) <= 1830.1
    verdict = summary["verdict"]
    assert verdict["spoofed"] and 1799.9 <= verdict["incidents"][0]["start_s"] <= 1830.1


def test_blocking_real_satellites_removes_them_from_the_rinex_copy(tmp_path: Path) -> None:
    out = tmp_path / "gsi_blocked"
    assert main(["inject", str(GSI), "--attack", "blocking:count=2,seed=3,start=600,end=1200", "-o", str(out)]) == 0
    truth = AttackTruth.read(sidecar_path(out))
    back = read_log(out).observations
    window = (back["t_s"] >= 600.0) & (back["t_s"] <= 1200.0)
    assert not (back["sv_id"].isin(truth.satellites) & window).any()
    assert back["sv_id"].isin(truth.satellites).any()  # outside the window they are still there


def test_simulating_with_a_real_navigation_file(tmp_path: Path) -> None:
    from dataclasses import replace

    sc = replace(SCENARIOS["ground_raw"], constellation=str(GSI / "07590920.05n"))
    table = simulate(sc, seed=2, duration_s=60.0).table
    start = table.absolute_iso(0.0)
    assert start.startswith("2005-04-02")  # inside the navigation file's day
    assert table.ionosphere is not None
    per_epoch = table.observations.groupby("t_s").size()
    assert per_epoch.min() >= 5
    assert len(table.fixes) == 61
