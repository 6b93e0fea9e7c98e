"""The incident verdict: was GNSS spoofed, from when to when, and how sure.

Alarm intervals of every detector that ran are merged into incidents (overlapping or closer than
`merge_gap_s`). An incident's onset is the calibrated MLRT's posterior onset when it took part (it comes
with a credible interval), else the earliest onset estimate inside it; its end is the last alarm end.
Detectors marked advisory (an uncalibrated rule such as the paper's "l > 0") are reported but do not
make incidents. Confidence says how much
independent evidence there is: detectors that compare GNSS with something GNSS cannot fake (the
inertial sensors, a second receiver, a known station) count as independent of GNSS-only checks.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from spooflens.detectors.base import Alarm, DetectorResult

# Detectors whose alarms rest on a reference the spoofer cannot move; a GNSS-only check alone is weaker.
INDEPENDENT_REFERENCE = {"kf_innovation", "glrt", "mlrt", "mlrt_calibrated"}


@dataclass(frozen=True)
class Incident:
    start_s: float
    end_s: float
    onset_s: float
    onset_interval_s: tuple[float, float] | None
    detectors: tuple[str, ...]
    confidence: str  # "high" | "medium" | "low"


@dataclass
class Verdict:
    spoofed: bool
    incidents: list[Incident] = field(default_factory=list)
    detectors_run: tuple[str, ...] = ()
    detectors_not_run: tuple[str, ...] = ()
    detectors_advisory: tuple[str, ...] = ()  # ran, but their alarms do not count (see DetectorResult.advisory)

    @property
    def headline(self) -> str:
        if not self.detectors_run:
            return "NO VERDICT: no detector could run on this log"
        if not self.spoofed:
            advisory = f" ({len(self.detectors_advisory)} more advisory only)" if self.detectors_advisory else ""
            anomalies = sum(i.confidence == "low" for i in self.incidents)
            noted = f"; {anomalies} GNSS-only anomaly(ies) noted, not confirmed" if anomalies else ""
            return f"NO SPOOFING DETECTED by {len(self.detectors_run)} detector(s){advisory}{noted}"
        first = self.incidents[0]
        return (
            f"SPOOFING DETECTED: {len(self.incidents)} incident(s); first from {first.onset_s:.2f} s "
            f"(alarm {first.start_s:.2f} s) to {first.end_s:.2f} s, confidence {first.confidence}"
        )


def _confidence(detectors: set[str]) -> str:
    independent = detectors & INDEPENDENT_REFERENCE
    if len(independent) >= 2 or (independent and len(detectors) >= 2):
        return "high"
    if independent:
        return "medium"
    return "low"


def decide(results: list[DetectorResult], merge_gap_s: float = 5.0) -> Verdict:
    ran = tuple(r.name for r in results if r.ran and not r.advisory)
    advisory = tuple(r.name for r in results if r.ran and r.advisory)
    not_run = tuple(r.name for r in results if not r.ran)
    alarms = sorted(
        ((a, r.name) for r in results if r.ran and not r.advisory for a in r.alarms), key=lambda x: x[0].start_s
    )
    groups: list[list[tuple[Alarm, str]]] = []
    end = float("-inf")
    for a, name in alarms:
        if groups and a.start_s <= end + merge_gap_s:
            groups[-1].append((a, name))
            end = max(end, a.end_s)
        else:
            groups.append([(a, name)])
            end = a.end_s
    incidents = []
    for g in groups:
        items = [a for a, _ in g]
        names = {n for _, n in g}
        # an onset with a credible interval (the calibrated MLRT's posterior) beats point estimates
        with_interval = [(a.onset_s, a.onset_interval_s) for a in items if a.onset_interval_s is not None]
        onsets = [(a.onset_s, a.onset_interval_s) for a in items if a.onset_s is not None]
        if with_interval:
            onset, interval = min(with_interval, key=lambda o: o[0])
        elif onsets:
            onset, interval = min(onsets, key=lambda o: o[0])
        else:
            onset, interval = min(a.start_s for a in items), None
        incidents.append(
            Incident(
                min(a.start_s for a in items),
                max(a.end_s for a in items),
                onset,
                interval,
                tuple(sorted(names)),
                _confidence(names),
            )
        )
    # GNSS-only evidence alone (low confidence) is reported, not called spoofing: real receivers jump too
    return Verdict(any(i.confidence != "low" for i in incidents), incidents, ran, not_run, advisory)
