"""The whole analysis of one log, as every front end runs it (CLI analyze, report, batch, fleet):

    epoch table -> analyses (navigation, detectors) -> verdict -> confirmation and reconstruction of each
    incident (`spooflens.pipeline.reconstruction`) -> natural explanations and the kind of every event
    (`spooflens.pipeline.events`).

The sensors' noise is learned from the log (`spooflens.navigation.noise_learning`). An attack inside
the learning window would teach the filter that the attack is noise, so when the first pass finds
anything suspicious inside the stretch the noise was learned from, the noise is learned again with
those stretches left out and the analyses run a second time on that filter: the noise is kept fixed
through a suspected attack. Anything suspected after that stretch could not have taught the filter,
and the first pass stands.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from spooflens import plausibility
from spooflens.detectors.base import DetectorResult
from spooflens.epoch_table import EpochTable
from spooflens.errors import AnalysisError, SpooflensError
from spooflens.inventory import without_gnss
from spooflens.navigation.alignment import Alignment
from spooflens.navigation.loosely_coupled import FilterInputs
from spooflens.navigation.noise_learning import LearnedNoise
from spooflens.navigation.product import NAVIGATION, Navigation, navigations, solve_navigation
from spooflens.navigation.strapdown import NavState
from spooflens.pipeline.events import classify
from spooflens.pipeline.evidence import APART
from spooflens.pipeline.reconstruction import Envelope, clean_envelope, reconstruct
from spooflens.pipeline.registry import (
    NAVIGATION_PARTS,
    AnalysisContext,
    AnalyzeOptions,
    navigation_parts,
    run_with_context,
)
from spooflens.pipeline.verdict import Verdict, decide
from spooflens.schema import FRAMES

SUSPECT_MARGIN_S = 10.0


@dataclass(frozen=True)
class Analysis:
    table: EpochTable
    options: AnalyzeOptions
    results: list[DetectorResult]
    verdict: Verdict
    passes: int = 1
    suspected_s: tuple[tuple[float, float], ...] = ()  # left out of the noise learning of the last pass
    # what the results were made from (the navigation solution among them), kept only when asked: to
    # assess the results again with evidence added later (`spooflens fleet`)
    context: AnalysisContext | None = None
    learned_noise: LearnedNoise | None = None  # the navigation's, when it ran (what a baseline records)
    # how far GNSS departs from INS coasts started all over this log (`clean_coasts`: a baseline's)
    clean_envelope: Envelope | None = None


def last_fix_s(table: EpochTable) -> float | None:
    """The time of the log's last GNSS fix: an incident lasting to it lasted to the end of the log."""
    t = table.fixes["t_s"].to_numpy(dtype=float)
    return float(np.nanmax(t)) if len(t) and np.isfinite(t).any() else None


def assess(
    ctx: AnalysisContext, results: Sequence[DetectorResult], on_step: Callable[[str], None] | None = None
) -> Verdict:
    """The verdict on `results` (those `ctx` made, with any evidence added since, such as the fleet's): the
    incidents their alarms make, each inertial one confirmed, ended and reconstructed by coasting the INS
    of `ctx`, then each weighed against its natural explanations and given its kind. Every front end
    decides through here."""
    verdict = decide(list(results), log_end_s=last_fix_s(ctx.table), without_gnss=without_gnss(ctx.table))
    if on_step and verdict.incidents:
        on_step("confirmation and reconstruction")
    verdict = reconstruct(ctx, results, verdict)
    if on_step and verdict.incidents:
        on_step("natural explanations")
    return classify(ctx.table, results, verdict)


def _one_pass(
    table: EpochTable, options: AnalyzeOptions, on_step: Callable[[str], None] | None, cache: dict[str, object]
) -> tuple[AnalysisContext, Verdict]:
    ctx = AnalysisContext(table, options, cache=dict(cache))
    results = run_with_context(ctx, on_step)
    return ctx, assess(ctx, results, on_step)


def suspected_spans(verdict: Verdict, margin_s: float = SUSPECT_MARGIN_S) -> tuple[tuple[float, float], ...]:
    """Every incident and anomaly of a verdict, and every inertial alarm its coast cleared (no anomaly, yet
    where the filter's test alarmed: a capture filling the log alarms there too), widened by `margin_s`,
    merged; not those of the classes kept apart (a log off its vehicle's baseline: the baseline already
    caps what the noise learning may take from it, and a whole log left out would leave nothing to learn
    from)."""
    spans = sorted(
        [
            (min(i.onset_s, i.start_s) - margin_s, i.end_s + margin_s)
            for i in verdict.incidents
            if not set(i.evidence) <= APART or not i.evidence
        ]
        + [
            (min(c["incident_onset_s"], c["incident_start_s"]) - margin_s, c["incident_end_s"] + margin_s)
            for c in verdict.coasting_checks
            if c.get("cleared")
        ]
    )
    merged: list[tuple[float, float]] = []
    for a, b in spans:
        if merged and a <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], b))
        else:
            merged.append((a, b))
    return tuple(merged)


def _within_learning(spans: tuple[tuple[float, float], ...], part: AnalysisContext, nav: Navigation) -> bool:
    """Whether a suspected stretch touches the fixes the noise was learned from (the initial guess
    reads every fix of the part up to the learning window's end, the likelihood those inside it): a part
    between the IMU's gaps holds no fix before its span."""
    since = part.span_s[0] if part.span_s is not None else -np.inf
    return any(a <= nav.learned.window_s[1] and b >= since for a, b in spans)


def analyze_table(
    table: EpochTable,
    options: AnalyzeOptions | None = None,
    on_step: Callable[[str], None] | None = None,
    keep_context: bool = False,
    clean_coasts: bool = False,
) -> Analysis:
    """The whole analysis of one recording. `clean_coasts`: also measure how far GNSS departs from INS
    coasts started all over the log, its incidents left out (what a vehicle's baseline records)."""
    options = options or AnalyzeOptions()
    problems = plausibility.problems({name: table.frame(name) for name in FRAMES})
    if problems:  # a table built by hand: the readers drop and list such rows (spooflens.epoch_table.checked)
        raise AnalysisError(
            f"{table.source}: values no sensor produces ({'; '.join(problems[:4])}); nothing analysed "
            "(pass the table through spooflens.epoch_table.checked to drop and list them)"
        )
    ctx, verdict = _one_pass(table, options, on_step, {})
    kept = ctx if keep_context else None
    spans = suspected_spans(verdict)
    parts, navigated = navigation_parts(ctx), navigations(ctx)
    navs = [nav for _, nav in navigated]
    if not spans or not any(_within_learning(spans, part, nav) for part, nav in navigated):
        # nothing suspected, or only after the noise was learned: learning it again without those
        # stretches gives the same noise, and the second pass the same results
        return _done(Analysis(table, options, ctx.results, verdict, context=kept), navs, clean_coasts)
    # the first pass's shared work (its navigation solution: a gigabyte per hour of 10 Hz GNSS) goes
    # before the second pass builds its own; its results stay for when the second pass cannot run
    again = [_again(part, spans) for part in parts]
    segmented = parts[0] is not ctx
    first_results = ctx.results
    del ctx, parts, navigated, navs
    if on_step:
        on_step("learning the noise again without the suspected stretches")
    try:
        solved = [
            None if p.aligned is None else solve_navigation(p.table, options, exclude=spans, aligned=p.aligned)
            for p in again
        ]
    except SpooflensError:
        return Analysis(table, options, first_results, verdict, context=kept)
    del first_results, kept
    if segmented:
        seed: dict[str, object] = {
            NAVIGATION_PARTS: [
                AnalysisContext(p.table, options, {NAVIGATION: nav} if nav is not None else p.cache, span_s=p.span_s)
                for p, nav in zip(again, solved, strict=True)
            ]
        }
    else:
        seed = {NAVIGATION: solved[0]}
    del again, solved
    ctx, verdict = _one_pass(table, options, on_step, seed)
    return _done(
        Analysis(table, options, ctx.results, verdict, 2, spans, ctx if keep_context else None),
        [nav for _, nav in navigations(ctx)],
        clean_coasts,
    )


@dataclass(frozen=True)
class _SecondPass:
    """What the second pass takes of a part of the log the first navigated (`navigation_parts`)."""

    table: EpochTable
    span_s: tuple[float, float] | None
    # the IMU integrated and the alignment, when its noise is learned again (neither depends on the noise)
    aligned: tuple[FilterInputs, tuple[NavState, Alignment | None]] | None
    # else the part's work as it is: its noise was learned before anything suspected, and stands
    cache: dict[str, object]


def _again(part: AnalysisContext, spans: tuple[tuple[float, float], ...]) -> _SecondPass:
    nav: Navigation | None = part.cache.get(NAVIGATION)
    if nav is not None and _within_learning(spans, part, nav):
        return _SecondPass(part.table, part.span_s, (nav.inputs, nav.start), {})
    return _SecondPass(part.table, part.span_s, None, dict(part.cache))


def _done(analysis: Analysis, navs: list[Navigation], clean_coasts: bool) -> Analysis:
    """The analysis with what it keeps of its navigation: the noise it learned and, when asked, the clean
    coasts' envelope (the solution itself, a gigabyte per hour of 10 Hz GNSS, is let go). Where the IMU
    stops, the longest stretch's: a baseline keeps one noise per log, and that stretch taught the most."""
    if not navs:
        return analysis
    nav = max(navs, key=lambda n: float(n.solution.t[-1] - n.solution.t[0]))
    envelope = None
    if clean_coasts:
        envelope = clean_envelope(nav, [(min(i.onset_s, i.start_s), i.end_s) for i in analysis.verdict.incidents])
    return replace(analysis, learned_noise=nav.learned, clean_envelope=envelope)


def analyze_segments(
    table: EpochTable,
    options: AnalyzeOptions | None = None,
    on_step: Callable[[str], None] | None = None,
    clean_coasts: bool = False,
) -> list[Analysis]:
    """One analysis per recording: a log that joins several (its clock jumped back) is never analysed
    as one interleaved stream."""
    if len(table.segments) < 2:
        return [analyze_table(table, options, on_step, clean_coasts)]
    return [analyze_table(table.segment(k), options, on_step, clean_coasts) for k in range(len(table.segments))]
