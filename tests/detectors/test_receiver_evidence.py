"""receiver_evidence against a vehicle's baseline: a log whose indicators sit off the vehicle's clean
levels from its first fix to its last shows there, where against its own median it cannot."""

from __future__ import annotations

import numpy as np
import pandas as pd
from baseline_support import px4_like, receiver_fixes

from spooflens.detectors.receiver_evidence import run_receiver_evidence, run_receiver_levels
from spooflens.pipeline.evidence import Evidence, confidence
from spooflens.schema import make_frame


def test_a_log_attacked_throughout_is_flagged_only_against_the_baseline() -> None:
    """Issue 42: real PX4 logs recorded whole under attack read twice their clean noise level and a tenth
    of their jamming indicator."""
    attacked = receiver_fixes(noise=190.0, jamming=4.0)
    assert not run_receiver_evidence(attacked).alarms
    assert not run_receiver_evidence(attacked, baseline=px4_like()).alarms  # against itself: nothing changed
    with_baseline = run_receiver_levels(attacked, px4_like())
    assert with_baseline.evidence == Evidence.VEHICLE_BASELINE
    (alarm,) = with_baseline.alarms
    assert alarm.start_s < 15.0 and alarm.end_s > 590.0
    finding = next(f.text for f in with_baseline.findings if "off the vehicle's baseline" in f.text)
    assert "noise level" in finding and "jamming indicator" in finding


def test_a_clean_log_of_the_vehicle_stays_clean_against_its_baseline() -> None:
    for seed in range(3):
        clean = receiver_fixes(noise=96.0, jamming=38.0, cn0=42.4, seed=seed)
        assert not run_receiver_evidence(clean, baseline=px4_like()).alarms
        result = run_receiver_levels(clean, px4_like())
        assert not result.alarms, result.findings
        assert "levels against the baseline" in result.reason


def test_one_family_off_is_no_alarm() -> None:
    """More noise alone (the vehicle's own electronics, a jammer's power) is one family: no level alarm."""
    assert not run_receiver_levels(receiver_fixes(noise=190.0, jamming=40.0), px4_like()).alarms


def test_levels_its_logs_disagree_on_are_not_yardsticks() -> None:
    from baseline_support import measurement

    from spooflens.baseline.learn import aggregate

    split = aggregate(
        [
            measurement(0, {"noise_per_ms": (95.0, 3.0), "jamming_indicator": (40.0, 4.0)}),
            measurement(1, {"noise_per_ms": (96.0, 3.0), "jamming_indicator": (250.0, 8.0)}),
        ]
    )
    result = run_receiver_levels(receiver_fixes(noise=190.0, jamming=4.0), split)
    assert not result.alarms
    assert "not against it where its logs disagree (jamming indicator)" in result.reason


def test_a_whole_log_off_its_baseline_is_an_anomaly_apart() -> None:
    """It lasts as long as the log: merged with the events in it, it would join them all into one incident
    and seem to corroborate any GNSS-only glitch anywhere in it."""
    from spooflens.detectors.base import Alarm, DetectorResult
    from spooflens.pipeline.verdict import decide

    vb = Evidence.VEHICLE_BASELINE
    assert confidence({vb}) == "low" and confidence({vb, Evidence.GNSS_ONLY}) == "low"
    levels = DetectorResult("receiver_levels", True, alarms=[Alarm(0.0, 600.0, 9.0, 5.0)], evidence=vb)
    glitch = DetectorResult(
        "gnss_consistency", True, alarms=[Alarm(300.0, 302.0, 40.0, 301.0)], evidence=Evidence.GNSS_ONLY
    )
    jump = DetectorResult(
        "receiver_evidence", True, alarms=[Alarm(300.5, 303.0, 9.0, 301.0)], evidence=Evidence.RECEIVER
    )
    verdict = decide([levels, glitch, jump])
    assert [(i.start_s, i.evidence, i.confidence) for i in verdict.incidents] == [
        (0.0, (vb,), "low"),
        (300.0, (Evidence.GNSS_ONLY, Evidence.RECEIVER), "medium"),
    ]


def _accuracies_worse(satellites_lost: bool) -> pd.DataFrame:
    """1 Hz fixes for 300 s whose three reported accuracies triple from 150 s to 180 s (one fix gone bad),
    their satellites used falling from 14 to 4 there too when asked."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 300.0, 1.0)
    bad = (t >= 150.0) & (t < 180.0)
    noise = lambda scale: scale * rng.standard_normal(len(t))  # noqa: E731
    return make_frame(
        "fixes",
        {
            "t_s": t,
            "receiver_id": np.full(len(t), "gps"),
            "lat_deg": np.full(len(t), 47.0),
            "lon_deg": np.full(len(t), 8.0),
            "height_m": np.full(len(t), 500.0),
            "h_acc_m": np.where(bad, 4.5, 1.5) + noise(0.05),
            "v_acc_m": np.where(bad, 7.5, 2.5) + noise(0.08),
            "vel_acc_mps": np.where(bad, 1.2, 0.4) + noise(0.01),
            "sats_used": np.where(bad & satellites_lost, 4.0, 14.0) + rng.integers(-1, 2, len(t)),
            "fix_type": np.full(len(t), 3),
        },
    )


def test_three_accuracies_of_one_fix_are_one_witness() -> None:
    """A receiver's horizontal, vertical and speed accuracies are read off one covariance: a fix gone bad
    moves all three, which the two agreeing indicators the test asks for must not count three times (the
    clean husky bag's accuracies alone made an alarm). With the satellites lost beside them, two agree."""
    assert not run_receiver_evidence(_accuracies_worse(satellites_lost=False)).alarms
    (alarm,) = run_receiver_evidence(_accuracies_worse(satellites_lost=True)).alarms
    assert 150.0 <= alarm.start_s <= 152.0


def test_too_few_fixes_are_said_to_be_too_few_not_a_receiver_without_indicators() -> None:
    """An 8-fix excerpt of a phone's NMEA (satellites, HDOP, C/N0 all logged) was said to log no quality
    indicators at all."""
    short = run_receiver_evidence(receiver_fixes(100.0, 60.0, seconds=1.6))
    assert not short.ran
    assert short.reason == "needs 10 fixes of a receiver for its indicators' own baseline (8 found)"


def test_a_log_half_spoofed_dates_its_onset_after_the_last_real_fix_not_at_its_start() -> None:
    """A real receiver in Rome (AlexT2594/ml-gps-spoofing-gps-data-analysis, `true_with_spoof`): five fixes of
    the real sky, 21 s without a fix, then a GPS simulator's signals stronger than any sky. The simulator is
    half the log, so against the log's own median the real fixes are off too and none is quiet: the onset
    fell back to the log's first fix (0 s), dating the attack to before the real sky was lost."""
    t = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 25.0, 26.0, 27.0, 28.0, 29.0, 30.0])
    cn0 = [26.9, 26.9, 26.45, 26.64, 26.55, 50.56, 50.56, 50.44, 50.33, 50.33, 50.33]
    fixes = make_frame(
        "fixes",
        {
            "t_s": t,
            "receiver_id": np.full(len(t), "GP"),
            "lat_deg": np.r_[np.full(5, 41.9300), np.full(6, 41.9304)],
            "lon_deg": np.full(len(t), 12.61),
            "height_m": np.r_[np.full(5, 67.0), np.zeros(6)],
            "sats_used": np.array([8, 8, 8, 9, 8, 5, 5, 5, 5, 5, 5], dtype=float),
            "hdop": np.r_[np.full(5, 1.5), np.full(6, 1.6)],
            "cn0_mean_dbhz": np.array(cn0),
            "fix_type": np.full(len(t), 3),
        },
    )
    (alarm,) = run_receiver_evidence(fixes).alarms
    assert alarm.start_s == 25.0
    assert alarm.onset_s == 4.0
