"""The loosely coupled filter and smoother on simulated logs (truth known) and on the real husky bag."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from filterpy.kalman import KalmanFilter
from shared_inputs import read_shared, simulated

from spooflens.epoch_table import EpochTable
from spooflens.geodesy import geodetic_to_enu
from spooflens.navigation.imu_models import grade
from spooflens.navigation.loosely_coupled import FilterOptions, NavSolution, run_filter
from spooflens.navigation.smoother import smooth
from spooflens.simulation.simulate import SCENARIOS, simulate


@pytest.fixture(scope="module")
def ground() -> tuple[EpochTable, NavSolution]:
    sim = simulated("ground", 3)
    return sim.table, run_filter(sim.table, options=FilterOptions(grade=SCENARIOS["ground"].imu_grade))


def _errors(table: EpochTable, t: np.ndarray, state: np.ndarray) -> np.ndarray:
    tr = table.truth
    k = np.searchsorted(tr["t_s"].to_numpy(), t - 1e-9)
    ref = tr.iloc[0]
    truth = geodetic_to_enu(
        tr["lat_deg"].to_numpy()[k],
        tr["lon_deg"].to_numpy()[k],
        tr["height_m"].to_numpy()[k],
        ref.lat_deg,
        ref.lon_deg,
        ref.height_m,
    )
    est = geodetic_to_enu(
        np.degrees(state[:, 0]), np.degrees(state[:, 1]), state[:, 2], ref.lat_deg, ref.lon_deg, ref.height_m
    )
    return est - truth


@pytest.mark.parametrize("name", ["ground", "aircraft"])
def test_nis_averages_its_degrees_of_freedom(name: str) -> None:
    sim = simulate(name, seed=5)
    sol = run_filter(sim.table, options=FilterOptions(grade=SCENARIOS[name].imu_grade))
    settled = sol.t > sol.t[0] + 30.0
    assert np.nanmean(sol.nis[settled]) == pytest.approx(np.mean(sol.dof[settled]), rel=0.10)
    assert sol.alignment is not None and "attitude from the log's orientation" in sol.alignment.method


def test_without_an_orientation_the_ins_aligns_by_velocity_matching() -> None:
    sim = simulate("aircraft", seed=5, duration_s=200.0)
    sim.table.imu[["qw", "qx", "qy", "qz"]] = np.nan
    sol = run_filter(sim.table, options=FilterOptions(grade=SCENARIOS["aircraft"].imu_grade))
    assert sol.alignment is not None and "velocity matching" in sol.alignment.method
    settled = sol.t > sol.t[0] + 30.0
    assert np.nanmean(sol.nis[settled]) == pytest.approx(np.mean(sol.dof[settled]), rel=0.15)


def test_smoothed_position_error_is_below_the_filtered_one(ground: tuple[EpochTable, NavSolution]) -> None:
    table, sol = ground
    sm = smooth(sol)
    settled = sol.t > sol.t[0] + 30.0
    filtered = np.sqrt(np.mean(np.sum(_errors(table, sol.t, sol.state)[settled] ** 2, axis=1)))
    smoothed = np.sqrt(np.mean(np.sum(_errors(table, sm.t, sm.state)[settled] ** 2, axis=1)))
    assert smoothed < 0.85 * filtered
    # and the smoother's covariance tells the truth about its errors (3 sigma per axis almost always)
    err = _errors(table, sm.t, sm.state)[settled]
    sigma = np.sqrt(sm.var[settled][:, 6:9])
    assert np.mean(np.abs(err) < 3 * sigma) > 0.97


@pytest.mark.parametrize("every", [7, 10])
def test_smoothing_from_every_nth_updated_covariance_equals_smoothing_from_all(
    ground: tuple[EpochTable, NavSolution], every: int
) -> None:
    """A solution that kept the updated covariance of every n-th epoch only is smoothed as the full one
    (the smoother makes the others again, so each run of n epochs and the last, shorter one agree)."""
    table, full = ground
    opts = FilterOptions(grade=SCENARIOS["ground"].imu_grade, P_upd_every=every)
    thinned = run_filter(table, options=opts)
    assert len(thinned.P_upd) == -(-len(thinned.t) // every) and len(thinned.t) % every != 0
    np.testing.assert_array_equal(thinned.P_upd, full.P_upd[::every])
    a, b = smooth(full), smooth(thinned)
    np.testing.assert_allclose(b.delta, a.delta, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(b.var, a.var, rtol=1e-7, atol=1e-12)
    with pytest.raises(ValueError, match="record="):
        smooth(run_filter(table, options=replace(opts, record=("Phi", "Qd", "P_upd"))))


def test_a_filter_over_checkpointed_integrals_is_the_filter_over_integrals_at_every_sample(
    ground: tuple[EpochTable, NavSolution],
) -> None:
    """A long log's IMU keeps its integrals every few samples (`strapdown.DENSE_SAMPLES`): the closed-loop
    filter over them, and over a cut of them (a continued run), is the same bit for bit."""
    from spooflens.navigation.loosely_coupled import initial_state, prepare, run_prepared
    from spooflens.navigation.strapdown import NavState, preintegrate

    table, _ = ground
    inputs = prepare(table)
    pre = inputs.pre
    sparse = replace(inputs, pre=preintegrate(pre.t, pre.f_axes, pre.w_axes, every=8))
    opts = FilterOptions(grade=SCENARIOS["ground"].imu_grade)
    start = initial_state(inputs, opts)
    a, b = run_prepared(inputs, opts, start), run_prepared(sparse, opts, start)
    for name in ("state", "nis", "S", "P_upd", "track_llh"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    # a cut between checkpoints makes its integrals again: the same numbers at every sample
    k0 = int(np.searchsorted(pre.t, a.t[len(a.t) // 3])) // 8 * 8 + 3
    dense_cut, sparse_cut = pre.between(k0, len(pre.t)), sparse.pre.between(k0, len(pre.t))
    rows = np.arange(len(dense_cut.t))
    for x, y in zip(dense_cut.integrals(rows), sparse_cut.integrals(rows), strict=True):
        np.testing.assert_array_equal(x, y)
    # a run continued from an epoch's update starts from the checkpoint before it: the integrals are views
    # (not made again to the log's end), and the run is the one over the integrals at every sample
    e = len(a.t) // 3
    cont = replace(opts, initial=NavState.from_vector(a.state[e]), initial_covariance=a.P_upd[e], initial_gm=a.gm[e])
    cut = sparse.between(float(a.t[e]))
    assert np.shares_memory(cut.pre.Qb, sparse.pre.Qb) and cut.pre.t[0] <= a.state[e, 21]
    a2, b2 = run_prepared(inputs.between(float(a.t[e])), cont), run_prepared(cut, cont)
    for name in ("state", "nis", "S", "P_upd", "track_llh"):
        np.testing.assert_array_equal(getattr(a2, name), getattr(b2, name))
    np.testing.assert_array_equal(a2.state[-5:], a.state[-5:])


def test_without_odometry_the_solution_keeps_one_h_and_everything_reads_it_as_the_per_epoch_copies(
    ground: tuple[EpochTable, NavSolution],
) -> None:
    """A log without odometry has the same H at every epoch (its odometry rows, never used, zero): the
    solution keeps one, seen at every epoch (0.15 GB a day of 1 Hz GNSS). The smoother, the detectors'
    model, seed 000's filters and the offline MLRT give what they give from per-epoch copies; with
    odometry measured, H is kept per epoch."""
    from spooflens.detectors.mlrt import MlrtOptions, statistics
    from spooflens.estimation.marginalised_likelihood import ramp_two_filter_offline
    from spooflens.navigation.loosely_coupled import OdometryAiding, prepare, run_prepared

    table, sol = ground
    assert sol.H.strides[0] == 0 and not sol.H.flags.writeable and sol.H.shape == (len(sol.t), 9, 24)
    copies = np.ascontiguousarray(sol.H)  # one H per epoch, C-contiguous as the filter keeps it with odometry
    assert (copies[:, 6:9, :6] == 0).all() and (copies[:, 6:9, 21:] == -np.eye(3)).all()
    dense = replace(sol, H=copies)
    a, b = smooth(sol), smooth(dense)
    np.testing.assert_array_equal(a.delta, b.delta)
    np.testing.assert_array_equal(a.var, b.var)
    m1, m2 = sol.error_model(), dense.error_model()
    np.testing.assert_array_equal(m1.y, m2.y)
    s1, s2 = statistics(m1, MlrtOptions()), statistics(m2, MlrtOptions())
    np.testing.assert_array_equal(s1.ramp.log_bf, s2.ramp.log_bf)
    np.testing.assert_array_equal(s1.kf_nis, s2.kf_nis)
    o1, o2 = (ramp_two_filter_offline(m, (0, 1, 2), np.full(3, 3.0), stride=10) for m in (m1, m2))
    np.testing.assert_array_equal(o1.log_bf, o2.log_bf)
    # odometry (here the truth's velocity in the body frame, as wheels would give it) is an H per epoch
    inputs = prepare(table)
    odo = pd.DataFrame({"t_s": sol.t, "odometry_id": "wheels", "vx_mps": 1.0, "vy_mps": 0.0, "vz_mps": 0.0})
    aided = replace(inputs, table=replace(table, odometry=odo))
    opts = FilterOptions(grade=SCENARIOS["ground"].imu_grade, odometry=OdometryAiding(np.eye(3), odometry_id="wheels"))
    with_odometry = run_prepared(aided, opts)
    assert with_odometry.H.strides[0] != 0 and np.ptp(with_odometry.H[:, 6:9, :6], axis=0).max() > 0


@pytest.mark.parametrize("variances", [True, False])
def test_a_solution_with_covariances_that_are_not_finite_cannot_be_smoothed_and_says_so(
    ground: tuple[EpochTable, NavSolution], variances: bool
) -> None:
    """An IMU whose stamps a damaged schema made wild left NaN covariances; the smoother's LinAlgError was
    an internal error (the fuzz run's), now the navigation's reason for not running."""
    from spooflens.errors import AnalysisError
    from spooflens.navigation.smoother import check_smoothable

    _, sol = ground
    damaged = replace(sol, P_upd=np.full_like(sol.P_upd, np.nan))
    with pytest.raises(AnalysisError, match="the smoother met a covariance it cannot invert"):
        smooth(damaged, variances=variances)
    # found before the smoother is begun in the background, so the navigation fails as it always did
    with pytest.raises(AnalysisError, match="the smoother met a covariance it cannot invert"):
        check_smoothable(damaged)
    check_smoothable(sol)


def test_the_smoothed_error_without_variances_is_the_full_smoothers(ground: tuple[EpochTable, NavSolution]) -> None:
    """The drawn tracks need the smoothed error only: one solve per epoch instead of the gain and the
    covariance recursion gives the same error and track to rounding."""
    _, sol = ground
    full, mean_only = smooth(sol), smooth(sol, variances=False)
    assert full.var.shape == (len(sol.t), 24) and mean_only.var.shape == (len(sol.t), 0)
    assert np.abs(full.delta).max() > 1e-3  # something to compare
    np.testing.assert_allclose(mean_only.delta, full.delta, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(mean_only.state, full.state, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(mean_only.track_llh[:, :2], full.track_llh[:, :2], rtol=0, atol=1e-15)
    np.testing.assert_allclose(mean_only.track_llh[:, 2], full.track_llh[:, 2], rtol=0, atol=1e-9)


def test_the_filters_log_det_s_is_that_of_its_used_rows_and_the_likelihood_reads_it(
    ground: tuple[EpochTable, NavSolution],
) -> None:
    """Noise learning scores a run by sum(nis + log det S) over the used rows; the filter's log det is
    that of numpy's determinant of those rows, NaN where no row was used, and a NaN among the scored
    epochs (S not positive definite) makes the candidate unusable."""
    from spooflens.navigation.noise_learning import score

    table, sol = ground
    some = sol.dof > 0
    for e in np.flatnonzero(some)[:: max(1, some.sum() // 200)]:
        rows = np.flatnonzero(sol.used[e])
        sign, expected = np.linalg.slogdet(sol.S[e][np.ix_(rows, rows)])
        assert sign > 0 and sol.logdet_S[e] == pytest.approx(expected, rel=1e-12, abs=1e-12)
    t_out = float(sol.t[len(sol.t) // 2])
    opts = FilterOptions(grade=sol.grade, exclude_after_s=t_out, exclude_until_s=t_out + 5.0, exclude_velocity_too=True)
    gap = run_filter(table, options=opts)
    assert (gap.dof == 0).sum() >= 10 and np.isnan(gap.logdet_S[gap.dof == 0]).all()
    assert np.isfinite(gap.logdet_S[gap.dof > 0]).all()
    sel = np.isfinite(sol.nis) & some
    assert score(sol) == pytest.approx(np.sum(sol.nis[sel]) + np.sum(sol.logdet_S[sel]), rel=1e-15)
    broken = sol.logdet_S.copy()
    broken[np.flatnonzero(sel)[5]] = np.nan
    assert score(replace(sol, logdet_S=broken)) == np.inf
    mask = np.zeros(len(sol.t), dtype=bool)
    mask[np.flatnonzero(sel)[6:]] = True  # the broken epoch not scored
    assert np.isfinite(score(replace(sol, logdet_S=broken), mask))


def test_open_loop_error_model_reproduces_the_filters_innovations(ground: tuple[EpochTable, NavSolution]) -> None:
    """A textbook KF (filterpy) on the exported linear model gives the same innovations and S."""
    _, sol = ground
    model = sol.error_model()
    kf = KalmanFilter(dim_x=model.n_states, dim_z=model.n_measurements)
    kf.x, kf.P = model.x0.copy(), model.P0.copy()
    for k in range(min(400, model.n_epochs)):
        if k > 0:
            kf.F, kf.Q = model.A.at(k), model.Q.at(k)
            kf.predict()
        use = np.isfinite(model.y[k])
        kf.H, kf.R = model.C[k][use], model.R[k][np.ix_(use, use)]
        kf.dim_z = int(use.sum())
        kf.update(model.y[k][use])
        np.testing.assert_allclose(kf.y, sol.nu[k][use], rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(kf.S, sol.S[k][np.ix_(use, use)], rtol=1e-6, atol=1e-10)


def test_gnss_outage_is_coasted_and_recovered() -> None:
    sim = simulate("ground", seed=4)
    table = sim.table
    t = table.fixes["t_s"].to_numpy()
    table.fixes = table.fixes[(t < 150.0) | (t > 170.0)].reset_index(drop=True)
    sol = run_filter(table, options=FilterOptions(grade=SCENARIOS["ground"].imu_grade))
    assert not np.any((sol.t > 150.0) & (sol.t < 170.0))
    err = np.linalg.norm(_errors(table, sol.t, sol.state), axis=1)
    after = sol.t > 175.0
    assert err[after].max() < 2.0
    first_back = int(np.argmax(sol.t > 170.0))
    assert sol.nis[first_back] < 40.0  # the coasted INS is still consistent with the first fix back


def test_excluding_gnss_coasts_on_the_ins() -> None:
    sim = simulate("aircraft", seed=2, duration_s=200.0)
    opts = FilterOptions(grade=SCENARIOS["aircraft"].imu_grade, exclude_after_s=150.0)
    sol = run_filter(sim.table, options=opts)
    late = sol.t >= 150.0
    assert not sol.used[late].any() and np.all(sol.dof[late] == 0)
    err = np.linalg.norm(_errors(sim.table, sol.t, sol.state)[late], axis=1)
    assert err.max() < 5.0  # 50 s of tactical-grade coasting


def test_husky_bag_end_to_end_with_the_rotated_imu(husky_bag: Path) -> None:
    table = read_shared(husky_bag)
    sol = run_filter(table, options=FilterOptions(grade=grade("consumer_mems")))
    assert sol.alignment is not None
    assert len(sol.t) > 900 and set(np.unique(sol.dof)) == {3}  # NavSatFix: position only
    nis = sol.nis[sol.t > sol.t[0] + 30.0]
    # README reports these statistics; bounds are loose on purpose: a real consumer IMU and SBAS fixes
    assert 1.5 < np.nanmean(nis) < 6.0 and np.nanpercentile(nis, 99) < 30.0
    # the levelled attitude puts the IMU's +y (where gravity appears) up
    C = sol.state[0, 6:15].reshape(3, 3)
    assert (C @ np.array([0.0, 1.0, 0.0]))[2] > 0.95


def test_the_smoothed_track_corrected_a_chunk_at_a_time_is_the_whole_tracks(
    ground: tuple[EpochTable, NavSolution], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A day-long track is corrected `TRACK_CHUNK` blocks at a time (its temporaries were the voyage's
    memory peak): chunks of 7 blocks, which cut inter-epoch segments anywhere, give the same track."""
    from spooflens.navigation import smoother

    _, sol = ground
    whole = smooth(sol, variances=False)
    monkeypatch.setattr(smoother, "TRACK_CHUNK", 7)
    chunked = smooth(sol, variances=False)
    assert len(sol.track_t) > 10 * 7
    np.testing.assert_array_equal(chunked.track_llh, whole.track_llh)
    assert np.abs(whole.track_llh - sol.track_llh).max() > 0  # the correction moved the track
