"""A u-blox receiver's stored position log read back (UBX-LOG-RETRIEVEPOS): its records are fixes, each at
its own UTC date and time, read as the receiver's fixes and said to be the stored log, not live output;
records retrieved out of time order are sorted; beside live fixes the stored log is left out."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from pyubx2 import GET, UBXMessage

from readers import read_log
from spooflens.cli import main
from spooflens.epoch_table import HOLDS
from spooflens.schema import FixType

LOGRETRIEVE = "corpus/gpsd/ublox-zoe-m8b-logretrieve.log"
EXIT_DAMAGED = 3  # the capture's last message is cut by the end of the file


def test_the_stored_log_of_a_zoe_m8b_reads_as_its_fixes(real: Path) -> None:
    table = read_log(real / LOGRETRIEVE)
    f = table.fixes
    assert len(f) == 34  # 34 LOG-RETRIEVEPOS records, every one a 3-D fix
    assert table.time_reference == "gps"
    assert table.absolute_iso(0.0).startswith("2020-02-04T13:03:13")  # the first record's own UTC time
    assert float(f["t_s"].iloc[-1]) == 532.0  # 13:12:05: ten-second records and one pause of 209 s
    first = f.iloc[0]  # lon 6.653144, lat 46.542021 (1e-7 deg), hMSL 716.6 m, hAcc 15 m, 0.12 m/s at 156 deg
    assert (first["lat_deg"], first["lon_deg"]) == pytest.approx((46.542021, 6.653144), abs=1e-9)
    assert first["height_m"] == pytest.approx(716.6)
    assert first["h_acc_m"] == 15.0 and first["sats_used"] == 8.0
    assert first["vel_n_mps"] == pytest.approx(0.12 * math.cos(math.radians(156.0)))
    assert first["vel_e_mps"] == pytest.approx(0.12 * math.sin(math.radians(156.0)))
    assert math.isnan(first["vel_u_mps"]) and math.isnan(first["v_acc_m"])
    assert set(f["fix_type"]) == {FixType.FIX_3D}
    assert f["lat_deg"].between(46.5419, 46.5421).all() and f["lon_deg"].between(6.6530, 6.6533).all()
    assert "stored position log read back" in table.metadata["fixes.source"]
    assert "not its live output" in table.metadata["fixes.source"]
    (stream,) = [s for s in table.streams if s.role == "fix"]
    assert stream.msgtype == "UBX LOG-RETRIEVEPOS"
    reasons = {s.stream: s.reason for s in table.skipped}
    assert "odometer" in reasons["LOG-RETRIEVEPOSEXTRA"]
    assert "hMSL" in reasons["LOG-RETRIEVEPOS"]


def test_analyze_gives_the_stored_log_a_verdict(real: Path, tmp_path: Path) -> None:
    summary = tmp_path / "s.json"
    args = ["analyze", str(real / LOGRETRIEVE), "-o", str(tmp_path / "s.rrd"), "--json", str(summary), "--quiet"]
    assert main(args) == EXIT_DAMAGED
    verdict = json.loads(summary.read_text())["verdict"]
    assert verdict["headline"].startswith("NO SPOOFING DETECTED") and verdict["spoofed"] is False


def _record(entry: int, second: int, fix_type: int = 3) -> bytes:
    return UBXMessage(
        "LOG", "LOG-RETRIEVEPOS", GET, entryIndex=entry, lon=6.6531, lat=46.542, hMSL=716_000, hAcc=7000,
        gSpeed=0, heading=0, fixType=fix_type, year=2020, month=2, day=4, hour=13, minute=3, second=second, numSV=8,
    ).serialize()  # fmt: skip


def test_records_retrieved_out_of_time_order_are_sorted_and_said_so(tmp_path: Path) -> None:
    # a circular log that wrapped: entries 0-2 are the newest, 3-5 the oldest; entry 4 holds no fix
    path = tmp_path / "wrapped.ubx"
    seconds = (40, 50, 55, 10, 20, 30)
    path.write_bytes(b"".join(_record(k, s, 0 if k == 4 else 3) for k, s in enumerate(seconds)))
    table = read_log(path)
    assert table.fixes["t_s"].tolist() == [0.0, 20.0, 30.0, 40.0, 45.0]
    assert "sorted by their own date and time" in table.metadata["fixes.order"]
    repaired = [s for s in table.skipped if "not in time order" in s.reason]
    assert [(s.count, s.action) for s in repaired] == [(1, "repaired")]
    assert any(s.count == 1 and "without a fix" in s.reason for s in table.skipped)


def test_a_stored_log_without_any_fix_holds_nothing_to_judge_and_says_it_is_the_stored_log(tmp_path: Path) -> None:
    path = tmp_path / "empty_log.ubx"
    path.write_bytes(_record(0, 10, 0) + _record(1, 20, 0))
    table = read_log(path)
    assert not table.streams and "the receiver's stored log read back" in table.metadata[HOLDS]


def test_beside_live_fixes_the_stored_log_is_left_out(tmp_path: Path) -> None:
    live = UBXMessage(
        "NAV", "NAV-PVT", GET, iTOW=186_400_000, year=2024, month=3, day=5, hour=3, min=46, second=22,
        validDate=1, validTime=1, fixType=3, gnssFixOk=1, numSV=14, lon=7.5, lat=45.1, height=300_000,
        hAcc=1500, vAcc=2500,
    ).serialize()  # fmt: skip
    path = tmp_path / "live_and_stored.ubx"
    path.write_bytes(live + _record(0, 10) + _record(1, 20))
    table = read_log(path)
    assert table.fixes["lat_deg"].tolist() == [pytest.approx(45.1)]  # the live fix only
    assert "fixes.source" not in table.metadata
    (left_out,) = [s for s in table.skipped if s.stream == "LOG-RETRIEVEPOS"]
    assert left_out.count == 2 and "beside its live fixes" in left_out.reason
