"""The kind of every event, the third step of the verdict (`spooflens.pipeline.run.assess`).

For each incident the natural explanations of its alarms are weighed (`spooflens.pipeline.explanations`);
the alarms they account for stay in the incident and count for nothing, so SPOOFING needs evidence no
natural cause covers, while evidence a cause does not reach (an inertial departure confirmed by coasting,
a second receiver, the log's clock) keeps its weight whatever the sky did (an inertial alarm yields only
to the vehicle's own shock, a tumble or an impact its IMU read just before the alarm began). Then each incident is:

- spoofing: still of medium or high confidence;
- jamming: interference evidence (the interference detector's class, the receiver's jamming state,
  jamming indicator, noise or AGC) and no spoofing;
- degradation or receiver fault: every evidence interval accounted for by natural causes, the kind of
  the first of them that names one;
- unknown: an anomaly nothing explains (one evidence class, never spoofing).

Interference alarms in a spoofing incident that begin before its first spoofing evidence, and the stretch
of its alarms a jammed receiver's noise accounts for before the first evidence no cause accounts for (the
takeover), are an event of their own (unless a jamming event of the interference detector's covers it):
the spoofing event begins at the takeover. Likewise alarms that corroborated nothing before the spoofing
evidence began (natural causes, one-class anomalies, separated from it by more than the corroboration
window) are an event of their own kind, and the spoofing incident begins with its evidence. A jamming event
whose end lies within `SEQUENCE_S` of a spoofing event's onset is linked to it (`follows` / `followed_by`):
jamming to break the receiver's lock, then the takeover.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from spooflens.detectors.base import DetectorResult
from spooflens.epoch_table import EpochTable
from spooflens.pipeline.evidence import CORROBORATION_S, EVIDENCE, NOT_SPOOFING, Evidence, confidence, label
from spooflens.pipeline.explanations import (
    Excursion,
    ExplanationOptions,
    Weighed,
    alarm_began,
    explain,
    incident_alarms,
    interference_alarms,
    scene_of,
)
from spooflens.pipeline.verdict import Event, Incident, Kind, SpooferMark, Verdict

# a takeover within this long of the end of the interference is one attack with it (jam, then spoof):
# receivers re-acquire within seconds to a minute of losing lock (hot start), the window a spoofer uses
SEQUENCE_S = 60.0


@dataclass(frozen=True)
class _Decided:
    kind: Kind
    confidence: str
    evidence_for: tuple[str, ...]
    evidence_against: tuple[str, ...]
    spoofer_marks: tuple[SpooferMark, ...] = ()


def _classes_text(classes: Sequence[Evidence]) -> str:
    return ", ".join(label(c) for c in classes) or "none"


def _detectors_of(incident: Incident, results: Sequence[DetectorResult], cls: Evidence) -> list[str]:
    return sorted({r.name for a, r in incident_alarms(results, incident) if r.evidence == cls})


def _spoofing(incident: Incident, weighed: Weighed, results: Sequence[DetectorResult]) -> _Decided:
    support = tuple(
        f"{label(c)} ({', '.join(_detectors_of(incident, results, c)) or 'coasting check'})"
        for c in incident.unexplained
    )
    reached = _classes_text([c for c in incident.unexplained if EVIDENCE[c].independent] or incident.unexplained)
    against = tuple(f"{e.text}; it does not account for {reached}" for e in weighed.explanations) + tuple(
        f"ruled out {r}" for r in weighed.ruled_out
    )
    return _Decided(Kind.SPOOFING, incident.confidence, support, against)


def _not_spoofing(incident: Incident) -> str:
    if incident.confidence_of_alarms == "low":
        if not incident.corroborating:
            return "not spoofing: no evidence class confirmed"
        return f"not spoofing: one evidence class only ({_classes_text(incident.corroborating)})"
    explained = [c for c in incident.corroborating if c not in incident.unexplained]
    return (
        f"not spoofing: the alarms alone gave {incident.confidence_of_alarms} confidence "
        f"({_classes_text(incident.corroborating)}), natural causes account for {_classes_text(explained)}"
    )


def _decide(incident: Incident, weighed: Weighed, results: Sequence[DetectorResult]) -> _Decided:
    if incident.is_spoofing:
        return _spoofing(incident, weighed, results)
    jamming = [e for e in weighed.explanations if e.kind == Kind.JAMMING]
    detector = Evidence.INTERFERENCE in incident.evidence
    ruled_out = tuple(f"ruled out {r}" for r in weighed.ruled_out)
    marks = tuple(f"also a spoofer's mark: {m.text}" for m in weighed.spoofer_marks)
    if incident.kept_apart:
        return _off_baseline(incident, results, ruled_out)
    if jamming or detector or weighed.interference:
        # the receiver's own signs count for the kind even where a spoofer's mark keeps them from explaining
        # any alarm away: a receiver jammed and flagging spoofing is jammed, and its flag is listed
        receiver_signs = tuple(x for x in weighed.interference if x not in {f for e in jamming for f in e.facts})
        support = (*(e.text for e in jamming), *receiver_signs)
        if detector:
            names = ", ".join(_detectors_of(incident, results, Evidence.INTERFERENCE))
            support = (f"{label(Evidence.INTERFERENCE)} ({names})", *support)
        sources = int(detector) + int(bool(weighed.interference))
        confidence = "high" if sources >= 2 else "medium"
        return _Decided(Kind.JAMMING, confidence, support, (_not_spoofing(incident), *marks, *ruled_out))
    counted = [sp for sp in incident.spans if sp[0] != Evidence.INTERFERENCE]
    all_explained = bool(counted) and all(sp in set(incident.explained_spans) for sp in counted)
    named = [e for e in weighed.explanations if e.kind not in (Kind.UNKNOWN, Kind.JAMMING)]
    if all_explained and named:
        kind = named[0].kind
        mine = [e for e in named if e.kind == kind]
        most = max(len(e.facts) for e in mine)
        confidence = "high" if most >= 3 else "medium" if most == 2 else "low"
        others = tuple(e.text for e in weighed.explanations if e.kind != kind)
        return _Decided(kind, confidence, tuple(e.text for e in mine), (_not_spoofing(incident), *others, *ruled_out))
    support = tuple(e.text for e in weighed.explanations)
    classes = incident.unexplained or incident.evidence
    detectors = sorted({n for c in classes for n in _detectors_of(incident, results, c)})
    # alarms with no evidence class left: inertial ones the coasting check did not confirm
    alone = (
        f"{_classes_text(classes)} ({', '.join(detectors)})"
        if classes
        else f"alarms no check confirmed ({', '.join(incident.detectors)})"
    )
    marked = tuple(f"a spoofer's mark (one evidence class: not confirmed): {m.text}" for m in weighed.strong_marks)
    return _Decided(
        Kind.UNKNOWN,
        "low",
        (alone, *support, *marked),
        (_not_spoofing(incident), *ruled_out),
        weighed.strong_marks,
    )


def _off_baseline(incident: Incident, results: Sequence[DetectorResult], ruled_out: tuple[str, ...]) -> _Decided:
    """A log off its vehicle's baseline: an anomaly, said with what is off. The receiver's own signs of
    interference over the incident are no reading of it: they compare the log with itself, and this
    incident spans the log (a takeover's transient at its start would name it all jamming); which way the
    levels moved against the clean logs is in the level test's finding."""
    classes = incident.evidence
    found = [
        f.text
        for a, r in incident_alarms(results, incident)
        for f in r.findings
        if f.start_s == a.start_s and f.end_s == a.end_s and f.receiver_id == a.receiver_id
    ]
    detectors = sorted({n for c in classes for n in _detectors_of(incident, results, c)})
    support = (f"{_classes_text(classes)} ({', '.join(detectors)})" + "".join(f": {x}" for x in found[:1]), *found[1:])
    against = (
        _not_spoofing(incident),
        "another antenna installation, receiver configuration or place also moves a receiver's levels; a "
        "takeover from before the first fix may show nothing else (its drag, the velocity consistent from the "
        "start, moves no inertial reference)",
        *ruled_out,
    )
    return _Decided(Kind.UNKNOWN, "low", support, against)


def _alarm_names(incident: Incident, results: Sequence[DetectorResult], attribute: str) -> tuple[str, ...]:
    # `systems` and `bands` are named by the detectors that know them (the interference detector)
    found = {x for a, _ in incident_alarms(results, incident) for x in getattr(a, attribute, ())}
    return tuple(sorted(found))


def _event(
    incident: Incident, index: int, decided: _Decided, results: Sequence[DetectorResult], after_s: float | None = None
) -> Event:
    """The incident as an event; `after_s`: where its spoofing evidence began, after interference of its own."""
    if after_s is not None:
        incident = replace(incident, start_s=max(incident.start_s, after_s))
    end = "the end of the log" if incident.ongoing_at_end else f"{incident.end_s:.2f} s"
    # a spoofing event names every class that made it, another kind the cause that decided it
    what = "; ".join(decided.evidence_for) if decided.kind == Kind.SPOOFING else next(iter(decided.evidence_for), "")
    text = (
        f"{decided.kind.value} from {min(incident.onset_s, incident.start_s):.2f} s (alarm {incident.start_s:.2f} s) "
        f"to {end}, confidence {decided.confidence}" + (f": {what}" if what else "")
    )
    return Event(
        decided.kind,
        incident.start_s,
        incident.end_s,
        incident.onset_s,
        decided.confidence,
        index,
        text,
        decided.evidence_for,
        decided.evidence_against,
        incident.onset_interval_s,
        incident.end_interval_s,
        incident.ongoing_at_end,
        incident.receivers,
        incident.satellites,
        _alarm_names(incident, results, "systems"),
        _alarm_names(incident, results, "bands"),
        spoofer_marks=decided.spoofer_marks,
    )


def jamming_span(
    incident: Incident, results: Sequence[DetectorResult], lead_s: float = ExplanationOptions.interference_lead_s
) -> tuple[float, float] | None:
    """Where a jamming incident's interference was: the interference detector's alarms in it and the alarms
    the jamming explains (with the receiver's recovery), and the incident's alarms that began with them. An
    incident merged from interference and other alarms (an INS's misfit on a clean stretch) is jamming only
    there; None: no time the interference shows."""
    times = [
        (alarm_began(a), a.end_s)
        for a in interference_alarms(results)
        if alarm_began(a) <= incident.end_s and a.end_s >= incident.start_s
    ]
    if incident.explanations and all(e.kind == Kind.JAMMING for e in incident.explanations):
        times += [(sp[1], sp[2]) for sp in incident.explained_spans]
        times += [(sp[1], min(sp[2], until)) for sp, until in incident.partly_explained]
    if not times:
        return None
    j0, j1 = min(t for t, _ in times), max(t for _, t in times)
    with_it = [a.start_s for a, _ in incident_alarms(results, incident) if j0 - lead_s <= a.start_s <= j1]
    return max(incident.start_s, min([j0, *with_it])), min(incident.end_s, j1)


def _outside_jamming(
    incident: Incident, index: int, span: tuple[float, float], results: Sequence[DetectorResult]
) -> list[Event]:
    """The parts of a jamming incident before and after its interference, as anomalies of their own."""
    parts = []
    if incident.start_s < span[0]:
        parts.append((incident.start_s, span[0], False, "before"))
    if incident.end_s > span[1]:
        parts.append((span[1], incident.end_s, incident.ongoing_at_end, "after"))
    alarms = incident_alarms(results, incident)
    events = []
    for lo, hi, ongoing, where in parts:
        names = sorted({r.name for a, r in alarms if a.start_s < hi and a.end_s > lo})
        end = "the end of the log" if ongoing else f"{hi:.2f} s"
        text = f"unknown from {lo:.2f} s to {end}, confidence low: alarms {where} the interference, not explained by it"
        against = ("not spoofing: they belong to an incident that was not spoofing",)
        events.append(
            Event(
                Kind.UNKNOWN,
                lo,
                hi,
                lo,
                "low",
                index,
                text,
                (f"alarms of {', '.join(names)}",) if names else (),
                against,
                ongoing_at_end=ongoing,
                receivers=incident.receivers,
            )
        )
    return events


def first_unexplained_s(incident: Incident) -> float | None:
    """Where the spoofing evidence no natural cause accounts for begins (None: there is none)."""
    counted = [sp[1] for sp in incident.counted_spans if sp[0] not in NOT_SPOOFING]
    return min(counted) if counted else None


def _lead_in(incident: Incident, index: int, results: Sequence[DetectorResult]) -> Event | None:
    """What began a spoofing incident before its first spoofing evidence, as a jamming event: interference
    alarms, and the stretch of its alarms the jamming accounts for (a jammed receiver's noise) before the
    first evidence no cause accounts for."""
    first = first_unexplained_s(incident)
    if first is None:
        return None
    lead = [sp for sp in incident.spans if sp[0] == Evidence.INTERFERENCE and sp[1] < first]
    jammed = [e for e in incident.explanations if e.kind == Kind.JAMMING]
    evidence: list[str] = []
    start = end = first
    if lead:
        start, end = min(sp[1] for sp in lead), min(max(sp[2] for sp in lead), first)
        names = ", ".join(_detectors_of(incident, results, Evidence.INTERFERENCE))
        evidence.append(f"{label(Evidence.INTERFERENCE)} ({names})")
    if jammed and incident.start_s < first:
        start, end = min(start, incident.start_s), first
        evidence += [e.text for e in jammed]
    if not evidence:
        return None
    text = f"jamming from {start:.2f} s to {end:.2f} s, before the spoofing evidence: {evidence[0]}"
    return Event(
        Kind.JAMMING,
        start,
        end,
        start,
        "medium",
        index,
        text,
        tuple(evidence),
        ("interference corroborates no spoofing by itself",),
        receivers=incident.receivers,
        satellites=incident.satellites,
        systems=_alarm_names(incident, results, "systems"),
        bands=_alarm_names(incident, results, "bands"),
    )


def spoofing_begins_s(incident: Incident) -> float | None:
    """Where the incident's spoofing evidence begins: the first time evidence no natural cause accounts
    for corroborates (an independent reference, or two classes within `CORROBORATION_S`), moved back over
    the unexplained alarms chained to it by gaps of at most `CORROBORATION_S` (a ramp's GNSS-only alarms
    before its second class confirms it are the ramp's). None: nothing corroborates."""
    spans = sorted(sp for sp in incident.counted_spans if sp[0] not in NOT_SPOOFING)
    times = [a0 for c, a0, _ in spans if confidence({c}) != "low"]
    times += [
        max(a0, b0)
        for c, a0, a1 in spans
        for d, b0, b1 in spans
        if c != d and b0 <= a1 + CORROBORATION_S and a0 <= b1 + CORROBORATION_S and confidence({c, d}) != "low"
    ]
    if not times:
        return None
    begins = min(times)
    moved = True
    while moved:
        moved = False
        for _, a0, a1 in spans:
            if a0 < begins <= a1 + CORROBORATION_S:
                begins, moved = a0, True
    return begins


def _natural_lead_in(incident: Incident, index: int, begins: float) -> Event:
    """The stretch of a spoofing incident before its spoofing evidence begins (`spoofing_begins_s`), where
    the alarms corroborated nothing: natural causes, or anomalies of one class at a time, an event of its
    own (an urban drive's degradation for 10 minutes, then a spoofer: the spoofing begins with the spoofer)."""
    named = [e for e in incident.explanations if e.kind not in (Kind.UNKNOWN, Kind.JAMMING, Kind.SPOOFING)]
    kind = named[0].kind if named else Kind.UNKNOWN
    evidence = tuple(e.text for e in named) or ("alarms of one evidence class at a time, none corroborated",)
    text = (
        f"{kind.value.replace('_', ' ')} from {incident.start_s:.2f} s to {begins:.2f} s, before the spoofing "
        f"evidence: {evidence[0]}"
    )
    return Event(
        kind,
        incident.start_s,
        begins,
        incident.start_s,
        "low",
        index,
        text,
        evidence,
        ("nothing corroborated before the spoofing evidence began",),
        receivers=incident.receivers,
        satellites=incident.satellites,
    )


def _after_lead_in(incident: Incident, results: Sequence[DetectorResult], jam_s: float, takeover: float) -> Incident:
    """The spoofing incident from its first evidence no natural cause accounts for (`takeover`): its first
    alarm there, and an onset estimated before it (from alarms under the jamming since `jam_s`) replaced by
    the onset estimates of the alarms that begin there (an alarm the jamming accounts for in part: the
    takeover)."""
    incident = replace(incident, start_s=max(incident.start_s, takeover))
    if incident.onset_s >= takeover:
        return incident
    own = [
        takeover if a.start_s < takeover else a.onset_s if a.onset_s is not None else a.start_s
        for a, r in incident_alarms(results, incident)
        if r.evidence not in NOT_SPOOFING and a.end_s >= takeover
    ]
    onset = max(min(own, default=takeover), jam_s)
    return replace(incident, onset_s=onset, onset_interval_s=(onset, takeover) if onset < takeover else None)


_CONFIDENCE_RANK = {"low": 0, "medium": 1, "high": 2}


def _union(*parts: tuple[str, ...]) -> tuple[str, ...]:
    return tuple(dict.fromkeys(x for part in parts for x in part))


def fold_jamming(events: list[Event]) -> list[Event]:
    """Jamming events that overlap in time are one episode of interference (the interference detector's
    incident and the GNSS-internal alarms it explains are incidents apart): one event, from the first's
    onset to the last's end, with the evidence of all; it keeps the earliest one's incident."""
    jams = sorted((e for e in events if e.kind == Kind.JAMMING), key=lambda e: e.start_s)
    groups: list[list[Event]] = []
    for e in jams:
        if groups and e.start_s <= max(g.end_s for g in groups[-1]):
            groups[-1].append(e)
        else:
            groups.append([e])
    folded = []
    for g in groups:
        if len(g) == 1:
            folded.append(g[0])
            continue
        first, last = g[0], max(g, key=lambda e: e.end_s)
        onset = min(e.onset_s for e in g)
        confidence = max((e.confidence for e in g), key=lambda c: _CONFIDENCE_RANK.get(c, 0))
        ongoing = any(e.ongoing_at_end for e in g)
        evidence_for = _union(*(e.evidence_for for e in g))
        end = "the end of the log" if ongoing else f"{last.end_s:.2f} s"
        text = (
            f"{Kind.JAMMING.value} from {min(onset, first.start_s):.2f} s (alarm {first.start_s:.2f} s) to {end}, "
            f"confidence {confidence}: " + "; ".join(evidence_for)
        )
        folded.append(
            replace(
                first,
                end_s=last.end_s,
                onset_s=onset,
                confidence=confidence,
                text=text,
                evidence_for=evidence_for,
                evidence_against=_union(*(e.evidence_against for e in g)),
                end_interval_s=last.end_interval_s,
                ongoing_at_end=ongoing,
                receivers=_union(*(e.receivers for e in g)),
                satellites=_union(*(e.satellites for e in g)),
                systems=_union(*(e.systems for e in g)),
                bands=_union(*(e.bands for e in g)),
            )
        )
    return [e for e in events if e.kind != Kind.JAMMING] + folded


def link_sequences(events: list[Event], within_s: float = SEQUENCE_S) -> list[Event]:
    """Each jamming event linked to the first spoofing event whose onset follows its end within `within_s`."""
    out = list(events)
    for j, jam in enumerate(out):
        if jam.kind != Kind.JAMMING or jam.followed_by is not None:
            continue
        for s, spoof in enumerate(out):
            starts = min(spoof.onset_s, spoof.start_s)
            if spoof.kind == Kind.SPOOFING and spoof.follows is None and jam.start_s <= starts <= jam.end_s + within_s:
                out[j] = replace(jam, followed_by=s)
                out[s] = replace(spoof, follows=j)
                break
    return out


def classify(table: EpochTable, results: Sequence[DetectorResult], verdict: Verdict) -> Verdict:
    """The verdict with every incident's natural explanations weighed and every incident and anomaly an
    event of its kind."""
    departures = [
        float(c["departure_s"])
        for c in verdict.coasting_checks
        if c.get("confirmed") and c.get("departure_s") is not None
    ]
    excursions = [
        Excursion(float(c["departure_s"]), float(c["end_s"]), float(c["offset_peak_m"]))
        for c in verdict.coasting_checks
        if c.get("confirmed")
        and c.get("departure_s") is not None
        and c.get("end_s") is not None
        and c.get("offset_peak_m") is not None
    ]
    scene = scene_of(table, results, departures_s=departures, excursions=excursions)
    spoofing_before = [i for i in verdict.incidents if i.is_spoofing]
    incidents: list[Incident] = []
    events: list[Event] = []
    leads: list[Event] = []
    for k, inc in enumerate(verdict.incidents):
        weighed = explain(table, results, inc, scene=scene)
        inc = inc.explained_by(weighed.explanations, weighed.explained_spans, weighed.partly_explained)
        decided = _decide(inc, weighed, results)
        inc = replace(inc, kind=decided.kind)
        alarms = incident_alarms(results, inc)
        if decided.kind == Kind.JAMMING and alarms and inc.end_method.startswith("GNSS"):
            # the coast that ended it weighed the jammed fixes with their clean noise: its end is its alarms'
            inc = replace(
                inc,
                end_s=max(a.end_s for a, _ in alarms),
                end_interval_s=None,
                ongoing_at_end=False,
                end_method="last alarm (the coasted INS's departure was the jammed receiver's noise)",
            )
        lead = _lead_in(inc, k, results) if decided.kind == Kind.SPOOFING else None
        begins = spoofing_begins_s(inc) if decided.kind == Kind.SPOOFING and lead is None else None
        if lead is None and begins is not None and begins - inc.start_s > CORROBORATION_S:
            lead = _natural_lead_in(inc, k, begins)
        if lead is not None:
            leads.append(lead)
            inc = _after_lead_in(inc, results, lead.start_s, lead.end_s)
        elif decided.kind == Kind.SPOOFING:
            # an onset estimated back inside interference (a long-window test's estimate reaching into the
            # jamming before a takeover) is the jamming's, not the takeover's
            first = first_unexplained_s(inc)
            under = [(alarm_began(a), a.end_s) for a in interference_alarms(results) if first is not None]
            if first is not None and any(a <= inc.onset_s <= b and a < first for a, b in under):
                inc = _after_lead_in(inc, results, min(a for a, _ in under if a <= inc.onset_s), first)
        span = jamming_span(inc, results, scene.opts.interference_lead_s) if decided.kind == Kind.JAMMING else None
        if span is not None and span != (inc.start_s, inc.end_s):
            # the incident is the jamming where it was; its alarms before and after are anomalies of their own
            trimmed = replace(
                inc,
                start_s=span[0],
                end_s=span[1],
                onset_s=max(inc.onset_s, span[0] - scene.opts.interference_lead_s),
                onset_interval_s=None,
                end_interval_s=None,
                ongoing_at_end=inc.ongoing_at_end and span[1] >= inc.end_s,
            )
            incidents.append(trimmed)
            events.append(_event(trimmed, k, decided, results))
            events += _outside_jamming(inc, k, span, results)
        else:
            incidents.append(inc)
            events.append(_event(inc, k, decided, results))
    # a lead-in the interference detector's own jamming event already covers is that event
    jams = [e for e in events if e.kind == Kind.JAMMING]
    events += [lead for lead in leads if not any(j.start_s <= lead.end_s and lead.start_s <= j.end_s for j in jams)]
    events = fold_jamming(events)
    events.sort(key=lambda e: (e.start_s, e.kind != Kind.JAMMING))
    # the tracks reconstructed for incidents no longer called spoofing go with them
    reconstructed = verdict.reconstructed
    if len(reconstructed) == len(spoofing_before):
        still = {id(v) for v, inc in zip(verdict.incidents, incidents, strict=True) if inc.is_spoofing}
        reconstructed = tuple(tr for tr, v in zip(reconstructed, spoofing_before, strict=True) if id(v) in still)
    return replace(
        verdict,
        spoofed=any(i.is_spoofing for i in incidents),
        incidents=tuple(incidents),
        events=tuple(link_sequences(events)),
        reconstructed=reconstructed,
    )
