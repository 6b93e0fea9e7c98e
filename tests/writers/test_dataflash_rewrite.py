"""Attacked copies of DataFlash logs of every revision: the receiver's time moved under the field names the
log's own revision gives it (a 2015 ArduCopter 3.3 log calls GPS week and ms of week `Week`/`TimeMS`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from paths import real_log

from readers import read_log
from spooflens.cli import main


def test_an_attack_that_moves_the_clock_rewrites_an_old_logs_week_and_time_of_week(tmp_path: Path) -> None:
    log = real_log("corpus/dronekit-la-testdata/log171.bin")
    out = tmp_path / "log171_capture.bin"
    assert main(["inject", str(log), "--attack", "capture:start=60,clock=0.5", "-o", str(out)]) == 0
    clean, spoofed = read_log(log).fixes, read_log(out).fixes
    before = clean["t_s"].to_numpy() < 59.0
    moved = spoofed["time_offset_s"].to_numpy() - clean["time_offset_s"].to_numpy()
    # the log's clock is put on GPS time by the median offset over all fixes, attacked ones included: the
    # attack shows as one step of the receiver's time, 0.5 s (GMS/TimeMS is whole milliseconds), after 60 s
    low, high = moved[before].min(), moved[-1]
    assert np.ptp(moved[before]) < 1e-6 and high - low == pytest.approx(0.5, abs=2e-3)
    assert np.all((np.abs(moved - low) < 2e-3) | (np.abs(moved - high) < 2e-3))
    assert np.all(np.diff(moved) > -2e-3)  # once moved, it stays moved
