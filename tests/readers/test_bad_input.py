"""Bad input: a clear one-line error naming file, stream and problem, or a reported repair."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pipeline_support import circling_table

from readers import read_log
from spooflens.cli import main
from spooflens.errors import ReaderError, UnsupportedFormatError
from spooflens.writers import write_log


@pytest.fixture(scope="module")
def good_mcap(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("mcap") / "good.mcap"
    write_log(circling_table(seconds=120.0), path, "mcap-ros2")
    return path


def test_empty_file(tmp_path: Path) -> None:
    (tmp_path / "empty.mcap").write_bytes(b"")
    with pytest.raises(ReaderError, match=r"empty.mcap: file is empty"):
        read_log(tmp_path / "empty.mcap")


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ReaderError, match="no such file"):
        read_log(tmp_path / "nope.bag")


def test_garbage_bytes(tmp_path: Path) -> None:
    (tmp_path / "junk.mcap").write_bytes(bytes(range(256)) * 4)
    with pytest.raises(UnsupportedFormatError, match=r"junk.mcap: unknown format .*supported: MCAP"):
        read_log(tmp_path / "junk.mcap")


def test_wrong_extension_is_read_by_content(good_mcap: Path, tmp_path: Path) -> None:
    renamed = tmp_path / "actually_mcap.bag"
    shutil.copy(good_mcap, renamed)
    assert len(read_log(renamed).fixes) == len(read_log(good_mcap).fixes)


def test_truncated_mcap_keeps_what_was_read(good_mcap: Path, tmp_path: Path) -> None:
    data = good_mcap.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    table = read_log(cut)
    full = read_log(good_mcap)
    assert 0 < len(table.imu) < len(full.imu)
    lost = [s for s in table.skipped if s.action == "lost"]
    assert lost and "cut short" in lost[0].reason


def test_corrupt_chunk_crc_costs_only_that_chunk(tmp_path: Path) -> None:
    from mcap.writer import CompressionType, Writer

    path = tmp_path / "crc.mcap"
    with path.open("wb") as f:  # uncompressed chunks, so flipping a byte reaches the CRC check
        w = Writer(f, compression=CompressionType.NONE, chunk_size=4096)
        w.start()
        sid = w.register_schema("foxglove.LocationFix", "jsonschema", b"{}")
        cid = w.register_channel("/fix", "json", sid)
        for i in range(400):
            msg = (
                f'{{"timestamp": {{"sec": {1000 + i}, "nsec": 0}}, "latitude": 45.0, "longitude": 7.0, "altitude": 1}}'
            )
            w.add_message(cid, log_time=(1000 + i) * 10**9, data=msg.encode(), publish_time=0)
        w.finish()
    data = bytearray(path.read_bytes())
    pos = data.find(b'"sec": 1100')
    data[pos + 8] = ord("9")  # 1100 -> 1190 inside one chunk: its CRC no longer matches
    path.write_bytes(bytes(data))
    table = read_log(path)
    assert 300 < len(table.fixes) < 400
    assert any("CRC" in s.reason and s.action == "lost" for s in table.skipped)


def test_truncated_ros1_bag_is_scanned_sequentially(husky_bag: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.bag"
    cut.write_bytes(husky_bag.read_bytes()[:700_000])
    table = read_log(cut)
    assert 0 < len(table.fixes) < 989 and 0 < len(table.imu) < 11865
    assert any("read sequentially" in s.reason for s in table.skipped)


def test_nan_zero_fixes_backwards_time_and_duplicates_are_repaired(tmp_path: Path) -> None:
    table = circling_table(seconds=30.0)
    fixes = table.fixes.copy()
    fixes.loc[3, "lat_deg"] = np.nan
    fixes.loc[5, ["lat_deg", "lon_deg"]] = 0.0
    fixes.loc[8, "t_s"] = fixes.loc[9, "t_s"]  # duplicate stamp
    fixes = pd.concat([fixes.iloc[:12], fixes.iloc[14:15], fixes.iloc[12:14], fixes.iloc[15:]])  # backwards
    table.fixes = fixes.reset_index(drop=True)
    path = tmp_path / "csvlog"
    write_log(table, path, "csv")
    back = read_log(path)
    reasons = " | ".join(str(s) for s in back.skipped)
    assert "NaN or zero" in reasons and "duplicate" in reasons and "backwards" in reasons
    assert len(back.fixes) == 30 - 3
    assert np.all(np.diff(back.fixes["t_s"]) > 0)


def test_unknown_message_types_are_listed_not_fatal(tmp_path: Path) -> None:
    from mcap.writer import Writer

    path = tmp_path / "extra.mcap"
    write_log(circling_table(seconds=10.0), path, "mcap-json")
    data = path.read_bytes()
    with (tmp_path / "mixed.mcap").open("wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("acme.Thing", "jsonschema", b"{}")
        cid = w.register_channel("/thing", "json", sid)
        for i in range(5):
            w.add_message(cid, log_time=i, data=b"{}", publish_time=i)
        w.finish()
    assert data  # the original is fine; the mixed one has only the unknown type
    table = read_log(tmp_path / "mixed.mcap")
    assert [str(s) for s in table.skipped] == ["/thing: skipped 5 (unsupported message type acme.Thing (json))"]


def test_topic_override_for_a_missing_topic_names_the_topics_there(good_mcap: Path) -> None:
    with pytest.raises(ReaderError, match=r"--topic fix=/gps2/fix: no such topic; topics are \['/gps/fix'"):
        read_log(good_mcap, topics={"fix": "/gps2/fix"})


def test_cli_gives_one_line_and_nonzero_exit(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "empty.bag").write_bytes(b"")
    assert main(["analyze", str(tmp_path / "empty.bag"), "-o", str(tmp_path / "x.rrd"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"spooflens: error: {tmp_path / 'empty.bag'}: file is empty (0 bytes)"]


def test_cli_on_a_log_without_gnss_says_there_is_nothing_to_judge(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An IMU without GNSS is not an empty log: it is analysed to a NO VERDICT that says why, and its recording
    and report show what it holds."""
    table = circling_table(seconds=20.0)
    table.fixes = table.fixes.iloc[:0]
    path = tmp_path / "imu_only.mcap"
    write_log(table, path, "mcap-ros2")
    outputs = [tmp_path / "imu.rrd", tmp_path / "imu.json", tmp_path / "imu.html"]
    code = main(
        ["analyze", str(path), "-o", str(outputs[0]), "--json", str(outputs[1]), "--html", str(outputs[2]), "--quiet"]
    )
    out = capsys.readouterr().out
    assert code == 0 and all(p.exists() for p in outputs)
    headline = json.loads(outputs[1].read_text())["verdict"]["headline"]
    assert headline.startswith("NO VERDICT: no GNSS data to judge: the log holds imu ") and headline in out


def test_cli_on_a_log_without_any_data_fails_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    table = circling_table(seconds=20.0)
    table.fixes, table.imu = table.fixes.iloc[:0], table.imu.iloc[:0]
    path = tmp_path / "nothing.mcap"
    write_log(table, path, "mcap-ros2")
    outputs = [tmp_path / "x.rrd", tmp_path / "x.json", tmp_path / "x.html"]
    code = main(
        ["analyze", str(path), "-o", str(outputs[0]), "--json", str(outputs[1]), "--html", str(outputs[2]), "--quiet"]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        code == 2
        and len(err) == 1
        and "no GNSS fixes, raw observations or satellite reports found" in err[0]
        and "nothing.mcap" in err[0]
    )
    assert "nothing written" in err[0] and not any(p.exists() for p in outputs)


def test_cli_on_a_truncated_log_analyses_and_exits_3(
    good_mcap: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(good_mcap.read_bytes()[:-3000])
    code = main(["analyze", str(cut), "-o", str(tmp_path / "cut.rrd"), "--json", str(tmp_path / "cut.json"), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 3 and len(err) == 1 and "input damaged" in err[0]
    assert (tmp_path / "cut.json").exists()
