"""Values no sensor produces, in any numeric column: repaired (rows dropped and listed) or refused with
one line, never an internal error from the analysis; and no analysis of a table holding them."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from paths import REAL, SAMPLE_LOGS
from pipeline_support import circling_table

from readers import read_log
from spooflens.cli import main
from spooflens.detectors.base import DetectorResult
from spooflens.epoch_table import EpochTable, checked
from spooflens.errors import AnalysisError
from spooflens.pipeline.run import analyze_table
from spooflens.plausibility import clean_optional
from spooflens.writers import write_log

EXTREMES = (1e300, -1e308, 1e308, np.nan, np.inf, -np.inf)


@pytest.fixture(scope="module")
def clean_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("clean") / "log"
    write_log(circling_table(seconds=120.0), path, "csv")
    return path


def _with_values(src: Path, dst: Path, file: str, column: str, rows: list[int], value: float) -> Path:
    """A copy of a CSV log with `value` written into `column` of `file` at data `rows`."""
    import shutil

    shutil.copytree(src, dst)
    text = (dst / file).read_text().splitlines()
    header = next(i for i, line in enumerate(text) if not line.startswith("#"))
    col = text[header].split(",").index(column)
    for r in rows:
        cells = text[header + 1 + r].split(",")
        cells[col] = repr(float(value))
        text[header + 1 + r] = ",".join(cells)
    (dst / file).write_text("\n".join(text) + "\n")
    return dst


def _analyse(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, list[str]]:
    code = main(["analyze", str(log), "-o", str(tmp_path / "x.rrd"), "--json", str(tmp_path / "x.json"), "--quiet"])
    return code, capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize(
    ("file", "column"),
    [
        ("fixes.csv", "lat_deg"),
        ("fixes.csv", "lon_deg"),
        ("fixes.csv", "height_m"),
        ("fixes.csv", "vel_e_mps"),
        ("fixes.csv", "h_acc_m"),
        ("fixes.csv", "sats_used"),
        ("imu.csv", "ax_mps2"),
        ("imu.csv", "wz_radps"),
    ],
)
def test_extreme_values_in_any_column_are_dropped_or_cleared_and_listed(
    clean_csv: Path, tmp_path: Path, file: str, column: str
) -> None:
    clean = read_log(clean_csv)
    for k, value in enumerate(EXTREMES):
        log = _with_values(clean_csv, tmp_path / f"v{k}", file, column, [10, 11, 40], value)
        table = read_log(log)
        frame = table.imu if file == "imu.csv" else table.fixes
        numbers = frame.select_dtypes("number").to_numpy(dtype=float)
        assert np.all(np.abs(numbers[np.isfinite(numbers)]) < 1e15), (column, value)
        listed = sum(s.count for s in table.skipped if s.stream in ("/gps/fix", "/imu"))
        if column in ("vel_e_mps", "h_acc_m", "sats_used"):  # optional: the value is cleared, the fix kept
            # NaN is the schema's "not known": nothing to list; anything else impossible is cleared and listed
            assert len(table.fixes) == len(clean.fixes) and listed == (0 if np.isnan(value) else 3), (column, value)
            assert frame[column].isna().sum() == 3
        else:  # required: the row goes
            assert len(frame) == len(clean.imu if file == "imu.csv" else clean.fixes) - 3, (column, value)
            assert listed == 3, (column, value, [str(s) for s in table.skipped])


@pytest.mark.parametrize("value", [1e300, -1e308, np.inf])
def test_analyze_on_extreme_imu_and_fix_values_never_fails_inside(
    clean_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], value: float
) -> None:
    log = _with_values(clean_csv, tmp_path / "a", "imu.csv", "az_mps2", list(range(100, 400, 7)), value)
    log = _with_values(log, tmp_path / "b", "fixes.csv", "height_m", [20, 21, 22], value)
    code, err = _analyse(log, tmp_path, capsys)
    assert code == 0 and not err  # dropped and listed: a repair, not damage


def test_an_mcap_with_extreme_values_is_analysed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    table = circling_table(seconds=120.0)
    table.imu.loc[500:520, "ax_mps2"] = 1e300
    table.imu.loc[600:610, "wz_radps"] = -1e308
    table.fixes.loc[30:32, "lat_deg"] = 1e300
    write_log(table, tmp_path / "x.mcap", "mcap-ros2")
    read = read_log(tmp_path / "x.mcap")
    reasons = [str(s) for s in read.skipped]
    assert any("/imu: skipped 32" in r and "above 200 g" in r for r in reasons), reasons
    assert any("/gps/fix: skipped 3" in r and "out of range" in r for r in reasons), reasons
    code, err = _analyse(tmp_path / "x.mcap", tmp_path, capsys)
    assert code == 0 and not err


def test_the_pipeline_refuses_a_table_with_impossible_values_in_one_line() -> None:
    table = copy.copy(circling_table(seconds=60.0))
    table.fixes = table.fixes.copy()
    table.fixes.loc[5, "height_m"] = 1e300
    table.imu = table.imu.copy()
    table.imu.loc[7, "wx_radps"] = np.inf
    with pytest.raises(AnalysisError, match=r"values no sensor produces \(.*fixes: 1 rows with height outside") as err:
        analyze_table(table)
    assert "\n" not in str(err.value) and "imu: 1 rows with NaN specific force" in str(err.value)
    cleaned = checked(table)  # the way out the message names
    assert len(cleaned.fixes) == len(table.fixes) - 1 and len(cleaned.imu) == len(table.imu) - 1
    assert {(s.stream, s.reason, s.count) for s in cleaned.skipped} >= {
        ("/imu", "NaN specific force or angular rate", 1),
        ("/gps/fix", "height outside -2 km .. 100 km", 1),
    }


def test_nan_and_infinite_pseudoranges_are_counted(tmp_path: Path) -> None:
    import shutil

    log = tmp_path / "raw"
    shutil.copytree(SAMPLE_LOGS / "meaconed_raw", log)
    obs = (log / "observations.csv").read_text().splitlines()
    header = next(i for i, line in enumerate(obs) if not line.startswith("#"))
    col = obs[header].split(",").index("pseudorange_m")
    for k, bad in zip(range(header + 1, header + 31, 3), ["nan", "inf", "-inf", "1e300", "0"] * 2, strict=True):
        cells = obs[k].split(",")
        cells[col] = bad
        obs[k] = ",".join(cells)
    (log / "observations.csv").write_text("\n".join(obs) + "\n")
    table = read_log(log)
    counts = {s.reason: s.count for s in table.skipped}
    assert counts["NaN or infinite pseudorange"] == 6
    assert counts["pseudorange outside 1,000 .. 100,000 km"] == 4
    assert len(table.observations) == len(read_log(SAMPLE_LOGS / "meaconed_raw").observations) - 10
    assert isinstance(table.observations, pd.DataFrame)


def test_a_navigation_record_with_a_week_beyond_64_bits_is_dropped_not_an_overflow(tmp_path: Path) -> None:
    """The fuzzer wrote 9223372036854775808 into a RINEX 2 nav file (an OverflowError before)."""
    from readers.rinex.navigation import read_rinex_nav_file

    real = REAL / "rinex_gsi_pair/07590920.05n"
    lines = real.read_text().splitlines()
    first = next(i for i, line in enumerate(lines) if "END OF HEADER" in line) + 1
    week = lines[first + 5]
    lines[first + 5] = week[:41] + " 9.223372036855D+18" + week[60:]  # the 19-column field
    damaged = tmp_path / "07590920.05n"
    damaged.write_text("\n".join(lines) + "\n")
    nav = read_rinex_nav_file(damaged)
    whole = read_rinex_nav_file(real)
    assert len(nav.ephemerides) == len(whole.ephemerides) - 1
    assert any("out of range" in s.reason and s.count == 1 for s in nav.skipped)


def _navigation_result(table: EpochTable) -> DetectorResult:
    return next(r for r in analyze_table(table).results if r.name == "navigation")


def test_an_imu_that_ends_before_the_alignment_window_leaves_the_navigation_not_run() -> None:
    """The fuzzer cut an IMU stream to its first seconds (IndexError in the alignment before)."""
    table = copy.copy(circling_table(seconds=60.0))
    table.imu = table.imu[table.imu["t_s"] < 2.5].reset_index(drop=True)
    nav = _navigation_result(table)
    assert not nav.ran and "too few GNSS fixes inside the IMU's time span" in nav.reason


def test_non_finite_values_in_the_alignment_window_are_refused_not_an_svd_error() -> None:
    """Values each within range whose integrals overflow (1e300-scale damage) reached the SVD before."""
    from spooflens.navigation.alignment import align
    from spooflens.navigation.strapdown import preintegrate

    table = circling_table(seconds=60.0)
    imu, fixes = table.imu, table.fixes
    f_b = imu[["ax_mps2", "ay_mps2", "az_mps2"]].to_numpy(float)
    w_b = imu[["wx_radps", "wy_radps", "wz_radps"]].to_numpy(float)
    pre = preintegrate(imu["t_s"].to_numpy(float), f_b, w_b)
    pre.H[200:220] = np.inf  # what an overflowed double integral leaves
    with np.errstate(invalid="ignore"), pytest.raises(AnalysisError, match="not finite: cannot align"):
        align(pre, imu, fixes, 0.0)


def test_a_navigation_record_with_an_infinite_clock_time_is_dropped_not_an_overflow(tmp_path: Path) -> None:
    """The 10^4 fuzz run wrote 'inf' into a RINEX 2 nav file's epoch seconds (an OverflowError before)."""
    from readers.rinex.navigation import read_rinex_nav_file

    real = REAL / "rinex_gsi_pair/07590920.05n"
    if not real.exists():
        pytest.skip("the GSI navigation file is not present")
    lines = real.read_text().splitlines()
    first = next(i for i, line in enumerate(lines) if "END OF HEADER" in line) + 1
    lines[first] = lines[first][:17] + "  inf" + lines[first][22:]  # the toc seconds field
    damaged = tmp_path / "07590920.05n"
    damaged.write_text("\n".join(lines) + "\n")
    nav = read_rinex_nav_file(damaged)
    assert len(nav.ephemerides) == len(read_rinex_nav_file(real).ephemerides) - 1
    assert any(s.count == 1 and s.action == "lost" and "navigation records" in s.reason for s in nav.skipped)


def test_a_velocity_missing_one_axis_is_not_used_not_a_singular_matrix(tmp_path: Path) -> None:
    """The 10^4 fuzz run blanked one velocity column of a PX4 CSV export: no velocity noise could be
    learned, yet the other axes reached the filter with zero variance (LinAlgError before)."""
    table = copy.copy(circling_table(seconds=90.0))
    table.fixes = table.fixes.assign(vel_n_mps=np.nan)
    result = analyze_table(table)
    nav = next(r for r in result.results if r.name == "navigation")
    assert nav.ran
    assert result.verdict.spoofed is False


def test_time_stamps_beyond_any_clock_are_dropped_and_counted_not_an_overflow() -> None:
    """The fuzz run overwrote ULog and MCAP time fields with 2^63-scale values; subtracting such stamps
    overflowed int64 while the recordings of a joined log were laid out (OverflowError before)."""
    from spooflens.epoch_table import build_table

    table = circling_table(seconds=60.0)
    t0 = 1_700_000_000_000_000_000
    frames = {}
    for name in ("imu", "fixes"):
        df = getattr(table, name).copy()
        df.insert(0, "t_ns", t0 + np.round(df.pop("t_s").to_numpy() * 1e9).astype(np.int64))
        frames[name] = df
    t = frames["fixes"]["t_ns"].to_numpy().copy()
    t[[5, 20]] = [np.iinfo(np.int64).max, np.iinfo(np.int64).min]
    t[40:] -= 3_600_000_000_000  # and a second recording an hour earlier: the layout subtracts stamps
    frames["fixes"]["t_ns"] = t
    out = build_table(Path("x.csv"), "csv", "unix", frames, list(table.streams), [])
    lost = [s for s in out.skipped if "beyond any clock" in s.reason]
    assert [(s.stream, s.count, s.action) for s in lost] == [(str(table.fixes["receiver_id"].iloc[0]), 2, "lost")]
    assert len(out.fixes) == len(table.fixes) - 2 and len(out.segments) == 2


def test_recordings_whose_spans_add_up_beyond_any_clock_are_not_laid_end_to_end() -> None:
    """A flipped bit in a schema made an IMU's stamps wild: its 'recordings' spanned 10^18 ns each, and
    laying them end to end overflowed int64 (the fuzz run's one internal error). Now: not split, and said."""
    from spooflens.epoch_table import Skipped, _segment_frames

    # 46 groups of 5 stamps 1 s apart, the groups 1.1e17 ns apart: 4.95e18 ns in all (groups, not strays)
    one = (np.arange(46, dtype=np.int64)[:, None] * 110_000_000_000_000_000 + np.arange(5) * 1_000_000_000).ravel()
    imu = pd.DataFrame({"t_ns": np.r_[one, one], "imu_id": "/imu"})  # the clock jumps back once
    skipped: list[Skipped] = []
    frames, layout = _segment_frames({"imu": imu}, skipped)
    assert layout == [] and frames["imu"] is imu
    assert [s.action for s in skipped] == ["not segmented"] and "beyond any clock" in skipped[0].reason


def test_a_day_in_which_no_stream_has_a_stamp_separates_recordings_and_wild_stamps_do_not() -> None:
    """A folder of NMEA files from different years (the real `nmea_boats`: 2011 and 2018) never goes back
    in time, yet holds separate recordings; an hour's silence does not separate them, nor do stamps a
    corrupt field scattered over years."""
    from spooflens.epoch_table import Skipped, _segment_frames

    day_ns, s_ns = 86_400_000_000_000, 1_000_000_000
    t0 = 1_306_933_631 * s_ns
    ship_2011 = t0 + np.arange(12) * s_ns
    ship_2018 = t0 + 2_637 * day_ns + np.arange(150) * s_ns
    boat_2018 = ship_2018[-1] + 355 * s_ns + np.arange(300) * s_ns  # six minutes later: the same recording
    fixes = pd.DataFrame(
        {
            "t_ns": np.r_[ship_2011, ship_2018, boat_2018],
            "receiver_id": ["a"] * 12 + ["b"] * 150 + ["c"] * 300,
        }
    )
    headings = pd.DataFrame({"t_ns": ship_2011 + s_ns // 2, "heading_id": "a/HDT"})
    skipped: list[Skipped] = []
    frames, layout = _segment_frames({"fixes": fixes, "headings": headings}, skipped)
    assert [(start, end) for _, start, end in layout] == [
        (ship_2011[0], ship_2011[-1] + s_ns // 2),
        (ship_2018[0], boat_2018[-1]),
    ]
    assert [s.action for s in skipped] == ["segmented"] and "more than a day" in skipped[0].reason
    second = frames["fixes"]["t_ns"].to_numpy()[12:]
    assert second[0] - (ship_2011[-1] + s_ns // 2) == 60 * s_ns  # laid SEGMENT_GAP_S after the first
    assert np.array_equal(np.diff(second), np.diff(np.r_[ship_2018, boat_2018]))
    # an hour's silence: one recording
    skipped = []
    hour = pd.DataFrame({"t_ns": np.r_[ship_2011, ship_2011 + 3_600 * s_ns], "receiver_id": "a"})
    assert _segment_frames({"fixes": hour}, skipped) == ({"fixes": hour}, []) and skipped == []
    # one receiver whose time jumps a week forward (spoofed, or its date set wrong): one recording, the
    # jump left for the detectors
    jumped = pd.DataFrame({"t_ns": np.r_[ship_2011, ship_2011[-1] + 7 * day_ns + ship_2011 - t0], "receiver_id": "a"})
    assert _segment_frames({"fixes": jumped}, skipped)[1] == [] and skipped == []
    # an IMU on another clock, years off: no recording of its own (no GNSS in it); the cross-check drops it
    imu = pd.DataFrame({"t_ns": ship_2011 - 1_000 * day_ns, "imu_id": "/imu"})
    assert _segment_frames({"fixes": hour, "imu": imu}, skipped)[1] == [] and skipped == []
    # scattered stamps of one stream: no recordings (the stream goes on across every silence)
    wild = (np.arange(20)[:, None] * 400 * day_ns + np.arange(5) * s_ns).ravel()
    scattered = pd.DataFrame({"t_ns": wild, "receiver_id": "a"})
    assert _segment_frames({"fixes": scattered}, skipped)[1] == [] and skipped == []
    # 20 receivers each in another year: corrupt time fields, not 20 recordings (and said)
    scattered["receiver_id"] = np.repeat([f"rx{k}" for k in range(20)], 5)
    frames, layout = _segment_frames({"fixes": scattered}, skipped)
    assert layout == [] and frames["fixes"] is scattered and [s.action for s in skipped] == ["not segmented"]


def test_a_stream_made_only_of_small_groups_far_apart_keeps_them_all() -> None:
    """A stray group is one far from the rest of its stream; four sentences of sessions years apart (the
    Unicore sample of pynmeagps) have no rest to stray from, and dropping every one left no fix."""
    from spooflens.plausibility import stray_stamps

    hour = 3_600_000_000_000
    scattered = np.array([0, 2 * hour, 5 * hour, 9 * hour], dtype=np.int64)
    assert not stray_stamps(scattered).any()
    recording = np.r_[np.arange(10, dtype=np.int64) * 1_000_000_000, 20 * hour]  # ten rows and one far off
    assert stray_stamps(recording).tolist() == [False] * 10 + [True]


# S1 of a spacecraft's receiver (ICESat's BlackJack, RINEX 2.20 `ice12720.07o` in CS-SI/Orekit's test data), four
# epochs of its seven satellites: RINEX 2 writes signal strengths "as given by the receiver", here raw counts
ICESAT_S1 = [30, 359, 46, 171, 183, 231, 631, 27, 336, 42, 162, 180, 230, 620]
ICESAT_S1 += [26, 330, 40, 160, 178, 228, 610, 26, 325, 38, 158, 175, 225, 600]


def test_signal_strengths_in_a_receivers_own_units_are_not_read_as_c_n0() -> None:
    """Clearing only the counts above 100 kept 30, 46, 27 ... of two satellites as dB-Hz, and satellite_signals
    judged "7 satellites" on them."""
    (cleared,) = clean_optional("observations", {"cn0_dbhz": np.array(ICESAT_S1, dtype=float)})
    names, rows, finding = cleared
    assert names == ("cn0_dbhz",) and rows.all()
    assert finding.reason.startswith("signal strengths not in dB-Hz (20 of 28 above 100")
    one_to_nine = np.array([5, 6, 7, 7, 8, 6, 5, 9, 7, 6], dtype=float)  # RINEX 2's strength scale written as S
    (cleared,) = clean_optional("satellites", {"cn0_dbhz": one_to_nine})
    assert cleared[1].all() and "median 6.5" in cleared[2].reason
    # a C/N0 column with one corrupt value loses that value only
    sky = np.array([42.0, 45.0, 38.0, 255.0, 40.0, 44.0, 47.0, 39.0, 41.0, 43.0, 0.0, 36.0])
    (cleared,) = clean_optional("satellites", {"cn0_dbhz": sky})
    assert np.flatnonzero(cleared[1]).tolist() == [3] and "outside 0 .. 100 dB-Hz" in cleared[2].reason
