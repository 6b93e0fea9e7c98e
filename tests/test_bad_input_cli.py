"""Commands given what they cannot do: one line and exit 2 (or the thing done right), never an internal
error, a wrong success, or a file where the user did not ask for one."""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from paths import REAL, SAMPLE_LOGS

from readers import read_log
from spooflens.cli import DIRECTORY_FORMATS, SIMULATE_FORMATS, cli, main
from spooflens.errors import ReaderError
from spooflens.geodesy import geodetic_to_enu
from spooflens.navigation.imu_models import PRESETS
from spooflens.writers import SUFFIX, WRITERS

GSI = REAL / "rinex_gsi_pair"
SAMPLE = SAMPLE_LOGS


def test_imu_grade_is_a_choice_listed_in_help(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", str(SAMPLE / "ground.bag"), "--imu-grade", "bogus", "-o", "x.rrd"]) == 2
    err = capsys.readouterr().err
    assert "Invalid value for '--imu-grade': 'bogus' is not one of" in err and "consumer_mems" in err
    help_text = CliRunner().invoke(cli, ["analyze", "--help"]).output
    assert all(name in help_text for name in PRESETS)


def test_simulate_choices_match_the_writers() -> None:
    assert set(SIMULATE_FORMATS) == set(WRITERS)
    assert set(DIRECTORY_FORMATS) == {f for f, suffix in SUFFIX.items() if not suffix}


def test_simulate_refuses_a_file_name_for_a_directory_format(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "x.csv"
    assert main(["simulate", "ground", "-o", str(out), "--format", "csv", "--seconds", "5"]) == 2
    err = capsys.readouterr().err
    assert "writes a directory of files" in err and not out.exists()
    assert main(["simulate", "ground", "-o", str(tmp_path / "x"), "--format", "csv", "--seconds", "5"]) == 0
    assert (tmp_path / "x" / "fixes.csv").is_file()


def test_inject_refuses_a_start_after_the_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "x.bag"
    assert main(["inject", str(SAMPLE / "ground.bag"), "--attack", "ramp:start=100", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "start=100 s is after the end of the log's fixes (60.0 s)" in err[0]
    assert not out.exists()


def test_a_fix_level_attack_on_a_raw_observation_log_moves_the_solved_fixes(tmp_path: Path) -> None:
    """RINEX holds pseudoranges only: the ramp goes into them, so the fixes analyze solves follow it."""
    for f in ("07590920.05o", "07590920.05n"):
        shutil.copy(GSI / f, tmp_path / f)
    out = tmp_path / "ramp.05o"
    assert main(["inject", str(tmp_path / "07590920.05o"), "--attack", "ramp:rate=2,start=1200", "-o", str(out)]) == 0
    shutil.copy(tmp_path / "07590920.05n", tmp_path / "ramp.05n")
    clean_json, ramp_json = tmp_path / "c.json", tmp_path / "r.json"
    from spooflens.service import read_table

    clean, ramp = read_table(tmp_path / "07590920.05o", {}, False), read_table(out, {}, False)
    a, b = clean.fixes, ramp.fixes
    assert len(a) == len(b) and len(a) > 100
    enu = geodetic_to_enu(b["lat_deg"], b["lon_deg"], b["height_m"], a["lat_deg"], a["lon_deg"], a["height_m"])
    t = a["t_s"].to_numpy()
    expected = np.c_[np.clip(t - 1200.0, 0.0, None) * 2.0, np.clip(t - 1200.0, 0.0, None) * 2.0, np.zeros(len(t))]
    error = np.linalg.norm(enu - expected, axis=1)
    # exact to centimetres, but where the moved antenna sees a satellite cross the elevation mask (a
    # different set of satellites: the solution noise of one removal, about a metre)
    assert np.mean(error < 0.05) > 0.97 and error.max() < 3.0
    truth = json.loads((tmp_path / "ramp.05o.attack.json").read_text())
    offsets = np.array(truth["offsets"]["0759"])
    # the sidecar says what the solver will find (RINEX keeps pseudoranges to the millimetre)
    np.testing.assert_allclose(offsets[:, 1:], enu, atol=1e-2)
    assert not clean_json.exists() and not ramp_json.exists()


def test_bench_read_reads_every_format_and_leaves_nothing_in_the_current_directory(tmp_path: Path) -> None:
    from spooflens.bench.read_bench import OTHER_FORMATS

    cwd = Path.cwd()
    os.chdir(tmp_path)
    try:
        result = CliRunner().invoke(cli, ["bench", "read", "--duration", "3", "--formats"])
    finally:
        os.chdir(cwd)
    assert result.exit_code == 0, result.output
    assert list(tmp_path.iterdir()) == []
    assert "the same 630 messages" in result.output  # 600 IMU samples + 30 fixes
    for label, *_ in OTHER_FORMATS:  # each read whole
        assert re.search(rf"{re.escape(label)}\s*│\s*630\s*│", result.output), result.output


def test_a_multi_line_error_is_printed_as_one_line(monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    import readers

    def broken(path: Path, topics=None, progress=None):
        raise ReaderError(path, "schema text:\nfloat64 x\nfloat64 y\n")

    monkeypatch.setitem(readers.READERS, readers.sniff_format(SAMPLE / "ground.bag"), broken)
    assert main(["inspect", str(SAMPLE / "ground.bag")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"spooflens: error: {SAMPLE / 'ground.bag'}: schema text: float64 x float64 y"]


def test_velocity_rows_are_rewritten_for_the_receiver_the_reader_chose(tmp_path: Path) -> None:
    """`--topic vel=` and `--topic fix=`: inject edits each velocity message with the values of the fix
    the reader attached it to, so reading the spoofed copy back gives the spoofed table."""
    from pipeline_support import circling_table

    table = circling_table(seconds=60.0)
    second = table.fixes.copy()
    second["receiver_id"] = "/b/fix"
    second[["vel_e_mps", "vel_n_mps", "vel_u_mps"]] = np.nan  # no velocity topic of its own
    first = table.fixes.copy()
    first["receiver_id"] = "/a/fix"
    import pandas as pd

    table.fixes = pd.concat([first, second], ignore_index=True)
    src = tmp_path / "two.mcap"
    from spooflens.writers import write_log

    write_log(table, src, "mcap-ros2")
    topics = ["--topic", "vel=/a/fix_velocity", "--topic", "fix=/b/fix", "--topic", "fix2=/a/fix"]
    read = read_log(src, topics={"vel": "/a/fix_velocity", "fix": "/b/fix", "fix2": "/a/fix"})
    assert read.fixes_of("/b/fix")["vel_e_mps"].notna().all()  # the velocity went to /b, as asked
    assert read.stream("vel", "/a/fix_velocity").receiver == "/b/fix"  # type: ignore[union-attr]
    out = tmp_path / "spoofed.mcap"
    code = main(
        ["inject", str(src), "--attack", "velocity_pull:dv=3,axes=e,start=20,receiver=/b/fix", "-o", str(out), *topics]
    )
    assert code == 0
    back = read_log(out, topics={"vel": "/a/fix_velocity", "fix": "/b/fix", "fix2": "/a/fix"})
    b0, b1 = read.fixes_of("/b/fix"), back.fixes_of("/b/fix")
    late = b0["t_s"].to_numpy() >= 20
    np.testing.assert_allclose(b1["vel_e_mps"][late], b0["vel_e_mps"][late] + 3.0, atol=1e-9)
    np.testing.assert_allclose(b1["vel_e_mps"][~late], b0["vel_e_mps"][~late], atol=1e-12)


def test_an_output_that_cannot_be_written_is_a_usage_error_before_the_analysis(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """It was an internal error (Rerun's, or the file system's) after the whole analysis had run; `report` and
    `inject` alike."""
    log = str(SAMPLE / "ground_ros2.mcap")
    for option, path, said in (
        ("-o", tmp_path / "none" / "x.rrd", "there is no folder"),
        ("--json", tmp_path, "is a folder"),
        ("--html", tmp_path / "none" / "r.html", "there is no folder"),
    ):
        args = ["analyze", log, "-o", str(tmp_path / "ok.rrd"), option, str(path), "--quiet"]
        assert main(args) == 2
        err = capsys.readouterr().err
        assert said in err and "Traceback" not in err and "internal error" not in err
        assert not (tmp_path / "ok.rrd").exists()  # nothing analysed, nothing written
    nowhere = str(tmp_path / "none" / "x")
    for args in (
        ["report", log, "-o", nowhere, "--quiet"],
        ["inject", log, "--attack", "step:start=20", "-o", nowhere],
    ):
        assert main(args) == 2
        err = capsys.readouterr().err
        assert "there is no folder" in err and "internal error" not in err


def test_an_output_folder_that_cannot_be_made_is_a_usage_error_before_any_log_is_read(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`batch` made it after finding the logs (an internal error), `fleet` after analysing them all."""
    a_file = tmp_path / "a_file"
    a_file.write_text("not a folder")
    log = str(SAMPLE / "ground_ros2.mcap")
    for args in (["batch", log, "-o", str(a_file / "results")], ["fleet", log, log, "-o", str(a_file / "out")]):
        assert main(args) == 2
        err = capsys.readouterr().err
        assert "cannot make this folder" in err and "internal error" not in err
    # a results folder that holds folders of its own is still a folder outputs can go to
    results = tmp_path / "results"
    (results / "x").mkdir(parents=True)
    from spooflens.service import make_output_folder

    make_output_folder(results, "--output")
