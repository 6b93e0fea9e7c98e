"""From clean logs' measurements to a baseline: levels, spreads, agreement, one receiver model."""

from __future__ import annotations

import numpy as np
import pytest
from baseline_support import measurement, px4_like

from spooflens.baseline.format import BaselineError, RefusedLog
from spooflens.baseline.indicators import INDICATORS
from spooflens.baseline.learn import aggregate, between_spread
from spooflens.baseline.use import ALLOWANCE, cap, level_scale


def test_levels_and_spreads() -> None:
    ms = [measurement(k, {"noise_per_ms": (v, 3.0)}) for k, v in enumerate((90.0, 95.0, 100.0, 96.0))]
    q = aggregate(ms).indicator("gps", "noise_per_ms")
    assert q is not None
    assert q.centre == pytest.approx(95.5) and q.within == pytest.approx(3.0)
    assert q.between == pytest.approx(1.4826 * np.median(np.abs(np.array([90, 95, 100, 96]) - 95.5)))
    assert q.agree is True and q.n_logs == 4
    assert between_spread([1.0]) is None and between_spread([1.0, 2.128]) == pytest.approx(1.0)


def test_logs_that_disagree_are_said_per_quantity() -> None:
    """One drone's jamming indicator reads 40, another's 250 (flight_review issue 200)."""
    ms = [
        measurement(0, {"jamming_indicator": (40.0, 4.0), "cn0_mean_dbhz": (42.0, 0.6)}),
        measurement(1, {"jamming_indicator": (250.0, 10.0), "cn0_mean_dbhz": (42.3, 0.6)}),
    ]
    b = aggregate(ms)
    jam, cn0 = b.indicator("gps", "jamming_indicator"), b.indicator("gps", "cn0_mean_dbhz")
    assert jam is not None and jam.agree is False
    assert cn0 is not None and cn0.agree is True
    one = aggregate(ms[:1]).indicator("gps", "jamming_indicator")
    assert one is not None and one.agree is None and one.between is None


def test_a_baseline_is_of_one_receiver_model() -> None:
    ms = [
        measurement(0, {"hdop": (0.8, 0.05)}, model="u-blox ZED-F9P"),
        measurement(1, {"hdop": (0.8, 0.05)}, model="NEO-M8N"),
    ]
    with pytest.raises(BaselineError, match=r"clean1.ulg: receiver gps is a NEO-M8N, in clean0.ulg a u-blox ZED-F9P"):
        aggregate(ms)
    same = [measurement(0, {"hdop": (0.8, 0.05)}, model="ZED-F9P"), measurement(1, {"hdop": (0.8, 0.05)}, model=None)]
    assert aggregate(same).receivers["gps"].model == "ZED-F9P"


def test_no_clean_log_is_no_baseline() -> None:
    with pytest.raises(BaselineError, match=r"no clean log to learn a baseline from \(a.ulg: a spoofing incident\)"):
        aggregate([], [RefusedLog("a.ulg", "a spoofing incident")])


def test_the_level_scale_shrinks_with_more_agreeing_logs_but_never_below_the_resolution() -> None:
    spec = INDICATORS["cn0_mean_dbhz"]
    scales = []
    for n in (1, 2, 4, 8):
        q = aggregate([measurement(k, {"cn0_mean_dbhz": (42.0 + 0.3 * (-1) ** k, 0.6)}) for k in range(n)]).indicator(
            "gps", "cn0_mean_dbhz"
        )
        assert q is not None
        scales.append(level_scale(q, spec))
    assert scales[0] == spec.prior(42.0) == scales[1]  # one or two logs: the prior
    assert scales[3] < scales[2] and scales[3] >= spec.resolution(42.0)


def test_a_log_may_learn_at_most_twice_the_noisiest_clean_log() -> None:
    b = px4_like()
    assert b.navigation is not None
    q = b.navigation.parameters["b_h"]
    assert cap(q) == pytest.approx(ALLOWANCE * max(q.values)) and cap(None) == np.inf


def test_a_wanders_driving_noise_is_capped_as_its_size() -> None:
    from spooflens.baseline.format import Quantity
    from spooflens.baseline.use import rate_cap

    sigma = Quantity(0.04, "m/s", (0.05, 0.03), None, 0.02, True)
    tau = Quantity(12.0, "s", (17.0, 6.0), None, 10.0, True)
    assert rate_cap(sigma, tau) == pytest.approx(ALLOWANCE**2 * max(0.05**2 / 17.0, 0.03**2 / 6.0))
    one = Quantity(0.05, "m/s", (0.05,), None, None, None)
    assert rate_cap(one, tau) == np.inf and rate_cap(sigma, None) == np.inf
