"""One result per detector from the stretches the navigation ran on between an IMU's gaps."""

from __future__ import annotations

import numpy as np

from spooflens.detectors.base import Alarm, DetectorResult, Series, Track, Unmet
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.joined import NAVIGATED_SPANS, joined


def _stretch(t0: float, advisory: bool = False, whiteness: float = 0.1) -> DetectorResult:
    t = t0 + np.arange(5.0)
    return DetectorResult(
        "glrt",
        True,
        f"ran from {t0:g}",
        [Alarm(t0 + 1.0, t0 + 2.0, 30.0, t0 + 1.0)],
        [Series("glr", t, np.arange(5.0), "", 25.9)],
        tracks=[Track("ins_smoothed", t, np.full(5, 50.0), np.full(5, 8.0), np.zeros(5))],
        extras={"innovation_whiteness": whiteness, "receiver_id": "gps"},
        advisory=advisory,
        evidence=Evidence.INERTIAL,
        limitations=[Unmet("noise_learning", "GNSS with the IMU for 40 s", "noise learning reads 300 s", stops=False)],
    )


def test_stretches_join_end_to_end_with_a_nan_between_and_facts_said_per_stretch() -> None:
    (r,) = joined([((0.0, 4.0), [_stretch(0.0)]), ((10.0, 14.0), [_stretch(10.0, whiteness=0.2)])])
    assert r.ran and r.evidence == Evidence.INERTIAL and not r.advisory
    assert [a.start_s for a in r.alarms] == [1.0, 11.0]
    (s,) = r.series
    assert np.array_equal(s.t, [0, 1, 2, 3, 4, 7, 10, 11, 12, 13, 14]) and np.isnan(s.values[5])
    assert np.isfinite(np.delete(s.values, 5)).all() and s.threshold == 25.9
    (tr,) = r.tracks
    assert np.isnan(tr.lat_deg[5]) and len(tr.t) == 11
    assert r.extras["receiver_id"] == "gps" and "innovation_whiteness" not in r.extras
    assert r.extras[NAVIGATED_SPANS] == [
        {"from_s": 0.0, "to_s": 4.0, "innovation_whiteness": 0.1},
        {"from_s": 10.0, "to_s": 14.0, "innovation_whiteness": 0.2},
    ]
    assert r.reason == "on 0.0-4.0 s: ran from 0; on 10.0-14.0 s: ran from 10"
    assert [u.found for u in r.limitations] == [
        "0.0-4.0 s: GNSS with the IMU for 40 s",
        "10.0-14.0 s: GNSS with the IMU for 40 s",
    ]


def test_a_stretch_the_model_does_not_fit_keeps_its_alarms_out_while_another_counts() -> None:
    (r,) = joined([((0.0, 4.0), [_stretch(0.0, advisory=True)]), ((10.0, 14.0), [_stretch(10.0)])])
    assert not r.advisory and [a.start_s for a in r.alarms] == [11.0]
    assert "on 0.0-4.0 s: ran from 0 (its alarms left out: another stretch's count)" in r.reason
    (both,) = joined([((0.0, 4.0), [_stretch(0.0, advisory=True)]), ((10.0, 14.0), [_stretch(10.0, advisory=True)])])
    assert both.advisory and len(both.alarms) == 2


def test_a_detector_that_ran_on_no_stretch_says_why_on_each() -> None:
    skipped = [
        ((0.0, 4.0), [DetectorResult.skipped("glrt", "GNSS with the IMU for 15 s", Evidence.INERTIAL)]),
        ((10.0, 14.0), [DetectorResult.skipped("glrt", "GNSS with the IMU for 12 s", Evidence.INERTIAL)]),
    ]
    (r,) = joined(skipped)
    assert not r.ran
    assert (
        r.reason
        == "on 0.0-4.0 s: not run: GNSS with the IMU for 15 s; on 10.0-14.0 s: not run: GNSS with the IMU for 12 s"
    )
