"""A jammed receiver's noisier fixes against the INS: inertial (and GNSS-internal) alarms under interference
whose GNSS-minus-INS departure stays within the receiver's own error grown by its C/N0 loss are the
jamming's; a departure beyond it (a takeover inside one alarm) counts from there; an accuracy the receiver
claims inflated, without the C/N0 loss, accounts for nothing. Built from detector results made here."""

from __future__ import annotations

import copy
from dataclasses import replace
from functools import cache

import numpy as np
from numpy.typing import NDArray
from pipeline_support import circling_table

from spooflens.detectors.base import Alarm, DetectorResult, Series
from spooflens.epoch_table import EpochTable
from spooflens.output.summary import build_summary
from spooflens.pipeline.events import classify
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.explanations import JAMMED
from spooflens.pipeline.verdict import Kind, Verdict, decide

RX = "/gps/fix"
JAM = (100.0, 130.0)
ENU = ("east", "north", "up")


def result(name: str, evidence: Evidence, *alarms: Alarm) -> DetectorResult:
    return DetectorResult(name, True, alarms=list(alarms), evidence=evidence)


def jamming(start: float, end: float) -> DetectorResult:
    return result("interference", Evidence.INTERFERENCE, Alarm(start, end, 20.0, start + 1, start, receiver_id=RX))


def verdict_of(table: EpochTable, results: list[DetectorResult]) -> Verdict:
    return classify(table, results, decide(results, log_end_s=float(table.fixes["t_s"].max())))


@cache
def jammed_table(cn0_drop_db: float = 15.0, claimed_x: float = 5.6) -> EpochTable:
    """The circling vehicle with its receiver jammed over JAM: mean C/N0 down, reported accuracies up."""
    table = copy.copy(circling_table())
    fx = table.fixes.copy()
    t = fx["t_s"].to_numpy(float)
    on = (t >= JAM[0]) & (t <= JAM[1])
    fx["cn0_mean_dbhz"] = np.where(on, 40.0 - cn0_drop_db, 40.0)
    fx["h_acc_m"] = np.where(on, 2.5 * claimed_x, 2.5)
    fx["vel_acc_mps"] = np.where(on, 0.1 * claimed_x, 0.1)
    table.fixes = fx
    return table


def navigation(
    table: EpochTable, takeover_s: float | None = None, drag_mps: float = 3.0, jam_noise: float = 1.0
) -> DetectorResult:
    """The GNSS/INS filter's innovations: clean noise, the jammed receiver's larger noise over JAM (x4 in
    velocity), and from `takeover_s` a spoofer's drag (velocity `drag_mps` east, its position growing)."""
    rng = np.random.default_rng(3)
    t = table.fixes["t_s"].to_numpy(float)
    on = ((t >= JAM[0]) & (t <= JAM[1]))[:, None]
    pos = rng.normal(0.0, 1.0, (len(t), 3)) * np.where(on, jam_noise, 0.5)
    vel = rng.normal(0.0, 1.0, (len(t), 3)) * np.where(on, 0.2 * jam_noise, 0.05)
    if takeover_s is not None:
        after = np.clip(t - takeover_s, 0.0, None)
        pos[:, 0] += np.where(t >= takeover_s, 5.0 + drag_mps * after, 0.0)
        vel[:, 0] += np.where(t >= takeover_s, drag_mps, 0.0)

    def sigma(x: float) -> NDArray[np.float64]:
        return np.full((len(t), 3), x)

    return DetectorResult(
        "navigation",
        True,
        series=[
            Series("innovation_position", t, pos, "m", components=ENU),
            Series("innovation_position_sigma", t, sigma(0.5), "m", components=ENU),
            Series("innovation_velocity", t, vel, "m/s", components=ENU),
            Series("innovation_velocity_sigma", t, sigma(0.05), "m/s", components=ENU),
        ],
        extras={"receiver_id": RX},
    )


def alarms(inertial: tuple[float, float] = (101.0, 129.0)) -> list[DetectorResult]:
    return [
        jamming(*JAM),
        result("gnss_consistency", Evidence.GNSS_ONLY, Alarm(105.0, 125.0, 40.0, 106.0, 104.0, receiver_id=RX)),
        result("receiver_evidence", Evidence.RECEIVER, Alarm(100.5, 129.5, 9.0, 101.0, 100.0, receiver_id=RX)),
        result("velocity_innovation", Evidence.INERTIAL, Alarm(*inertial, 90.0, inertial[0] + 1.0)),
    ]


def test_a_jammed_receivers_bounded_noise_is_jamming_not_spoofing() -> None:
    table = jammed_table()
    verdict = verdict_of(table, [*alarms(), navigation(table)])
    assert not verdict.spoofed
    spoofing_like = [i for i in verdict.incidents if Evidence.INERTIAL in i.evidence]
    (incident,) = spoofing_like
    assert incident.kind == Kind.JAMMING and incident.confidence_of_alarms == "high"
    assert (Evidence.INERTIAL, 101.0, 129.0) in incident.explained_spans
    (jammed,) = [e for e in incident.explanations if e.cause == JAMMED]
    assert jammed.detectors == ("velocity_innovation",)
    assert "mean C/N0 down 15.0 dB" in " ".join(jammed.facts)
    assert {e.kind for e in verdict.events} == {Kind.JAMMING}


def test_without_the_filters_innovations_an_inertial_alarm_stays_unexplained() -> None:
    verdict = verdict_of(jammed_table(), alarms())
    assert verdict.spoofed  # nothing says how far GNSS went from the INS: the inertial alarm keeps its weight


def test_a_takeover_inside_the_alarm_counts_from_the_takeover() -> None:
    table = jammed_table()
    verdict = verdict_of(table, [*alarms((101.0, 160.0)), navigation(table, takeover_s=120.0)])
    assert verdict.spoofed
    (incident,) = [i for i in verdict.incidents if i.is_spoofing]
    until = dict(incident.partly_explained)[(Evidence.INERTIAL, 101.0, 160.0)]
    assert 118.0 <= until < 120.0
    spoof = next(e for e in verdict.events if e.kind == Kind.SPOOFING)
    assert 118.0 <= spoof.start_s <= 120.0 and incident.start_s == spoof.start_s
    jam = verdict.events[spoof.follows] if spoof.follows is not None else None
    assert jam is not None and jam.kind == Kind.JAMMING and jam.start_s == JAM[0]
    assert verdict.headline.startswith("SPOOFING DETECTED") and "after JAMMING / INTERFERENCE" in verdict.headline
    summary = build_summary(table, [*alarms((101.0, 160.0)), navigation(table, takeover_s=120.0)], verdict)
    (spoofing,) = [i for i in summary["verdict"]["incidents"] if i["spoofing"]]
    (part,) = [p for p in spoofing["partly_explained"] if p["start_s"] == 101.0]
    assert part["evidence"] == "inertial" and part["explained_until_s"] == until


def test_a_claimed_accuracy_without_the_c_n0_loss_accounts_for_nothing() -> None:
    # a spoofer inflating the reported accuracy x10 while dragging 0.6 m/s, the sky's C/N0 not lowered
    table = jammed_table(cn0_drop_db=0.0, claimed_x=10.0)
    verdict = verdict_of(table, [*alarms(), navigation(table, takeover_s=101.0, drag_mps=0.6, jam_noise=0.25)])
    assert verdict.spoofed
    (incident,) = [i for i in verdict.incidents if i.is_spoofing]
    assert Evidence.INERTIAL in incident.unexplained
    assert not any(e.cause == JAMMED for e in incident.explanations)


def test_a_drag_under_the_jamming_beyond_its_noise_is_spoofing() -> None:
    # jammed (C/N0 -15 dB) and dragged at 3 m/s from the jamming's start: beyond what the C/N0 loss allows
    table = jammed_table()
    verdict = verdict_of(table, [*alarms(), navigation(table, takeover_s=100.0)])
    assert verdict.spoofed
    (incident,) = [i for i in verdict.incidents if i.is_spoofing]
    assert Evidence.INERTIAL in incident.unexplained


def test_a_coasts_departure_under_the_jamming_is_its_noise() -> None:
    # the reconstruction stage's coast (GNSS weighed with its clean noise) confirmed a departure at 110 s:
    # its departure interval, with no alarm behind it, is accounted for with the jammed noise's alarms
    table = jammed_table()
    results = [*alarms(), navigation(table)]
    before = decide(results, log_end_s=float(table.fixes["t_s"].max()))
    inc = next(i for i in before.incidents if Evidence.INERTIAL in i.evidence)
    confirmed = inc.with_spans((*inc.spans, (Evidence.INERTIAL, 100.0, 299.0)))
    checks = ({"incident_onset_s": 100.0, "confirmed": True, "departure_s": 110.0},)
    incidents = tuple(confirmed if i is inc else i for i in before.incidents)
    verdict = classify(table, results, replace(before, incidents=incidents, coasting_checks=checks))
    assert not verdict.spoofed
