"""Logs in the wrong unit, built here from a clean one: recognised by physics at the reader boundary
(gravity at rest, angular rates a vehicle reaches, the track against the reported speed, heights that
do not jump kilometres) and scaled with a listed note, or left out with one; sentinels and zero
coordinates dropped. Each repaired log reads back as the clean one."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from paths import SAMPLE_LOGS
from pipeline_support import circling_table

from readers import read_log
from spooflens.cli import main
from spooflens.writers import write_log


@pytest.fixture(scope="module")
def clean(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("clean") / "log"
    write_log(circling_table(seconds=300.0), path, "csv")
    return path


def _scaled(src: Path, dst: Path, file: str, columns: tuple[str, ...], factor: float) -> Path:
    shutil.copytree(src, dst)
    lines = (dst / file).read_text().splitlines()
    h = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    idx = [lines[h].split(",").index(c) for c in columns]
    for i in range(h + 1, len(lines)):
        cells = lines[i].split(",")
        for k in idx:
            cells[k] = repr(float(cells[k]) * factor)
        lines[i] = ",".join(cells)
    (dst / file).write_text("\n".join(lines) + "\n")
    return dst


def _notes(table, action: str = "repaired") -> list[str]:
    return [s.reason for s in table.skipped if s.action == action]


@pytest.mark.parametrize(
    ("file", "columns", "factor", "note"),
    [
        ("imu.csv", ("ax_mps2", "ay_mps2", "az_mps2"), 1 / 9.80665, "specific force in g"),
        ("imu.csv", ("ax_mps2", "ay_mps2", "az_mps2"), 1000 / 9.80665, "specific force in milli-g"),
        ("imu.csv", ("wx_radps", "wy_radps", "wz_radps"), 180 / np.pi, "angular rate in deg/s (the gyro turns"),
        ("fixes.csv", ("lat_deg", "lon_deg"), np.pi / 180, "latitude/longitude in radians"),
        ("fixes.csv", ("height_m",), 1000.0, "height in millimetres"),
    ],
)
def test_a_wrong_unit_is_recognised_and_scaled_back(
    clean: Path, tmp_path: Path, file: str, columns: tuple[str, ...], factor: float, note: str
) -> None:
    expected = read_log(clean)
    table = read_log(_scaled(clean, tmp_path / "log", file, columns, factor))
    assert any(note in r for r in _notes(table)), _notes(table)
    frame, ref = (table.imu, expected.imu) if file == "imu.csv" else (table.fixes, expected.fixes)
    for c in columns:
        np.testing.assert_allclose(frame[c], ref[c], rtol=1e-9, atol=1e-12)


def test_a_fast_gyro_in_deg_per_s_is_recognised_by_its_range(clean: Path, tmp_path: Path) -> None:
    log = tmp_path / "rolling"
    shutil.copytree(clean, log)
    lines = (log / "imu.csv").read_text().splitlines()
    h = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    wx = lines[h].split(",").index("wx_radps")
    for i in range(h + 1, len(lines), 10):  # a vehicle that rocks at +-1 rad/s now and then
        cells = lines[i].split(",")
        cells[wx] = "1.0" if i % 20 else "-1.0"
        lines[i] = ",".join(cells)
    (log / "imu.csv").write_text("\n".join(lines) + "\n")
    table = read_log(_scaled(log, tmp_path / "deg", "imu.csv", ("wx_radps", "wy_radps", "wz_radps"), 180 / np.pi))
    assert any("angular rate in deg/s (99th percentile" in r for r in _notes(table))
    assert table.imu["wx_radps"].abs().max() == pytest.approx(1.0, rel=1e-9)
    assert table.imu["wz_radps"].median() == pytest.approx(1 / 60, rel=1e-9)  # scaled once, not twice


def test_an_imu_without_gravity_is_left_out_and_the_gnss_still_analysed(
    clean: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "log"
    shutil.copytree(clean, log)
    lines = (log / "imu.csv").read_text().splitlines()
    h = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    az = lines[h].split(",").index("az_mps2")
    for i in range(h + 1, len(lines)):  # "linear acceleration": gravity taken out
        cells = lines[i].split(",")
        cells[az] = repr(float(cells[az]) - 9.81)
        lines[i] = ",".join(cells)
    (log / "imu.csv").write_text("\n".join(lines) + "\n")
    table = read_log(log)
    assert not len(table.imu) and len(table.fixes) == 300
    assert any("not gravity's 9.8" in r and "left out" in r for r in _notes(table, "lost"))
    code = main(["analyze", str(log), "-o", str(tmp_path / "x.rrd"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 3 and "not gravity's 9.8" in err


def test_zero_coordinates_and_sentinels_are_dropped(clean: Path, tmp_path: Path) -> None:
    log = tmp_path / "log"
    shutil.copytree(clean, log)
    lines = (log / "fixes.csv").read_text().splitlines()
    h = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    names = lines[h].split(",")
    edits = {10: ("lat_deg", "0"), 11: ("lon_deg", "0"), 20: ("height_m", "999"), 21: ("height_m", "-9999"),
             30: ("lat_deg", "999"), 40: ("height_m", "99999")}  # fmt: skip
    for row, (col, value) in edits.items():
        cells = lines[h + 1 + row].split(",")
        cells[names.index(col)] = value
        lines[h + 1 + row] = ",".join(cells)
    (log / "fixes.csv").write_text("\n".join(lines) + "\n")
    table = read_log(log)
    assert len(table.fixes) == 300 - len(edits)
    counts = {s.reason: s.count for s in table.skipped}
    assert counts["latitude or longitude exactly 0 far from the track (no fix)"] == 2
    assert counts["no-data sentinel (999, 9999, ...) as position"] == 2
    assert counts["latitude/longitude out of range"] == 1 and counts["height outside -2 km .. 100 km"] == 1


def test_an_imu_on_another_clock_is_left_out(clean: Path, tmp_path: Path) -> None:
    log = tmp_path / "log"
    shutil.copytree(clean, log)
    text = (log / "imu.csv").read_text()
    (log / "imu.csv").write_text(text.replace("# t0_ns: 1700000000000000000", "# t0_ns: 1600000000000000000"))
    table = read_log(log)
    assert not len(table.imu) and table.duration_s == pytest.approx(299.0)  # the log starts at its first fix
    assert any("(another clock): IMU left out" in r for r in _notes(table, "lost"))


def test_clean_logs_are_left_alone() -> None:
    """No unit repair, drop or clearing on the sample logs and the real husky bag (a check that fires on
    good data would be worse than none)."""
    from paths import HUSKY_BAG

    for log in (
        SAMPLE_LOGS / "ground.bag",
        SAMPLE_LOGS / "spoofed_flight.mcap",
        SAMPLE_LOGS / "meaconed_raw",
        HUSKY_BAG,
    ):
        table = read_log(log)
        assert not [str(s) for s in table.skipped if "scaled" in s.reason or "set to NaN" in s.reason], log
