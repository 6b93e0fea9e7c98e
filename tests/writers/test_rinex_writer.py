"""Simulated raw logs written as RINEX 3.04 and read back: the same observations, satellites and solution."""

from __future__ import annotations

from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from readers import read_log
from spooflens.cli import main
from spooflens.epoch_table import EpochTable
from spooflens.errors import WriterError
from spooflens.geodesy import geodetic_to_enu
from spooflens.gnss.solved_fixes import with_solved_fixes
from spooflens.simulation.simulate import SCENARIOS, simulate
from spooflens.writers import write_log


@cache
def _table(seconds: float = 120.0) -> EpochTable:
    return simulate("ground_raw", seed=5, duration_s=seconds).table


def _sorted(obs):
    return obs.sort_values(["receiver_id", "t_s", "sv_id"]).reset_index(drop=True)


def test_round_trip_keeps_observations_to_rinex_precision(tmp_path: Path) -> None:
    table = _table()
    write_log(table, tmp_path / "rnx", "rinex")
    back = read_log(tmp_path / "rnx")
    assert back.format == "rinex" and back.time_reference == "gps"
    a, b = _sorted(table.observations), _sorted(back.observations)
    assert list(a["sv_id"]) == list(b["sv_id"]) and set(b["receiver_id"]) == {"/gps/fix"}  # marker = receiver id
    np.testing.assert_array_equal(table.gps_seconds(a["t_s"].to_numpy()), back.gps_seconds(b["t_s"].to_numpy()))
    for col in ("pseudorange_m", "carrier_phase_cycles", "doppler_hz", "cn0_dbhz"):
        np.testing.assert_allclose(b[col], a[col], atol=0.0005 + 1e-9)  # F14.3
    # satellite states recomputed from the written navigation file
    cols = ["sv_x_m", "sv_y_m", "sv_z_m"]
    np.testing.assert_allclose(b[cols].to_numpy(), a[cols].to_numpy(), atol=1e-3)
    np.testing.assert_allclose(b["sv_clock_bias_m"], a["sv_clock_bias_m"], atol=1e-6)


def test_a_gps_and_galileo_log_round_trips_with_both_systems_orbits(tmp_path: Path) -> None:
    """Galileo records are written with Galileo's fields (I/NAV data sources, BGD) in a mixed navigation
    file and read back as the same orbits."""
    table = simulate(replace(SCENARIOS["ground_raw"], constellation="synthetic_gps_galileo"), 5, 600.0).table
    write_log(table, tmp_path / "rnx", "rinex")
    assert (tmp_path / "rnx" / "BRDC_MN.rnx").read_text().startswith("     3.04           N: GNSS NAV DATA    M")
    back = read_log(tmp_path / "rnx")
    a, b = _sorted(table.observations), _sorted(back.observations)
    assert set(b["sv_id"].str[0]) == {"G", "E"} and list(a["sv_id"]) == list(b["sv_id"])
    for col in ("sv_x_m", "sv_y_m", "sv_z_m", "sv_clock_bias_m"):
        np.testing.assert_allclose(b[col], a[col], atol=1e-3)
    assert not [s for s in back.skipped if "Galileo" in s.reason]


def test_the_rinex_copy_solves_to_the_truth(tmp_path: Path) -> None:
    table = _table()
    write_log(table, tmp_path / "rnx", "rinex")
    solved = with_solved_fixes(read_log(tmp_path / "rnx"))
    truth = table.truth
    ref = tuple(float(truth[c].iloc[0]) for c in ("lat_deg", "lon_deg", "height_m"))
    fix = geodetic_to_enu(solved.fixes["lat_deg"], solved.fixes["lon_deg"], solved.fixes["height_m"], *ref)
    true = geodetic_to_enu(truth["lat_deg"], truth["lon_deg"], truth["height_m"], *ref)
    assert np.sqrt(np.mean(np.sum((fix - true)[:, :2] ** 2, axis=1))) < 3.0


def test_long_logs_get_navigation_records_every_two_hours(tmp_path: Path) -> None:
    """Other tools use a broadcast record for +-2 h only: a synthetic orbit is re-issued, unchanged."""
    from readers.rinex import read_rinex_nav
    from spooflens.gnss.ephemeris import satellite_states

    table = _table()
    start_gps = table.gps_seconds(0.0)
    assert start_gps is not None and table.ephemerides is not None
    start = float(start_gps)
    long = EpochTable(**{**table.__dict__})
    obs = table.observations.copy()
    obs.loc[obs.index[-1], "t_s"] = 5 * 3600.0  # one late row stretches the span to five hours
    long.observations = obs
    write_log(long, tmp_path / "rnx", "rinex")
    nav = read_rinex_nav(tmp_path / "rnx" / "BRDC_GN.rnx")
    g06 = nav.toe_s[nav.sv_id == "G06"]
    assert len(g06) >= 3 and np.all(np.diff(g06) == 7200.0)
    t: np.ndarray = start + np.linspace(0.0, 5 * 3600.0, 11)
    sv = np.array(["G06"] * len(t))
    np.testing.assert_allclose(
        satellite_states(nav, sv, t).pos_m, satellite_states(table.ephemerides, sv, t).pos_m, atol=1e-3
    )


def test_a_log_without_observations_cannot_be_rinex(tmp_path: Path) -> None:
    table = simulate("ground", seed=1, duration_s=10.0).table
    with pytest.raises(WriterError, match="no"):
        write_log(table, tmp_path / "x", "rinex")


def test_simulate_writes_rinex(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sim_rnx"
    assert main(["simulate", "ground_raw", "--format", "rinex", "--seconds", "30", "-o", str(out)]) == 0
    assert "IMU and fixes are not written" in capsys.readouterr().err
    assert len(read_log(out).observations) > 100
