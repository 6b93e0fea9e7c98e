"""The committed sample logs are what the generator makes, and each reads and analyses."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from paths import SAMPLE_LOGS

from readers import read_log
from spooflens.attacks import AttackTruth, sidecar_path
from spooflens.simulation.samples import SAMPLES, make, readme

SAMPLE_DIR = SAMPLE_LOGS


@pytest.mark.parametrize("sample", SAMPLES, ids=lambda s: s.name)
def test_committed_sample_equals_a_fresh_run(sample, tmp_path: Path) -> None:
    committed = read_log(SAMPLE_DIR / sample.name)
    fresh = read_log(make(sample, tmp_path))
    for frame in ("imu", "fixes", "observations"):
        pd.testing.assert_frame_equal(committed.frame(frame), fresh.frame(frame))
    truth = pd.read_csv(SAMPLE_DIR / f"{sample.name}.truth.csv")
    assert len(truth) == len(committed.fixes_of(committed.receivers()[0]))
    if sample.attack:
        assert AttackTruth.read(sidecar_path(SAMPLE_DIR / sample.name)).kind == sample.attack.split(":")[0]


def test_sample_readme_is_current() -> None:
    assert (SAMPLE_DIR / "README.md").read_text() == readme()
