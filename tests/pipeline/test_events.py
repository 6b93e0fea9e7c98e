"""The kind of every event: built from detector results made here (the interference detector's among them)
on a synthetic vehicle and on a real log's degraded sky."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import pytest
from paths import real_log
from pipeline_support import circling_table

from spooflens.detectors.base import Alarm, DetectorResult
from spooflens.epoch_table import EpochTable
from spooflens.output.summary import build_summary
from spooflens.pipeline.events import SEQUENCE_S, classify
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.verdict import Kind, Verdict, decide
from spooflens.service import read_table


@dataclass(frozen=True)
class BandAlarm(Alarm):
    """An alarm that names the systems and bands it hit, as the interference detector's do."""

    systems: tuple[str, ...] = ()
    bands: tuple[str, ...] = ()


def result(name: str, evidence: Evidence, *alarms: Alarm) -> DetectorResult:
    return DetectorResult(name, True, alarms=list(alarms), evidence=evidence)


@cache
def circling() -> EpochTable:
    return circling_table()


def verdict_of(table: EpochTable, results: list[DetectorResult]) -> Verdict:
    return classify(table, results, decide(results, log_end_s=float(table.fixes["t_s"].max())))


def jamming(start: float, end: float) -> DetectorResult:
    return result(
        "interference",
        Evidence.INTERFERENCE,
        BandAlarm(start, end, 20.0, start + 1, start, receiver_id="/gps/fix", systems=("GPS",), bands=("L1",)),
    )


def takeover(start: float) -> list[DetectorResult]:
    return [
        result(
            "gnss_consistency",
            Evidence.GNSS_ONLY,
            Alarm(start, start + 60, 50.0, start + 1, start - 1, receiver_id="/gps/fix"),
        ),
        result("kf_innovation", Evidence.INERTIAL, Alarm(start + 1, start + 60, 90.0, start + 2, start - 1)),
    ]


def quiet(name: str, evidence: Evidence) -> DetectorResult:
    return result(name, evidence)


def test_interference_alone_is_jamming_and_no_spoofing() -> None:
    verdict = verdict_of(circling(), [jamming(100.0, 130.0), quiet("gnss_consistency", Evidence.GNSS_ONLY)])
    assert not verdict.spoofed
    (event,) = verdict.events
    assert event.kind == Kind.JAMMING and event.systems == ("GPS",) and event.bands == ("L1",)
    assert verdict.headline.startswith("NO SPOOFING DETECTED by 1 detector(s)")
    assert "JAMMING / INTERFERENCE from 100.00 s to 130.00 s" in verdict.headline


def test_interference_is_no_spoofing_detector_yet_its_event_is_named() -> None:
    # the interference detector alone says what disturbed the signals, not whether they were spoofed
    verdict = verdict_of(circling(), [jamming(100.0, 130.0)])
    assert verdict.headline.startswith("NO VERDICT: no spoofing detector could run")
    assert "JAMMING / INTERFERENCE from 100.00 s to 130.00 s" in verdict.headline


def test_a_takeover_after_jamming_is_one_attack_sequence() -> None:
    verdict = verdict_of(circling(), [jamming(100.0, 130.0), *takeover(140.0)])
    assert verdict.spoofed
    jam, spoof = verdict.events
    assert (jam.kind, spoof.kind) == (Kind.JAMMING, Kind.SPOOFING)
    assert jam.followed_by == 1 and spoof.follows == 0
    assert verdict.headline.startswith("SPOOFING DETECTED")
    assert verdict.headline.endswith("after JAMMING / INTERFERENCE from 100.00 s to 130.00 s")
    summary = build_summary(circling(), [jamming(100.0, 130.0), *takeover(140.0)], verdict)
    events = summary["verdict"]["events"]
    assert events[0]["sequence"] == {"id": 1, "follows": None, "followed_by": 1}
    assert events[1]["sequence"] == {"id": 1, "follows": 0, "followed_by": None}
    assert events[0]["bands"] == ["L1"] and events[0]["systems"] == ["GPS"]


def test_jamming_long_before_a_takeover_is_not_linked_to_it() -> None:
    verdict = verdict_of(circling(), [jamming(20.0, 40.0), *takeover(40.0 + SEQUENCE_S + 20.0)])
    jam, spoof = verdict.events
    assert jam.followed_by is None and spoof.follows is None


def test_interference_that_runs_into_a_takeover_stays_an_incident_of_its_own() -> None:
    # the jammer is still on at the takeover's first alarm (jam then spoof): two incidents, one sequence
    verdict = verdict_of(circling(), [jamming(120.0, 142.0), *takeover(140.0)])
    jam_incident, spoof_incident = verdict.incidents
    assert not jam_incident.is_spoofing and spoof_incident.is_spoofing
    jam, spoof = verdict.events
    assert jam.kind == Kind.JAMMING and (jam.start_s, jam.end_s) == (120.0, 142.0)
    assert spoof.kind == Kind.SPOOFING and jam.followed_by == 1 and spoof.follows == 0
    # the takeover's onset and first alarm are its own evidence's, not the interference's: the GNSS-only
    # alarm that began under the jamming is accounted for by it while it lasts and the receiver recovers (to
    # 142 s, +60 s: all of it), so the first
    # alarm no cause accounts for is the inertial one at 141 s, and the onset its estimate (140 s)
    assert spoof.start_s == 141.0 and spoof.onset_s == 140.0 and spoof_incident.onset_s == 140.0
    assert (Evidence.GNSS_ONLY, 140.0, 200.0) in spoof_incident.explained_spans


@cache
def navisys() -> EpochTable:
    return read_table(real_log("corpus/gpsd/navisys-gr8013.log"), {}, False)


def test_degradation_explains_the_gnss_internal_classes_not_an_inertial_departure() -> None:
    # the real receiver's sky fell at 17 s (C/N0 12 dB down, satellites lost): it explains the GNSS-only and
    # receiver alarms there, not an inertial departure confirmed at the same time
    gnss = result("gnss_consistency", Evidence.GNSS_ONLY, Alarm(21.0, 34.0, 40.0, 22.0, 17.0, receiver_id="ubx"))
    receiver = result("receiver_evidence", Evidence.RECEIVER, Alarm(21.0, 34.0, 9.0, 22.0, 20.0, receiver_id="ubx"))
    alone = verdict_of(navisys(), [gnss, receiver])
    assert not alone.spoofed and alone.incidents[0].kind == Kind.DEGRADATION
    inertial = result("kf_innovation", Evidence.INERTIAL, Alarm(22.0, 34.0, 300.0, 23.0, 21.0))
    verdict = verdict_of(navisys(), [gnss, receiver, inertial])
    (incident,) = verdict.incidents
    assert verdict.spoofed and incident.kind == Kind.SPOOFING and incident.confidence == "medium"
    assert incident.unexplained == (Evidence.INERTIAL,)
    (event,) = verdict.events
    assert event.evidence_for == ("inertial reference (kf_innovation)",)
    assert any("does not account for inertial reference" in a for a in event.evidence_against)


def test_an_anomaly_nothing_explains_is_unknown() -> None:
    gnss = result(
        "gnss_consistency", Evidence.GNSS_ONLY, Alarm(150.0, 155.0, 40.0, 151.0, 149.0, receiver_id="/gps/fix")
    )
    verdict = verdict_of(circling(), [gnss])
    (event,) = verdict.events
    assert event.kind == Kind.UNKNOWN and event.confidence == "low"
    assert verdict.headline.endswith("1 anomaly(ies) of one evidence class noted, not confirmed")


@pytest.mark.parametrize("kind", list(Kind))
def test_every_kind_has_a_label(kind: Kind) -> None:
    from spooflens.pipeline.verdict import KIND_LABELS

    assert KIND_LABELS[kind]


def test_an_alarm_that_began_before_the_interference_is_not_the_jammings() -> None:
    # a receiver's fixes disagreeing with their velocities from 60 s to 200 s, jammed from 100 s to 130 s:
    # the jammer cannot have caused what began 40 s before it; the alarm stays an anomaly of its own, and
    # the jamming event is the jammer's 30 s, not "jamming from 60 s to 200 s"
    noisy = result("gnss_consistency", Evidence.GNSS_ONLY, Alarm(60.0, 200.0, 9.0, 61.0, 60.0, receiver_id="/gps/fix"))
    verdict = verdict_of(circling(), [jamming(100.0, 130.0), noisy])
    anomaly, jam = verdict.events
    assert (anomaly.kind, anomaly.start_s, anomaly.end_s) == (Kind.UNKNOWN, 60.0, 200.0)
    assert (jam.kind, jam.start_s, jam.end_s) == (Kind.JAMMING, 100.0, 130.0)
    explanation = next(i for i in verdict.incidents if i.kind == Kind.UNKNOWN)
    assert not any(e.cause == "interference" for e in explanation.explanations)
    assert "JAMMING / INTERFERENCE from 100.00 s to 130.00 s" in verdict.headline
    # an alarm that began with the jamming is still the jamming's
    with_it = result(
        "gnss_consistency", Evidence.GNSS_ONLY, Alarm(97.0, 135.0, 9.0, 98.0, 97.0, receiver_id="/gps/fix")
    )
    (event,) = verdict_of(circling(), [jamming(100.0, 130.0), with_it]).events
    assert event.kind == Kind.JAMMING
