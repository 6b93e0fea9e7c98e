"""Captures of a receiver that never had a fix but logged its interference monitor or its sky: read
(the `receiver_status` frame, the satellites frame), the interference detector runs on them, and a
capture with nothing usable is still refused by what it holds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from paths import real_log

from readers import read_log
from spooflens.epoch_table import HOLDS
from spooflens.errors import ReaderError
from spooflens.pipeline.run import analyze_table


def test_sec_sig_jamming_warning_without_a_fix_is_a_jamming_event_and_no_spoofing_verdict() -> None:
    table = read_log(real_log("corpus/pyubx2/pygpsdata-SEC.log"))
    assert table.fixes.empty and table.satellites.empty  # no position invented
    status = table.receiver_status
    assert status["jamming_state"].tolist() == [1.0, 2.0, 2.0]  # SEC-SIG jammingState: ok, warning, warning
    assert status["spoofing_state"].tolist() == [1.0, 3.0, 1.0]
    assert "no time in the capture" in table.metadata["clock.receiver_status"]
    analysis = analyze_table(table)
    headline = analysis.verdict.headline
    assert headline.startswith("NO VERDICT: no spoofing detector could run on this log")
    assert "JAMMING / INTERFERENCE" in headline
    (result,) = [r for r in analysis.results if r.name == "interference"]
    events = result.extras["events"]
    assert isinstance(events, list) and len(events) == 1
    event = events[0]
    assert event["because"] == "the receiver reported jamming (warning)"
    assert event["fix"] == {"logged": False}
    assert "no C/N0 logged" in result.findings[0].text


def test_mon_rf_and_mon_hw_without_a_fix_give_the_front_end_and_the_monitors_word() -> None:
    table = read_log(real_log("corpus/pyubx2/pygpsdata-MON.log"))
    status = table.receiver_status
    # one output cycle (MON-RF, MON-HW) then a second MON-RF: jamInd 255, jammingState 3 (critical)
    assert status["agc"].tolist() == [1404.0, 1404.0]
    assert status["noise_per_ms"].tolist() == [92.0, 92.0]
    assert status["jamming_indicator"].tolist() == [7.0, 255.0]
    assert status["jamming_state"].tolist() == [0.0, 3.0]
    analysis = analyze_table(table)
    assert analysis.verdict.headline.startswith("NO VERDICT: no spoofing detector could run on this log")
    (result,) = [r for r in analysis.results if r.name == "interference"]
    assert result.ran
    receivers = result.extras["receivers"]
    assert isinstance(receivers, dict)
    monitor = receivers["ubx"]["jamming_monitor"]
    assert monitor["reported"] == "interference reported"
    assert monitor["codes_seen"] == {"0": "unknown or monitor off", "3": "critical"}
    assert not result.alarms  # one critical report: the detector needs two (a state held, not a blip)


def test_a_capture_whose_nmea_reports_its_sky_but_no_fix_is_read_for_its_cn0() -> None:
    table = read_log(real_log("corpus/pyubx2/2023-4-17_82912_serial-COM3.ubx"))
    assert table.fixes.empty
    sats = table.satellites
    assert set(sats["sv_id"]) >= {"G06", "G25"}
    assert np.isfinite(sats["cn0_dbhz"].to_numpy(float)).all()
    analysis = analyze_table(table)
    (result,) = [r for r in analysis.results if r.name == "interference"]
    assert result.ran and "C/N0 from the receiver's satellite reports" in result.reason
    assert not analysis.verdict.spoofed


def test_a_capture_of_navigation_messages_alone_holds_nothing_to_judge() -> None:
    table = read_log(real_log("corpus/gpsd/ublox-ned-m8t-sbfrx3.log"))
    assert not table.streams and table.format == "ubx"
    assert table.metadata[HOLDS].endswith("it holds navigation messages only (RXM-SFRBX x165)")
    headline = analyze_table(table).verdict.headline
    assert headline.startswith("NO VERDICT: no GNSS data to judge: no fix, raw observation or IMU sample")


def test_a_capture_of_no_message_is_still_refused(tmp_path: Path) -> None:
    path = tmp_path / "torn.ubx"
    path.write_bytes(b"\xb5\x62\x01\x07\x5c\x00" + bytes(40))  # a NAV-PVT header, its payload cut
    with pytest.raises(ReaderError, match=r"torn\.ubx"):
        read_log(path)


def test_a_capture_fixed_by_its_nmea_keeps_the_sky_its_gsv_states() -> None:
    # RTKLIB's 2008 capture: UBX RXM-RAW/SFRB and the receiver's NMEA; its fixes are the NMEA's GGA/RMC
    # and its sky the GSV (no NAV-SAT). The GSV's C/N0 per satellite is what the interference test and
    # the satellite-signal tests read; it was dropped once the capture had fixes
    table = read_log(real_log("corpus/rtklib/ubx_20080526.ubx"))
    assert len(table.fixes) == 242
    sats = table.satellites
    assert len(sats) > 10 * len(table.fixes) // 2 and np.isfinite(sats["cn0_dbhz"]).mean() > 0.5
    assert set(sats["receiver_id"].astype(str)) == set(table.fixes["receiver_id"].astype(str))
    t_fix, t_sky = table.fixes["t_s"].to_numpy(float), sats["t_s"].to_numpy(float)
    assert t_sky.min() >= t_fix.min() - 1.0 and t_sky.max() <= t_fix.max() + 1.0  # on the fixes' clock
    analysis = analyze_table(table)
    interference = next(r for r in analysis.results if r.name == "interference")
    assert interference.ran and "satellite reports" in interference.reason
    assert not analysis.verdict.spoofed
