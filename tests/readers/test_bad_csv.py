"""CSV logs as they arrive damaged: the clock comment, shifted headers, rows cut or garbage, the wrong
time unit, a very long file; each built here, each either read with its loss counted or refused in one
line naming the file."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from paths import SAMPLE_LOGS
from pipeline_support import circling_table

from readers import read_log
from spooflens.cli import main
from spooflens.writers import write_log


@pytest.fixture(scope="module")
def clean_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("clean") / "log"
    write_log(circling_table(seconds=120.0), path, "csv")
    return path


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def _lines(path: Path) -> list[str]:
    return path.read_text().splitlines()


def _header(lines: list[str]) -> int:
    return next(i for i, line in enumerate(lines) if not line.startswith("#"))


@pytest.mark.parametrize(
    ("t0", "why"),
    [
        ("99999999999999999999999999", "not a whole number of nanoseconds from 0"),  # beyond int64
        ("-1700000000000000000", "not a whole number"),  # negative: 1970 minus 54 years
        ("1e30", "not a whole number"),
        ("nan", "not a whole number"),
    ],
)
def test_a_bad_t0_comment_is_refused_in_one_line(
    clean_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], t0: str, why: str
) -> None:
    log = _copy(clean_csv, tmp_path / "log")
    text = (log / "fixes.csv").read_text()
    (log / "fixes.csv").write_text(text.replace("# t0_ns: 1700000000000000000", f"# t0_ns: {t0}"))
    # the file with the bad clock is left out and listed; the IMU file is still read
    assert main(["inspect", str(log)]) == 3
    assert "fixes.csv: lost 1 (file not read: # t0_ns:" in capsys.readouterr().out
    # with no fixes left there is no GNSS to judge: the IMU is analysed, the verdict says why, the loss is listed
    assert main(["analyze", str(log), "-o", str(tmp_path / "x.rrd"), "--quiet"]) == 3
    captured = capsys.readouterr()
    assert "NO VERDICT: no GNSS data to judge: the log holds imu" in captured.out
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "input damaged" in err[0] and "fixes.csv: lost 1 (file not read: # t0_ns:" in err[0]
    assert why in err[0] and (tmp_path / "x.rrd").exists()
    # a single CSV file with a bad clock is refused outright
    assert main(["inspect", str(log / "fixes.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "fixes.csv [fixes]: # t0_ns:" in err[0] and why in err[0]


def test_a_file_without_t0_beside_files_with_one_takes_theirs(clean_csv: Path, tmp_path: Path) -> None:
    log = _copy(clean_csv, tmp_path / "log")
    lines = [line for line in _lines(log / "imu.csv") if not line.startswith("# t0_ns")]
    (log / "imu.csv").write_text("\n".join(lines) + "\n")
    table = read_log(log)
    assert table.duration_s == pytest.approx(119.98) and table.t0_ns == 1_700_000_000_000_000_000
    assert any("no # t0_ns: comment: took the other files' start" in s.reason for s in table.skipped)


def test_shifted_observation_headers_are_never_an_internal_error(tmp_path: Path) -> None:
    for shift in (1, -1):
        log = _copy(SAMPLE_LOGS / "meaconed_raw", tmp_path / f"s{shift}")
        lines = _lines(log / "observations.csv")
        h = _header(lines)
        names = lines[h].split(",")
        lines[h] = ",".join([*names[1:], "extra"] if shift == 1 else ["extra", *names[:-1]])
        (log / "observations.csv").write_text("\n".join(lines) + "\n")
        code = main(["analyze", str(log), "-o", str(tmp_path / "x.rrd"), "--quiet"])
        assert code in (0, 2, 3)


def test_a_shifted_header_in_the_observations_drops_what_it_scrambled(tmp_path: Path) -> None:
    log = _copy(SAMPLE_LOGS / "meaconed_raw", tmp_path / "log")
    lines = _lines(log / "observations.csv")
    h = _header(lines)
    names = lines[h].split(",")
    lines[h] = ",".join(["extra", *names[:-1]])  # every column now holds its left neighbour's values
    (log / "observations.csv").write_text("\n".join(lines) + "\n")
    table = read_log(log)
    # the time column now holds receiver names: no row has a time, the file is listed as lost, and the
    # fixes and IMU beside it are analysed all the same
    lost = [str(s) for s in table.skipped if s.action == "lost"]
    assert lost == ["observations.csv: lost 1 (file not read: no row has a usable time (t_s))"]
    assert not len(table.observations) and len(table.fixes) == 181 and len(table.imu) == 4501


def test_a_csv_cut_in_the_middle_of_a_row_counts_the_row_as_lost(
    clean_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    full = read_log(clean_csv)
    for k, cut in enumerate((-30, -3)):  # fields missing; the last number cut short
        log = _copy(clean_csv, tmp_path / f"cut{k}")
        data = (log / "fixes.csv").read_bytes()
        (log / "fixes.csv").write_bytes(data[:cut])
        table = read_log(log)
        lost = [s for s in table.skipped if s.action == "lost"]
        assert len(table.fixes) == len(full.fixes) - 1 and len(lost) == 1 and lost[0].count == 1
        assert "middle of its last row" in lost[0].reason or "fields" in lost[0].reason
        code = main(["analyze", str(log), "-o", str(tmp_path / "x.rrd"), "--quiet"])
        assert code == 3 and "input damaged" in capsys.readouterr().err


def test_garbage_lines_are_counted_not_taken_as_rows(clean_csv: Path, tmp_path: Path) -> None:
    full = read_log(clean_csv)
    log = _copy(clean_csv, tmp_path / "log")
    lines = _lines(log / "fixes.csv")
    h = _header(lines)
    rng = np.random.default_rng(0)
    junk = bytes(rng.integers(33, 127, 5_000_000, dtype=np.uint8)).decode().replace(",", ";")
    lines[h + 50 : h + 50] = [junk, "1," * 40_000, "7" * 1000]
    (log / "fixes.csv").write_text("\n".join(lines) + "\n")
    table = read_log(log)
    lost = {s.reason: s.count for s in table.skipped if s.action == "lost"}
    fields = len(lines[h].split(","))
    assert lost == {f"rows whose number of fields is not the header's {fields} (garbage or cut short)": 3}
    assert len(table.fixes) == len(full.fixes)
    np.testing.assert_array_equal(table.fixes["lat_deg"], full.fixes["lat_deg"])


def test_a_header_of_a_million_fields_is_refused_for_its_file_quickly(clean_csv: Path, tmp_path: Path) -> None:
    """The 10^4 fuzz run put a 1 MB line of commas where fixes.csv's header was: pandas named the
    million empty columns in quadratic time (a hang before). The file is now no table, said so."""
    log = _copy(clean_csv, tmp_path / "log")
    lines = _lines(log / "fixes.csv")
    lines[_header(lines)] = "," * 1_000_000
    (log / "fixes.csv").write_text("\n".join(lines) + "\n")
    table = read_log(log)
    assert not len(table.fixes) and len(table.imu)
    assert any(s.stream == "fixes.csv" and "cannot tell what this CSV holds" in s.reason for s in table.skipped)


def test_t_s_in_milliseconds_is_recognised_by_its_rates(clean_csv: Path, tmp_path: Path) -> None:
    log = _copy(clean_csv, tmp_path / "log")
    for name in ("fixes.csv", "imu.csv"):
        lines = _lines(log / name)
        h = _header(lines)
        for i in range(h + 1, len(lines)):
            cells = lines[i].split(",")
            cells[0] = repr(float(cells[0]) * 1000.0)
            lines[i] = ",".join(cells)
        (log / name).write_text("\n".join(lines) + "\n")
    table = read_log(log)
    assert table.duration_s == pytest.approx(119.98)
    notes = [s.reason for s in table.skipped if s.action == "repaired"]
    assert any("(IMU at 0.05 Hz): milliseconds" in r for r in notes), notes
    assert any("(GNSS at 0.001 Hz): milliseconds" in r for r in notes), notes


def test_unix_time_in_milliseconds_is_scaled(tmp_path: Path) -> None:
    path = tmp_path / "fixes.csv"
    t = 1.7e12 + np.arange(60) * 1000.0
    rows = [f"{u:.0f},45.0,7.0,300.0" for u in t]
    path.write_text("unix_time_s,lat,lon,height\n" + "\n".join(rows) + "\n")
    table = read_log(path)
    assert table.time_reference == "unix" and table.t0_ns == 1_700_000_000_000_000_000 and table.duration_s == 59.0
    assert any("unix_time_s in milliseconds" in s.reason for s in table.skipped)


# the child's own peak (VmHWM): ru_maxrss would start at the test process's, so a reader growing by less
# than pytest holds would show no growth at all
_MEASURE = """
import json, sys
from readers import read_log
from spooflens.bench.common import peak_rss_mb
base = peak_rss_mb()
table = read_log(sys.argv[1])
print(json.dumps({"rows": len(table.fixes), "extra_kib": (peak_rss_mb() - base) * 1024}))
"""


def test_a_long_csv_is_read_in_a_bounded_memory_per_row(tmp_path: Path) -> None:
    """Streamed: a 3-million-row file then needs about 1 GB, not the 4 GB at which it failed."""
    n = 400_000
    t = np.arange(n) * 0.1
    rng = np.random.default_rng(0)
    cols = np.c_[t, 42 + 1e-5 * np.sin(t / 100), -71 + 1e-5 * np.cos(t / 100), 10 + rng.normal(0, 1, n)]
    body = "\n".join(f"{a:.1f},rx,{b:.9f},{c:.9f},{d:.3f},0.1,0.1,0.0,1.5,3.0,9,2" for a, b, c, d in cols)
    path = tmp_path / "fixes.csv"
    path.write_text(
        "# time_reference: unix\n# t0_ns: 1772366400000000000\n"
        "t_s,receiver_id,lat_deg,lon_deg,height_m,vel_e_mps,vel_n_mps,vel_u_mps,h_acc_m,v_acc_m,sats_used,fix_type\n"
        + body
        + "\n"
    )
    env = {"ARROW_DEFAULT_MEMORY_POOL": "system", "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", _MEASURE, str(path)], capture_output=True, text=True, env=env)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["rows"] == n
    per_row = result["extra_kib"] * 1024 / n
    assert per_row < 400, f"{per_row:.0f} bytes per row"  # the frame itself is 23 float columns: 184 B


def test_a_row_with_a_corrupt_time_far_from_the_rest_is_dropped(clean_csv: Path, tmp_path: Path) -> None:
    """One stamp of -5e8 s (or +5e8 s) would stretch the log to 16 years: it is a stray, not a recording."""
    for value in ("-500000000", "500000000"):
        log = _copy(clean_csv, tmp_path / value)
        lines = _lines(log / "fixes.csv")
        h = _header(lines)
        cells = lines[h + 30].split(",")
        cells[0] = value
        lines[h + 30] = ",".join(cells)
        (log / "fixes.csv").write_text("\n".join(lines) + "\n")
        table = read_log(log)
        assert table.duration_s == pytest.approx(119.98) and len(table.fixes) == 119
        assert any(
            s.reason == "rows whose time lies an hour or more from the rest of the stream" for s in table.skipped
        )
