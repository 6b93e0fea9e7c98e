"""Evidence classes: what each detector compares GNSS with, and how the verdict weighs agreement.

Four tests on one filter's innovations are one piece of evidence, not four: a detector declares the
class of reference it uses, and an incident's confidence counts the distinct classes that agree
(`spooflens.pipeline.verdict`). A class is *independent* when its reference is something a spoofer of this
receiver cannot move (the vehicle's own inertial sensors, a second antenna, a surveyed station, other
vehicles, a gyrocompass, the other satellites' signals and the broadcast orbits, the logger's clock). The receiver's own
outputs checked against each other, and what the receiver says about itself, are evidence too, but a
single such class alone never makes a spoofing verdict: real receivers jump and complain without an
attacker.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum


class Evidence(StrEnum):
    GNSS_ONLY = "gnss_only"
    RECEIVER = "receiver"
    RAW_MEASUREMENT = "raw_measurement"
    LOG_CLOCK = "log_clock"
    INERTIAL = "inertial"
    SECOND_RECEIVER = "second_receiver"
    KNOWN_STATION = "known_station"
    FLEET = "fleet"
    HEADING = "heading"
    INTERFERENCE = "interference"
    VEHICLE_BASELINE = "vehicle_baseline"


@dataclass(frozen=True)
class EvidenceInfo:
    label: str
    reference: str  # what GNSS is compared with
    independent: bool  # a spoofer of this receiver cannot move the reference


EVIDENCE: dict[Evidence, EvidenceInfo] = {
    Evidence.GNSS_ONLY: EvidenceInfo(
        "GNSS-only consistency", "the receiver's own position, velocity and time against each other", False
    ),
    Evidence.RECEIVER: EvidenceInfo(
        "receiver self-report",
        "the receiver's flags and indicators (spoofing/jamming state, noise, AGC, C/N0, satellites, "
        "reported accuracy) against their own baseline in the log and their documented normal ranges",
        False,
    ),
    # a log off its vehicle's clean levels (`analyze --baseline`): a different day, place or installation
    # does that too, and over a whole log it would corroborate any glitch in it (see APART)
    Evidence.VEHICLE_BASELINE: EvidenceInfo(
        "vehicle baseline",
        "the receiver's indicator levels against those of the vehicle's clean logs",
        False,
    ),
    Evidence.RAW_MEASUREMENT: EvidenceInfo(
        "raw-measurement consistency",
        "each satellite's pseudorange and rate against the other satellites and the broadcast orbits",
        True,
    ),
    Evidence.LOG_CLOCK: EvidenceInfo(
        "log clock",
        "the log's own clock (the autopilot's or phone's boot clock, the logging host's time), which the "
        "receiver does not set",
        True,
    ),
    Evidence.INERTIAL: EvidenceInfo("inertial reference", "the vehicle's inertial sensors (and odometry)", True),
    Evidence.SECOND_RECEIVER: EvidenceInfo("second receiver", "a second antenna and receiver on the vehicle", True),
    Evidence.KNOWN_STATION: EvidenceInfo(
        "known station", "a surveyed position or a trusted trajectory the spoofer cannot move", True
    ),
    Evidence.FLEET: EvidenceInfo("fleet", "other vehicles' receivers in the same area and time", True),
    Evidence.HEADING: EvidenceInfo("heading reference", "a gyrocompass or magnetic heading", True),
    # what jams a receiver: never evidence of spoofing by itself (a jammer, a faulty transmitter nearby or
    # the vehicle's own electronics drown the signals; nothing moves the fix), so it corroborates nothing
    Evidence.INTERFERENCE: EvidenceInfo(
        "radio-frequency interference",
        "the receiver's signal levels (C/N0 of every satellite, AGC, noise and jamming indicators) against "
        "their own baseline in the log and their documented ranges",
        False,
    ),
}

# classes that say what disturbed the signals, not that GNSS was moved: they make no spoofing incident
NOT_SPOOFING: frozenset[Evidence] = frozenset({Evidence.INTERFERENCE})
# classes whose alarms make incidents of their own, never merged with another class's alarms and never
# corroborating them: a level off the vehicle's baseline lasts as long as the log, so it would join every
# event in it into one incident and seem to corroborate any glitch anywhere in it
APART: frozenset[Evidence] = frozenset({Evidence.VEHICLE_BASELINE})

# The order evidence is listed in (report timeline strips, console): self-report first, strongest last.
ORDER: tuple[Evidence, ...] = tuple(EVIDENCE)


def label(evidence: Evidence | str) -> str:
    return EVIDENCE[Evidence(evidence)].label


def confidence(classes: set[Evidence]) -> str:
    """How sure an incident is, from the distinct evidence classes whose detectors alarmed in it.

    high: an independent reference and at least one more class agree, or three classes agree;
    medium: one independent reference alone, or two GNSS-internal classes agree;
    low: a single GNSS-internal class (reported as an anomaly, never called spoofing).
    Classes that are not spoofing evidence (`NOT_SPOOFING`) and those kept apart (`APART`) count for
    nothing here: an incident of theirs alone is an anomaly.
    """
    classes = {c for c in classes if c not in NOT_SPOOFING | APART}
    independent = {c for c in classes if EVIDENCE[c].independent}
    if (independent and len(classes) >= 2) or len(classes) >= 3:
        return "high"
    if independent or len(classes) == 2:
        return "medium"
    return "low"


RANK = {"low": 0, "medium": 1, "high": 2}
# Classes corroborate each other only when their alarms point at the same time: a receiver complaining
# while it converges at power-on and a GNSS-only glitch a minute later are two unrelated events.
CORROBORATION_S = 10.0

# an evidence class's alarm interval: (class, start s, end s)
Span = tuple[Evidence, float, float]


def corroborated(spans: Iterable[Span], window_s: float = CORROBORATION_S) -> set[Evidence]:
    """The classes that agree in time: for each alarm interval, the classes with an interval within
    `window_s` of it; of those sets, the one of highest confidence (then the most classes)."""
    spans = list(spans)
    best: set[Evidence] = set()
    for _, a0, a1 in spans:
        near = {c for c, b0, b1 in spans if b0 <= a1 + window_s and a0 <= b1 + window_s}
        if (RANK[confidence(near)], len(near)) > (RANK[confidence(best)] if best else -1, len(best)):
            best = near
    return best
