"""A log off its vehicle's baseline from its first fix to its last is an anomaly of its own over all of it:
never merged into another incident (`APART`), whatever else the verdict stages do with the log's events."""

from __future__ import annotations

from baseline_support import indicator_levels, loaded

from spooflens.baseline.learn import aggregate
from spooflens.baseline.loaded import check
from spooflens.bench.baseline_sim import LogSpec, coverage, simulate_log
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.registry import AnalyzeOptions
from spooflens.pipeline.run import analyze_table


def test_a_whole_log_level_anomaly_is_not_absorbed_into_the_takeovers_incident() -> None:
    # bench car 1, log 1600: the takeover's transient (GNSS-only and receiver alarms, 0.9-12.7 s: two
    # classes, so a spoofing candidate until the natural explanations are weighed) came before inertial
    # alarms the reconstruction stage coasted; it absorbed the level alarm that began inside it (1.3 s to
    # the end) and ended it at 12.7 s: the log flagged over 8 % of its length instead of all of it.
    # A baseline of the car's clean levels only, so the navigation learns as without one
    baseline = aggregate([indicator_levels(simulate_log(LogSpec("car", 1, 1000 + k))[0], k) for k in range(8)])
    table, _ = simulate_log(LogSpec("car", 1, 1600, "capture"))
    analysis = analyze_table(table, AnalyzeOptions(baseline=check(loaded(baseline), table)))
    t = table.fixes["t_s"].to_numpy(dtype=float)
    incidents = analysis.verdict.incidents
    (apart,) = [i for i in incidents if Evidence.VEHICLE_BASELINE in i.evidence]
    assert apart.evidence == (Evidence.VEHICLE_BASELINE,)
    assert apart.start_s < 5.0 and apart.ongoing_at_end
    assert coverage(list(incidents), float(t.min()), float(t.max())) > 0.95
    # and nothing else took it in
    assert all(Evidence.VEHICLE_BASELINE not in i.evidence for i in incidents if i is not apart)


def test_a_whole_log_level_anomaly_is_said_as_one_not_as_the_takeovers_jamming() -> None:
    # bench aircraft 2, log 2600 with eight clean logs: a level alarm from 2.6 s, just after the takeover's
    # transient (its jamming indicator +80), to the end; the log's own interference signs over that span
    # (the transient against the fixes before it) named the whole log JAMMING / INTERFERENCE
    from spooflens.detectors.base import Alarm, DetectorResult, Finding
    from spooflens.pipeline.events import classify
    from spooflens.pipeline.verdict import Kind, decide

    table, _ = simulate_log(LogSpec("aircraft", 2, 2600, "capture"))
    end = float(table.fixes["t_s"].max())
    off = "/gps/fix: indicator levels off the vehicle's baseline: mean C/N0 44.05 (baseline 39.6, z 3.8)"
    levels = DetectorResult(
        "receiver_levels",
        True,
        alarms=[Alarm(2.6, end, 5.0, 100.0, 0.0, receiver_id="/gps/fix")],
        findings=[Finding(off, 2.6, end, receiver_id="/gps/fix")],
        evidence=Evidence.VEHICLE_BASELINE,
    )
    verdict = classify(table, [levels], decide([levels], log_end_s=end))
    (event,) = verdict.events
    assert event.kind == Kind.UNKNOWN and event.confidence == "low"
    assert off in event.text
    assert any("takeover from before the first fix" in a for a in event.evidence_against)
    assert "JAMMING" not in verdict.headline
    assert verdict.headline.endswith(
        "receiver indicators off the vehicle's baseline from 2.60 s to the end of the log (one evidence class, "
        "not confirmed)"
    )
