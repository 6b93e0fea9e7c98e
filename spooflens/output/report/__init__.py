"""The operator report: one self-contained HTML page per analysis (`spooflens report`, `analyze --html`).

    from spooflens.output.report import write_report
    write_report(Path("report.html"), analysis)   # analysis = spooflens.pipeline.run.analyze_table(...)

The page opens offline in any browser: CSS and figures (SVG drawn by matplotlib) are inline, there is
no script, and a Content-Security-Policy forbids fetching anything. Figures come from what the
analysis declares (`figures.py`), the page's text from the verdict, the table and the detector
declarations (`page.py`).
"""

from __future__ import annotations

from pathlib import Path

from spooflens.output.report.figures import Plot
from spooflens.pipeline.registry import detector_infos
from spooflens.pipeline.run import Analysis


def build_plots(analysis: Analysis) -> list[Plot]:
    """Every figure of the report, in page order within each section."""
    from spooflens.output.report import figures

    table, results, verdict = analysis.table, analysis.results, analysis.verdict
    infos = detector_infos()
    with figures.style():
        # a log of no stream (nothing to judge) has no time axis to draw on
        plots = [figures.timeline(table, results, verdict, infos)] if table.streams else []
        plots += [p for p in (figures.track(table, results, verdict), figures.departure(table, results, verdict)) if p]
        for r in results:
            plots += figures.detector_plots(r, table)
        plots += figures.receiver_quality(table, verdict)
        plots += figures.odometry(table, verdict)
    return plots


def render_report(analysis: Analysis) -> str:
    from spooflens.output.report.page import page
    from spooflens.output.report.provenance import identify

    return page(analysis, build_plots(analysis), identify(analysis.table.source), detector_infos())


def write_report(path: Path, analysis: Analysis) -> int:
    """Write the report of `analysis` to `path`; returns its size in bytes."""
    text = render_report(analysis)
    data = text.encode("utf-8")
    Path(path).write_bytes(data)
    return len(data)
