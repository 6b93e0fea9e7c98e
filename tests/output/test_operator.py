"""What an operator expects around the report: `inspect` figures, odometry and truth drawn, the event
log's advisory tags, --fail-on-spoof, the recording's Overview tab, and the viewer kept offline."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from browser import Browser, chromium_path
from paths import REAL, SAMPLE_LOGS
from pipeline_support import circling_table
from rerun.chunk import RrdReader

from spooflens.cli import main
from spooflens.detectors.base import Alarm
from spooflens.epoch_table import EpochTable, StreamInfo
from spooflens.schema import make_frame
from spooflens.writers import write_log

SAMPLES = SAMPLE_LOGS
REAL_RINEX = REAL / "rinex_gsi_pair" / "07590920.05o"


def _row(out: str, first: str) -> str:
    return next(line for line in out.splitlines() if line.strip("│ ").startswith(first))


def test_inspect_gives_velocity_streams_their_rate_and_span(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(SAMPLES / "ground.bag")]) == 0
    out = capsys.readouterr().out
    vel = _row(out, "vel")
    assert "nan" not in vel and "301 messages" in vel and "5.00" in vel and "0.0 to 60.0" in vel
    # the same names `analyze` reports under: detectors and products, not the analysis modules
    names = [line.split("│")[1].strip() for line in out[out.index("Analyses") :].splitlines() if line.startswith("│")]
    assert {"kf_innovation", "navigation", "gnss_consistency"} <= set(names) and "inertial" not in names


def test_inspect_counts_observation_epochs_not_rows(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(SAMPLES / "meaconed_raw")]) == 0
    out = capsys.readouterr().out
    obs = _row(out, "observations")
    assert "181 epochs (1448 observations)" in obs and "1.00" in obs  # 1 Hz receiver, ~8 satellites


def test_inspect_a_rinex_log_lists_solved_fixes_as_computed_and_the_nav_file_plainly(
    capsys: pytest.CaptureFixture[str],
) -> None:
    if not REAL_RINEX.exists():
        pytest.fail(f"real log missing: {REAL_RINEX}")
    assert main(["inspect", str(REAL_RINEX)]) == 0
    out = capsys.readouterr().out
    obs, nav, fix = _row(out, "observations"), _row(out, "nav"), _row(out, "fix")
    assert "120 epochs" in obs and "1 per 30 s" in obs  # a 30 s RINEX file
    assert "162 records" in nav and "toe -16.0 to 86400.0" in nav and "│ -" in nav  # no rate for a nav file
    assert "│ computed " in fix and "single-point solution" in fix
    skipped = out[out.index("Skipped or repaired") : out.index("Computed")]
    assert "single-point" not in skipped and "single-point" in out[out.index("Computed") :]


def _circling_with_odometry(ramp_mps: float) -> EpochTable:
    """The circling vehicle with wheel odometry that follows the true circle (10 m/s, 1/60 rad/s)."""
    table = circling_table(ramp_mps=ramp_mps)
    t = np.arange(0.0, 300.0, 0.1)
    n = len(t)
    table.odometry = make_frame(
        "odometry",
        {
            "t_s": t,
            "odometry_id": ["/odom"] * n,
            "x_m": 600 * np.sin(t / 60),
            "y_m": 600 * (1 - np.cos(t / 60)),
            "z_m": np.zeros(n),
            "vx_mps": np.full(n, 10.0),
            "vy_mps": np.zeros(n),
            "vz_mps": np.zeros(n),
            "wz_radps": np.full(n, 1 / 60),
        },
    )
    table.streams.append(StreamInfo("odometry", "/odom", "/odom", "nav_msgs/msg/Odometry", n, 0.0, float(t[-1])))
    return table


def test_spoofed_log_with_odometry_fails_on_spoof_and_draws_the_wheels(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "circling.mcap"
    write_log(_circling_with_odometry(ramp_mps=3.0), log, "mcap-ros2")
    rrd, html, js = tmp_path / "c.rrd", tmp_path / "c.html", tmp_path / "c.json"
    code = main(["analyze", str(log), "-o", str(rrd), "--html", str(html), "--json", str(js), "--fail-on-spoof"])
    assert code == 4 and json.loads(js.read_text())["verdict"]["spoofed"]
    assert "SPOOFING DETECTED" in capsys.readouterr().out
    paths = {str(p) for p in RrdReader(str(rrd)).store().schema().entity_paths()}
    assert {"/odometry/odom/speed_mps", "/odometry/odom/path"} <= paths
    text = html.read_text()
    assert 'data-plot="odometry"' in text and "wheel odometry /odom" in text
    # without the flag the same verdict is not an error
    assert main(["analyze", str(log), "-o", str(rrd), "--quiet"]) == 0


def test_advisory_alarms_say_so_in_the_event_log() -> None:
    from spooflens.output.recording import _alarm_events

    alarm = Alarm(20.0, 30.0, 5.0, 25.0, onset_s=18.0)
    t, text, level = _alarm_events("mlrt", [alarm], advisory=True)
    assert all("advisory" in x.lower() for x in text) and level == ["INFO", "INFO"] and t == [20.0, 18.0]
    _, text, level = _alarm_events("glrt", [alarm], advisory=False)
    assert text[0].startswith("glrt: ALARM") and level == ["WARN", "WARN"]


def test_recording_opens_on_the_overview_tab_then_the_detectors() -> None:
    from spooflens.output.recording import default_blueprint, detector_panels, key_statistics, overview_lanes
    from spooflens.pipeline.registry import run_analyses
    from spooflens.pipeline.verdict import decide

    results = run_analyses(circling_table(ramp_mps=3.0))
    keys = key_statistics(results)
    # one key statistic per evidence class that ran, from a detector that alarmed
    assert [k.evidence.value for k in keys] == ["gnss_only", "receiver", "inertial"]
    assert keys[0].detector == "gnss_consistency" and keys[1].detector == "receiver_evidence"
    by_name = {r.name: r for r in results}
    inertial = by_name[keys[2].detector]
    assert inertial.alarms and not inertial.advisory  # the inertial detector that alarmed, not the first that ran
    assert keys[2].paths[0].startswith(f"/detectors/{inertial.name}/") and keys[2].paths[1].endswith("_threshold")
    panels = detector_panels(results)
    tabs = default_blueprint(panels, keys).root_container
    contents = list(tabs.contents)
    assert tabs.active_tab is not None and contents[0].name == "Overview"
    assert [c.name for c in contents[1 : 1 + len(panels)]] == [title for title, _ in panels]
    lanes = {name: level for name, _, level in overview_lanes(results, decide(results), 300.0)}
    assert set(lanes) == {"GNSS-only consistency", "receiver self-report", "inertial reference", "spoofing incidents"}
    assert lanes["inertial reference"].max() == pytest.approx(2.8) and lanes["spoofing incidents"].max() == 0.8 - 1


def test_viewer_runs_with_rerun_analytics_disabled(tmp_path: Path) -> None:
    from spooflens.output.viewer import private_rerun_config, rerun_binary

    with private_rerun_config() as env:
        shown = subprocess.run(
            [rerun_binary(), "analytics", "config"], env=env, capture_output=True, text=True, timeout=60
        )
        config_home = env["XDG_CONFIG_HOME"]
    config = json.loads(shown.stdout[shown.stdout.index("{") : shown.stdout.rindex("}") + 1])
    assert config["analytics_enabled"] is False
    assert not Path(config_home).exists()  # made for the run, removed after it


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def _listening(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


def test_web_viewer_is_served_on_loopback_and_calls_nowhere(tmp_path: Path) -> None:
    """`spooflens view --web` in a real browser: the viewer loads from this machine and reads the recording
    from this machine; its telemetry, update check and web font are refused before they leave."""
    if chromium_path() is None:
        pytest.fail("chromium is not installed: the README's test command installs it")
    from spooflens.output.recording import write_recording

    table = circling_table(seconds=60.0)
    rrd = tmp_path / "v.rrd"
    write_recording(rrd, table, [])
    port, grpc = _free_port(), _free_port()
    cmd = [sys.executable, "-m", "spooflens.cli", "view", str(rrd), "--web", "--port", str(port)]
    proc = subprocess.Popen([*cmd, "--grpc-port", str(grpc)], stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not _listening(port) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
        assert _listening(port), "spooflens view --web did not start"
        url = f"http://127.0.0.1:{port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}%2Fproxy"
        with Browser() as browser:
            page = browser.open(url)
            # until the viewer asked for the recording, then long enough for what it would call after that
            asked = f"http://127.0.0.1:{grpc}/"
            browser.wait_for(page, lambda p: any(r.startswith(asked) for r in p.requests), 30.0, then_s=3.0)
        loopback = ("http://127.0.0.1:", "http://localhost:")
        assert any(r.endswith("re_viewer_bg.wasm") for r in page.requests)  # the viewer itself loaded
        assert any(r.startswith(asked) for r in page.requests)  # and asked for the data
        left = [r for r in page.requests if not r.startswith(loopback) and r not in page.blocked]
        assert left == []
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    assert not _listening(port) and not _listening(grpc)  # the viewer went with it
