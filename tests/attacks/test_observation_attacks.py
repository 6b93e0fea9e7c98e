"""Attacks on raw pseudoranges: what each kind does to the signals, and how the fixes follow."""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from paths import SAMPLE_LOGS
from shared_inputs import simulated

from readers import read_log
from spooflens.attacks import AttackError, AttackTruth, apply_attack, parse_attack, sidecar_path
from spooflens.cli import main
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import add_enu_offset, geodetic_to_ecef, geodetic_to_enu
from spooflens.gnss.ephemeris import C_MPS, GPS_L1_HZ
from spooflens.gnss.single_point import solve
from spooflens.simulation.simulate import simulate
from spooflens.writers import write_log

START = 60.0


@cache
def _table() -> EpochTable:
    return simulated("ground_raw", 3, 120.0).table


def _offsets(truth: AttackTruth) -> np.ndarray:
    return np.array(truth.offsets["/gps/fix"])


def test_the_same_delay_on_every_satellite_moves_only_the_clock() -> None:
    table = _table()
    spoofed, truth = apply_attack(table, parse_attack(f"pr_delay:delay=300,start={START}"))
    after = table.observations["t_s"] >= START
    d_pr = spoofed.observations["pseudorange_m"] - table.observations["pseudorange_m"]
    np.testing.assert_allclose(d_pr[after], 300.0, atol=1e-6)
    np.testing.assert_allclose(d_pr[~after], 0.0, atol=0.0)
    d_phase = spoofed.observations["carrier_phase_cycles"] - table.observations["carrier_phase_cycles"]
    np.testing.assert_allclose(d_phase[after], 300.0 * GPS_L1_HZ / C_MPS, rtol=1e-9)
    assert np.abs(_offsets(truth)[:, 1:]).max() < 0.01
    clean, attacked = solve(table.observations), solve(spoofed.observations)
    np.testing.assert_allclose((attacked.clock_m - clean.clock_m)[clean.t_s >= START], 300.0, atol=0.01)


def test_a_delay_on_some_satellites_moves_the_fix_only_inside_the_window() -> None:
    table = _table()
    spoofed, truth = apply_attack(table, parse_attack(f"pr_delay:delay=300,count=2,start={START},end=100"))
    assert len(truth.satellites) == 2
    off = _offsets(truth)
    inside = (off[:, 0] >= START) & (off[:, 0] <= 100.0)
    assert np.abs(off[~inside, 1:]).max() < 1e-6
    assert np.linalg.norm(off[inside, 1:], axis=1).min() > 20.0
    # each fix moved by the truth's offset, in its own local frame
    moved = np.array(
        [
            geodetic_to_enu(a.lat_deg, a.lon_deg, a.height_m, b.lat_deg, b.lon_deg, b.height_m)
            for a, b in zip(spoofed.fixes.itertuples(), table.fixes.itertuples(), strict=True)
        ]
    )
    np.testing.assert_allclose(moved, off[:, 1:], atol=1e-3)
    # the attacked fixes are exactly the receiver's own solution of the attacked pseudoranges
    attacked = solve(spoofed.observations)
    lat, lon, h = attacked.geodetic()
    np.testing.assert_allclose(spoofed.fixes["lat_deg"], lat, atol=1e-7)
    np.testing.assert_allclose(spoofed.fixes["lon_deg"], lon, atol=1e-7)
    np.testing.assert_allclose(spoofed.fixes["height_m"], h, atol=0.05)


@settings(max_examples=8, deadline=None)
@given(delay=st.floats(20.0, 2000.0), count=st.integers(1, 4), seed=st.integers(0, 50))
def test_the_position_offset_is_linear_in_the_delay(delay: float, count: int, seed: int) -> None:
    """Seed 004's homology index does not depend on the bias amplitude because of this.

    Linear where the receiver uses the same satellites: its elevation mask is applied from its own
    (spoofed) position, so a satellite crossing the mask can come or go one epoch earlier.
    """
    table = _table()
    spec = f"pr_delay:count={count},seed={seed},start={START}"
    clean = solve(table.observations)
    shifts, used = [], []
    for d in (delay, 2 * delay):
        spoofed, _ = apply_attack(table, parse_attack(f"{spec},delay={d}"))
        sol = solve(spoofed.observations)
        shifts.append(sol.ecef_m - clean.ecef_m)
        used.append(np.isfinite(sol.residual_m))
    same = np.ones(len(clean.t_s), dtype=bool)
    same[np.unique(clean.row_epoch[used[0] != np.isfinite(clean.residual_m)])] = False
    same[np.unique(clean.row_epoch[used[1] != used[0]])] = False
    assert same.mean() > 0.8
    # not exactly: the troposphere model follows the solution's own height (about 0.3 mm per m of height,
    # times up to 6 near the mask), so a shift of hundreds of metres bends by a few tenths of a percent
    error = np.linalg.norm(shifts[1][same] - 2.0 * shifts[0][same], axis=1)
    assert np.all(error <= 5e-3 * np.linalg.norm(2.0 * shifts[0][same], axis=1) + 0.05)


def test_a_growing_delay_changes_rates_and_doppler_consistently() -> None:
    table = _table()
    spoofed, truth = apply_attack(table, parse_attack(f"pr_delay:delay=0,rate=4,svs=G17,start={START}"))
    assert truth.satellites == ["G17"]
    hit = (table.observations["sv_id"] == "G17") & (table.observations["t_s"] >= START)
    d_rate = spoofed.observations["pseudorange_rate_mps"] - table.observations["pseudorange_rate_mps"]
    np.testing.assert_allclose(d_rate[hit], 4.0, atol=1e-9)
    np.testing.assert_allclose(d_rate[~hit], 0.0, atol=0.0)
    d_dopp = spoofed.observations["doppler_hz"] - table.observations["doppler_hz"]
    np.testing.assert_allclose(d_dopp[hit], -4.0 * GPS_L1_HZ / C_MPS, rtol=1e-9)
    t = table.observations["t_s"][hit]
    d_pr = (spoofed.observations["pseudorange_m"] - table.observations["pseudorange_m"])[hit]
    np.testing.assert_allclose(d_pr, 4.0 * (t - START), atol=1e-6)


def test_meaconing_puts_the_fix_at_the_meaconers_antenna() -> None:
    table = _table()
    spoofed, truth = apply_attack(table, parse_attack(f"meaconing:east=400,north=-250,up=10,start={START}"))
    clean = solve(table.observations)
    first = int(np.flatnonzero(clean.t_s >= START)[0])
    lat0, lon0, h0 = (float(v[first]) for v in clean.geodetic())
    meaconer = geodetic_to_ecef(*add_enu_offset(lat0, lon0, h0, np.array([400.0, -250.0, 10.0])))
    after = spoofed.fixes["t_s"] >= START
    fixes = geodetic_to_ecef(spoofed.fixes["lat_deg"], spoofed.fixes["lon_deg"], spoofed.fixes["height_m"])
    dist = np.linalg.norm(fixes[after.to_numpy()] - meaconer, axis=1)
    assert np.median(dist) < 3.0 and dist.max() < 10.0  # solution noise around the meaconer
    assert np.abs(_offsets(truth)[~after.to_numpy(), 1:]).max() < 1e-6
    # the receiver believes it stands still at the meaconer: Doppler velocity near zero
    speed = np.linalg.norm(spoofed.fixes.loc[after, ["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy(), axis=1)
    true_speed = np.linalg.norm(table.fixes.loc[after, ["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy(), axis=1)
    assert np.median(speed) < 0.2 < np.median(true_speed)


def test_blocking_removes_only_the_chosen_satellites_inside_the_window() -> None:
    table = _table()
    spoofed, truth = apply_attack(table, parse_attack(f"blocking:svs=G17+G24,start={START},end=90"))
    assert truth.satellites == ["G17", "G24"]
    obs = table.observations
    gone = obs["sv_id"].isin(["G17", "G24"]) & (obs["t_s"] >= START) & (obs["t_s"] <= 90.0)
    assert len(spoofed.observations) == len(obs) - int(gone.sum()) and gone.sum() > 0
    kept = spoofed.observations
    assert not (kept["sv_id"].isin(["G17", "G24"]) & (kept["t_s"] >= START) & (kept["t_s"] <= 90.0)).any()


def test_spoofed_subset_keeps_the_authentic_satellites_and_delays_the_rest() -> None:
    table = _table()
    spoofed, truth = apply_attack(table, parse_attack(f"spoofed_subset:keep=4,delay=500,seed=2,start={START}"))
    assert len(truth.authentic) == 4 and not set(truth.authentic) & set(truth.satellites)
    d_pr = spoofed.observations["pseudorange_m"] - table.observations["pseudorange_m"]
    after = table.observations["t_s"] >= START
    authentic = table.observations["sv_id"].isin(truth.authentic)
    np.testing.assert_allclose(d_pr[after & authentic], 0.0, atol=0.0)
    np.testing.assert_allclose(d_pr[after & ~authentic], 500.0, atol=1e-6)


@pytest.mark.parametrize(
    ("attack", "message"),
    [
        ("pr_delay:svs=G99", "not in the log"),
        ("blocking:count=40", "only"),
        ("pr_delay:count=1.5", "whole number"),
        ("spoofed_subset:keep=99", "only"),
    ],
)
def test_bad_raw_attacks_are_refused_clearly(attack: str, message: str) -> None:
    with pytest.raises(AttackError, match=message):
        apply_attack(_table(), parse_attack(attack))


def test_raw_attacks_need_pseudoranges() -> None:
    table = simulate("ground", seed=1, duration_s=30.0).table
    with pytest.raises(AttackError, match="raw pseudoranges"):
        apply_attack(table, parse_attack("blocking:count=1"))


def test_inject_writes_a_spoofed_raw_csv_log_that_reads_back(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    src = tmp_path / "raw"
    write_log(_table(), src, "csv")
    out = tmp_path / "raw_spoofed"
    assert main(["inject", str(src), "--attack", f"pr_delay:delay=200,count=3,start={START}", "-o", str(out)]) == 0
    assert "satellites" in capsys.readouterr().out
    truth = json.loads(sidecar_path(out).read_text())
    assert truth["kind"] == "pr_delay" and len(truth["satellites"]) == 3
    back, orig = read_log(out), read_log(src)
    hit = orig.observations["sv_id"].isin(truth["satellites"]) & (orig.observations["t_s"] >= START)
    d_pr = back.observations["pseudorange_m"] - orig.observations["pseudorange_m"]
    np.testing.assert_allclose(d_pr[hit], 200.0, atol=1e-6)
    np.testing.assert_allclose(d_pr[~hit], 0.0, atol=0.0)
    late = orig.fixes["t_s"] >= START
    assert (np.abs(back.fixes["lat_deg"] - orig.fixes["lat_deg"])[late] > 1e-7).all()
    np.testing.assert_array_equal(back.fixes["lat_deg"][~late], orig.fixes["lat_deg"][~late])


def test_analyze_a_log_of_pseudoranges_only(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    table = _table()
    bare = tmp_path / "bare"
    write_log(EpochTable(**{**table.__dict__, "fixes": table.fixes.iloc[:0]}), bare, "csv")
    out_json = tmp_path / "bare.json"
    assert main(["analyze", str(bare), "-o", str(tmp_path / "bare.rrd"), "--json", str(out_json)]) == 0
    summary = json.loads(out_json.read_text())
    assert any("single-point" in s["reason"] for s in summary["computed"])  # an addition, not a loss
    assert not any("single-point" in s["reason"] for s in summary["skipped"])
    ran = {a["name"] for a in summary["analyses"] if a["ran"]}
    assert {"gnss_consistency", "kf_innovation"} <= ran


def test_meaconed_receiver_keeps_its_own_noise() -> None:
    """A meaconed receiver still measures with its own noise; a noiseless fix would be an artefact."""
    table = _table()
    spoofed, _ = apply_attack(table, parse_attack(f"meaconing:east=400,start={START}"))
    after = (spoofed.fixes["t_s"] >= START + 10).to_numpy()
    lat0, lon0, h0 = spoofed.fixes.loc[after, ["lat_deg", "lon_deg", "height_m"]].iloc[0]
    enu = geodetic_to_enu(
        spoofed.fixes["lat_deg"][after],
        spoofed.fixes["lon_deg"][after],
        spoofed.fixes["height_m"][after],
        lat0,
        lon0,
        h0,
    )
    assert 0.2 < np.std(enu[:, 0]) < 3.0
    speed = spoofed.fixes.loc[after, ["vel_e_mps", "vel_n_mps"]].to_numpy()
    assert 0.005 < np.std(speed) < 0.2


def test_the_meaconed_sample_is_caught_when_the_meaconer_switches_on(tmp_path: Path) -> None:
    sample = SAMPLE_LOGS / "meaconed_raw"
    truth = AttackTruth.read(sidecar_path(sample))
    out = tmp_path / "m.json"
    assert main(["analyze", str(sample), "-o", str(tmp_path / "m.rrd"), "--json", str(out)]) == 0
    summary = json.loads(out.read_text())
    assert summary["verdict"]["spoofed"]
    incident = summary["verdict"]["incidents"][0]
    assert incident["confidence"] == "high"
    assert truth.start_s <= incident["start_s"] <= truth.start_s + 2.0
    assert abs(incident["onset_s"] - truth.start_s) <= 5.0
    counted = set(summary["verdict"]["detectors_counted"])
    for a in summary["analyses"]:
        if a["name"] in counted:
            assert all(x["start_s"] >= truth.start_s for x in a["alarms"]), a["name"]
