"""Every refusal tells the truth: other receivers' protocols named, NMEA of every shape recognised,
headings without a fix read as headings, AIS traffic said to be AIS."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from paths import real_log

from readers import read_log, sniff_format
from spooflens.cli import main
from spooflens.errors import UnsupportedFormatError

GPSD = "corpus/gpsd"


@pytest.mark.parametrize(
    ("log", "protocol"),
    [
        (f"{GPSD}/bu303-moving.log", "SiRF binary"),
        (f"{GPSD}/ublox-sirf1.log", "SiRF binary"),
        (f"{GPSD}/trimble-lassen_iq.log", "Trimble TSIP"),
        (f"{GPSD}/trimble-res720.log", "Trimble TSIP"),  # after a preamble of gpsd JSON reports
        (f"{GPSD}/garmin18x-bin.log", "Garmin binary"),
        (f"{GPSD}/oncore-m12.log", "Motorola Oncore binary"),
        (f"{GPSD}/greis-binary.log", "Javad GREIS"),
        (f"{GPSD}/skytraq-bin.log", "SkyTraq binary"),
        (f"{GPSD}/superstar2.log", "NovAtel SuperStar II binary"),
        ("corpus/rtklib/ss2_20080517.log", "NovAtel SuperStar II binary"),
        ("corpus/rtklib/cres_20080526.bin", "Hemisphere/Crescent binary ($BIN)"),
        (f"{GPSD}/zodiac.log", "Rockwell Zodiac binary"),
        (f"{GPSD}/navcom.log", "NavCom binary"),
        (f"{GPSD}/geostar-geos1m-binary.log", "GeoStar binary"),
        (f"{GPSD}/italk-binary.log", "Fastrax iTalk binary"),
        (f"{GPSD}/quectel-l76k-binary.log", "CASIC binary"),
        (f"{GPSD}/rtcm3.2.log", "RTCM 3"),
        (f"{GPSD}/rtcm2.log", "RTCM 2"),
        (f"{GPSD}/ntrip_sourcetable.log", "an NTRIP source table"),
    ],
)
def test_other_protocols_are_refused_by_name(log: str, protocol: str, capsys: pytest.CaptureFixture[str]) -> None:
    path = real_log(log)
    with pytest.raises(
        UnsupportedFormatError,
        match=rf"{path.name}: {protocol.replace('(', '.').replace(')', '.').replace('$', '.')}.*not supported",
    ):
        sniff_format(path)
    assert main(["inspect", str(path)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err and "unknown format" not in err


def test_random_bytes_stay_unknown(tmp_path: Path) -> None:
    junk = tmp_path / "junk.bin"
    junk.write_bytes(np.random.default_rng(3).integers(0, 256, 20_000, dtype=np.uint8).tobytes())
    with pytest.raises(UnsupportedFormatError, match="unknown format"):
        sniff_format(junk)


def test_a_damaged_nmea_log_with_a_comment_header_is_nmea() -> None:
    """gpsd's GPS-320FW cold boot: `#` header, then as many broken checksums as good ones (was: a CSV)."""
    path = real_log(f"{GPSD}/gp-320fw-2019-04-07-coldboot.log")
    assert sniff_format(path) == "nmea"
    t = read_log(path)
    assert len(t.fixes) and any("bad checksum" in s.reason for s in t.skipped)


@pytest.mark.parametrize(
    ("log", "streams"),
    [(f"{GPSD}/pypilot.log", {"APHDM"}), ("corpus/signalk/n2kd-183-merrimac.log", {"24HDG", "04HDM"})],
)
def test_instruments_with_a_heading_and_no_fix_are_read_as_headings(log: str, streams: set[str]) -> None:
    """An autopilot's $APHDM, an N2K gateway's $04HDM/$24HDG (numeric talkers): headings, said to be
    magnetic taken as true where there is no variation, in file order where the log has no time."""
    t = read_log(real_log(log))
    assert set(t.headings["heading_id"]) == streams and not len(t.fixes)
    reasons = " ".join(s.reason for s in t.skipped if s.action == "repaired")
    assert "taken as true" in reasons and "placed by line number" in reasons
    assert main(["inspect", str(real_log(log))]) == 0


@pytest.mark.parametrize(
    ("log", "why"),
    [
        (f"{GPSD}/pypilot.log", "the log holds heading APHDM (7)"),
        (f"{GPSD}/ublox-lea-5q.log", "receiver GP never had a fix: 10 epochs without a valid position"),
        (f"{GPSD}/eXplorist110.log", "receiver GP never had a fix: 29 epochs without a valid position"),
        ("corpus/px4-pyulog/sample.ulg", "the log holds imu sensor_combined (17070)"),
        # sound logs of messages none of which spooflens reads: what they hold, named
        (
            f"{GPSD}/ais-18-27.log",
            "AIS messages only (276 VDM: other stations' reports; none of its own station's, VDO)",
        ),
        # a base station's own reports (!BSVDO, !AIVDO): one class A position report among them, two fragments
        # of one binary message counted as the sentences they are
        (
            f"{GPSD}/ais-nmea-type6-fid55.log",
            "1474 VDM: other stations' reports; 6 VDO sentences, its own station's, 1 of",
        ),
        (
            "corpus/pynmeagps/quectel_nmea_response.log",
            "only sentences spooflens does not read ($PQTMCFGMSGRATE x17, $PQTMCFGUART x6,",
        ),
        (f"{GPSD}/skytraq-err.log", "only sentences spooflens does not read ($STI x6)"),
        (f"{GPSD}/tnt-revolution.log", "($PTNTHTM x50, $HCXDR x10): no position, heading or satellite report"),
        ("corpus/pynmeagps/pygpsdata-maritime.log", "($IIALF x3, $AIEPV x2,"),
        (f"{GPSD}/ublox-ned-m8t-sbfrx3.log", "it holds navigation messages only (RXM-SFRBX x165)"),
    ],
)
def test_a_log_without_gnss_data_is_analysed_to_no_verdict(
    log: str, why: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Not an empty log: a heading, an IMU or a receiver that never saw a satellite. What the log holds is
    recorded and the verdict says there is no GNSS to judge, and why."""
    capsys.readouterr()
    json_path = tmp_path / "v.json"
    args = ["analyze", str(real_log(log)), "-o", str(tmp_path / "v.rrd"), "--json", str(json_path), "--quiet"]
    assert main(args) == 0
    headline = json.loads(json_path.read_text())["verdict"]["headline"]
    assert headline.startswith("NO VERDICT: no GNSS data to judge: ") and why in headline


def test_the_report_of_a_log_with_nothing_to_judge_draws_no_empty_timeline(tmp_path: Path) -> None:
    html = tmp_path / "r.html"
    args = ["analyze", str(real_log(f"{GPSD}/tnt-revolution.log")), "-o", str(tmp_path / "r.rrd"), "--quiet"]
    assert main([*args, "--html", str(html)]) == 0
    text = html.read_text()
    assert "No stream spooflens reads: nothing to draw." in text and "<svg" not in text
    assert "only sentences spooflens does not read ($PTNTHTM x50, $HCXDR x10)" in text


def test_doubled_dollar_sentences() -> None:
    """ST Teseo LIV4F logged as `$$GNGSA,...`: the sentences are read (was: unknown format)."""
    t = read_log(real_log(f"{GPSD}/st-teseo-liv4f.log"))
    assert len(t.fixes) >= 10


@pytest.mark.parametrize(
    "log", [f"{GPSD}/ais-18-27.log", f"{GPSD}/ublox-ned-m8t-sbfrx3.log", "corpus/pynmeagps/quectel_nmea_response.log"]
)
def test_a_log_with_nothing_to_judge_is_inspected_and_never_spoofed(
    log: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`inspect` says what it holds (exit 0); `inject` has nothing to spoof: one line, exit 2."""
    path = real_log(log)
    assert main(["inspect", str(path)]) == 0
    assert "no GNSS data to judge: " in capsys.readouterr().out
    assert main(["inject", str(path), "-o", str(tmp_path / path.name), "--attack", "ramp:rate=2,axes=en,start=1"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err and path.name in err
    assert not (tmp_path / path.name).exists()


def test_a_long_list_of_proprietary_sentences_is_cut_between_names(tmp_path: Path) -> None:
    """Lines shaped as proprietary sentences whose checksums all fail are no NMEA log: named, cut between names."""
    names = [f"PQTMCFG{chr(65 + i)}{chr(65 + j)}" for i in range(4) for j in range(10)]
    path = tmp_path / "config.log"
    path.write_text("".join(f"${name},OK*00\r\n" for name in names))
    with pytest.raises(UnsupportedFormatError) as refusal:
        sniff_format(path)
    assert "$PQTMCFGAF and 34 more), no standard sentence" in str(refusal.value)
