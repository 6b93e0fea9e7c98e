"""The whole analysis of one log, as every front end runs it (CLI analyze, report, batch, fleet):

epoch table -> analyses (navigation, detectors) -> verdict -> reconstruction of each incident.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from spooflens.analysis import AnalysisContext, AnalyzeOptions, run_with_context
from spooflens.detectors.base import DetectorResult
from spooflens.epoch_table import EpochTable
from spooflens.verdict import Verdict, decide


@dataclass
class Analysis:
    table: EpochTable
    options: AnalyzeOptions
    results: list[DetectorResult]
    verdict: Verdict


def analyze_table(
    table: EpochTable, options: AnalyzeOptions | None = None, on_step: Callable[[str], None] | None = None
) -> Analysis:
    from spooflens.reconstruction import reconstruct

    ctx = AnalysisContext(table, options or AnalyzeOptions())
    results = run_with_context(ctx, on_step)
    verdict = decide(results)
    if on_step and any(i.is_spoofing for i in verdict.incidents):
        on_step("reconstruction")
    verdict = reconstruct(ctx, verdict)
    return Analysis(table, ctx.options, ctx.results, verdict)
