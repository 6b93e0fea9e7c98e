"""Satellite orbits, the pseudorange model, simulated raw observations and single-point positioning."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from shared_inputs import simulated

from spooflens.geodesy import ecef_to_geodetic, geodetic_to_ecef, geodetic_to_enu
from spooflens.gnss.ephemeris import (
    GM_GPS,
    OMEGA_E_GPS,
    GpsEphemerides,
    Klobuchar,
    satellite_states,
    synthetic_constellation,
)
from spooflens.gnss.geometry import azimuth_elevation, sagnac_range
from spooflens.gnss.single_point import SinglePointOptions, solve
from spooflens.gnss.solved_fixes import with_solved_fixes
from spooflens.simulation.observations import ObservationNoise, simulate_observations
from spooflens.simulation.simulate import simulate

T0 = 1_400_000_000.0  # GPS seconds, 2024-05
IONO = Klobuchar((1.118e-8, 1.49e-8, -5.96e-8, -5.96e-8), (8.806e4, 1.638e4, -1.966e5, -1.311e5))
BOSTON = geodetic_to_ecef(42.37, -71.1, 30.0)


def _static_obs(
    n: int = 600, seed: int = 0, noise: ObservationNoise | None = None
) -> tuple[pd.DataFrame, GpsEphemerides]:
    rng = np.random.default_rng(seed)
    eph = replace(synthetic_constellation(T0, rng=rng), iono=IONO)
    t = np.arange(n, dtype=float)
    rx = np.repeat(BOSTON[None], n, axis=0)
    obs = simulate_observations("rx", t, T0 + t, rx, np.zeros((n, 3)), eph, noise or ObservationNoise(), rng)
    return obs, eph


def test_synthetic_orbits_obey_kepler_independently_of_the_orbit_code() -> None:
    eph = synthetic_constellation(T0)
    sv = np.array(eph.satellites())
    for dt in (0.0, 3600.0, 5 * 86400.0):
        st = satellite_states(eph, sv, np.full(len(sv), T0 + dt))
        r = st.pos_m
        v_inertial = st.vel_mps + np.cross([0.0, 0.0, OMEGA_E_GPS], r)
        a = eph.sqrt_a[0] ** 2
        np.testing.assert_allclose(np.linalg.norm(r, axis=1), a, rtol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(v_inertial, axis=1), np.sqrt(GM_GPS / a), rtol=1e-6)
        h = np.cross(r, v_inertial)
        np.testing.assert_allclose(np.degrees(np.arccos(h[:, 2] / np.linalg.norm(h, axis=1))), 55.0, atol=1e-6)


def test_a_mid_latitude_receiver_sees_a_realistic_sky() -> None:
    eph = synthetic_constellation(T0)
    sv = np.array(eph.satellites())
    counts = []
    for dt in np.arange(0.0, 86400.0, 1800.0):
        st = satellite_states(eph, sv, np.full(len(sv), T0 + dt))
        _, el = azimuth_elevation(st.pos_m, np.broadcast_to(BOSTON, st.pos_m.shape))
        counts.append(int(np.sum(el > np.radians(5.0))))
    assert min(counts) >= 5 and max(counts) <= 13


def test_sagnac_term_matches_rotating_the_satellite_during_the_flight() -> None:
    st = satellite_states(synthetic_constellation(T0), np.array(["G01", "G05", "G09"]), np.full(3, T0))
    tau = np.linalg.norm(st.pos_m - BOSTON, axis=1) / 299792458.0
    angle = OMEGA_E_GPS * tau
    rotated = np.stack(
        [
            np.cos(angle) * st.pos_m[:, 0] + np.sin(angle) * st.pos_m[:, 1],
            -np.sin(angle) * st.pos_m[:, 0] + np.cos(angle) * st.pos_m[:, 1],
            st.pos_m[:, 2],
        ],
        axis=1,
    )
    exact = np.linalg.norm(rotated - BOSTON, axis=1)
    np.testing.assert_allclose(sagnac_range(st.pos_m, np.broadcast_to(BOSTON, st.pos_m.shape)), exact, atol=1e-3)


def test_single_point_finds_a_static_receiver_and_its_clock() -> None:
    obs, eph = _static_obs()
    sol = solve(obs, T0 + obs["t_s"].to_numpy(), SinglePointOptions(iono=eph.iono))
    assert sol.ok.all()
    lat, lon, h = ecef_to_geodetic(BOSTON)
    enu = geodetic_to_enu(*sol.geodetic(), lat, lon, h)
    assert np.sqrt(np.mean(enu[:, 0] ** 2 + enu[:, 1] ** 2)) < 2.5
    assert abs(np.mean(enu[:, 2])) < 1.0 and np.std(enu[:, 2]) < 4.0
    assert np.sqrt(np.mean(np.sum(sol.vel_ecef_mps**2, axis=1))) < 0.15
    assert np.all((sol.pdop > 1.0) & (sol.pdop < 10.0)) and np.all(sol.hdop < sol.pdop)
    assert np.nanmedian(sol.residual_rms_m) < 2.0


def test_leaving_out_the_ionosphere_biases_the_solution() -> None:
    obs, eph = _static_obs(120)
    with_model = solve(obs, T0 + obs["t_s"].to_numpy(), SinglePointOptions(iono=eph.iono))
    without = solve(obs, None)
    lat, lon, h = ecef_to_geodetic(BOSTON)
    up_with = geodetic_to_enu(*with_model.geodetic(), lat, lon, h)[:, 2].mean()
    up_without = geodetic_to_enu(*without.geodetic(), lat, lon, h)[:, 2].mean()
    assert abs(up_with) < 1.0 < abs(up_without)


def test_each_satellite_system_gets_its_own_clock() -> None:
    obs, eph = _static_obs(60)
    galileo = obs["sv_id"].isin(["G01", "G02", "G03", "G04", "G09", "G10", "G13", "G14", "G17", "G18", "G21"])
    obs.loc[galileo, "sv_id"] = "E" + obs.loc[galileo, "sv_id"].str[1:]
    obs.loc[galileo, "pseudorange_m"] += 12_345.0  # the system time offset
    sol = solve(obs, T0 + obs["t_s"].to_numpy(), SinglePointOptions(iono=eph.iono))
    assert sol.systems == ("G", "E")
    lat, lon, h = ecef_to_geodetic(BOSTON)
    enu = geodetic_to_enu(*sol.geodetic(), lat, lon, h)
    solved = sol.ok
    assert solved.mean() > 0.8
    assert np.sqrt(np.mean(np.sum(enu[solved] ** 2, axis=1))) < 6.0


def test_epochs_with_too_few_satellites_are_left_unsolved() -> None:
    obs, _ = _static_obs(10)
    first = obs["t_s"] == 0.0
    keep = ~first | obs.index.isin(obs[first].index[:3])
    sol = solve(obs[keep])
    assert not sol.ok[0] and sol.ok[1:].all()
    assert np.isnan(sol.ecef_m[0]).all()


def test_an_epoch_of_degenerate_geometry_is_left_unsolved_not_a_singular_matrix() -> None:
    """The second 10^4 fuzz run zeroed the satellites' x positions of an observations CSV: some epochs'
    normal equations were singular and failed the whole batch (LinAlgError before)."""
    obs, _ = _static_obs(10)
    first = (obs["t_s"] == 0.0).to_numpy()
    degenerate = obs.copy()
    # every satellite of the first epoch at one point: no geometry to solve from
    degenerate.loc[first, ["sv_x_m", "sv_y_m", "sv_z_m"]] = (
        degenerate.loc[first, ["sv_x_m", "sv_y_m", "sv_z_m"]].iloc[0].to_numpy()
    )
    sol = solve(degenerate)
    assert not sol.ok[0] and sol.ok[1:].all()
    np.testing.assert_allclose(sol.ecef_m[1:], solve(obs).ecef_m[1:], atol=1e-6)


def test_simulated_receiver_fixes_are_its_own_solution_near_the_truth() -> None:
    sim = simulated("ground_raw", 3, 120.0)
    table = sim.table
    assert len(table.observations) > 6 * len(table.fixes)
    truth = table.truth
    ref = (truth["lat_deg"][0], truth["lon_deg"][0], truth["height_m"][0])
    fix = geodetic_to_enu(table.fixes["lat_deg"], table.fixes["lon_deg"], table.fixes["height_m"], *ref)
    true = geodetic_to_enu(truth["lat_deg"], truth["lon_deg"], truth["height_m"], *ref)
    err = fix - true
    assert np.sqrt(np.mean(err[:, 0] ** 2 + err[:, 1] ** 2)) < 3.0
    vel_err = (
        table.fixes[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy()
        - truth[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy()
    )
    assert np.sqrt(np.mean(vel_err**2)) < 0.1
    assert (table.fixes["h_acc_m"] > 0.5).all()


def test_a_log_with_only_pseudoranges_gets_fixes_from_them() -> None:
    table = simulate("ground_raw", seed=4, duration_s=60.0).table
    bare = replace(table, fixes=table.fixes.iloc[:0])
    solved = with_solved_fixes(bare)
    assert len(solved.fixes) == len(table.fixes)
    assert any(s.action == "computed" and "single-point" in s.reason for s in solved.skipped)
    np.testing.assert_allclose(solved.fixes["lat_deg"], table.fixes["lat_deg"], atol=2e-5)
    assert with_solved_fixes(table) is table  # a receiver's own fixes are never replaced


@pytest.mark.parametrize("sigma", [0.5, 2.0])
def test_solution_noise_scales_with_pseudorange_noise(sigma: float) -> None:
    obs, eph = _static_obs(300, seed=1, noise=ObservationNoise(pseudorange_sigma_m=sigma))
    sol = solve(obs, T0 + obs["t_s"].to_numpy(), SinglePointOptions(iono=eph.iono))
    lat, lon, h = ecef_to_geodetic(BOSTON)
    horiz = geodetic_to_enu(*sol.geodetic(), lat, lon, h)[:, :2]
    rms = np.sqrt(np.mean(np.sum(horiz**2, axis=1)))
    expected = sigma * np.sqrt(2.0) * np.nanmedian(sol.hdop)  # sigma(el) averages about sqrt(2) x zenith
    assert 0.5 * expected < rms < 2.0 * expected


def test_two_raw_receivers_a_set_baseline_apart() -> None:
    from spooflens.simulation.simulate import SCENARIOS

    sc = replace(SCENARIOS["dual_receiver"], gnss_hz=1.0, observations=ObservationNoise())
    sim = simulate(sc, seed=6, duration_s=180.0)
    table = sim.table
    assert set(table.observations["receiver_id"]) == {"/gps/fix", "/gps2/fix"}
    one, two = table.fixes_of("/gps/fix"), table.fixes_of("/gps2/fix")
    ref = tuple(float(one.iloc[0][c]) for c in ("lat_deg", "lon_deg", "height_m"))
    d = geodetic_to_enu(two["lat_deg"], two["lon_deg"], two["height_m"], *ref) - geodetic_to_enu(
        one["lat_deg"], one["lon_deg"], one["height_m"], *ref
    )
    step = round(sc.imu_hz / sc.gnss_hz)
    lever = (sim.truth.C[::step] @ np.array(sc.second_receiver_lever_m))[: len(d)]
    # each receiver has its own noise and clock, yet on average the baseline is the lever arm
    np.testing.assert_allclose(d.mean(axis=0)[:2], lever.mean(axis=0)[:2], atol=0.5)
    clocks = table.observations.groupby("receiver_id")["pseudorange_m"].mean()
    assert abs(clocks["/gps/fix"] - clocks["/gps2/fix"]) > 10.0  # independent receiver clocks
