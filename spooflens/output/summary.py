"""The machine-readable summary of an analysis (written by `spooflens analyze --json`).

Every time is given relative to the log start (`*_s`) and in the log's own clock (`*_abs_ns`, integer
nanoseconds, plus `*_utc` when the log has an absolute clock), so results map back to the raw log.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from typing import TYPE_CHECKING, Any

from spooflens import __version__
from spooflens.detectors.base import Alarm, DetectorResult, Finding
from spooflens.epoch_table import EpochTable
from spooflens.inventory import computed, skipped_or_repaired
from spooflens.pipeline.departure import gnss_departure
from spooflens.pipeline.evidence import label
from spooflens.pipeline.verdict import KIND_LABELS, Event, Explanation, Incident, Kind, Verdict

if TYPE_CHECKING:
    from spooflens.baseline.loaded import LoadedBaseline


def json_safe(x: Any) -> Any:
    """JSON cannot carry NaN/inf: they become null."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [json_safe(v) for v in x]
    return x


def _time(table: EpochTable, key: str, t_s: float | None) -> dict[str, Any]:
    if t_s is None:
        return {f"{key}_s": None}
    out: dict[str, Any] = {f"{key}_s": round(t_s, 6), f"{key}_abs_ns": int(table.absolute_ns(t_s))}
    if table.unix_ns(t_s) is not None:
        out[f"{key}_utc"] = table.absolute_iso(t_s)
    return out


def _alarm(table: EpochTable, a: Alarm) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, t in (("start", a.start_s), ("end", a.end_s), ("onset", a.onset_s), ("peak", a.peak_s)):
        out |= _time(table, key, t)
    out["peak_statistic"] = a.peak_statistic
    if a.onset_interval_s is not None:
        out["onset_interval_s"] = list(a.onset_interval_s)
    if a.receiver_id:
        out["receiver_id"] = a.receiver_id
    if a.satellites:
        out["satellites"] = list(a.satellites)
    if a.systems:
        out["systems"] = list(a.systems)
    if a.bands:
        out["bands"] = list(a.bands)
    if a.end_interval_s is not None:
        out["end_interval_s"] = list(a.end_interval_s)
    if a.range_error_m is not None:
        out["range_error_m"] = a.range_error_m
    return out


def _departure(
    table: EpochTable, results: list[DetectorResult], verdict: Verdict, inc: Incident
) -> list[dict[str, Any]]:
    """How far GNSS went from the reconstructed track: peak and at the end, per receiver."""
    out = []
    for d in gnss_departure(table, results, verdict, inc):
        item: dict[str, Any] = {"receiver_id": d.receiver_id, "track": d.track, "peak_m": round(d.peak_m, 2)}
        item |= _time(table, "peak", d.peak_s) | {"end_m": round(d.end_m, 2)} | _time(table, "at_end", d.end_s)
        out.append(item)
    return out


def _explanation(e: Explanation) -> dict[str, Any]:
    return {
        "kind": str(e.kind),
        "cause": e.cause,
        "text": e.text,
        "evidence": list(e.facts),
        "detectors": list(e.detectors),
        "receiver_id": e.receiver_id,
    }


def _kind(inc: Incident) -> Kind:
    if inc.kind is not None:
        return inc.kind
    return Kind.SPOOFING if inc.is_spoofing else Kind.UNKNOWN  # a verdict made without the event stage


def _incident(table: EpochTable, inc: Incident) -> dict[str, Any]:
    kind = _kind(inc)
    # the explanation that decided the kind (for a spoofing incident: the first weighed, which did not suffice)
    main = next((e for e in inc.explanations if e.kind == kind), inc.explanations[0] if inc.explanations else None)
    d: dict[str, Any] = {
        "kind": str(kind),
        "detectors": list(inc.detectors),
        "confidence": inc.confidence,
        "confidence_of_alarms": inc.confidence_of_alarms,
        "spoofing": inc.is_spoofing,
        "evidence": [str(e) for e in inc.evidence],
        "evidence_labels": [label(e) for e in inc.evidence],
        # the classes that alarmed at the same time, and of them the ones no natural cause accounts for: what
        # the confidence counts
        "corroborating_evidence": [str(e) for e in inc.corroborating],
        "unexplained_evidence": [str(e) for e in inc.unexplained],
        "explanation": _explanation(main) if main is not None else None,
        "explanations": [_explanation(e) for e in inc.explanations],
        "receivers": list(inc.receivers),
        "satellites": list(inc.satellites),
        "ongoing_at_end": inc.ongoing_at_end,
        "end_method": inc.end_method,
        "gnss_offset_from_reference_peak_m": inc.offset_peak_m,
        "gnss_offset_from_reference_at_end_m": inc.offset_end_m,
    }
    for key, t in (("onset", inc.onset_s), ("start", inc.start_s), ("end", inc.end_s)):
        d |= _time(table, key, t)
    if inc.onset_interval_s:
        d["onset_interval_s"] = list(inc.onset_interval_s)
    if inc.end_interval_s:
        d["end_interval_s"] = list(inc.end_interval_s)
    if inc.partly_explained:
        # alarm intervals a natural cause accounts for up to a time only (a takeover after jamming): what
        # follows is counted
        d["partly_explained"] = [
            {"evidence": str(sp[0]), "start_s": sp[1], "end_s": sp[2], "explained_until_s": until}
            for sp, until in inc.partly_explained
        ]
    return d


def _event(table: EpochTable, e: Event, sequences: dict[int, int]) -> dict[str, Any]:
    d: dict[str, Any] = {
        "kind": str(e.kind),
        "kind_label": KIND_LABELS[e.kind],
        "text": e.text,
        "confidence": e.confidence,
        "incident": e.incident,
        "evidence_for": list(e.evidence_for),
        "evidence_against": list(e.evidence_against),
        "spoofer_marks": [m.text for m in e.spoofer_marks],
        "ongoing_at_end": e.ongoing_at_end,
        "receivers": list(e.receivers),
        "satellites": list(e.satellites),
        "systems": list(e.systems),
        "bands": list(e.bands),
    }
    for key, t in (("onset", e.onset_s), ("start", e.start_s), ("end", e.end_s)):
        d |= _time(table, key, t)
    d["onset_interval_s"] = list(e.onset_interval_s) if e.onset_interval_s else None
    d["end_interval_s"] = list(e.end_interval_s) if e.end_interval_s else None
    # one attack sequence: a jamming event and the takeover that followed it (indices into `events`)
    d["sequence"] = (
        {"id": sequences[id(e)], "follows": e.follows, "followed_by": e.followed_by} if id(e) in sequences else None
    )
    return d


def _events(table: EpochTable, events: tuple[Event, ...]) -> list[dict[str, Any]]:
    sequences: dict[int, int] = {}
    for e in events:
        if e.followed_by is not None:
            n = len({*sequences.values()}) + 1
            sequences[id(e)] = sequences[id(events[e.followed_by])] = n
    return [_event(table, e, sequences) for e in events]


def _finding(table: EpochTable, f: Finding) -> dict[str, Any]:
    out: dict[str, Any] = {"text": f.text, "satellites": list(f.satellites), "receiver_id": f.receiver_id}
    if f.range_error_m is not None:
        out["range_error_m"] = f.range_error_m
    for key, t in (("start", f.start_s), ("end", f.end_s)):
        out |= _time(table, key, t)
    return out


def _analysis(table: EpochTable, r: DetectorResult) -> dict[str, Any]:
    out: dict[str, Any] = {
        "name": r.name,
        "ran": r.ran,
        "evidence": str(r.evidence) if r.evidence else None,
        "evidence_label": label(r.evidence) if r.evidence else None,
        "advisory": r.advisory,
        "reason": r.reason,
        "alarms": [_alarm(table, a) for a in r.alarms],
    }
    if r.ran:
        out["series"] = [
            {"name": s.name, "unit": s.unit, "threshold": s.threshold, "epochs": len(s.t)} for s in r.series
        ]
    if r.precondition is not None:  # what kept it from running, structured (`reason` says it in words)
        out["precondition"] = r.precondition.as_dict()
    if r.limitations:
        out["limitations"] = [u.as_dict() for u in r.limitations]
    if r.extras:
        out["facts"] = r.extras
    if r.findings:
        out["findings"] = [_finding(table, f) for f in r.findings]
    return out


def baseline_block(loaded: LoadedBaseline, results: list[DetectorResult]) -> dict[str, Any]:
    """What came from a baseline: its file and SHA-256, and what each analysis took from it."""
    b = loaded.content
    return {
        "file": loaded.file,
        "sha256": loaded.sha256,
        "created_utc": b.created_utc,
        "logs": len(b.logs),
        "warnings": list(loaded.warnings),
        "used_by": {r.name: str(r.extras["from_baseline"]) for r in results if "from_baseline" in r.extras},
    }


def build_summary(
    table: EpochTable, results: list[DetectorResult], verdict: Verdict, baseline: LoadedBaseline | None = None
) -> dict[str, Any]:
    incidents = [_incident(table, inc) for inc in verdict.incidents]
    # the reconstruction leaves GNSS out during the incident that made the verdict; during any other
    # incident the track still follows GNSS, so a distance from it would mean nothing
    deciding = verdict.deciding_incident
    for inc, d in zip(verdict.incidents, incidents, strict=True):
        if inc is deciding and inc.is_spoofing:
            d["gnss_departure"] = _departure(table, results, verdict, inc)
    summary = {
        "spooflens_version": __version__,
        "file": str(table.source),
        "format": table.format,
        "time_reference": table.time_reference,
        "t0_abs_ns": table.t0_ns,
        "metadata": dict(table.metadata),
        "t0_utc": table.absolute_iso(0.0) if table.unix_ns(0.0) is not None else None,
        "duration_s": round(table.duration_s, 6),
        "streams": [asdict(s) | {"rate_hz": s.rate_hz} for s in table.streams],
        "skipped": [s.as_dict() for s in skipped_or_repaired(table)],
        "computed": [s.as_dict() for s in computed(table)],
        "verdict": {
            "spoofed": verdict.spoofed,
            "headline": verdict.headline,
            "incidents": incidents,
            "events": _events(table, verdict.events),
            "detectors_counted": list(verdict.detectors_run),
            "detectors_advisory": list(verdict.detectors_advisory),
            "detectors_not_run": list(verdict.detectors_not_run),
            "findings": [_finding(table, f) for f in verdict.findings],
            "coasting_checks": list(verdict.coasting_checks),
            "reconstructed_tracks": [tr.name for tr in verdict.reconstructed],
        },
        "analyses": [_analysis(table, r) for r in results],
    }
    if baseline is not None:
        summary["baseline"] = baseline_block(baseline, results)
    return dict(json_safe(summary))
