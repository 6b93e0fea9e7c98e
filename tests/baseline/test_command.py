"""`spooflens baseline` and `--baseline` on analyze, report, batch and fleet: what is learned, what the
outputs say came from it, and every bad baseline refused in one line with exit 2 before anything is
analysed or written."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest
from paths import SAMPLE_LOGS, real_log

from spooflens.baseline.format import load_baseline
from spooflens.cli import main

F9P_CLEAN = "corpus/gpsd/ublox-zed-f9p-sfrbx.log"
F9P_OTHER = "corpus/gpsd/ublox-zed-f9p-hp.log"


@pytest.fixture(scope="module")
def f9p_baseline(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("baseline") / "f9p.baseline.json"
    assert (
        main(
            [
                "baseline",
                str(real_log(F9P_CLEAN)),
                str(real_log("corpus/gpsd/ublox-zed-f9p-rtk.log")),
                "-o",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    return out


def test_a_baseline_of_two_clean_logs(f9p_baseline: Path, capsys: pytest.CaptureFixture[str]) -> None:
    b = load_baseline(f9p_baseline)
    assert [log.name for log in b.logs] == ["ublox-zed-f9p-sfrbx.log", "ublox-zed-f9p-rtk.log"]
    assert b.receivers["ubx"].model == "u-blox ZED-F9P" and set(b.receivers["ubx"].firmware) == {"HPG 1.12", "HPG 1.32"}
    hacc = b.indicator("ubx", "h_acc_m")
    assert hacc is not None and hacc.n_logs == 2 and hacc.agree is False  # 5.2 m against an RTK fix's 0.3 m


def test_the_baseline_command_says_what_it_learned_and_where_the_logs_disagree(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "x.baseline.json"
    assert (
        main(["baseline", str(real_log(F9P_CLEAN)), str(real_log("corpus/gpsd/ublox-zed-f9p-rtk.log")), "-o", str(out)])
        == 0
    )
    text = capsys.readouterr().out
    assert "learned from ublox-zed-f9p-sfrbx.log" in text and "receiver ubx: u-blox ZED-F9P" in text
    assert "the logs disagree on" in text and "ubx.h_acc_m" in text


def test_analyze_with_a_baseline_says_what_came_from_it(
    f9p_baseline: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = real_log(F9P_OTHER)
    summary, html = tmp_path / "x.json", tmp_path / "x.html"
    args = ["analyze", str(log), "-o", str(tmp_path / "x.rrd"), "--json", str(summary), "--html", str(html)]
    assert main([*args, "--baseline", str(f9p_baseline)]) == 0
    block = json.loads(summary.read_text())["baseline"]
    import hashlib

    assert block["file"] == "f9p.baseline.json" and block["logs"] == 2
    assert block["sha256"] == hashlib.sha256(f9p_baseline.read_bytes()).hexdigest()
    assert "receiver_evidence" in block["used_by"]
    assert any("receiver firmware HPG 1.11" in w for w in block["warnings"])
    page = html.read_text()
    assert "f9p.baseline.json" in page and block["sha256"] in page
    captured = capsys.readouterr()
    assert "baseline: f9p.baseline.json" in captured.out and "warning" in captured.err
    # without --baseline nothing of it appears
    assert main(args) == 0
    assert "baseline" not in json.loads(summary.read_text())


def _edited(source: Path, tmp_path: Path, change: Callable[[dict], object], name: str = "edited") -> Path:
    data = json.loads(source.read_text())
    change(data)
    out = tmp_path / f"{name}.baseline.json"
    out.write_text(json.dumps(data))
    return out


def _refused(args: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str], problem: str) -> None:
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and problem in err[0] and "Traceback" not in err[0], err
    assert not list(tmp_path.glob("out*")), "nothing is written"


def test_bad_baselines_are_refused_before_anything_is_analysed(
    f9p_baseline: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = str(real_log(F9P_OTHER))
    out = ["-o", str(tmp_path / "out.rrd"), "--json", str(tmp_path / "out.json")]
    other_version = _edited(f9p_baseline, tmp_path, lambda d: d.update(version=2), "v2")
    _refused(["analyze", log, *out, "--baseline", str(other_version)], tmp_path, capsys, "baseline version 2")
    malformed = tmp_path / "malformed.baseline.json"
    malformed.write_text('{"format": "spooflens-baseline", ')
    _refused(["analyze", log, *out, "--baseline", str(malformed)], tmp_path, capsys, "malformed JSON")
    summary = tmp_path / "summary.json"
    summary.write_text(json.dumps({"verdict": {"spoofed": False}}))
    _refused(["analyze", log, *out, "--baseline", str(summary)], tmp_path, capsys, "not a spooflens baseline")
    _refused(["analyze", log, *out, "--baseline", str(tmp_path / "none.json")], tmp_path, capsys, "no such baseline")
    model = _edited(f9p_baseline, tmp_path, lambda d: d["receivers"]["ubx"].update(model="NEO-M8N"), "m8n")
    _refused(
        ["analyze", log, *out, "--baseline", str(model)],
        tmp_path,
        capsys,
        "receiver ubx of the baseline is a NEO-M8N, of ublox-zed-f9p-hp.log a ZED-F9P",
    )
    moved = _edited(f9p_baseline, tmp_path, lambda d: d.update(receivers={"GPS[0]": d["receivers"]["ubx"]}), "gps0")
    _refused(["analyze", log, *out, "--baseline", str(moved)], tmp_path, capsys, "none in common")
    _refused(
        ["report", log, "-o", str(tmp_path / "out.html"), "--baseline", str(other_version)],
        tmp_path,
        capsys,
        "version 2",
    )
    _refused(
        ["batch", log, "-o", str(tmp_path / "out"), "--baseline", str(malformed)], tmp_path, capsys, "malformed JSON"
    )
    _refused(
        ["fleet", log, log, "-o", str(tmp_path / "out"), "--baseline", str(other_version)],
        tmp_path,
        capsys,
        "version 2",
    )


def test_a_log_that_may_have_been_spoofed_is_no_yardstick(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "x.baseline.json"
    assert main(["baseline", str(SAMPLE_LOGS / "spoofed_flight.mcap"), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no clean log to learn a baseline from (spoofed_flight.mcap: a spoofing incident" in err[0]
    assert not out.exists()


def test_a_batch_worker_reads_the_baseline_and_records_it(f9p_baseline: Path, tmp_path: Path) -> None:
    import hashlib

    from spooflens.batch import analyse_one

    log = real_log(F9P_OTHER)
    record = analyse_one(str(log), "digest", str(tmp_path / "out"), None, str(f9p_baseline))
    assert record["status"] == "done", record
    assert record["baseline_sha256"] == hashlib.sha256(f9p_baseline.read_bytes()).hexdigest()
    summary = json.loads((tmp_path / "out" / f"{log.name}.json").read_text())
    assert summary["baseline"]["file"] == "f9p.baseline.json"
    moved = _edited(f9p_baseline, tmp_path, lambda d: d.update(receivers={"GPS[0]": d["receivers"]["ubx"]}))
    failed = analyse_one(str(log), "digest", str(tmp_path / "out2"), None, str(moved))
    assert failed["status"] == "failed" and "none in common" in failed["error"]


def test_a_log_with_nothing_to_judge_is_no_baseline_and_says_what_it_holds(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "ais.baseline.json"
    assert main(["baseline", str(real_log("corpus/gpsd/ais-18-27.log")), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "it holds AIS messages only (276 VDM" in err and not out.exists()
