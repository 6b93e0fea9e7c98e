"""Seed 000's detectors on simulated logs: quiet when clean, fast and well-placed on a ramp."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from spooflens.attacks import apply_attack, parse_attack
from spooflens.detectors.mlrt import MlrtOptions, detect
from spooflens.navigation.loosely_coupled import FilterOptions, run_filter
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.run import analyze_table
from spooflens.simulation.sensors import GnssNoise
from spooflens.simulation.simulate import SCENARIOS, simulate


def _run(rate: float, seed: int = 3, start: float = 120.0, scenario: str = "ground", **kw) -> dict:
    sim = simulate(scenario, seed=seed, duration_s=240.0)
    table = sim.table
    if rate:
        table, _ = apply_attack(table, parse_attack(f"ramp:rate={rate},axes=en,start={start}"))
    sol = run_filter(table, options=FilterOptions(grade=SCENARIOS[scenario].imu_grade))
    return {r.name: r for r in detect(sol.error_model(), MlrtOptions(**kw))}


def test_clean_log_raises_no_calibrated_alarm() -> None:
    res = _run(0.0)
    for name in ("kf_innovation", "glrt", "mlrt_calibrated"):
        assert res[name].alarms == [], name
    assert abs(res["glrt"].extras["innovation_whiteness"]) < 0.2


def test_ramp_is_detected_with_onset_and_credible_interval() -> None:
    res = _run(1.0)
    cal = res["mlrt_calibrated"].alarms[0]
    assert 120.0 < cal.start_s < 130.0
    assert cal.onset_interval_s is not None
    assert cal.onset_interval_s[0] - 1.0 <= 120.0 <= cal.onset_interval_s[1] + 1.0
    assert abs(cal.onset_s - 120.0) < 3.0
    glrt = res["glrt"].alarms[0]
    assert 120.0 < glrt.start_s < 130.0 and abs(glrt.onset_s - 120.0) < 5.0
    curve = res["mlrt_calibrated"].curves[0]
    assert abs(curve.x[int(np.nanargmax(curve.y))] - 120.0) < 5.0  # l_N(m) peaks near the true onset


def test_larger_ramps_are_detected_no_later() -> None:
    delays = [_run(rate, offline=False)["glrt"].alarms[0].start_s for rate in (0.5, 1.0, 3.0)]
    assert delays == sorted(delays, reverse=True)


def test_time_correlated_gnss_errors_make_the_ramp_tests_advisory() -> None:
    sc = replace(SCENARIOS["ground"], gnss=GnssNoise((1.5, 1.5, 3.0), 0.08, correlation_s=30.0))
    sim = simulate(sc, seed=2, duration_s=200.0)
    sol = run_filter(sim.table, options=FilterOptions(grade=sc.imu_grade))
    res = {r.name: r for r in detect(sol.error_model(), MlrtOptions(offline=False))}
    whiteness = res["glrt"].extras["innovation_whiteness"]
    assert isinstance(whiteness, float) and whiteness > 0.5
    assert res["glrt"].advisory and res["mlrt_calibrated"].advisory and not res["kf_innovation"].advisory
    assert "MODEL MISMATCH" in res["glrt"].reason


def test_analyze_pipeline_reconstructs_the_trajectory_during_the_attack() -> None:
    sim = simulate("ground", seed=5, duration_s=200.0)
    spoofed, _ = apply_attack(sim.table, parse_attack("ramp:rate=2,axes=en,start=120"))
    verdict = analyze_table(spoofed).verdict
    assert verdict.spoofed and verdict.incidents[0].confidence == "high"
    assert set(verdict.incidents[0].evidence) == {Evidence.GNSS_ONLY, Evidence.INERTIAL}
    assert abs(verdict.incidents[0].onset_s - 120.0) < 3.0
    (rec,) = verdict.reconstructed  # the INS with GNSS left out over the incident
    assert "GNSS velocity" in rec.name  # the ramp leaves the velocity honest, so it is used
    truth = sim.table.truth
    k = np.searchsorted(truth["t_s"].to_numpy(), rec.t)
    late = (rec.t > 150) & (k < len(truth))
    from spooflens.geodesy import geodetic_to_enu

    ref = truth.iloc[0]
    err = geodetic_to_enu(
        rec.lat_deg[late], rec.lon_deg[late], rec.height_m[late], ref.lat_deg, ref.lon_deg, ref.height_m
    ) - geodetic_to_enu(
        truth["lat_deg"].to_numpy()[k[late]],
        truth["lon_deg"].to_numpy()[k[late]],
        truth["height_m"].to_numpy()[k[late]],
        ref.lat_deg,
        ref.lon_deg,
        ref.height_m,
    )
    horizontal = np.linalg.norm(err[:, :2], axis=1)
    spoofed_offset = 2 * np.sqrt(2) * (rec.t[late] - 120)
    assert np.median(horizontal) < 0.1 * np.median(spoofed_offset)  # the INS keeps the truth


@pytest.mark.parametrize("name", ["kf_innovation", "glrt", "mlrt", "mlrt_calibrated"])
def test_every_detector_reports_its_statistic_and_threshold(name: str) -> None:
    res = _run(2.0, offline=False)
    s = res[name].series[0]
    assert len(s.t) == len(s.values) and s.threshold is not None


def test_statistics_a_block_at_a_time_equal_the_whole_logs_filter_bit_for_bit() -> None:
    """Seed 000 holds the forward filter's gains and S a block at a time (a day of them was 0.26 GB): the
    ramp statistics, NIS and whiteness are those of one filter and one pass over the whole log."""
    from spooflens.detectors.innovation_tests import position_nis
    from spooflens.detectors.mlrt import normalised_position_innovations, statistics
    from spooflens.estimation.kalman import forward_filter, model_arrays
    from spooflens.estimation.ramp_signature import RampPass

    sim = simulate("ground", seed=5, duration_s=120.0)
    table, _ = apply_attack(sim.table, parse_attack("ramp:rate=1.5,axes=en,start=60"))
    model = run_filter(table, options=FilterOptions(grade=SCENARIOS["ground"].imu_grade)).error_model()
    # the last block of 100 is one epoch, whose slice of the broadcast H is contiguous but read-only: handed
    # over as it is, it was an argument type no kernel is built for (a minute of compiling in an analysis)
    assert model.C.strides[0] == 0 and model.n_epochs % 100 == 1
    last = model_arrays(model, slice(model.n_epochs - 1, model.n_epochs))
    assert all(x.flags.c_contiguous and x.flags.writeable for x in last)
    opts = MlrtOptions()
    fwd = forward_filter(model, keep_states=False)
    sigma = np.array(opts.sigma_rate_mps)
    whole = RampPass(model, (0, 1, 2), opts.window_s, opts.step_s, sigma, opts.attacks_per_hour, 3).whole_log(fwd)
    assert np.isfinite(whole.glr).sum() > 100
    z = normalised_position_innovations(fwd.eps, fwd.S)
    # blocks shorter than the 30 s window, so candidates read far into the next block; and one block
    for block in (37, 100, model.n_epochs):
        st = statistics(model, opts, block=block)
        for name in ("glr", "glr_onset", "mlr", "mlr_onset", "log_bf", "bf_onset", "log_odds", "candidates"):
            np.testing.assert_array_equal(getattr(st.ramp, name), getattr(whole, name), err_msg=f"{name}, {block}")
        np.testing.assert_array_equal(st.kf_nis, position_nis(fwd))
        np.testing.assert_array_equal(st.z, z)
