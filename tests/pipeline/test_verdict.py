"""The onset interval of an incident: the union of what the detectors that alarmed at its start say."""

from __future__ import annotations

import pytest

from spooflens.detectors.base import Alarm, DetectorResult
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.verdict import decide


def _result(name: str, evidence: Evidence, *alarms: Alarm) -> DetectorResult:
    return DetectorResult(name, ran=True, alarms=list(alarms), evidence=evidence)


def test_a_capture_seen_by_the_receiver_first_widens_the_inertial_interval_to_its_alarm() -> None:
    receiver = _result("receiver_evidence", Evidence.RECEIVER, Alarm(200.0, 260.0, 9.0, 200.0))
    inertial = _result("mlrt_calibrated", Evidence.INERTIAL, Alarm(200.9, 260.0, 99.0, 201.0, 200.6, (200.4, 200.8)))
    incident = decide([receiver, inertial]).incidents[0]
    assert incident.is_spoofing
    assert incident.onset_s == pytest.approx(200.6)  # the estimate with a credible interval
    assert incident.onset_interval_s == pytest.approx((200.0, 200.8))


def test_one_detector_keeps_its_own_interval_and_a_later_alarm_does_not_stretch_it() -> None:
    inertial = _result("mlrt_calibrated", Evidence.INERTIAL, Alarm(50.5, 90.0, 99.0, 60.0, 50.2, (50.0, 50.4)))
    later = _result("gnss_consistency", Evidence.GNSS_ONLY, Alarm(75.0, 80.0, 30.0, 76.0, 74.0))
    incident = decide([inertial, later]).incidents[0]
    assert incident.onset_interval_s == pytest.approx((50.0, 50.4))


def test_an_incident_that_lasts_to_the_last_fix_is_ongoing_at_the_end_of_the_log() -> None:
    heading = _result(
        "heading_reference", Evidence.HEADING, Alarm(70.0, 147.6, 50.0, 71.0, 69.0), Alarm(20.0, 30.0, 9.0, 21.0, 19.0)
    )
    incidents = decide([heading], log_end_s=148.4).incidents
    assert [i.ongoing_at_end for i in incidents] == [False, True]
    assert incidents[1].end_method == "last alarm, at the end of the log"
    # without the log's end the verdict cannot tell
    assert not any(i.ongoing_at_end for i in decide([heading]).incidents)
