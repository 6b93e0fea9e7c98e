"""The analysis's passes: the noise is learned again without what the first pass suspected only when a
suspected stretch touches the fixes it was learned from; and an inertial glitch shortly before an
attack is not confirmed by the attack's own departure."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from shared_inputs import simulated

from spooflens.attacks import apply_attack, parse_attack
from spooflens.navigation.loosely_coupled import ANALYSIS_NEEDS, run_prepared
from spooflens.navigation.product import solve_navigation
from spooflens.pipeline.reconstruction import coast
from spooflens.pipeline.registry import AnalyzeOptions
from spooflens.pipeline.run import analyze_table, suspected_spans
from spooflens.simulation.simulate import simulate


def test_an_attack_after_the_learning_window_needs_no_second_pass_and_keeps_its_own_onset() -> None:
    # 10 Hz GNSS: the noise is learned on the first 300 s; a 30 m step at 500 s. This clean flight has
    # an inertial glitch (GLRT alone, not confirmed) at 465 s, 35 s before the attack
    clean = simulated("multirotor", 2, 600.0).table
    table, _ = apply_attack(clean, parse_attack("step:offset=30,start=500"))
    analysis = analyze_table(table)
    assert analysis.passes == 1 and analysis.suspected_s == ()
    attack = next(i for i in analysis.verdict.incidents if i.is_spoofing)
    # the glitch's coast must not be confirmed by the step: the step is the next incident's departure
    assert 499.0 <= attack.onset_s <= 500.0 and attack.ongoing_at_end, attack
    glitch = [i for i in analysis.verdict.incidents if i.end_s < 490.0]
    assert glitch and not any(i.is_spoofing for i in glitch)

    # what the skipped pass would have learned: the same noise, to the last digit
    nav = solve_navigation(table, AnalyzeOptions())
    spans = suspected_spans(analysis.verdict)
    assert spans and min(a for a, _ in spans) > nav.learned.window_s[1]
    again = solve_navigation(table, AnalyzeOptions(), exclude=spans, aligned=(nav.inputs, nav.start))
    assert again.learned.noise == nav.learned.noise and again.learned.imu_scale == nav.learned.imu_scale


def test_an_attack_inside_the_learning_window_is_left_out_of_a_second_learning() -> None:
    # 1 Hz GNSS: the noise is learned on the first 1,500 fixes, which the attack at 500 s falls inside
    clean = simulate("ship", seed=1, duration_s=600.0).table
    table, _ = apply_attack(clean, parse_attack("step:offset=30,start=500"))
    analysis = analyze_table(table)
    assert analysis.passes == 2
    assert any(a <= 500.0 <= b for a, b in analysis.suspected_s), analysis.suspected_s
    attack = next(i for i in analysis.verdict.incidents if i.is_spoofing)
    assert 498.0 <= attack.onset_s <= 500.0 and attack.ongoing_at_end


def test_the_learning_runs_stop_at_the_last_scored_epoch_and_learn_what_runs_to_the_windows_end_learn(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The filter is causal, so candidate runs that stop at the last scored epoch give every score, and
    so the learned noise, bit for bit; a second pass whose suspected stretch runs past the window's end
    runs only the span before it."""
    from spooflens.navigation import noise_learning
    from spooflens.navigation.imu_models import grade

    table = simulate("aircraft", seed=4, duration_s=160.0).table
    nav = solve_navigation(table, AnalyzeOptions())
    preset = grade("consumer_mems")
    t0 = float(nav.inputs.fixes["t_s"].iloc[0])
    suspected = ((t0 + 70.0, t0 + 1e6),)
    opts = noise_learning.LearnOptions(min_window_s=120.0, max_epochs=1000)  # a short window: fewer runs
    ends: list[float] = []
    cut = noise_learning._up_to_last_scored

    def spy(*args: Any) -> Any:
        inputs, mask = cut(*args)
        ends.append(float(inputs.fixes["t_s"].iloc[-1]))
        assert len(mask) == len(inputs.fixes)
        return inputs, mask

    learned = {}
    for name, stop in (("stopped", spy), ("whole", lambda inputs, t, mask: (inputs, mask))):
        monkeypatch.setattr(noise_learning, "_up_to_last_scored", stop)
        learned[name] = [
            noise_learning.learn_noise(nav.inputs, preset, nav.start, None, exclude, opts)
            for exclude in ((), suspected)
        ]
    assert learned["stopped"] == learned["whole"]  # noise, IMU scale, run count and likelihood, exactly
    assert learned["whole"][1].neg_log_likelihood != learned["whole"][0].neg_log_likelihood
    assert t0 + 40.0 < ends[1] < t0 + 70.0  # the second pass's runs stop where the suspected stretch begins


def test_a_coast_from_the_solution_that_keeps_every_tenth_covariance_is_the_full_solutions() -> None:
    table = simulate("multirotor", seed=4, duration_s=240.0).table
    nav = solve_navigation(table, AnalyzeOptions())
    every = nav.solution.P_upd_every
    assert every == 10 and len(nav.solution.P_upd) == -(-len(nav.solution.t) // every)
    full = run_prepared(nav.inputs, replace(nav.solution.options, record=ANALYSIS_NEEDS, P_upd_every=1), nav.start)
    assert full.P_upd_every == 1 and np.array_equal(full.nu, nav.solution.nu, equal_nan=True)
    for t_from in (100.0, 123.37, 187.05):  # on a kept epoch, between, just after one
        thinned, whole = coast(nav, t_from, t_from + 40.0), coast(nav, t_from, t_from + 40.0, base=full)
        assert thinned is not None and whole is not None
        assert np.array_equal(thinned.t, whole.t) and thinned.t[0] > t_from
        assert np.allclose(thinned.nu, whole.nu, rtol=1e-9, atol=1e-9, equal_nan=True)
        assert np.allclose(thinned.S_all, whole.S_all, rtol=1e-9, atol=1e-12)
        assert len(thinned.S_all) == len(thinned.t)  # a coast is compared with the GNSS it leaves out
    assert len(nav.solution.S_all) == 1  # the solution itself is not: no (M, 9, 9) kept for nothing
