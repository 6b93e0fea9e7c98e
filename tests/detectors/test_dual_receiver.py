"""Seed 003: the statistics (eq. 13 corrected, Rayleigh ML scale, Rice fit, window null distribution with
an effective window) and the dual-receiver detectors on simulated and real pairs."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from paths import REAL
from scipy import stats

from readers import read_log
from spooflens.attacks import apply_attack, parse_attack
from spooflens.attacks.single_antenna_raw import single_antenna_observations
from spooflens.detectors.dual_receiver import (
    BASELINE_ERROR,
    COLLAPSE,
    PR_COLLAPSE,
    DualReceiverOptions,
    align_pair,
    detect,
    pseudorange_differences,
)
from spooflens.detectors.statistics import rayleigh as ry
from spooflens.simulation.simulate import SCENARIOS, simulate

GSI = REAL / "rinex_gsi_pair"


def test_eq13_as_printed_is_not_a_variance_and_the_correction_is():
    d = np.array([1.0, 2.0, 3.0])
    assert ry.eq13_as_printed(d) == pytest.approx(-5.0)  # 14/2 - 36/3: negative, no square root
    rng = np.random.default_rng(1)
    d = 3.2e5 + rng.normal(0.0, 0.7, 9)  # a receiver clock difference of ~1 ms plus the spread
    n = len(d)
    textbook = np.sqrt((np.sum((d - 3.2e5) ** 2) - np.sum(d - 3.2e5) ** 2 / n) / (n - 1))
    assert ry.difference_sd(d) == pytest.approx(textbook, rel=1e-9)
    assert ry.difference_sd(d) == pytest.approx(np.std(d, ddof=1), rel=1e-12)


def test_difference_sd_keeps_one_mean_per_system():
    rng = np.random.default_rng(2)
    g, e = rng.normal(0, 1.0, 6), rng.normal(0, 1.0, 5)
    d = np.r_[g + 1e5, e - 3e4]  # each system has its own clock difference
    sys = np.r_[np.zeros(6, int), np.ones(5, int)]
    pooled = np.sqrt((np.sum((g - g.mean()) ** 2) + np.sum((e - e.mean()) ** 2)) / (11 - 2))
    assert ry.difference_sd(d, sys) == pytest.approx(pooled, rel=1e-9)


def test_rayleigh_scale_is_the_maximum_likelihood_estimate():
    x = stats.rayleigh(scale=2.5).rvs(4000, random_state=3)
    _, scale = stats.rayleigh.fit(x, floc=0)
    assert ry.rayleigh_scale(x) == pytest.approx(scale, rel=1e-4)
    k = 7
    w = ry.windowed_scale(x, k)
    assert np.isnan(w[:k]).all()
    for j in (k, 100, 3999):
        assert w[j] == pytest.approx(ry.rayleigh_scale(x[j - k : j]), rel=1e-12)  # samples j-1 ... j-K, eq. 18
    assert ry.windowed_scale(x, k, include_current=True)[k - 1] == pytest.approx(ry.rayleigh_scale(x[:k]))


def test_rice_fit_by_moments():
    nu, sigma = ry.rice_fit(stats.rice(3.0 / 1.2, scale=1.2).rvs(200_000, random_state=4))
    assert nu == pytest.approx(3.0, rel=0.03) and sigma == pytest.approx(1.2, rel=0.03)
    nu0, s0 = ry.rice_fit(stats.rayleigh(scale=2.0).rvs(200_000, random_state=5))
    # near nu = 0 the moments pin nu only to the fourth root of their noise; the fit is Rayleigh all the same
    assert nu0 / s0 < 0.35 and s0 == pytest.approx(2.0, rel=0.05)
    assert stats.rice(nu0 / s0, scale=s0).ppf(1e-3) == pytest.approx(stats.rayleigh(scale=2.0).ppf(1e-3), rel=0.05)
    far = ry.rice_fit(3335.0 + stats.norm(scale=0.3).rvs(5000, random_state=6))  # a long baseline
    assert far[0] == pytest.approx(3335.0, abs=0.05) and far[1] == pytest.approx(0.3, rel=0.1)


@pytest.mark.parametrize(("k", "p_fa"), [(1, 0.217), (2, 0.0866), (5, 0.0083), (10, 2.3e-4)])
def test_false_alarm_at_the_papers_boundary(k, p_fa):
    # SEEDS.md: P_FA = F_chi2(2K)(2K th^2 / sigma_GNSS^2) at th = 4.97 (sigma_GNSS 10.06), P_MD ~ 0 (sigma_S 0.12)
    th = ry.paper_boundary(10.06, 0.12)
    assert th == pytest.approx(4.97)
    assert ry.scale_probability_below(th, 10.06, 0.0, k) == pytest.approx(p_fa, rel=0.01)
    assert 1.0 - ry.scale_probability_below(th, 0.12, 0.0, k) < 1e-12


@pytest.mark.parametrize("nu", [0.0, 1.2, 40.0])
def test_scale_threshold_gives_the_stated_rate(nu):
    rng = np.random.default_rng(7)
    sigma, k, p = 2.0, 6, 0.01
    th = ry.scale_threshold(p, sigma, nu, k)
    assert ry.scale_probability_below(th, sigma, nu, k) == pytest.approx(p, rel=1e-6)
    e = rng.normal(0.0, sigma, (200_000, k, 2))
    d = np.linalg.norm(e + np.array([nu, 0.0]), axis=2)
    scale = np.sqrt(np.mean(d**2, axis=1) / 2)
    assert np.mean(scale < th) == pytest.approx(p, rel=0.1)
    up = ry.scale_threshold(p, sigma, nu, k, upper=True)
    assert np.mean(scale > up) == pytest.approx(p, rel=0.1)


def test_effective_window_restores_the_rate_on_correlated_samples():
    rng = np.random.default_rng(8)
    n, k, p, sigma, a = 400_000, 20, 0.01, 1.0, 0.9
    w = rng.normal(0.0, sigma * np.sqrt(1 - a * a), (n, 2))
    e = np.empty((n, 2))
    e[0] = rng.normal(0.0, sigma, 2)
    for i in range(1, n):  # AR(1): about 10 samples per independent one
        e[i] = a * e[i - 1] + w[i]
    d = np.linalg.norm(e, axis=1)
    scale = ry.windowed_scale(d, k)[k:]
    k_eff = ry.effective_window(d, np.ones(n, bool), k)
    iid = ry.effective_window(rng.rayleigh(1.0, n), np.ones(n, bool), k)
    assert iid == pytest.approx(k, rel=0.05)
    assert 2.0 < k_eff < 8.0
    naive = np.mean(scale < ry.scale_threshold(p, sigma, 0.0, k))
    corrected = np.mean(scale < ry.scale_threshold(p, sigma, 0.0, k_eff))
    assert naive > 10 * p  # K correlated samples taken as independent: far more false alarms than stated
    # K_eff matches the window sum's mean and variance (Satterthwaite); its far lower tail is lighter than
    # chi-square's, so the corrected rule errs on the side of fewer false alarms (measured 2.3e-4 at 1e-2)
    assert p / 100 < corrected <= p


def test_changepoint_and_calibration_on_a_collapsing_series():
    rng = np.random.default_rng(9)
    x = np.r_[rng.rayleigh(2.0, 600), rng.rayleigh(0.05, 300)]
    assert ry.scale_changepoint(x, 500, 700) == 600
    cal, _, alarm = ry.calibrate(x, 10, 1e-5)
    assert cal.calibrated and cal.iterations >= 2
    assert cal.sigma == pytest.approx(2.0, rel=0.1)  # fitted on the clean part, not the whole series
    assert not alarm[:600].any()
    assert alarm[620:].all()


def _dual(seed: int, seconds: float = 240.0):
    sc = replace(SCENARIOS["dual_receiver"], imu_hz=25.0, gnss_hz=5.0)
    return simulate(sc, seed=seed, duration_s=seconds).table


def test_align_pair_interpolates_the_denser_receiver_within_its_gap_bound():
    table = _dual(1, 60.0)
    a, b = table.receivers()
    fa, fb = table.fixes_of(a), table.fixes_of(b)
    fa = fa.iloc[::5].reset_index(drop=True)  # receiver a at 1 Hz, b at 5 Hz
    fb = fb.drop(index=range(100, 120)).reset_index(drop=True)  # b loses 4 s
    pair = align_pair(fa, fb, a, b, DualReceiverOptions())
    assert len(pair.t) == len(fa) - 4  # the epochs inside b's gap are not guessed
    assert np.all((pair.t < 20.0) | (pair.t > 23.9))
    d = np.linalg.norm(pair.ecef_a - pair.ecef_b, axis=1)
    assert 0.3 < np.median(d) < 5.0


def test_the_clean_sample_pair_stays_clean():
    # the scenario and seed of sample_logs/dual_receiver.mcap, its first 90 s (before its attack), 5 Hz
    res = {r.name: r for r in detect(_dual(2, 90.0))}
    assert res[COLLAPSE].ran and not res[COLLAPSE].alarms


def test_simulated_pair_clean_then_single_antenna():
    table = _dual(3)
    clean = {r.name: r for r in detect(table)}
    assert clean[COLLAPSE].ran and not clean[COLLAPSE].alarms
    assert not clean[PR_COLLAPSE].ran and "raw observations" in clean[PR_COLLAPSE].reason
    assert not clean[BASELINE_ERROR].ran  # a moving car: no known baseline vector
    spoofed, _ = apply_attack(table, parse_attack("single_antenna:rate=1,start=150"))
    res = {r.name: r for r in detect(spoofed)}[COLLAPSE]
    first = min(a.start_s for a in res.alarms)
    assert 150.0 < first < 160.0  # a 10 s window: the scale halves after a few seconds
    assert {a.receiver_id for a in res.alarms} == set(table.receivers())
    assert all(abs(a.onset_s - 150.0) <= 1.0 for a in res.alarms)
    assert any(h.name.endswith("_flagged") for h in res.histograms)


@pytest.fixture(scope="module")
def gsi():
    from readers import read_log
    from spooflens.gnss.solved_fixes import with_solved_fixes

    raw = read_log(GSI)
    return raw, with_solved_fixes(raw)


def test_real_gsi_pair_is_clean_at_defaults(gsi):
    _, table = gsi
    res = {r.name: r for r in detect(table)}
    for name in (COLLAPSE, PR_COLLAPSE, BASELINE_ERROR):
        assert res[name].ran, res[name].reason
        assert not res[name].alarms, name
    facts = res[BASELINE_ERROR].extras["0759-3040"]
    assert facts["baseline_source"].startswith("surveyed")
    assert facts["baseline_m"] == pytest.approx(3335.4, abs=0.1)
    assert facts["rice_sigma"] < 1.0  # the baseline is known to well under a metre
    t, sd, n = pseudorange_differences(
        table.observations, table.fixes_of("3040"), "0759", "3040", DualReceiverOptions()
    )
    assert len(t) == 120 and n.min() >= 6
    assert 1000.0 < np.median(sd) < 2000.0  # the spread of e_i . b over a 3.3 km baseline


def test_real_gsi_pair_with_the_single_antenna_spoofer_of_eq_7g(gsi):
    raw, _ = gsi
    spoofed = single_antenna_observations(raw, "0759", "3040", start_s=1800.0, noise_m=0.2, seed=1)
    res = {r.name: r for r in detect(spoofed)}
    for name in (COLLAPSE, PR_COLLAPSE, BASELINE_ERROR):
        assert res[name].alarms, name
        first = min(a.start_s for a in res[name].alarms)
        assert 1800.0 <= first <= 1800.0 + 6 * 30.0, (name, first)
    facts = res[PR_COLLAPSE].extras["0759-3040"]
    assert facts["sigma_s_rayleigh"] < 0.5  # the receivers' own noise (0.2 m) is all that is left
    t, sd, _ = pseudorange_differences(
        spoofed.observations, spoofed.fixes_of("3040"), "0759", "3040", DualReceiverOptions()
    )
    assert np.median(sd[t >= 1800.0]) == pytest.approx(0.2, rel=0.3)


def test_recording_draws_the_histograms_as_bar_charts(gsi, tmp_path):
    from rerun.chunk import RrdReader

    from spooflens.output.recording import entity, histogram_origin, histogram_views, write_recording

    raw, _ = gsi
    spoofed = single_antenna_observations(raw, "0759", "3040", start_s=1800.0, seed=2)
    results = detect(spoofed)
    out = tmp_path / "pair.rrd"
    write_recording(out, spoofed, results)
    static = {c.entity_path for c in RrdReader(str(out)).store().stream() if c.is_static}
    collapse = next(r for r in results if r.name == COLLAPSE)
    names = {h.name for h in collapse.histograms}
    assert names == {"0759-3040/baseline_distance_clean", "0759-3040/baseline_distance_flagged"}
    for h in collapse.histograms:
        for bars in h.bars:  # data and fitted densities, each a bar chart of its own
            assert "/" + entity(histogram_origin(COLLAPSE, h), bars.label) in static
        assert sum(b.counts.sum() for b in h.bars if not b.fitted) > 0
    assert any(title.startswith(COLLAPSE) for title, _ in histogram_views(results))


def test_a_collapse_from_the_first_fix_is_seen_only_against_the_clean_logs_model():
    """Two receivers 1.2 m apart, each with its own noise; a single-antenna spoofer from the first fix
    leaves only their tracking noise between them: the log's own fit takes that for clean, the model of
    the vehicle's clean logs does not."""
    from baseline_support import quantity

    from spooflens.baseline.format import RicePair
    from spooflens.detectors.dual_receiver import DualReceiverOptions, collapse_rule

    rng = np.random.default_rng(3)
    t = np.arange(0.0, 300.0, 0.2)

    def distance(nu: float, sigma: float) -> np.ndarray:
        return np.hypot(nu + rng.normal(0.0, sigma, len(t)), rng.normal(0.0, sigma, len(t)))

    opts = DualReceiverOptions()
    collapsed = distance(0.0, 0.3)
    assert not collapse_rule(t, collapsed, opts).episodes
    prior = RicePair(quantity([1.2, 1.25]), quantity([0.35, 0.4]), quantity([0.6, 0.5]), 50)
    caught = collapse_rule(t, collapsed, opts, prior=prior)
    assert caught.flagged.mean() > 0.9
    assert not collapse_rule(t, distance(1.2, 0.35), opts, prior=prior).episodes


def test_a_short_stretch_of_two_receivers_wandering_closer_is_no_collapse():
    """A boat's two NMEA 2000 GNSS sources (canboat's Furuno figure-8 capture) 1 to 13 m apart, their errors
    wandering for tens of seconds. Cut to 153.6-303.6 s, the window grew to 80 s, two thirds of the stretch,
    where the fit had fewer than three windows of clean samples, and their natural approach at 234-249 s was
    a collapse (SPOOFING, medium): the window now grows only while the stretch holds three of it. Cut to
    40.3-130.3 s, they came from 13 m to 4 m apart in its last 20 s: on less than 300 s of clean distance the
    floor is not known, and such a collapse is shown, not counted. The whole capture (357 s) raises nothing."""
    log = read_log(REAL / "corpus/canboat/furuno-130842-figure8-fast.raw")
    (cut,) = [r for r in detect(log.between(153.6, 303.6)) if r.name == COLLAPSE]
    assert cut.ran and cut.alarms == []
    (short,) = [r for r in detect(log.between(40.3, 130.3)) if r.name == COLLAPSE]
    assert short.alarms and short.advisory and "wander over minutes" in short.reason
    (whole,) = [r for r in detect(log) if r.name == COLLAPSE]
    assert whole.ran and whole.alarms == [] and not whole.advisory
