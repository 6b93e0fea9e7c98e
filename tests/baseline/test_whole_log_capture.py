"""A baseline never makes a detector blinder: a capture filling the whole log, judged against its vehicle's
clean logs, is at least as detected as without them (`spooflens bench baseline`'s car of vehicle seed 1,
its attacked log 1601)."""

from __future__ import annotations

import pytest

from spooflens.baseline.loaded import check
from spooflens.bench.baseline_bench import _loaded, _measure
from spooflens.bench.baseline_sim import LogSpec, coverage, simulate_log
from spooflens.pipeline.registry import AnalyzeOptions
from spooflens.pipeline.run import Analysis, analyze_table

pytestmark = pytest.mark.slow


def test_a_whole_log_capture_is_no_less_detected_with_the_vehicles_baseline() -> None:
    # the bench's car 1, log 1601: without a baseline a spoofing verdict over nearly the whole log; with a
    # baseline of the car's first two clean logs it was an anomaly over a tenth of it. The cap held the
    # velocity wander's size but not its time constant: the search made the wander five times faster
    # (0.1 m/s over 2 s where the clean logs learned 0.05 m/s over 6-17 s), the drag became the receiver's
    # noise, and the first pass suspected nothing to leave out of the learning
    baseline = _loaded([_measure(LogSpec("car", 1, 1000 + k)) for k in range(2)], "car 1, 2 logs")
    table, _ = simulate_log(LogSpec("car", 1, 1601, "capture"))
    t = table.fixes["t_s"].to_numpy(dtype=float)
    without = analyze_table(table)
    held = analyze_table(table, AnalyzeOptions(baseline=check(baseline, table)))

    def judged(analysis: Analysis) -> tuple[bool, float]:
        spoofing = [i for i in analysis.verdict.incidents if i.is_spoofing]
        return bool(spoofing), coverage(spoofing, float(t.min()), float(t.max()))

    (spoofed, covered), (spoofed_held, covered_held) = judged(without), judged(held)
    assert spoofed and covered > 0.8
    assert spoofed_held and covered_held >= covered - 0.05
    # the learned noise stays inside what the clean logs allow, the wanders' driving noise included
    nav = baseline.content.navigation
    assert nav is not None and held.learned_noise is not None
    noise = held.learned_noise.noise
    for sigma, tau, mine in (("bv_h", "tau_v", noise.gm_vel_mps[0]), ("b_h", "tau_p", noise.gm_pos_m[0])):
        rates = [s * s / c for s, c in zip(nav.parameters[sigma].values, nav.parameters[tau].values, strict=True)]
        tau_mine = noise.tau_vel_s if tau == "tau_v" else noise.tau_pos_s
        assert mine**2 / tau_mine <= 4.0 * max(rates) * (1 + 1e-9)
