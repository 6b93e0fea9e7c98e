"""The incident verdict: was GNSS spoofed, from when to when, and how sure.

Alarm intervals of every detector that ran are merged into incidents (overlapping or closer than
`merge_gap_s`). An incident's onset is the estimate that comes with a credible interval when one took
part, else the earliest onset estimate inside it; its end is the last alarm end (the reconstruction
stage, `spooflens.pipeline.reconstruction`, refines it). Detectors marked advisory (an uncalibrated rule, a test
whose model does not fit the log) are reported but do not make incidents.

Confidence counts the distinct evidence classes whose detectors alarmed in the incident at the same
time (`spooflens.pipeline.evidence.corroborated`, `confidence`): several tests on one filter's innovations are
one class, and classes whose alarms lie minutes apart inside one long incident do not corroborate each
other. A low-confidence incident (one GNSS-internal class alone) is an anomaly, never a spoofing
verdict.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from spooflens.detectors.base import Alarm, DetectorResult, Finding
from spooflens.pipeline.evidence import APART, CORROBORATION_S, ORDER, Evidence, Span, confidence, corroborated

ONGOING_WITHIN_S = 1.0  # an incident whose last alarm is this close to the last fix is ongoing at the end


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

    def with_spans(self, spans: tuple[Span, ...]) -> Incident:
        """This incident with these evidence intervals: its classes and confidence follow from them."""
        classes = {c for c, _, _ in spans}
        return replace(
            self,
            spans=spans,
            evidence=tuple(c for c in ORDER if c in classes),
            confidence=confidence(corroborated(spans)) if spans else "low",
        )

    @property
    def corroborating(self) -> tuple[Evidence, ...]:
        """The classes that agree in time, the ones the confidence counts."""
        found = corroborated(self.spans)
        return tuple(c for c in ORDER if c in found)

    @property
    def is_spoofing(self) -> bool:
        return self.confidence != "low"


@dataclass
class Verdict:
    spoofed: bool
    incidents: list[Incident] = field(default_factory=list)
    detectors_run: tuple[str, ...] = ()
    detectors_not_run: tuple[str, ...] = ()
    detectors_advisory: tuple[str, ...] = ()  # ran, but their alarms do not count (see DetectorResult.advisory)
    findings: list[Finding] = field(default_factory=list)

    @property
    def deciding_incident(self) -> Incident | None:
        """The incident that made the verdict: the first spoofing incident, else the first anomaly."""
        spoofing = [i for i in self.incidents if i.is_spoofing]
        return spoofing[0] if spoofing else (self.incidents[0] if self.incidents else None)

    @property
    def headline(self) -> str:
        if not self.detectors_run:
            return "NO VERDICT: no detector could run on this log"
        if not self.spoofed:
            advisory = f" ({len(self.detectors_advisory)} more advisory only)" if self.detectors_advisory else ""
            anomalies = sum(not i.is_spoofing for i in self.incidents)
            noted = f"; {anomalies} anomaly(ies) of one evidence class noted, not confirmed" if anomalies else ""
            return f"NO SPOOFING DETECTED by {len(self.detectors_run)} detector(s){advisory}{noted}"
        spoofing = [i for i in self.incidents if i.is_spoofing]
        first = spoofing[0]
        end = "the end of the log" if first.ongoing_at_end else f"{first.end_s:.2f} s"
        return (
            f"SPOOFING DETECTED: {len(spoofing)} incident(s); first from {first.onset_s:.2f} s "
            f"(alarm {first.start_s:.2f} s) to {end}, confidence {first.confidence}"
        )


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
    # an onset with a credible interval beats point estimates
    estimates: list[tuple[float, tuple[float, float] | None]] = [
        (a.onset_s, a.onset_interval_s) for a in items if a.onset_s is not None
    ]
    with_interval = [e for e in estimates if e[1] is not None]
    onset: float
    interval: tuple[float, float] | None
    if with_interval or estimates:
        onset, interval = min(with_interval or estimates, key=lambda e: e[0])
    else:
        onset, interval = min(a.start_s for a in items), None
    interval = _joint_interval(items, interval)
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


def decide(results: list[DetectorResult], merge_gap_s: float = 5.0, log_end_s: float | None = None) -> Verdict:
    """Incidents from every counted detector's alarms. An incident whose last alarm is within a second of
    `log_end_s` (the last GNSS fix) was still going on when the log ended: its end is the log's, not the
    attack's (the reconstruction stage says the same for the incidents it confirms)."""
    detectors = [r for r in results if r.is_detector]
    ran = tuple(r.name for r in detectors if r.ran and not r.advisory)
    advisory = tuple(r.name for r in detectors if r.ran and r.advisory)
    not_run = tuple(r.name for r in detectors if not r.ran)
    counted = [r for r in detectors if r.ran and not r.advisory]
    alarms = [(a, r) for r in counted for a in r.alarms if r.evidence not in APART]
    apart = [(a, r) for r in counted for a in r.alarms if r.evidence in APART]
    groups = _group(alarms, merge_gap_s) + [
        g for c in APART for g in _group([x for x in apart if x[1].evidence == c], merge_gap_s)
    ]
    incidents = sorted((_incident(g) for g in groups), key=lambda i: i.start_s)
    if log_end_s is not None:
        incidents = [
            replace(i, ongoing_at_end=True, end_method="last alarm, at the end of the log")
            if i.end_s >= log_end_s - ONGOING_WITHIN_S
            else i
            for i in incidents
        ]
    findings = [f for r in counted for f in r.findings]
    return Verdict(any(i.is_spoofing for i in incidents), incidents, ran, not_run, advisory, findings)
