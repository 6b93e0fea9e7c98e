"""The coasting check looks just past its deadline first and coasts on to the end of the log only for a
departure (or a disagreement still running where the first look ends): its decisions are those of the
coast to the end."""

from __future__ import annotations

from dataclasses import replace
from itertools import pairwise
from pathlib import Path

import numpy as np
from shared_inputs import simulated

from spooflens.attacks import apply_attack, parse_attack
from spooflens.navigation.product import solve_navigation
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.reconstruction import (
    CoastingCheck,
    CoastingOptions,
    Envelope,
    Placebo,
    _jumps_back,
    clean_coast_bound,
    coasting_check,
    placebo_coasts,
)
from spooflens.pipeline.registry import AnalyzeOptions
from spooflens.pipeline.run import analyze_segments
from spooflens.pipeline.verdict import Incident
from spooflens.service import read_table


def test_a_short_first_look_decides_as_the_coast_to_the_end() -> None:
    clean = simulated("multirotor", 2, 600.0).table
    table, _ = apply_attack(clean, parse_attack("step:offset=30,start=500"))
    nav = solve_navigation(table, AnalyzeOptions())
    opts = CoastingOptions()
    placebo = placebo_coasts(nav, opts)
    whole = replace(opts, first_look_s=1e9)  # the first look covers the log: one coast to the end
    for onset, confirmed in ((200.0, False), (499.0, True)):
        envelope = placebo.envelope((onset, onset + 1.0), [], opts.margin_s, opts.placebo_trim)
        deadline = onset + opts.confirm_window_s
        short, full = coasting_check(nav, onset, envelope, opts=opts), coasting_check(nav, onset, envelope, opts=whole)
        assert short.confirmed is full.confirmed is confirmed
        assert short.departure_s == full.departure_s and short.end_s == full.end_s
        assert full.t[-1] == nav.solution.t[-1]
        if confirmed:  # a departure: coasted on to the end, the same coast
            np.testing.assert_array_equal(short.t, full.t)
            np.testing.assert_array_equal(short.offset_m, full.offset_m)
        else:  # no departure: the coast stopped a first look past the deadline
            assert short.t[-1] <= deadline + opts.first_look_s < full.t[-1]
            n = len(short.t)
            np.testing.assert_array_equal(short.offset_m, full.offset_m[:n])


def test_a_gnss_outage_longer_than_a_coast_leaves_nothing_to_compare_and_the_analysis_goes_on() -> None:
    """No fix for 115 s (a jammed receiver reports nothing), then a 30 m step at 500 s: the clean coasts
    that fall in the outage are left out, a check starting in it coasts on to the next fixes, and the
    attack is caught (these coasts used to stop the whole analysis: 'no GNSS fix inside the IMU's time
    span')."""
    from spooflens.pipeline.reconstruction import coast
    from spooflens.pipeline.run import analyze_table

    table = simulated("multirotor", 2, 600.0).table
    table, _ = apply_attack(table, parse_attack("step:offset=30,start=500"))
    t = table.fixes["t_s"].to_numpy()
    table.fixes = table.fixes[(t < 205.0) | (t > 320.0)].reset_index(drop=True)
    nav = solve_navigation(table, AnalyzeOptions())
    assert coast(nav, 210.0, 300.0) is None
    opts = CoastingOptions()
    envelope = placebo_coasts(nav, opts).envelope((210.0, 211.0), [], opts.margin_s, opts.placebo_trim)
    check = coasting_check(nav, 210.0, envelope, opts=opts)
    assert check.t[0] > 320.0  # the first fixes after the outage are the first compared
    analysis = analyze_table(table)
    attack = next(i for i in analysis.verdict.incidents if i.is_spoofing)
    assert 495.0 <= attack.onset_s <= 501.0 and attack.ongoing_at_end


def test_a_clean_coast_cut_short_by_an_incident_still_bounds_the_longer_horizons() -> None:
    """Each clean coast's curve is a running maximum: one cut at 20 s (it reached a later incident) after
    departing to 6x the model by 10 s would have been at least that far at 50 s. Two quiet coasts that ran
    their full length do not make the envelope at 50 s the model's alone (on the husky bag attacked from
    157 s, that let its own wander of 2x at 50 s confirm a fictitious incident from 52 s)."""
    grid = np.arange(0.0, 61.0)
    loud = np.minimum(grid * 0.6, 6.0)  # 6x the model by 10 s
    curves = np.vstack([loud, np.full(len(grid), 0.7), np.full(len(grid), 0.9)])
    placebo = Placebo(np.array([30.0, 90.0, 240.0]), grid, curves)
    envelope = placebo.envelope((52.0, 60.0), [], 1.0, trim=0.0, later=[(152.0, 400.0)])
    # coast 30 s is clean up to the incident (20 s); coast 240 s starts inside the later one and counts nowhere
    assert envelope.runs == 2
    assert envelope.at(np.array([5.0]))[0] == 3.0
    assert envelope.at(np.array([50.0]))[0] == 6.0


def _coast_offsets(before_en: tuple[float, float], after_en: tuple[float, float], at_s: float) -> CoastingCheck:
    """A coasting check whose GNSS-minus-reference offset is `before_en` up to `at_s`, `after_en` after."""
    t = np.arange(100.0, 200.0, 0.4)
    d = np.where((t < at_s)[:, None], np.array(before_en), np.array(after_en))
    nothing = np.zeros_like(t)
    offset = np.hypot(d[:, 0], d[:, 1])
    return CoastingCheck(100.0, t, nothing, nothing, offset, True, 120.0, None, None, 130.0, d)


def test_only_a_jump_back_toward_the_reference_is_the_receivers_return() -> None:
    """GNSS 20 m east of the coasted reference: a transient across which it comes back to the reference
    ends the incident; one across which it jumps 50 m further away (a spoofer's step, a new attack) does not,
    though it is as large."""
    transient = Incident(157.6, 158.0, 157.2, None, ("gnss_consistency",), "low", (Evidence.GNSS_ONLY,))
    assert _jumps_back(_coast_offsets((20.0, 0.0), (1.0, 0.5), 157.6), transient, 10.0)
    assert not _jumps_back(_coast_offsets((20.0, 0.0), (70.0, 0.0), 157.6), transient, 10.0)
    assert not _jumps_back(_coast_offsets((20.0, 0.0), (20.0, 50.0), 157.6), transient, 10.0)


def test_the_margin_over_few_clean_coasts_is_a_next_clean_coasts_bound() -> None:
    """With one clean coast of an INS as spread as the real husky bag's, the next clean one may depart 19
    times further (1 % of them more); the bound falls with more coasts, and faster when the log's own coasts
    agree closely (never slower when they spread wider); a baseline's envelope, or many coasts, need only
    `margin`; none, the model's 5 times."""
    opts = CoastingOptions()
    prior = [clean_coast_bound(n, opts) for n in (1, 2, 5, 10, 30)]
    assert 18.0 < prior[0] < 21.0 and all(a > b for a, b in pairwise(prior))
    assert clean_coast_bound(5, opts, peak_log_sd=0.1) < clean_coast_bound(5, opts)
    # "clean" coasts spread wider than any real INS's hold something else: they never widen the bound
    assert clean_coast_bound(5, opts, peak_log_sd=1.5) == clean_coast_bound(5, opts)
    grid = np.arange(0.0, 61.0)
    few = Envelope(grid, np.ones_like(grid), 1)
    assert few.margin(opts) == clean_coast_bound(1, opts)
    assert Envelope(grid, np.ones_like(grid), 40, peak_log_sd=0.2).margin(opts) == opts.margin
    assert Envelope(grid, np.ones_like(grid), 1, from_baseline=True).margin(opts) == opts.margin
    assert Envelope(np.array([]), np.array([]), 0).margin(opts) == opts.uncalibrated_margin


def test_nested_calibration_coasts_count_as_the_independent_coasts_they_are_worth() -> None:
    """Calibration coasts every 5 s, each run up to the same incident, share most of their span: eight over
    40 s are worth under two independent coasts, and the bound of a next clean coast rests on that. Coasts
    that do not overlap each count one; placebo coasts (not nested) keep their count."""
    opts = CoastingOptions()
    grid = np.arange(0.0, 41.0)
    starts = np.arange(0.0, 40.0, 5.0)
    curves = np.ones((len(starts), len(grid)))
    nested = Placebo(starts, grid, curves, nested=True).envelope((45.0, 50.0), [], 0.0)
    assert nested.runs == 8 and 1.5 < nested.samples < 2.0
    assert nested.margin(opts) == clean_coast_bound(nested.samples, opts) > 3 * clean_coast_bound(8, opts)
    apart = Placebo(np.array([0.0, 100.0, 200.0]), np.arange(0.0, 11.0), np.ones((3, 11)), nested=True)
    assert apart.envelope((500.0, 510.0), [], 0.0).samples == 3.0
    assert Placebo(starts, grid, curves).envelope((45.0, 50.0), [], 0.0).samples == 8.0


def test_coasts_that_stayed_within_the_model_say_nothing_of_the_spread() -> None:
    """A clean coast's peak is floored at the model (1): coasts that all stayed within it are censored there,
    not a spread of 0 that would narrow the bound of the next one; the spread comes from peaks above it."""
    grid = np.arange(0.0, 31.0)
    starts = np.array([0.0, 40.0, 80.0])
    within = Placebo(starts, grid, np.full((3, len(grid)), 0.6)).envelope((200.0, 210.0), [], 0.0)
    assert within.runs == 3 and within.peak_log_sd is None
    assert within.margin(CoastingOptions()) == clean_coast_bound(3, CoastingOptions())
    curves = np.ones((3, len(grid))) * np.array([[0.6], [2.0], [3.0]])
    mixed = Placebo(starts, grid, curves).envelope((200.0, 210.0), [], 0.0)
    assert mixed.peak_log_sd is not None and abs(mixed.peak_log_sd - float(np.std(np.log([2.0, 3.0]), ddof=1))) < 1e-12


def test_the_husky_bags_late_glrt_alarm_against_coasts_within_the_model_is_no_spoofing(husky_bag: Path) -> None:
    """The real husky bag cut at 191.5 s for 180 s (`bench windows --seed 64`): a glrt alarm 20 s before the
    stretch's end departed 4.6 times the envelope of three clean coasts that all stayed within the model.
    Their floored peaks were read as a spread of 0 (bound 3.8): SPOOFING (medium); censored, the husky's
    prior spread holds (bound 5.1)."""
    table = read_table(husky_bag, {}, False)
    analysis = analyze_segments(table.between(191.5, 371.5))[0]
    assert not analysis.verdict.spoofed, analysis.verdict.headline
    (check,) = [c for c in analysis.verdict.coasting_checks if c["incident_start_s"] > 350.0]
    assert check["clean_coasts"] == 3 and not check["confirmed"] and 4.0 < check["peak_ratio_over_envelope"] < 5.1


def test_a_copters_manoeuvres_before_its_crash_against_nested_coasts_are_no_spoofing(real: Path) -> None:
    """The real log171 copter cut at 146.8 s for 75 s (`bench windows --seed 61`): its INS alarmed through
    the manoeuvres just before the crash, 4.4 times the envelope of 8 calibration coasts all run up to the
    alarm. Counted as 8 independent coasts they allowed 2.5 times, and the stretch was SPOOFING (medium)
    where the same log cut a few seconds earlier or later raised nothing; worth 1.8, they allow 9."""
    table = read_table(real / "corpus/dronekit-la-testdata/log171.bin", {}, False)
    analysis = analyze_segments(table.between(146.8, 221.8))[0]
    assert not analysis.verdict.spoofed, analysis.verdict.headline
    (check,) = [c for c in analysis.verdict.coasting_checks if c["incident_onset_s"] > 208.0]
    assert check["clean_coasts"] == 8 and check["independent_coasts"] < 2.0 and not check["confirmed"]


def test_beyond_its_longest_clean_horizon_the_envelope_grows_as_its_square() -> None:
    """A calibration coast of 8 s measured 3.7: at 16 s nothing measured says less than 4 times that."""
    envelope = Envelope(np.arange(0.0, 9.0), np.full(9, 3.7), 1)
    assert np.allclose(envelope.at(np.array([4.0, 8.0, 16.0])), [3.7, 3.7, 14.8])
