"""ArduPilot DataFlash logs saved as text (Mission Planner / APM Planner `.log`): the same log read as binary
and as text gives the same table and the same verdict; the 2013-2014 revisions, both delimiters, CRLF and a
BOM; damaged lines skipped and counted; NMEA `.log` files not claimed; inject writes an attacked text copy.

The text logs are written in tmp_path from binary logs (`dataflash_text_support.write_text_log`): the real
ones of the corpus and, for the revisions the corpus has no log of, logs built from those years' FMTs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from dataflash_support import WEEK, Fmt, flight, write_dataflash
from dataflash_text_support import write_text_log
from paths import real_log

from readers import read_log, sniff_format
from readers.dataflash_text import open_text_dataflash
from spooflens.cli import main
from spooflens.epoch_table import EpochTable
from spooflens.errors import ReaderError, UnsupportedFormatError

FRAMES = ("fixes", "imu", "autopilot_ekf", "receiver_status", "observations")
GPS_2014 = Fmt(130, "GPS", "BIHBcLLeeEefI", "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs,VZ,T")
GPS_2013 = Fmt(130, "GPS", "BIHBcLLeeEe", "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs")
IMU_2014 = Fmt(131, "IMU", "Iffffff", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")


def assert_same_table(binary: EpochTable, text: EpochTable) -> None:
    """Everything read from the text log is what the binary log gives, apart from the format's name."""
    for frame in FRAMES:
        pd.testing.assert_frame_equal(getattr(binary, frame), getattr(text, frame), obj=frame)
    assert (binary.t0_ns, binary.time_reference) == (text.t0_ns, text.time_reference)
    assert {k: v for k, v in text.metadata.items() if k != "log_format"} == binary.metadata
    assert [(s.stream, s.reason, s.count) for s in text.skipped] == [
        (s.stream, s.reason, s.count) for s in binary.skipped
    ]
    assert [(s.role, s.stream_id, s.count) for s in text.streams] == [
        (s.role, s.stream_id, s.count) for s in binary.streams
    ]
    assert binary.format == "ardupilot" and text.format == "ardupilot_text"
    assert all(s.msgtype.startswith("ardupilot_text/") for s in text.streams if s.role != "nav")


def log_2014(tmp_path: Path, n_gps: int = 20) -> Path:
    """Copter 3.1-3.2 (2014): GPS with ms of week `TimeMS`, `Week` and boot time `T`; IMU on `TimeMS`."""
    msgs = []
    for boot_ms, tow, lat, lon in flight(n_gps):
        msgs += [IMU_2014.message(TimeMS=boot_ms - 200 + 20 * k, AccZ=-9.81, GyrZ=0.01) for k in range(10)]
        fix = {"Status": 3, "TimeMS": tow, "Week": WEEK, "NSats": 9, "HDop": 1.2, "Lat": lat, "Lng": lon}
        msgs.append(GPS_2014.message(**fix, Alt=584.3, Spd=5.0, GCrs=0.0, VZ=-0.5, T=boot_ms))
    return write_dataflash(tmp_path / "2014.bin", [GPS_2014, IMU_2014], msgs)


@pytest.mark.parametrize(
    "relative", ["ardupilot_dataflash/amc_backend_log_80k.bin", "ardupilot_dataflash/flightdata_center_0003.bin"]
)
def test_a_real_log_read_as_text_gives_the_binary_logs_table(relative: str, tmp_path: Path) -> None:
    binary = real_log(relative)
    text = write_text_log(binary, tmp_path / "flight.log")
    assert sniff_format(text) == "ardupilot_text"
    assert_same_table(read_log(binary), read_log(text))


def test_a_real_log_as_text_gets_the_binary_logs_verdict(tmp_path: Path) -> None:
    binary = real_log("ardupilot_dataflash/flightdata_center_0003.bin")
    text = write_text_log(binary, tmp_path / "flight.log")
    verdicts = []
    for log in (binary, text):
        summary = tmp_path / f"{log.suffix[1:]}.json"
        assert main(["analyze", str(log), "-o", str(tmp_path / "a.rrd"), "--json", str(summary), "--quiet"]) == 0
        verdicts.append(json.loads(summary.read_text())["verdict"])
    assert verdicts[0] == verdicts[1]
    assert verdicts[0]["headline"]


def test_2014_revision_as_text(tmp_path: Path) -> None:
    binary = log_2014(tmp_path)
    text = read_log(write_text_log(binary, tmp_path / "2014.log"))
    assert_same_table(read_log(binary), text)
    assert text.time_reference == "gps" and len(text.fixes) == 20 and len(text.imu) == 200
    np.testing.assert_allclose(text.fixes["vel_u_mps"], 0.5)


def test_2013_revision_as_text_places_gps_by_the_line_before_it(tmp_path: Path) -> None:
    """Copter 3.0 (2013): GPS without a boot time takes that of the IMU line written just before it, so the
    text reader must keep the file's order (each row's `_ofs` is its line's offset)."""
    msgs = []
    for boot_ms, tow, lat, lon in flight():
        msgs += [IMU_2014.message(TimeMS=boot_ms - 20 * k, AccZ=-9.81) for k in range(10, 0, -1)]
        msgs.append(GPS_2013.message(Status=3, TimeMS=tow, Week=WEEK, NSats=8, HDop=1.5, Lat=lat, Lng=lon, Alt=584))
    binary = write_dataflash(tmp_path / "2013.bin", [GPS_2013, IMU_2014], msgs)
    text = read_log(write_text_log(binary, tmp_path / "2013.log"))
    assert_same_table(read_log(binary), text)
    gps_s = text.gps_seconds(text.fixes["t_s"].to_numpy())
    assert gps_s is not None
    np.testing.assert_allclose(np.diff(gps_s), 0.2, atol=1e-6)
    assert "boot time of the message logged before" in text.metadata["dataflash.GPS.TimeUS"]


@pytest.mark.parametrize(
    ("delimiter", "newline", "bom"),
    [(", ", "\r\n", False), (",", "\n", False), (", ", "\n", True), (",", "\r\n", True)],
)
def test_delimiters_line_endings_and_a_bom(delimiter: str, newline: str, bom: bool, tmp_path: Path) -> None:
    binary = log_2014(tmp_path)
    text = write_text_log(binary, tmp_path / "log.txt", delimiter=delimiter, newline=newline, bom=bom)
    assert sniff_format(text) == "ardupilot_text"  # by content, whatever the extension
    assert_same_table(read_log(binary), read_log(text))


def test_a_hand_written_log_as_the_documentation_shows_it(tmp_path: Path) -> None:
    """Blank lines before the first FMT, the FMT of FMT without its last column name, a MSG with commas."""
    path = tmp_path / "hand.log"
    path.write_text(
        "\n\nFMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format\n"
        "FMT, 130, 45, GPS, BIHBcLLeeEefI, Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs,VZ,T\n"
        "FMT, 132, 67, MSG, Z, Message\n"
        "MSG, ArduCopter V3.2.1 (36b405fb)\n"
        "MSG, GPS 1: u-blox, found at 38400 baud\n"
        "GPS, 3, 122376200, 1790, 9, 1.67, -35.3632621, 149.1652374, 0.00, 584.09, 5.00, 90.00, -0.50, 12345\n"
        "GPS, 3, 122376400, 1790, 9, 1.67, -35.3632621, 149.1652929, 0.00, 584.09, 5.00, 90.00, -0.50, 12545\n"
    )
    t = read_log(path)
    assert t.format == "ardupilot_text" and len(t.fixes) == 2
    assert t.fixes["lat_deg"].iloc[0] == -35.3632621 and t.fixes["height_m"].iloc[0] == 584.09
    np.testing.assert_allclose(t.fixes[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].iloc[0], [5.0, 0.0, 0.5], atol=1e-12)
    assert t.metadata["firmware"] == "ArduCopter V3.2.1 (36b405fb)"
    assert t.metadata["receivers"] == "GPS 1: u-blox, found at 38400 baud"  # the commas are the message's text


def test_a_log_downloaded_over_the_console_with_its_banner(tmp_path: Path) -> None:
    """Mission Planner saved an APM 2.x log downloaded over the CLI with what the board printed first (as
    ArduPilot's own LogAnalyzer examples of 2013-2014 open): read, the banner listed, not called damage."""
    binary = log_2014(tmp_path)
    plain = write_text_log(binary, tmp_path / "plain.log")
    banner = b"1\r\n\r\nArduCopter V3.0.1 (5c6503e2)\r\nFree RAM: 1331\r\nArduPilot 2\r\n"
    downloaded = tmp_path / "downloaded.log"
    downloaded.write_bytes(banner + plain.read_bytes())
    assert sniff_format(downloaded) == "ardupilot_text"
    table = read_log(downloaded)
    (said,) = [s for s in table.skipped if "download banner" in s.reason]
    assert said.count == 4 and said.action == "skipped" and "ArduCopter V3.0.1 (5c6503e2)" in said.reason
    table.skipped.remove(said)
    assert table.metadata.pop("firmware") == "ArduCopter V3.0.1 (5c6503e2)"  # named nowhere else in a 2013 log
    assert_same_table(read_log(binary), table)
    # more than a banner's worth of text, or binary, before the FMT: not a text DataFlash log
    chatter = tmp_path / "chatter.log"
    chatter.write_bytes(b"hello\n" * 17 + plain.read_bytes())
    junk = tmp_path / "junk.log"
    junk.write_bytes(b"\x00\xff\x13\n" + plain.read_bytes())
    for refused in (chatter, junk):
        with pytest.raises(UnsupportedFormatError, match="unknown format"):
            sniff_format(refused)


def test_damaged_lines_are_skipped_counted_and_the_rest_read(tmp_path: Path) -> None:
    lines = write_text_log(log_2014(tmp_path), tmp_path / "clean.log").read_bytes().split(b"\r\n")[:-1]
    gps = [i for i, line in enumerate(lines) if line.startswith(b"GPS, ")]
    damaged = list(lines)
    damaged[gps[2]] = damaged[gps[2]].rsplit(b",", 1)[0]  # a field short
    damaged[gps[4]] += b", 7"  # a field too many
    damaged[gps[6]] = damaged[gps[6]].replace(b", 3, ", b", x3, ", 1)  # text where a number belongs
    damaged[gps[8] + 1] = b"\x00\xa3\x95\x80garbage\xff"  # binary junk
    damaged.insert(gps[9], b"XYZ, 1, 2, 3")  # a message type no FMT defines
    cut = b"\r\n".join(damaged) + b"\r\n" + lines[gps[5]][:30]  # a last line cut without its newline
    path = tmp_path / "damaged.log"
    path.write_bytes(cut)
    t = read_log(path)
    lost = {(s.stream, s.reason): s.count for s in t.skipped if s.action == "lost"}
    assert lost == {
        ("<ardupilot_text>", "line that is not a message (binary junk or damaged text)"): 1,
        ("GPS", "line cut off at the end of the file (no newline)"): 1,
        ("GPS", "line with too few fields for its FMT (13)"): 1,
        ("GPS", "line with too many fields for its FMT (13)"): 1,
        ("GPS", "a field that is not a number where the format has one"): 1,
        ("XYZ", "no FMT line defines this message type"): 1,
    }
    assert len(t.fixes) == 20 - 3 and len(t.imu) == 200 - 1
    assert main(["inspect", str(path)]) == 3  # damaged input: what could be read is analysed, and said so


def test_nmea_logs_named_log_are_not_claimed(tmp_path: Path) -> None:
    for relative in ("nmea_boats/gpsd_saab-r4.log", "nmea_boats/signalk_plaka.log", "nmea_boats/gpsd_bundg_zeus_9.log"):
        assert sniff_format(real_log(relative)) == "nmea"
    # a line that merely mentions FMT is not the FMT of FMT
    other = tmp_path / "notes.log"
    other.write_text("FMT, 130, 45, GPS, BIHBcLLeeEefI, Status\nGPS, 3, 1\n")
    with pytest.raises(ReaderError):
        sniff_format(other)


@pytest.mark.parametrize(
    ("content", "says"),
    [
        (b"", "file is empty"),
        (b"\xef\xbb\xbf\r\n\r\n", "unknown format"),
        (b"GPS, 3, 122376200, 1790, 9, 1.67\n", "unknown format"),
        (b"FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format,Columns\n", "no GPS, IMU or EKF message"),
    ],
    ids=["empty", "bom-and-blank-lines", "no-fmt", "fmt-alone"],
)
def test_a_log_with_nothing_to_read_is_refused_in_one_line(
    content: bytes, says: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "flight.log"
    path.write_bytes(content)
    assert main(["inspect", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and str(path) in err and "Traceback" not in err and len(err.splitlines()) == 1


def test_the_text_reader_refuses_a_file_without_an_fmt_line(tmp_path: Path) -> None:
    path = tmp_path / "flight.log"
    path.write_bytes(b"GPS, 3, 122376200\r\nIMU, 1, 2\r\n")
    with pytest.raises(ReaderError, match="no FMT line"):
        open_text_dataflash(path)


def test_inject_on_a_text_log_writes_text_that_reads_as_the_attacked_binary(tmp_path: Path) -> None:
    binary = log_2014(tmp_path, n_gps=60)
    text = write_text_log(binary, tmp_path / "2014.log")
    attack = "capture:start=4,clock=0.5"
    outs = [tmp_path / "attacked.bin", tmp_path / "attacked.log"]
    for src, out in zip((binary, text), outs, strict=True):
        assert main(["inject", str(src), "--attack", attack, "-o", str(out)]) == 0
    attacked_bin, attacked_text = read_log(outs[0]), read_log(outs[1])
    pd.testing.assert_frame_equal(attacked_bin.fixes, attacked_text.fixes)
    assert not attacked_text.fixes["lat_deg"].equals(read_log(text).fixes["lat_deg"])  # the attack is in it
    before, after = text.read_bytes().split(b"\r\n"), outs[1].read_bytes().split(b"\r\n")
    assert len(before) == len(after)
    changed = [(b, a) for b, a in zip(before, after, strict=True) if b != a]
    assert changed and all(b.startswith(b"GPS, ") and a.startswith(b"GPS, ") for b, a in changed)
    # the rewritten lines keep their delimiter and their fields' count
    assert all(a.count(b", ") == b.count(b", ") for b, a in changed)
