"""A folder is one log only when it holds nothing but that log's files: NMEA files of one voyage, a
RINEX pair, a CSV log. A folder that also holds logs of other formats (u-blox captures beside NMEA, a
phone's GnssLogger and NMEA files beside its RINEX) is a folder of separate logs: `analyze` says so in
one line, and `batch` takes each file as its own log rather than dropping them unread."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from paths import SAMPLE_LOGS, real_log

from readers import is_companion, separate_logs, sniff_format
from spooflens.batch import find_logs
from spooflens.cli import main
from spooflens.errors import UnsupportedFormatError

SAAB = "nmea_boats/gpsd_saab-r4.log"
ZEUS = "nmea_boats/gpsd_bundg_zeus_9.log"
F9R = "ubx_receivers/gpsd_ublox-zed-f9r.log"


def _folder(root: Path, name: str, *logs: str) -> Path:
    folder = root / name
    folder.mkdir(parents=True)
    for log in logs:
        shutil.copyfile(real_log(log), folder / Path(log).name)  # copies: batch resolves links
    return folder


def test_nmea_files_with_a_readme_beside_them_are_one_log(tmp_path: Path) -> None:
    voyage = _folder(tmp_path, "voyage", SAAB, ZEUS)
    (voyage / "SOURCE.md").write_text("# where these came from\nrecorded by a, b and c\n")
    with pytest.raises(UnsupportedFormatError):  # text with commas, but no CSV log's header
        sniff_format(voyage / "SOURCE.md")
    assert separate_logs(voyage, "nmea") == []
    assert sniff_format(voyage) == "nmea"


def test_a_u_blox_capture_beside_nmea_files_makes_a_folder_of_separate_logs(tmp_path: Path) -> None:
    folder = _folder(tmp_path, "receivers", SAAB, F9R)
    assert sniff_format(folder / Path(F9R).name) == "ubx"
    assert [(p.name, fmt) for p, fmt in separate_logs(folder, "nmea")] == [(Path(F9R).name, "ubx")]
    with pytest.raises(UnsupportedFormatError, match=r"folder of separate logs, not one nmea log: .*f9r\.log \(ubx\)"):
        sniff_format(folder)


def test_analyze_of_a_folder_of_separate_logs_is_a_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _folder(tmp_path, "receivers", SAAB, F9R)
    assert main(["analyze", str(folder), "-o", str(tmp_path / "x.rrd")]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(folder) in err and "spooflens batch" in err
    assert not (tmp_path / "x.rrd").exists()


def test_batch_takes_each_log_of_a_folder_of_separate_logs_and_a_voyage_folder_as_one(tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    _folder(logs, "receivers", SAAB, F9R)
    _folder(logs, "voyage", SAAB, ZEUS)
    found, _ = find_logs((f"{logs}/**/*",))
    assert sorted(str(p.relative_to(logs)) for p in found) == [
        "receivers/gpsd_saab-r4.log",
        "receivers/gpsd_ublox-zed-f9r.log",
        "voyage",
    ]
    assert find_logs((str(logs),)) == find_logs((f"{logs}/**/*",))  # a folder named as it is: every depth
    assert find_logs((str(logs / "voyage"),))[0] == [(logs / "voyage").resolve()]  # a folder that is one log


def test_the_phone_folder_of_the_real_logs_is_three_logs() -> None:
    phone = real_log("android_gnsslogger/gnss_lib_py")
    found, _ = find_logs((str(phone), f"{phone}/*"))  # the folder itself and what it holds
    assert sorted(p.name for p in found) == ["pixel6.23o", "pixel6.nmea", "pixel6.txt"]


def test_a_csv_log_of_another_name_needs_a_log_header(tmp_path: Path) -> None:
    named = tmp_path / "fixes.log"
    named.write_text("# a logger's export\nt_s,lat,lon,alt\n0,1,2,3\n")
    assert sniff_format(named) == "csv"
    prose = tmp_path / "README"
    prose.write_text("recorded by a, b and c\nwith care\n")
    with pytest.raises(UnsupportedFormatError, match="unknown format"):
        sniff_format(prose)
    odd = tmp_path / "odd.csv"  # a .csv file is the format's own: its columns are judged when read
    odd.write_text("a,b\n1,2\n")
    assert sniff_format(odd) == "csv"


def test_rinex_navigation_files_serve_logs_and_are_not_logs_themselves() -> None:
    phone = real_log("android_gnsslogger/gps-measurement-tools")
    found, not_logs = find_logs((f"{phone}/*",))
    assert sorted(p.name for p in found) == [
        "pseudoranges_log_2016_06_30_21_26_07.txt",
        "pseudoranges_log_2016_08_22_14_45_50.txt",
    ]
    assert {"hour1820.16n", "hour2350.16n"} <= {p.name for p in not_logs}
    assert is_companion(phone / "hour1820.16n", "rinex")
    assert not is_companion(real_log("rinex_gsi_pair/07590920.05o"), "rinex")


def test_a_folder_of_mcap_files_without_a_bag_s_metadata_is_a_folder_of_separate_logs(tmp_path: Path) -> None:
    samples = SAMPLE_LOGS
    folder = tmp_path / "flights"
    folder.mkdir()
    for name in ("ground_ros2.mcap", "dual_receiver.mcap"):
        shutil.copyfile(samples / name, folder / name)
    # not a ROS2 bag (no metadata.yaml, no database): each file is a log the MCAP reader takes alone
    with pytest.raises(
        UnsupportedFormatError, match=r"folder of separate logs, it holds dual_receiver\.mcap \(mcap\), ground_ros2"
    ):
        sniff_format(folder)
    assert sorted(p.name for p in find_logs((str(folder / "*"),))[0]) == ["dual_receiver.mcap", "ground_ros2.mcap"]
    # the folder named as it is: the logs in it
    assert sorted(p.name for p in find_logs((str(folder),))[0]) == ["dual_receiver.mcap", "ground_ros2.mcap"]
    bag = samples / "ground_ros2_sqlite3"
    assert sniff_format(bag) == "ros2bag" and find_logs((str(bag),))[0] == [bag]


def test_the_real_boat_folder_holds_a_2011_recording_and_a_2018_one() -> None:
    from readers import read_log

    table = read_log(real_log("nmea_boats"))
    assert len(table.segments) == 2
    first, second = table.segment(0), table.segment(1)
    assert first.receivers() == ["gpsd_saab-r4.log/GP"] and first.absolute_iso(0.0).startswith("2011-06-01")
    assert second.receivers() == ["gpsd_bundg_zeus_9.log/GP", "signalk_plaka.log/GP"]
    assert second.absolute_iso(0.0).startswith("2018-08-20") and second.duration_s < 5 * 3600


def test_the_sample_folder_names_its_logs_not_their_truth_files() -> None:
    samples = SAMPLE_LOGS
    truth = samples / "ground.bag.truth.csv"
    assert sniff_format(truth) == "csv" and is_companion(truth, "csv")  # data for ground.bag, no log
    with pytest.raises(
        UnsupportedFormatError, match=r"it holds dual_receiver\.mcap \(mcap\), ground\.bag \(ros1bag\),"
    ):
        sniff_format(samples)  # not "not one csv log": truth files make no CSV folder


def test_a_rinex_observation_file_without_navigation_is_analysed_by_what_needs_only_observations(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The real phone RINEX `pixel6.23o` has no navigation file beside it: no fixes, no satellite
    positions. It was refused ("no GNSS fixes"); its C/N0 across satellites is still evidence."""
    import json

    log = real_log("android_gnsslogger/gnss_lib_py/pixel6.23o")
    out = tmp_path / "p6.json"
    assert main(["analyze", str(log), "-o", str(tmp_path / "p6.rrd"), "--json", str(out), "--quiet"]) == 0
    summary = json.loads(out.read_text())
    ran = {a["name"]: a for a in summary["analyses"] if a.get("ran")}
    assert "satellite_signals" in ran and "raim" not in ran
    assert summary["verdict"]["headline"].startswith("NO SPOOFING DETECTED by 1 detector")
    assert capsys.readouterr().out.strip().startswith("NO SPOOFING DETECTED")


def test_raw_observations_with_satellite_positions_and_no_fixes_are_solved_and_analysed(tmp_path: Path) -> None:
    """The meaconed sample without its receiver's fixes: refused before ("no GNSS fixes"); its pseudoranges
    give the fixes, and the meaconing at 120 s is found as with them."""
    import json

    samples = SAMPLE_LOGS
    log = tmp_path / "raw_only"
    shutil.copytree(samples / "meaconed_raw", log)
    (log / "fixes.csv").unlink()
    out = tmp_path / "raw.json"
    assert main(["analyze", str(log), "-o", str(tmp_path / "raw.rrd"), "--json", str(out), "--quiet"]) == 0
    summary = json.loads(out.read_text())
    assert [c["action"] for c in summary["computed"]] == ["computed"]
    spoofing = [i for i in summary["verdict"]["incidents"] if i["spoofing"]]
    assert spoofing and abs(spoofing[0]["start_s"] - 120.0) <= 2.0
