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
