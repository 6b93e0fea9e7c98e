"""The seed-000 benchmark machinery on a couple of runs (the figures come from `spooflens bench mlrt`)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from python_kernels import python_kernels

from spooflens.bench import mlrt_bench as sb
from spooflens.detectors.innovation_tests import threshold


def test_kf_threshold_is_the_papers() -> None:
    assert threshold(1e-5, 3) == pytest.approx(25.9, abs=0.01)
    assert pytest.approx(25.9, abs=0.01) == sb.KF_THRESHOLD


def test_paper_scenario_detects_fast_ramps_and_counts_false_alarms(monkeypatch: pytest.MonkeyPatch) -> None:
    paper_two_filter = sb.paper_two_filter

    def paper_in_python(*args: Any, **kwargs: Any) -> Any:  # no analysis calls it (tests/support/python_kernels.py)
        with python_kernels():
            return paper_two_filter(*args, **kwargs)

    monkeypatch.setattr(sb, "paper_two_filter", paper_in_python)
    r = sb.paper_scenario(sb.BenchOptions(runs=2))
    for method in ("KF", "GLRT", "MLRT calibrated"):
        med, _, _, frac = sb.summarise(r["delays"][method]["en:5"])
        assert (
            frac == 1.0 and med is not None and 1.0 <= med <= 5.0
        )  # 1 Hz GNSS: nothing before the first spoofed epoch
        assert r["false_alarm_fraction"][method] == 0.0
    # the paper's "l > 0, no threshold" rule fires on clean data too (the FA rate it really has)
    assert r["false_alarm_fraction"]["MLRT (ramp, flat, l>0)"] == 1.0


def test_first_alarm_ignores_alarms_before_the_onset() -> None:
    t = np.arange(10.0)
    stat = np.array([9, 0, 0, 0, 0, 0, 9, 9, 0, 9], dtype=float)
    assert sb.first_alarm(t, stat, 5.0, 3.0) == 6.0
    assert sb.first_alarm(t, stat, 10.0, 3.0) is None
