"""Seed 002: pseudorange-change residuals on hand-computed cases, the predictors, compensation, and the detector
on a simulated station."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from spooflens.detectors import pr_change
from spooflens.detectors.references import station_reference
from spooflens.detectors.statistics.pseudorange_change import (
    MS_M,
    Prediction,
    clock_model_residual,
    compensation,
    esn_predictor,
    kalman_predictor,
    pseudorange_changes,
    train_esn,
)
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import ecef_to_geodetic
from spooflens.gnss.ephemeris import synthetic_constellation
from spooflens.gnss.grid import observation_grid
from spooflens.gnss.stations import STATION_OPTION, Station
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.registry import AnalysisContext, AnalyzeOptions
from spooflens.simulation.observations import ObservationNoise, simulate_observations

STATION = np.array([-3976219.5082, 3382372.5671, 3652512.9849])  # GSI 0759's surveyed site
START_GPS = 1.4e9


@pytest.fixture(scope="module")
def station_log() -> EpochTable:
    """A static receiver at a surveyed site, 1 Hz for 600 s, synthetic constellation, drifting clock."""
    eph = synthetic_constellation(START_GPS, rng=np.random.default_rng(0))
    t = np.arange(600.0)
    rx = np.tile(STATION, (len(t), 1))
    obs = simulate_observations(
        "stn", t, START_GPS + t, rx, np.zeros_like(rx), eph, ObservationNoise(), np.random.default_rng(1)
    )
    table = EpochTable(Path("station"), "simulation", round(START_GPS * 1e9), "gps", observations=obs)
    table.ephemerides = eph
    return table


def _changes(table: EpochTable, pr_offset=None):
    grid = observation_grid(table, "stn")
    if pr_offset is not None:
        grid = replace(grid, pseudorange_m=grid.pseudorange_m + pr_offset, carrier_m=grid.carrier_m + pr_offset)
    ref = station_reference(grid, Station("stn", STATION, "test"))
    return grid, pseudorange_changes(grid, ref, table.ionosphere)


def test_z_is_the_pseudorange_change_minus_the_range_change(station_log) -> None:
    """Hand computation at one epoch: the sum of what the simulator put in, receiver clock aside."""
    from spooflens.gnss.geometry import expected_pseudorange

    grid, ch = _changes(station_log)
    k, j = 300, int(np.flatnonzero(np.isfinite(ch.z[300]))[0])
    r = [
        expected_pseudorange(
            grid.sv_pos[e, j], grid.sv_clock_bias_m[e, j], STATION, np.zeros(()), grid.t_gps_s[e], None
        )
        for e in (k - 1, k)
    ]
    hand = (grid.pseudorange_m[k, j] - grid.pseudorange_m[k - 1, j]) - (r[1] - r[0])
    assert ch.z[k, j] == pytest.approx(hand, abs=1e-6)
    # the common part is the receiver clock change: a TCXO drifting tens of m/s; what is left is noise
    assert abs(ch.common[k]) > 1.0
    u = ch.z_median / ch.sigma_m
    assert np.nanstd(u) == pytest.approx(1.0, abs=0.15)
    # differenced white noise: lag-1 correlation -1/2
    a, b = u[1:-1].ravel(), u[2:].ravel()
    ok = np.isfinite(a) & np.isfinite(b)
    assert np.corrcoef(a[ok], b[ok])[0, 1] == pytest.approx(-0.5, abs=0.08)


def test_millisecond_clock_reset_is_removed(station_log) -> None:
    grid, ch = _changes(station_log)
    jump = np.zeros_like(grid.pseudorange_m)
    jump[200:] = MS_M  # the receiver steers its clock by 1 ms: every code range jumps by c x 1 ms
    _, ch2 = _changes(station_log, jump)
    assert ch2.clock_resets[200] == 1 and ch2.clock_resets.sum() == 1
    np.testing.assert_allclose(ch2.z_median, ch.z_median, atol=1e-6)


def test_kalman_flags_a_delayed_satellite_and_compensation_recovers_the_delay(station_log) -> None:
    grid, clean = _changes(station_log)
    kf = kalman_predictor(clean, 24.0)
    assert not kf.alarm.any()
    assert np.nanmean(kf.statistic) == pytest.approx(1.0, abs=0.25)  # calibrated on clean data
    j = int(np.flatnonzero(np.isfinite(clean.z[300]))[1])
    off = np.zeros_like(grid.pseudorange_m)
    off[300:, j] = 300.0
    _, ch = _changes(station_log, off)
    kf = kalman_predictor(ch, 24.0)
    assert np.flatnonzero(kf.alarm.any(axis=1)).tolist() == [300]
    assert np.flatnonzero(kf.alarm[300]).tolist() == [j]
    C = compensation(kf, ch.arc_start, 1.0)
    assert C[300, j] == pytest.approx(300.0, abs=5.0) and C[-1, j] == C[300, j]
    assert compensation(kf, ch.arc_start, 0.5)[-1, j] == pytest.approx(0.5 * C[-1, j])


def test_code_jump_without_the_carrier_is_taken_for_multipath(station_log) -> None:
    grid, _ = _changes(station_log)
    j = int(np.flatnonzero(np.isfinite(grid.pseudorange_m[300]))[1])
    pr = grid.pseudorange_m.copy()
    pr[300:, j] += 12.0  # code alone, less than multipath reaches
    ref = station_reference(grid, Station("stn", STATION, "test"))
    ch = pseudorange_changes(replace(grid, pseudorange_m=pr), ref, None)
    assert not ch.confirmed()[300, j]
    assert not kalman_predictor(ch, 24.0).alarm[300, j]
    pr[300:, j] += 100.0  # 112 m of code the carrier does not share: no real signal does that
    ch = pseudorange_changes(replace(grid, pseudorange_m=pr), ref, None)
    assert ch.confirmed()[300, j] and kalman_predictor(ch, 24.0).alarm[300, j]


def test_without_carrier_a_one_epoch_code_spike_is_a_glitch_and_a_held_delay_is_not(station_log) -> None:
    """A phone that logs no carrier (the real Android log of 2016-08-22: G12 44 m off for one epoch)."""
    grid, _ = _changes(station_log)
    grid = replace(grid, carrier_m=np.full_like(grid.carrier_m, np.nan))
    j = int(np.flatnonzero(np.isfinite(grid.pseudorange_m[300]))[1])
    ref = station_reference(grid, Station("stn", STATION, "test"))
    spike = grid.pseudorange_m.copy()
    spike[300, j] += 44.0
    ch = pseudorange_changes(replace(grid, pseudorange_m=spike), ref, None)
    assert ch.code_spikes()[300, j] and ch.code_spikes()[301, j] and not ch.confirmed()[300:302, j].any()
    assert not kalman_predictor(ch, 24.0).alarm[:, j].any()
    held = grid.pseudorange_m.copy()
    held[300:, j] += 44.0  # the delay a spoofer imposes and keeps
    ch = pseudorange_changes(replace(grid, pseudorange_m=held), ref, None)
    assert not ch.code_spikes()[300, j] and ch.confirmed()[300, j] and kalman_predictor(ch, 24.0).alarm[300, j]


def test_compensation_restarts_with_each_arc() -> None:
    v = np.array([[1.0], [2.0], [np.nan], [4.0], [8.0]])
    alarm = np.array([[True], [True], [False], [True], [False]])
    p = Prediction("t", v, np.ones_like(v), v**2, alarm, 1.0)
    arcs = np.array([[True], [False], [False], [True], [False]])
    np.testing.assert_allclose(compensation(p, arcs, 1.0)[:, 0], [1.0, 3.0, 3.0, 4.0, 4.0])


def test_echo_state_network_predicts_differenced_noise_better_than_the_kalman_filter(station_log) -> None:
    _, ch = _changes(station_log)
    u = ch.z_median / ch.sigma_m
    net = train_esn(u, ch.arc_start, np.ones(u.shape, dtype=bool))
    assert net.residual_var < 0.85  # of z's variance: the past predicts part of a differenced noise
    rnn = esn_predictor(ch, net, 24.0)
    kf = kalman_predictor(ch, 24.0)
    rms = [np.sqrt(np.nanmean((p.v / ch.sigma_m) ** 2)) for p in (rnn, kf)]
    assert rms[0] < 0.9 * rms[1]
    again = esn_predictor(ch, train_esn(u, ch.arc_start, np.ones(u.shape, dtype=bool)), 24.0)
    np.testing.assert_array_equal(again.v, rnn.v)  # seeded
    with pytest.raises(ValueError, match="clean samples"):
        train_esn(u, ch.arc_start, np.zeros(u.shape, dtype=bool))


def test_clock_model_variant_predicts_the_common_change(station_log) -> None:
    _, ch = _changes(station_log)
    _, pred = clock_model_residual(ch)
    ok = np.isfinite(pred) & np.isfinite(ch.common)
    assert np.sqrt(np.mean((pred[ok] - ch.common[ok]) ** 2)) < 1.0  # m per epoch, a clock drifting ~tens of m/s


def test_detector_on_a_station_given_on_the_command_line(station_log) -> None:
    from spooflens.schema import make_frame

    lat, lon, h = (float(v) for v in ecef_to_geodetic(STATION))
    table = replace(station_log)
    fixes = {"t_s": np.arange(3.0), "receiver_id": ["stn"] * 3, "lat_deg": [lat] * 3, "lon_deg": [lon] * 3}
    table.fixes = make_frame("fixes", fixes | {"height_m": [h] * 3, "fix_type": [2] * 3})
    none = pr_change.run(AnalysisContext(table, AnalyzeOptions()))
    assert not none[0].ran and "known position" in none[0].reason
    opts = AnalyzeOptions(extra={STATION_OPTION: [("stn", lat, lon, h)]})
    kf, rnn = pr_change.run(AnalysisContext(table, opts))
    assert kf.ran and rnn.ran and kf.evidence == Evidence.KNOWN_STATION
    assert not kf.alarms and not rnn.alarms
    grid = observation_grid(table, "stn")
    j = grid.sv_id[np.isfinite(grid.pseudorange_m[400])][0]
    obs = table.observations.copy()
    hit = (obs["sv_id"] == j) & (obs["t_s"] >= 400.0)
    obs.loc[hit, "pseudorange_m"] += 250.0
    obs.loc[hit, "carrier_phase_cycles"] += 250.0 / 0.1902936728
    spoofed = replace(table, observations=obs)
    kf, rnn = pr_change.run(AnalysisContext(spoofed, opts))
    for r in (kf, rnn):
        assert [(a.start_s, a.satellites) for a in r.alarms] == [(400.0, (str(j),))]
        estimate = float(r.findings[0].text.rsplit(f"{j} ", 1)[1].split(" m")[0])
        assert estimate == pytest.approx(250.0, abs=5.0)
