"""docs/architecture.md's worked example: a format is one reader module plus one line in READER_MODULES, a
detector one module plus one line in ANALYSIS_MODULES (and a precondition one entry in PRECONDITIONS). Both
toy modules are defined here and registered by monkeypatching the registries; from their declarations
alone the detector runs in `analyze`, appears in its JSON, in the report's method notes and in the
generated docs/detectors.md."""

from __future__ import annotations

import sys
import types
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import readers
from readers import ReaderFormat
from spooflens.detectors.base import DetectorResult, Series, Unmet, alarm_intervals
from spooflens.docs import render_detectors
from spooflens.epoch_table import EpochTable, StreamInfo, build_table
from spooflens.output.report import render_report
from spooflens.output.summary import build_summary
from spooflens.pipeline import preconditions, registry
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.preconditions import Precondition
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo
from spooflens.pipeline.run import analyze_table
from spooflens.schema import FixType
from spooflens.service import read_table

# --- the toy reader: a text file "TOYLOG" then "unix seconds,lat,lon,height" lines -------------------------


def read_toy(path: Path, topics: object = None, progress: object = None) -> EpochTable:
    rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    fixes = pd.DataFrame(
        {
            "t_ns": np.round(rows[:, 0] * 1e9).astype(np.int64),
            "receiver_id": "toy",
            "lat_deg": rows[:, 1],
            "lon_deg": rows[:, 2],
            "height_m": rows[:, 3],
            "fix_type": int(FixType.FIX_3D),
        }
    )
    streams = [StreamInfo("fix", "toy", path.name, "toy fix", len(fixes))]
    return build_table(path, "toy", "unix", {"fixes": fixes}, streams, [])


TOY_READER = types.ModuleType("toy_reader")
TOY_READER.FORMATS = (  # type: ignore[attr-defined]
    ReaderFormat("toy", "toy fixes (TOYLOG)", read_toy, lambda path, head: head.startswith(b"TOYLOG")),
)

# --- the toy detector: fix intervals much longer than the receiver's own ----------------------------------

TOY_DETECTOR_NAME = "toy_fix_interval"
TEN_FIXES = "toy_ten_fixes"


def ten_fixes(ctx: AnalysisContext) -> Unmet | None:
    n = len(ctx.table.fixes)
    return None if n >= 10 else Unmet(TEN_FIXES, f"{n} fixes", "the toy reads its fix period off 10 or more")


def run_toy(ctx: AnalysisContext) -> list[DetectorResult]:
    t = ctx.table.fixes["t_s"].to_numpy(float)
    ratio = np.r_[0.0, np.diff(t)] / np.median(np.diff(t))
    alarms = alarm_intervals(t, ratio, ratio > 3.0)
    return [DetectorResult(TOY_DETECTOR_NAME, True, "fix period read off the log", alarms, [Series("ratio", t, ratio)])]


TOY_DETECTOR = types.ModuleType("toy_detector")
TOY_DETECTOR.ANALYSIS = AnalysisSpec(  # type: ignore[attr-defined]
    "toy",
    "a toy: fix intervals against the receiver's own period",
    ("fixes",),
    run_toy,
    (
        DetectorInfo(
            TOY_DETECTOR_NAME,
            Evidence.GNSS_ONLY,
            "fix intervals longer than three fix periods",
            method="Each interval between fixes over the log's median interval.",
            threshold="3 fix periods",
            p_false_alarm="a toy's",
        ),
    ),
    preconditions=(TEN_FIXES,),
)


@pytest.fixture
def registered(monkeypatch: pytest.MonkeyPatch) -> None:
    """The one line each registry gets (here by monkeypatching), and the modules they name."""
    monkeypatch.setitem(sys.modules, "toy_reader", TOY_READER)
    monkeypatch.setitem(sys.modules, "toy_detector", TOY_DETECTOR)
    monkeypatch.setattr(readers, "READER_MODULES", ("toy_reader", *readers.READER_MODULES))
    monkeypatch.setattr(registry, "ANALYSIS_MODULES", (*registry.ANALYSIS_MODULES, "toy_detector"))
    monkeypatch.setitem(preconditions.PRECONDITIONS, TEN_FIXES, Precondition("10 fixes or more", ten_fixes))
    monkeypatch.setitem(readers.READERS, "toy", read_toy)  # the reader cache, restored after the test


def _toy_log(tmp_path: Path, n: int) -> Path:
    t = 1.7e9 + np.arange(n, dtype=float)
    t[n // 2 :] += 4.0  # one gap of five fix periods
    lines = [f"{s:.1f},{52.0 + 1e-5 * k:.7f},{5.0:.7f},40.0" for k, s in enumerate(t)]
    path = tmp_path / "flight.toy"
    path.write_text("TOYLOG\n" + "\n".join(lines) + "\n")
    return path


def test_a_toy_reader_and_detector_registered_by_one_line_each_run_in_analyze_json_report_and_docs(
    registered: None, tmp_path: Path
) -> None:
    table = read_table(_toy_log(tmp_path, 30), {}, show_progress=False)
    assert table.format == "toy" and len(table.fixes) == 30
    analysis = analyze_table(table)
    toy = next(r for r in analysis.results if r.name == TOY_DETECTOR_NAME)
    assert toy.ran and toy.evidence == Evidence.GNSS_ONLY  # the declared class
    assert [round(a.start_s) for a in toy.alarms] == [19]
    summary = build_summary(table, analysis.results, analysis.verdict)
    entry = next(a for a in summary["analyses"] if a["name"] == TOY_DETECTOR_NAME)
    assert entry["ran"] and entry["evidence"] == "gnss_only" and len(entry["alarms"]) == 1
    assert TOY_DETECTOR_NAME in summary["verdict"]["detectors_counted"]
    assert not summary["verdict"]["spoofed"]  # one GNSS-internal class is an anomaly, never spoofing
    page = render_report(analysis)
    assert f"<h3>{TOY_DETECTOR_NAME}" in page
    assert "Each interval between fixes over the log&#x27;s median interval." in page
    docs = render_detectors()
    assert f"| [`{TOY_DETECTOR_NAME}`](#{TOY_DETECTOR_NAME}) | `toy` | GNSS-only consistency | 3 fix periods |" in docs
    assert f"| `{TEN_FIXES}` | 10 fixes or more | stops | `{TOY_DETECTOR_NAME}` |" in docs


def test_the_toy_detector_does_not_run_where_its_precondition_fails_and_says_why(
    registered: None, tmp_path: Path
) -> None:
    table = read_table(_toy_log(tmp_path, 6), {}, show_progress=False)
    analysis = analyze_table(table)
    summary = build_summary(table, analysis.results, analysis.verdict)
    entry = next(a for a in summary["analyses"] if a["name"] == TOY_DETECTOR_NAME)
    assert not entry["ran"] and entry["reason"] == "6 fixes: the toy reads its fix period off 10 or more"
    assert entry["precondition"]["name"] == TEN_FIXES
    assert (
        f"<li><b>{TOY_DETECTOR_NAME}</b> (GNSS-only consistency): its model requires what this log does not have "
        f"({TEN_FIXES}): 6 fixes: the toy reads its fix period off 10 or more</li>"
    ) in render_report(analysis)
