"""The seed 001 and 002 benchmark machinery on a run or two (the figures come from `spooflens bench`)."""

from __future__ import annotations

import numpy as np
import pytest

from spooflens.bench import pr_change_bench as b2
from spooflens.bench import range_rate_bench as b1
from spooflens.geodesy import ecef_to_enu_vectors


def test_fake_trajectories_follow_table_3() -> None:
    t = np.arange(0.0, 1751.0)
    lat, lon = np.full_like(t, 34.0), np.full_like(t, 108.0)
    p = np.tile([-1.0e6, 5.0e6, 3.5e6], (len(t), 1)) + t[:, None] * [1.0, 2.0, 0.0]
    v = np.tile([1.0, 2.0, 0.0], (len(t), 1))
    on, pf, vf = b1.fake_trajectory("2 hover", t, p, v, lat, lon)
    assert on.sum() == 26 and (pf[on] == p[25]).all() and (vf[on] == 0).all() and (pf[~on] == p[~on]).all()
    on, pf, vf = b1.fake_trajectory("3 velocity pull", t, p, v, lat, lon)
    d = ecef_to_enu_vectors(lat[on], lon[on], vf[on] - v[on])
    np.testing.assert_allclose(d, np.tile([0.0, 0.1, 0.0], (on.sum(), 1)), atol=1e-12)
    for scheme, at_1510 in (("4 position step", 100.0), ("4 position ramp", 20.0)):
        on, pf, _ = b1.fake_trajectory(scheme, t, p, v, lat, lon)
        k = 1510
        np.testing.assert_allclose(ecef_to_enu_vectors(lat[k], lon[k], pf[k] - p[k]), [at_1510, 0.0, 0.0], atol=1e-9)


def test_paper_scenario_free_ins_drifts_and_the_windowed_one_does_not() -> None:
    from readers.rinex import read_rinex_nav

    if not b1.NAV.exists():
        pytest.skip("real navigation file not available")
    eph = read_rinex_nav(b1.NAV)
    opts = b1.BenchOptions(duration_s=400.0, count_from_s=250.0)
    run = b1.trajectory_statistics(b1.paper_profile(400.0), float(eph.toe_s.min()) + 3 * 3600, eph, 1000, opts)
    ev = b1.evaluate(run, opts)
    assert ev["denominator"] == 150
    free, windowed = ev["seed001_n1"], ev[f"seed001_n1{b1.WINDOWED}"]
    # the hover is seen on east at its first epoch, by both references
    assert free["rate"]["detect_delay"]["2 hover"] == 0.0 == windowed["rate"]["detect_delay"]["2 hover"]
    # the free INS drifts away from its first-200-s thresholds; restarted every 5 s it does not
    assert sum(free["rate"]["false_alarms"]) > 10 * max(sum(windowed["rate"]["false_alarms"]), 1)
    assert max(windowed["ins_velocity_error_200s"][:2]) < 0.01 < max(free["ins_velocity_error_200s"][:2])


def test_seed002_bench_on_a_short_station() -> None:
    if not b2.NAV.exists():
        pytest.skip("real navigation file not available")
    opts = b2.BenchOptions(runs=1, epochs=300, window=(100, 200))
    res = b2.simulated_station(opts)
    s = b2.summarise(res)
    for form in ("step", "gradual"):
        for name in ("kalman", "rnn"):
            m = s[form]["median"][name]
            assert m["false_alarm_epochs"] == 0
            assert m["improvement_mean"][0.0] == 0.0
    step = s["step"]["median"]["kalman"]
    assert step["detected"] == 1.0 and step["median_delay_epochs"] == 0 and step["named_right"] == 1.0
    assert step["improvement_mean"][1.0] > 0.5  # the step is removed; the slow follow-on drift is not
