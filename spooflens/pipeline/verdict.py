"""The incident verdict: was GNSS spoofed, from when to when, and how sure.

`decide` makes it from the detectors' alarms; the reconstruction stage (`spooflens.pipeline.reconstruction`)
confirms and ends each inertial incident and adds the tracks reconstructed with GNSS left out; the event
stage (`spooflens.pipeline.events`) weighs the natural explanations of each incident's evidence
(`spooflens.pipeline.explanations`) and gives every incident and anomaly its kind. The three together
(`spooflens.pipeline.run.assess`) give the one immutable verdict every output reads.

Alarm intervals of every detector that ran are merged into incidents (overlapping or closer than
`merge_gap_s`). An incident's onset is the estimate that comes with a credible interval when one took part,
else the earliest onset estimate inside it; its end is the last alarm end (the reconstruction stage,
`spooflens.pipeline.reconstruction`, refines it). Detectors marked advisory (an uncalibrated rule, a test
whose model does not fit the log) are reported but do not make incidents.

Alarms of classes that are no spoofing evidence (interference) make incidents of their own, never merged with
spoofing alarms. Confidence counts the distinct evidence classes whose detectors alarmed in the incident at
the same time (`spooflens.pipeline.evidence.corroborated`, `confidence`): several tests on one filter's
innovations are one class, and classes whose alarms lie minutes apart inside one long incident do not
corroborate each other. A low-confidence incident (one GNSS-internal class alone) is an anomaly, never a
spoofing verdict. Alarms a natural cause accounts for (`explained_spans`) stay in the incident but count for
nothing: the confidence is that of the evidence no natural explanation covers.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import StrEnum
from typing import Any, NamedTuple

from spooflens.detectors.base import Alarm, DetectorResult, Finding, Track
from spooflens.pipeline.evidence import (
    APART,
    CORROBORATION_S,
    NOT_SPOOFING,
    ORDER,
    Evidence,
    Span,
    confidence,
    corroborated,
)

ONGOING_WITHIN_S = 1.0  # an incident whose last alarm is this close to the last fix is ongoing at the end


class Kind(StrEnum):
    """What an event was (`spooflens.pipeline.events` decides it)."""

    SPOOFING = "spoofing"
    JAMMING = "jamming"  # radio-frequency interference
    DEGRADATION = "degradation"  # multipath, NLOS, obstruction
    RECEIVER_FAULT = "receiver_fault"  # reset, mode switch, convergence, week rollover, leap seconds, logger clock
    UNKNOWN = "unknown"


KIND_LABELS: dict[Kind, str] = {
    Kind.SPOOFING: "spoofing",
    Kind.JAMMING: "jamming / interference",
    Kind.DEGRADATION: "signal degradation",
    Kind.RECEIVER_FAULT: "receiver fault",
    Kind.UNKNOWN: "unknown",
}


@dataclass(frozen=True)
class Explanation:
    """A natural cause that accounts for some of an incident's alarms (`spooflens.pipeline.explanations`)."""

    cause: str  # e.g. "degradation", "cold_start", "week_rollover" (the signature that matched)
    kind: Kind  # the kind of event the cause is
    text: str  # one line, e.g. "C/N0 -8 dB and HDOP x2 while the fix jumped: degradation, not spoofing"
    facts: tuple[str, ...]  # the measurements it rests on
    detectors: tuple[str, ...]  # the detectors whose alarms in the incident it accounts for
    receiver_id: str | None = None


@dataclass(frozen=True)
class Incident:
    start_s: float  # first alarm
    end_s: float  # last alarm, or where GNSS agreed with the reference again
    onset_s: float  # estimated start of the attack
    onset_interval_s: tuple[float, float] | None
    detectors: tuple[str, ...]
    confidence: str  # "high" | "medium" | "low"
    evidence: tuple[Evidence, ...] = ()
    receivers: tuple[str, ...] = ()
    satellites: tuple[str, ...] = ()
    end_interval_s: tuple[float, float] | None = None
    ongoing_at_end: bool = False  # still going on when the log ends
    end_method: str = "last alarm"
    offset_peak_m: float | None = None  # largest horizontal distance GNSS - independent reference
    offset_end_m: float | None = None  # the same at the incident's end
    spans: tuple[Span, ...] = ()  # each class's alarm intervals: what corroborates what
    # the event stage's: the natural causes weighed, the alarm intervals they account for, the event's kind
    explanations: tuple[Explanation, ...] = ()
    explained_spans: tuple[Span, ...] = ()
    # alarm intervals a natural cause accounts for from their start up to a time, not beyond (a jammed
    # receiver's noise until the spoofer's takeover inside one alarm): only what follows counts
    partly_explained: tuple[tuple[Span, float], ...] = ()
    kind: Kind | None = None

    def with_spans(self, spans: tuple[Span, ...]) -> Incident:
        """This incident with these evidence intervals: its classes and confidence follow from them (alarm
        intervals a natural cause accounts for count for nothing)."""
        classes = {c for c, _, _ in spans}
        counted = self._counted(spans)
        return replace(
            self,
            spans=spans,
            evidence=tuple(c for c in ORDER if c in classes),
            confidence=confidence(corroborated(counted)) if counted else "low",
        )

    def _counted(self, spans: tuple[Span, ...]) -> tuple[Span, ...]:
        """The alarm intervals, or their parts, no natural cause accounts for."""
        explained = set(self.explained_spans)
        until = dict(self.partly_explained)
        out = []
        for sp in spans:
            if sp in explained:
                continue
            start = max(sp[1], until.get(sp, sp[1]))
            out.append((sp[0], start, sp[2]))
        return tuple(out)

    @property
    def counted_spans(self) -> tuple[Span, ...]:
        """The alarm intervals, or what is left of them, no natural cause accounts for: what the confidence
        counts."""
        return self._counted(self.spans)

    def explained_by(
        self,
        explanations: tuple[Explanation, ...],
        spans: tuple[Span, ...],
        partly: tuple[tuple[Span, float], ...] = (),
    ) -> Incident:
        """This incident with the natural causes weighed and the alarm intervals they account for (whole, or
        from their start up to a time: `partly`)."""
        return replace(self, explanations=explanations, explained_spans=spans, partly_explained=partly).with_spans(
            self.spans
        )

    @property
    def corroborating(self) -> tuple[Evidence, ...]:
        """The classes that agree in time (natural explanations or not)."""
        found = corroborated(self.spans)
        return tuple(c for c in ORDER if c in found)

    @property
    def unexplained(self) -> tuple[Evidence, ...]:
        """The classes that agree in time once the alarms a natural cause accounts for are left out: the
        ones the confidence counts."""
        found = corroborated(self.counted_spans)
        return tuple(c for c in ORDER if c in found)

    @property
    def confidence_of_alarms(self) -> str:
        """The confidence the alarms alone would give, before any natural explanation."""
        return confidence(corroborated(self.spans)) if self.spans else "low"

    @property
    def is_spoofing(self) -> bool:
        return self.confidence != "low"

    @property
    def kept_apart(self) -> bool:
        """Only a class kept apart alarmed in it (`APART`: levels off the vehicle's baseline)."""
        return bool(self.evidence) and set(self.evidence) <= APART


class SpooferMark(NamedTuple):
    """A mark a spoofer's signal leaves on the receiver's indicators and nature does not
    (`explanations.weighed_marks`)."""

    text: str  # the fact with its numbers ("12 satellites at one C/N0 (spread 0.9 dB): one transmitter")
    claim: str  # what it says of the signal, short enough for the headline ("one transmitter")
    strong: bool  # a sign on its own; a C/N0 risen a few dB only bars a natural reading


@dataclass(frozen=True)
class Event:
    """One incident or anomaly as what it was: its kind, what decided it and what argued against the other
    kinds (`spooflens.pipeline.events`). A spoofing incident that interference led into is two events, the
    jamming one `followed_by` the spoofing one."""

    kind: Kind
    start_s: float
    end_s: float
    onset_s: float
    confidence: str  # how sure the kind is: "high" | "medium" | "low"
    incident: int  # index of the incident in Verdict.incidents it comes from
    text: str  # one line
    evidence_for: tuple[str, ...] = ()
    evidence_against: tuple[str, ...] = ()
    onset_interval_s: tuple[float, float] | None = None
    end_interval_s: tuple[float, float] | None = None
    ongoing_at_end: bool = False
    receivers: tuple[str, ...] = ()
    satellites: tuple[str, ...] = ()
    systems: tuple[str, ...] = ()
    bands: tuple[str, ...] = ()
    follows: int | None = None  # index in Verdict.events of the event this one followed in one attack sequence
    followed_by: int | None = None
    # an anomaly's marks that a spoofer's signal leaves and nature does not (C/N0 above the sky's, satellites
    # at one C/N0, ...): one evidence class still, so not confirmed, but named in the headline
    spoofer_marks: tuple[SpooferMark, ...] = ()


def unknown_marks(events: list[Event]) -> str:
    """The first marked anomaly's spoofer's marks, each as its claim."""
    first = next(e for e in events if e.spoofer_marks)
    return "; ".join(m.claim for m in first.spoofer_marks)


def _interval_text(start_s: float, end_s: float, ongoing: bool) -> str:
    return f"from {start_s:.2f} s to " + ("the end of the log" if ongoing else f"{end_s:.2f} s")


@dataclass(frozen=True)
class Verdict:
    spoofed: bool
    incidents: tuple[Incident, ...] = ()
    detectors_run: tuple[str, ...] = ()
    detectors_not_run: tuple[str, ...] = ()
    detectors_advisory: tuple[str, ...] = ()  # ran, but their alarms do not count (see DetectorResult.advisory)
    findings: tuple[Finding, ...] = ()
    # the reconstruction stage's: where the vehicle was with GNSS left out over each confirmed incident, and
    # each inertial incident's coasting check (JSON-able facts)
    reconstructed: tuple[Track, ...] = ()
    coasting_checks: tuple[dict[str, Any], ...] = ()
    # the event stage's: every incident and anomaly as an event of its kind (`spooflens.pipeline.events`)
    events: tuple[Event, ...] = ()
    # why a log without GNSS data has nothing to judge (`inventory.without_gnss`), else ''
    without_gnss: str = ""

    @property
    def deciding_incident(self) -> Incident | None:
        """The incident that made the verdict: the first spoofing incident, else the first anomaly."""
        spoofing = [i for i in self.incidents if i.is_spoofing]
        return spoofing[0] if spoofing else (self.incidents[0] if self.incidents else None)

    def events_of(self, kind: Kind) -> list[Event]:
        return [e for e in self.events if e.kind == kind]

    @property
    def headline(self) -> str:
        """One line; it always begins with `NO VERDICT`, `NO SPOOFING DETECTED` or `SPOOFING DETECTED` (scripts
        grep them), then names the other kinds of event."""
        if not self.detectors_run:
            why = self.without_gnss or "no spoofing detector could run on this log"
            return f"NO VERDICT: {why}{self._other_kinds()}"
        if not self.spoofed:
            advisory = f" ({len(self.detectors_advisory)} more advisory only)" if self.detectors_advisory else ""
            return f"NO SPOOFING DETECTED by {len(self.detectors_run)} detector(s){advisory}{self._other_kinds()}"
        spoofing = [i for i in self.incidents if i.is_spoofing]
        first = spoofing[0]
        end = "the end of the log" if first.ongoing_at_end else f"{first.end_s:.2f} s"
        led_in = [
            self.events[e.follows]
            for e in self.events_of(Kind.SPOOFING)
            if e.follows is not None and self.incidents[e.incident] is first
        ]
        after = (
            f"; after JAMMING / INTERFERENCE {_interval_text(led_in[0].start_s, led_in[0].end_s, False)}"
            if led_in
            else ""
        )
        return (
            f"SPOOFING DETECTED: {len(spoofing)} incident(s); first from {first.onset_s:.2f} s "
            f"(alarm {first.start_s:.2f} s) to {end}, confidence {first.confidence}{after}"
        )

    def _other_kinds(self) -> str:
        """What a verdict without spoofing noted: interference, degradation, receiver faults, anomalies."""
        if not self.events:  # a verdict made without the event stage (`decide` alone)
            anomalies = sum(not i.is_spoofing for i in self.incidents)
            return f"; {anomalies} anomaly(ies) of one evidence class noted, not confirmed" if anomalies else ""
        parts = []
        for kind, words in (
            (Kind.JAMMING, "JAMMING / INTERFERENCE"),
            (Kind.DEGRADATION, "signal degradation"),
            (Kind.RECEIVER_FAULT, "receiver fault"),
        ):
            events = self.events_of(kind)
            if events:
                more = f" (and {len(events) - 1} more)" if len(events) > 1 else ""
                parts.append(
                    f"{words} {_interval_text(events[0].start_s, events[0].end_s, events[0].ongoing_at_end)}{more}"
                )
        # a log off its vehicle's baseline is named: it may last the whole log, which no other anomaly does
        unknown = self.events_of(Kind.UNKNOWN)
        apart = [e for e in unknown if self.incidents[e.incident].kept_apart]
        if apart:
            more = f" (and {len(apart) - 1} more)" if len(apart) > 1 else ""
            parts.append(
                f"receiver indicators off the vehicle's baseline "
                f"{_interval_text(apart[0].start_s, apart[0].end_s, apart[0].ongoing_at_end)}{more} "
                "(one evidence class, not confirmed)"
            )
        if len(unknown) > len(apart):
            marked = sum(bool(e.spoofer_marks) for e in unknown if not self.incidents[e.incident].kept_apart)
            with_marks = f" ({marked} with a spoofer's marks: {unknown_marks(unknown)})" if marked else ""
            parts.append(
                f"{len(unknown) - len(apart)} anomaly(ies) of one evidence class noted, not confirmed{with_marks}"
            )
        return "".join(f"; {p}" for p in parts)


def _group(alarms: list[tuple[Alarm, DetectorResult]], merge_gap_s: float) -> list[list[tuple[Alarm, DetectorResult]]]:
    groups: list[list[tuple[Alarm, DetectorResult]]] = []
    end = float("-inf")
    for a, r in sorted(alarms, key=lambda x: x[0].start_s):
        if groups and a.start_s <= end + merge_gap_s:
            groups[-1].append((a, r))
            end = max(end, a.end_s)
        else:
            groups.append([(a, r)])
            end = a.end_s
    return groups


def _joint_interval(items: list[Alarm], interval: tuple[float, float] | None) -> tuple[float, float] | None:
    """The onset interval of an incident: the union of what the detectors that alarmed at its start (within
    the corroboration window) say about the onset, their intervals and point estimates. Each method's
    interval rests on its own model (white errors, a ramp or a step); on real receivers one is often
    right where another is not (a capture is seen by the receiver at once and by the INS a little
    later; a ramp's onset is pulled early by a slow receiver error), so the union is what the evidence
    supports."""
    first = min(a.start_s for a in items)
    near = [a for a in items if a.start_s <= first + CORROBORATION_S]
    points = [a.onset_s if a.onset_s is not None else a.start_s for a in near]
    bounds = [a.onset_interval_s for a in near if a.onset_interval_s is not None]
    if not bounds and len(set(points)) < 2:
        return interval
    lo = min([*points, *(b[0] for b in bounds)])
    hi = max(b[1] for b in bounds) if bounds else max(points)
    return (float(lo), float(max(hi, lo)))


def _incident(group: list[tuple[Alarm, DetectorResult]]) -> Incident:
    items = [a for a, _ in group]
    spans = tuple(sorted({(r.evidence, a.start_s, a.end_s) for a, r in group if r.evidence is not None}))
    # the attack's onset is estimated from spoofing evidence: interference that led into it has its own event
    timed = [a for a, r in group if r.evidence not in NOT_SPOOFING] or items
    # an onset with a credible interval beats point estimates
    estimates: list[tuple[float, tuple[float, float] | None]] = [
        (a.onset_s, a.onset_interval_s) for a in timed if a.onset_s is not None
    ]
    with_interval = [e for e in estimates if e[1] is not None]
    onset: float
    interval: tuple[float, float] | None
    if with_interval or estimates:
        onset, interval = min(with_interval or estimates, key=lambda e: e[0])
    else:
        onset, interval = min(a.start_s for a in timed), None
    interval = _joint_interval(timed, interval)
    return Incident(
        min(a.start_s for a in items),
        max(a.end_s for a in items),
        float(onset),
        interval,
        tuple(sorted({r.name for _, r in group})),
        "low",
        receivers=tuple(sorted({a.receiver_id for a in items if a.receiver_id})),
        satellites=tuple(sorted({s for a in items for s in a.satellites})),
    ).with_spans(spans)


def decide(
    results: list[DetectorResult], merge_gap_s: float = 5.0, log_end_s: float | None = None, without_gnss: str = ""
) -> Verdict:
    """Incidents from every counted detector's alarms. An incident whose last alarm is within a second of
    `log_end_s` (the last GNSS fix) was still going on when the log ended: its end is the log's, not the
    attack's (the reconstruction stage says the same for the incidents it confirms). `without_gnss`: why the
    log has nothing to judge (`inventory.without_gnss`), said in the headline."""
    detectors = [r for r in results if r.is_detector]
    # the detectors a spoofing verdict rests on: one that can only say what disturbed the signals is none
    ran = tuple(r.name for r in detectors if r.ran and not r.advisory and r.evidence not in NOT_SPOOFING)
    advisory = tuple(r.name for r in detectors if r.ran and r.advisory)
    not_run = tuple(r.name for r in detectors if not r.ran)
    counted = [r for r in detectors if r.ran and not r.advisory]
    # what only disturbed the signals (interference) and what is kept apart (levels off the vehicle's baseline)
    # make incidents of their own: merged with spoofing alarms they would move their incident's onset and end
    separate = NOT_SPOOFING | APART
    alarms = [(a, r) for r in counted for a in r.alarms if r.evidence not in separate]
    groups = _group(alarms, merge_gap_s) + [
        g
        for c in sorted(separate)
        for g in _group([(a, r) for r in counted for a in r.alarms if r.evidence == c], merge_gap_s)
    ]
    incidents = sorted((_incident(g) for g in groups), key=lambda i: i.start_s)
    if log_end_s is not None:
        incidents = [
            replace(i, ongoing_at_end=True, end_method="last alarm, at the end of the log")
            if i.end_s >= log_end_s - ONGOING_WITHIN_S
            else i
            for i in incidents
        ]
    findings = tuple(f for r in counted for f in r.findings)
    return Verdict(
        any(i.is_spoofing for i in incidents),
        tuple(incidents),
        ran,
        not_run,
        advisory,
        findings,
        without_gnss=without_gnss,
    )


def incident_of(alarms: list[tuple[Alarm, DetectorResult]]) -> Incident:
    """The incident these alarms (with the results they came from) make, as `decide` makes each one."""
    return _incident(alarms)
