"""The console script's entry: `spooflens.cli:run` runs `main` and ends the process with its exit code."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

from paths import ROOT

from spooflens.service import EXIT_INPUT, EXIT_OK


def _spooflens(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """`spooflens ARGS` as the console script runs it (python -m runs the same `run`)."""
    return subprocess.run(
        [sys.executable, "-m", "spooflens.cli", *args], capture_output=True, text=True, cwd=cwd, check=False
    )


def test_the_console_script_is_run() -> None:
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["spooflens"] == "spooflens.cli:run"


def test_a_log_that_cannot_be_read_ends_the_process_with_the_input_error_code(tmp_path: Path) -> None:
    bad = tmp_path / "flight.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 40)  # the magic, then nothing readable
    done = _spooflens("analyze", str(bad), "-o", str(tmp_path / "out.rrd"), "--quiet", cwd=tmp_path)
    assert done.returncode == EXIT_INPUT
    assert "Traceback" not in done.stderr
    assert done.stderr.strip().startswith("spooflens: error:") and "flight.mcap" in done.stderr


def test_an_analysis_ends_the_process_with_success_and_its_outputs_complete(tmp_path: Path) -> None:
    rrd, report = tmp_path / "out.rrd", tmp_path / "out.json"
    log = ROOT / "sample_logs" / "ground_json.mcap"
    done = _spooflens("analyze", str(log), "-o", str(rrd), "--json", str(report), "--quiet", cwd=tmp_path)
    assert done.returncode == EXIT_OK, done.stderr
    assert rrd.stat().st_size > 0 and report.read_text().strip().endswith("}")
