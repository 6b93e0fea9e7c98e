"""The Rerun recording and JSON summary of an analysis, read back from disk."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from pipeline_support import circling_table
from rerun.chunk import RrdReader

from spooflens.output.recording import entity, write_recording
from spooflens.output.summary import build_summary
from spooflens.pipeline.registry import run_analyses
from spooflens.pipeline.verdict import decide


def _rows(path: Path, static: bool = False) -> dict[str, int]:
    """Rows per entity: time-indexed ones, or the static ones (lines, series names)."""
    rows: dict[str, int] = {}
    for chunk in RrdReader(str(path)).store().stream():
        if chunk.is_static == static:
            rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    return rows


def test_recording_holds_tracks_series_and_alarm_events(tmp_path: Path) -> None:
    table = circling_table(ramp_mps=3.0)
    results = run_analyses(table)
    verdict = decide(results)
    out = tmp_path / "a.rrd"
    write_recording(out, table, results, [(0.0, verdict.headline, "WARN")])
    rows = _rows(out)
    assert rows["/map/reported/gps/fix/position"] == 300
    assert rows["/local/reported/gps/fix/position"] == 300
    assert _rows(out, static=True)["/map/reported/gps/fix/track"] == 1  # the whole line, static
    assert rows["/imu/imu/specific_force_mps2"] == len(table.imu)
    assert rows["/detectors/gnss_consistency/gps/fix/statistic"] == 300
    assert rows["/detectors/gnss_consistency/gps/fix/statistic_threshold"] == 300
    # the verdict, then each alarm and its onset estimate
    expected = 1 + sum(len(r.alarms) + sum(a.onset_s is not None for a in r.alarms) for r in results)
    assert rows["/events"] == expected and next(r for r in results if r.name == "gnss_consistency").alarms
    assert rows["/detectors/glrt/glr"] == len(next(r for r in results if r.name == "glrt").series[0].t)


def test_summary_gives_times_relative_and_in_the_logs_clock(tmp_path: Path) -> None:
    table = circling_table(ramp_mps=3.0)
    results = run_analyses(table)
    summary = build_summary(table, results, decide(results))
    json.dumps(summary, allow_nan=False)  # strict JSON
    a = summary["analyses"][0]
    assert a["name"] == "gnss_consistency" and a["ran"]
    alarm = a["alarms"][0]
    assert alarm["start_abs_ns"] == table.t0_ns + round(alarm["start_s"] * 1e9)
    assert alarm["start_utc"].startswith("2023-11-14T22:")
    assert summary["verdict"]["spoofed"] and summary["verdict"]["incidents"][0]["onset_s"] <= alarm["start_s"]


def test_entity_paths_from_topics_are_clean() -> None:
    assert entity("map", "/gps/fix", "track") == "map/gps/fix/track"
    assert entity("imu", "imu data#1") == "imu/imu_data_1"


def test_each_detector_and_unit_gets_its_own_panel_of_real_entities(tmp_path: Path) -> None:
    from spooflens.output.recording import detector_panels

    table = circling_table(ramp_mps=3.0)
    results = run_analyses(table)
    out = tmp_path / "p.rrd"
    write_recording(out, table, results)
    written = {str(p) for p in RrdReader(str(out)).store().schema().entity_paths()}
    panels = dict(detector_panels(results))
    assert all(path in written for paths in panels.values() for path in paths)
    # a statistic and its threshold together; NIS, metres and metres per second apart
    assert panels["kf_innovation"] == [
        "/detectors/kf_innovation/position_nis",
        "/detectors/kf_innovation/position_nis_threshold",
    ]
    assert {"navigation (chi2(dof))", "navigation (m)", "navigation (m/s)"} <= set(panels)
    assert "/detectors/navigation/innovation_position_sigma" in panels["navigation (m)"]
    alarming = [r.name for r in results if r.alarms and not r.advisory]
    assert next(iter(panels)).split(" ")[0] in alarming  # the first tab shows a detector that alarmed


def test_the_writer_waits_for_rerun_to_write_what_it_sent_so_a_long_log_is_not_queued_in_memory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Rerun writes the file in threads of its own, slower than the columns are sent: the writer flushes
    every FLUSH_BYTES sent (a day of 100 Hz IMU series queued 0.6 GB otherwise), and the file holds the
    same rows however often it does."""
    import rerun as rr

    import spooflens.output.recording as recording

    table = circling_table(ramp_mps=3.0)
    results = run_analyses(table)
    flushes = []
    real_flush = rr.RecordingStream.flush

    def counted(self: rr.RecordingStream, **kw: float) -> None:
        flushes.append(1)
        real_flush(self, **kw)

    monkeypatch.setattr(rr.RecordingStream, "flush", counted)
    write_recording(tmp_path / "once.rrd", table, results)
    assert flushes == []  # a small log: all of it sent before Rerun is waited for (at the close)
    monkeypatch.setattr(recording, "FLUSH_BYTES", 10_000)
    write_recording(tmp_path / "often.rrd", table, results)
    assert len(flushes) > 10
    assert _rows(tmp_path / "often.rrd") == _rows(tmp_path / "once.rrd")
    assert _rows(tmp_path / "often.rrd", static=True) == _rows(tmp_path / "once.rrd", static=True)


def test_a_recording_begun_during_the_analysis_holds_what_one_written_after_it_does(tmp_path: Path) -> None:
    """`analyze` writes a log's streams while the analysis runs (side work) under a temporary name; the
    finished file holds the same rows as one written at once, and appears only when complete."""
    from spooflens.output.early_recording import EarlyRecording

    table = circling_table(ramp_mps=3.0)
    results = run_analyses(table)
    verdict = decide(results)
    lines = [(0.0, verdict.headline, "WARN")]
    at_once, begun = tmp_path / "a.rrd", tmp_path / "b.rrd"
    write_recording(at_once, table, results, lines, verdict)
    early = EarlyRecording(begun)
    early.begin(table)
    part = tmp_path / "b.rrd.part"
    assert part.exists() and not begun.exists()
    write_recording(begun, table, results, lines, verdict, early.take(begun, table))
    assert begun.exists() and not part.exists()
    assert _rows(begun) == _rows(at_once) and _rows(begun, static=True) == _rows(at_once, static=True)
    assert _rows(begun)["/imu/imu/specific_force_mps2"] == len(table.imu)
    early.begin(table)  # side work that starts late, after the recording was taken: nothing
    assert not part.exists()


def test_a_recording_begun_for_an_analysis_that_failed_leaves_the_earlier_file_alone(tmp_path: Path) -> None:
    from spooflens.output.early_recording import EarlyRecording

    table = circling_table(ramp_mps=0.0)
    out = tmp_path / "a.rrd"
    out.write_bytes(b"an earlier recording")
    early = EarlyRecording(out)
    early.begin(table)
    early.abandon()
    assert out.read_bytes() == b"an earlier recording" and not (tmp_path / "a.rrd.part").exists()
    other = EarlyRecording(out)  # begun for one table, asked for another (a log of several recordings)
    other.begin(table)
    assert other.take(out, circling_table(ramp_mps=0.0)) is None
    assert out.read_bytes() == b"an earlier recording" and not (tmp_path / "a.rrd.part").exists()


def test_the_overview_has_a_lane_per_kind_of_event_and_the_sky_shows_the_interference(tmp_path: Path) -> None:
    from dataclasses import replace

    import numpy as np

    from spooflens.detectors.base import Alarm, DetectorResult
    from spooflens.output.recording import overview_lanes
    from spooflens.pipeline.events import classify
    from spooflens.pipeline.evidence import Evidence

    table = circling_table()
    sats = pd.DataFrame(
        {
            "t_s": np.repeat(table.fixes["t_s"].to_numpy(), 6),
            "receiver_id": "/gps/fix",
            "sv_id": np.tile([f"G{k:02d}" for k in range(1, 7)], len(table.fixes)),
            "cn0_dbhz": 40.0,
        }
    )
    table = replace(table, satellites=sats)
    jam = DetectorResult(
        "interference", True, alarms=[Alarm(100.0, 130.0, 9.0, 101.0, 99.0)], evidence=Evidence.INTERFERENCE
    )
    odd = DetectorResult(
        "gnss_consistency", True, alarms=[Alarm(200.0, 205.0, 40.0, 201.0, 199.0)], evidence=Evidence.GNSS_ONLY
    )
    verdict = classify(table, [jam, odd], decide([jam, odd]))
    lanes = {name: level for name, _, level in overview_lanes([jam, odd], verdict, table.duration_s)}
    assert {"events: jamming", "events: unknown", "spoofing incidents"} <= set(lanes)
    assert lanes["events: jamming"].max() > lanes["events: jamming"].min()
    out = tmp_path / "k.rrd"
    write_recording(out, table, [jam, odd], [], verdict)
    rows = _rows(out)
    assert rows["/gnss/gps/fix/cn0_dbhz/interference"] > 0 and rows["/gnss/gps/fix/cn0_dbhz/G01"] == 300
    assert rows["/overview/events__jamming"] > 0
