"""Where the vehicle really was during each spoofing incident: the INS solution with the spoofed GNSS
left out, added to the navigation product's tracks.
"""

from __future__ import annotations

from spooflens.analysis import AnalysisContext
from spooflens.errors import SpooflensError
from spooflens.verdict import Verdict


def reconstruct(ctx: AnalysisContext, verdict: Verdict) -> Verdict:
    from spooflens.detectors.seed000 import reconstructed_track

    nav_result = next((r for r in ctx.results if r.name == "navigation" and r.ran), None)
    spoofing = [i for i in verdict.incidents if i.is_spoofing]
    if nav_result is None or not spoofing:
        return verdict
    try:
        nav = ctx.navigation()
    except SpooflensError:
        return verdict
    first = spoofing[0]
    sol = nav.solution
    end = None if first.end_s >= sol.t[-1] - 1e-6 else first.end_s
    velocity_honest = any(
        r.name == "gnss_consistency" and any(a.end_s >= first.onset_s for a in r.alarms) for r in ctx.results
    )
    nav_result.tracks.append(reconstructed_track(ctx.table, sol, first.onset_s, end, velocity_honest))
    return verdict
