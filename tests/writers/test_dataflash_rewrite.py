"""Attacked copies of DataFlash logs of every revision: the receiver's time moved under the field names the
log's own revision gives it (a 2015 ArduCopter 3.3 log calls GPS week and ms of week `Week`/`TimeMS`); a
jammer's marks written where the reader found them (GPS NSats/HDop, GPA or UBX3 accuracies, each receiver's
UBX1 noise, jamming indicator and AGC), its lost fixes as no fix."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from dataflash_support import WEEK, Fmt, flight, write_dataflash
from numpy.typing import NDArray
from paths import real_log

from readers import read_log
from readers.ardupilot import gps_clock, gps_fixes, gps_rows, ubx1_reports
from readers.dataflash import open_dataflash
from spooflens.attacks import apply_attack, parse_attack
from spooflens.cli import main
from spooflens.epoch_table import EpochTable
from spooflens.writers.dataflash_rewrite import rewrite_dataflash
from spooflens.writers.rewrite import unwritten_changes


def test_an_attack_that_moves_the_clock_rewrites_an_old_logs_week_and_time_of_week(tmp_path: Path) -> None:
    log = real_log("corpus/dronekit-la-testdata/log171.bin")
    out = tmp_path / "log171_capture.bin"
    assert main(["inject", str(log), "--attack", "capture:start=60,clock=0.5", "-o", str(out)]) == 0
    clean, spoofed = read_log(log).fixes, read_log(out).fixes
    before = clean["t_s"].to_numpy() < 59.0
    moved = spoofed["time_offset_s"].to_numpy() - clean["time_offset_s"].to_numpy()
    # the log's clock is put on GPS time by the median offset over all fixes, attacked ones included: the
    # attack shows as one step of the receiver's time, 0.5 s (GMS/TimeMS is whole milliseconds), after 60 s
    low, high = moved[before].min(), moved[-1]
    assert np.ptp(moved[before]) < 1e-6 and high - low == pytest.approx(0.5, abs=2e-3)
    assert np.all((np.abs(moved - low) < 2e-3) | (np.abs(moved - high) < 2e-3))
    assert np.all(np.diff(moved) > -2e-3)  # once moved, it stays moved


LOG171 = "corpus/dronekit-la-testdata/log171.bin"  # ArduCopter 3.3, 2015: UBX1 every ~2 s, UBX3 with each fix


def _ubx1_record_of_each_fix(path: Path, table: EpochTable) -> NDArray[np.float64]:
    """Where the UBX1 record the reader joined to each of the table's fixes sits in the file (NaN: none)."""
    gps = gps_rows(open_dataflash(path), [])
    assert gps is not None
    _, offset_ns, _ = gps_clock(gps)
    rows = gps_fixes(gps, offset_ns, [], {}).merge(gps[["ofs", "ubx1_ofs"]], on="ofs")
    fixes = table.fixes.assign(t_ns=table.absolute_ns(table.fixes["t_s"].to_numpy()))
    joined = fixes.merge(rows[["receiver_id", "t_ns", "ubx1_ofs"]], on=["receiver_id", "t_ns"], how="left")
    return joined["ubx1_ofs"].to_numpy(float)


MONITOR = ["noise_per_ms", "jamming_indicator", "agc"]


def _report_of_each_fix(path: Path, table: EpochTable, reports: pd.DataFrame) -> NDArray[np.float64]:
    """The values of the `reports` (`receiver_status` rows on `table`'s clock) whose UBX1 record each of
    the table's fixes was joined to: NaN for a fix joined to none."""
    log = open_dataflash(path)
    gps = gps_rows(log, [])
    assert gps is not None
    _, offset_ns, _ = gps_clock(gps)
    logged = ubx1_reports(log, offset_ns)
    assert logged is not None
    given = reports.assign(t_ns=table.absolute_ns(reports["t_s"].to_numpy()))
    by_record = logged[["receiver_id", "t_ns", "ofs"]].merge(given, on=["receiver_id", "t_ns"], validate="one_to_one")
    by_record = by_record.set_index("ofs")[MONITOR]
    return by_record.reindex(_ubx1_record_of_each_fix(path, table)).to_numpy(float)


def test_a_jammed_copy_of_an_old_log_carries_ubx1_ubx3_satellites_and_hdop(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log, out = real_log(LOG171), tmp_path / "log171_jam.bin"
    attack = "jam:start=100,end=150"
    assert main(["inject", str(log), "--attack", attack, "-o", str(out)]) == 0
    note = capsys.readouterr().out
    assert "UBX1" in note and "UBX3" in note and "not in the copy" not in note
    clean = read_log(log)
    jammed, _ = apply_attack(clean, parse_attack(attack))
    copy = read_log(out)
    assert copy.t0_ns == clean.t0_ns
    a, b = jammed.fixes, copy.fixes
    np.testing.assert_array_equal(b["t_s"], a["t_s"])
    np.testing.assert_array_equal(b["sats_used"], a["sats_used"])
    np.testing.assert_allclose(b["hdop"], a["hdop"], atol=0.005)  # HDop is logged in 0.01
    for column in ("h_acc_m", "v_acc_m", "vel_acc_mps"):  # UBX3: float32
        np.testing.assert_allclose(b[column], a[column], rtol=1e-6)
    # each UBX1 record carries the jammed values of its own report (its receiver_status row), and every fix
    # joined to it reads them
    np.testing.assert_array_equal(copy.receiver_status[MONITOR], jammed.receiver_status[MONITOR])
    assert (copy.receiver_status[MONITOR] != clean.receiver_status[MONITOR]).any(axis=1).sum() == 25
    assert np.isfinite(_ubx1_record_of_each_fix(out, copy)).mean() > 0.9
    np.testing.assert_array_equal(b[MONITOR].to_numpy(float), _report_of_each_fix(out, copy, jammed.receiver_status))
    t = b["t_s"].to_numpy()
    full_power = (t > 105) & (t < 145)
    before = clean.fixes["jamming_indicator"].to_numpy()
    assert (b["jamming_indicator"].to_numpy()[full_power] - before[full_power] >= 140).all()  # +150 at full power
    outside = (t < 100) | (t > 155)
    for column in ("noise_per_ms", "jamming_indicator", "agc", "sats_used", "hdop", "h_acc_m"):
        np.testing.assert_array_equal(b[column].to_numpy()[outside], clean.fixes[column].to_numpy()[outside])


def test_fixes_the_jammer_lost_are_written_as_no_fix(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log, out = real_log(LOG171), tmp_path / "log171_lost.bin"
    attack = "jam:start=100,end=150,lost=7"  # 7 of 10 satellites lost at half power: no fix
    assert main(["inject", str(log), "--attack", attack, "-o", str(out)]) == 0
    note = capsys.readouterr().out
    clean = read_log(log)
    jammed, _ = apply_attack(clean, parse_attack(attack))
    lost = len(clean.fixes) - len(jammed.fixes)
    assert lost > 100 and f"{lost} lost: Status 1, no fix" in note and "the lost fixes" not in note
    copy = read_log(out)
    np.testing.assert_array_equal(copy.fixes["t_s"], jammed.fixes["t_s"])  # the log's clock did not move
    no_fix = [s.count for s in copy.skipped if s.stream == "GPS[0]" and "no fix" in s.reason]
    before = [s.count for s in clean.skipped if s.stream == "GPS[0]" and "no fix" in s.reason]
    assert no_fix[0] == before[0] + lost
    # the receiver's UBX1 reports go on without the fix: each is written with the jammer at its own time
    assert "UBX1" in note
    np.testing.assert_array_equal(copy.receiver_status[MONITOR], jammed.receiver_status[MONITOR])
    t = copy.receiver_status["t_s"].to_numpy()
    fix_t = copy.fixes["t_s"].to_numpy()
    outage = (t > 103) & (t < 148)
    assert outage.sum() >= 20 and not ((fix_t > 102) & (fix_t < 149)).any()
    rise = copy.receiver_status["jamming_indicator"].to_numpy() - clean.receiver_status["jamming_indicator"].to_numpy()
    assert (rise[outage] == 150).all()  # +150 at full power, as on a fix
    agc = copy.receiver_status["agc"].to_numpy() / clean.receiver_status["agc"].to_numpy()
    np.testing.assert_allclose(agc[outage], 0.6, atol=1e-3)


# the GPS message of ArduPilot 3.4 on (2016+): microsecond boot time, instance, GPS week and milliseconds
GPS_2016 = Fmt(130, "GPS", "QBBIHBcLLeffffB", "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U")


def _two_receivers_with_ubx1(path: Path, seconds: int = 120) -> Path:
    """A 2016+ log: two u-blox receivers at 5 Hz, each with its GPA and a UBX1 (MON-HW) once a second,
    logged 2 ms before the fix it is joined to first."""
    gps = GPS_2016
    gpa = Fmt(152, "GPA", "QBCCCCfBIHf", "TimeUS,I,VDop,HAcc,VAcc,SAcc,YAcc,VV,SMS,Delta,Und")
    ubx1 = Fmt(160, "UBX1", "QBHBBHI", "TimeUS,Instance,noisePerMS,jamInd,aPower,agcCnt,config")
    msgs = []
    for i, (boot_ms, tow, lat, lon) in enumerate(flight(5 * seconds)):
        us = boot_ms * 1000
        for inst in (0, 1):
            if i % 5 == 0:
                monitor = {"noisePerMS": 90 + inst, "jamInd": 30 + 2 * inst, "agcCnt": 5000 + 100 * inst}
                msgs.append(ubx1.message(TimeUS=us - 2000 + inst, Instance=inst, **monitor))
            fix = {"Status": 3, "GMS": tow, "GWk": WEEK, "NSats": 12 - inst, "HDop": 0.8, "Lat": lat, "Lng": lon}
            msgs.append(gps.message(TimeUS=us + inst, I=inst, **fix, Alt=584 + inst, Spd=5, VZ=0.1, U=1))
            msgs.append(gpa.message(TimeUS=us + inst, I=inst, VDop=1.3, HAcc=1.1 + inst, VAcc=1.6, SAcc=0.2, Und=-20))
    return write_dataflash(path, [gps, gpa, ubx1], msgs)


def test_each_receivers_ubx1_is_written_back_to_its_own_records(tmp_path: Path) -> None:
    src = _two_receivers_with_ubx1(tmp_path / "two.bin")
    clean = read_log(src)
    jammed, _ = apply_attack(clean, parse_attack("jam:start=40,end=80,receiver=GPS[1]"))
    note = rewrite_dataflash(src, tmp_path / "jam.bin", clean, jammed, True)
    assert "UBX1" in note and "GPA" in note
    copy = read_log(tmp_path / "jam.bin")
    assert unwritten_changes(clean, jammed, copy) == []
    indicators = ["noise_per_ms", "jamming_indicator", "agc", "sats_used", "hdop", "vdop", "h_acc_m", "v_acc_m"]
    for rid in ("GPS[0]", "GPS[1]"):
        a = jammed.fixes[jammed.fixes["receiver_id"] == rid]
        b = copy.fixes[copy.fixes["receiver_id"] == rid]
        np.testing.assert_allclose(b[indicators[3:]], a[indicators[3:]], atol=0.005)  # GPA and HDop in 0.01
        # a UBX1 record once every 5 fixes, logged 2 ms before the first: the five read its report's values
        reports = jammed.receiver_status[jammed.receiver_status["receiver_id"] == rid]
        np.testing.assert_array_equal(b[MONITOR].to_numpy(), np.repeat(reports[MONITOR].to_numpy(), 5, axis=0))
    jammer_on = copy.fixes["t_s"].between(45, 75).to_numpy()
    gps1 = (copy.fixes["receiver_id"] == "GPS[1]").to_numpy()
    np.testing.assert_array_equal(copy.fixes["agc"][jammer_on & gps1], 0.6 * 5100)  # agc=0.6 at full power
    np.testing.assert_array_equal(copy.fixes["agc"][~gps1], 5000)  # the other receiver's records untouched


def test_a_2013_log_without_vz_or_receiver_messages_is_jammed_in_what_it_has(tmp_path: Path) -> None:
    # the 2013 GPS message has no VZ: the writer asked every log for one and failed on this revision
    gps = Fmt(130, "GPS", "BIHBcLLeeEe", "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs")
    imu = Fmt(131, "IMU", "Iffffff", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
    msgs = []
    for boot_ms, tow, lat, lon in flight(400):
        msgs += [imu.message(TimeMS=boot_ms - 20 * k, AccZ=-9.81) for k in range(10, 0, -1)]
        msgs.append(gps.message(Status=3, TimeMS=tow, Week=WEEK, NSats=8, HDop=1.5, Lat=lat, Lng=lon, Alt=584, Spd=5))
    src = write_dataflash(tmp_path / "2013.bin", [gps, imu], msgs)
    clean = read_log(src)
    jammed, _ = apply_attack(clean, parse_attack("jam:start=20,end=50"))
    note = rewrite_dataflash(src, tmp_path / "jam.bin", clean, jammed, True)
    assert note.startswith("150 GPS messages rewritten") and "UBX1" not in note
    copy = read_log(tmp_path / "jam.bin")
    assert unwritten_changes(clean, jammed, copy) == []  # no monitor or accuracy in the log: nothing to carry
    on = copy.fixes["t_s"].between(25, 45).to_numpy()
    assert (copy.fixes["sats_used"][on] == 7).all() and (copy.fixes["hdop"][on] == 1.6).all()
    np.testing.assert_allclose(copy.fixes["vel_n_mps"], jammed.fixes["vel_n_mps"], atol=0.006)  # Spd in cm/s
    assert copy.fixes["vel_n_mps"][on].std() > 0.05 and copy.fixes["vel_u_mps"].isna().all()


def _one_receiver_with_raw_measurements(path: Path, seconds: int = 100) -> Path:
    """A 2016+ log: a 5 Hz receiver and its RXM-RAWX as the autopilot logs it (GRXH, then a GRXS per
    satellite) once a second, eight GPS satellites from 32 to 46 dB-Hz."""
    gps = GPS_2016
    grxh = Fmt(161, "GRXH", "QdHbBB", "TimeUS,rcvTime,week,leapS,numMeas,recStat")
    grxs = Fmt(162, "GRXS", "QddfBBBHBBBBB", "TimeUS,prMes,cpMes,doMes,gnss,sv,freq,lock,cno,prD,cpD,doD,trk")
    msgs = []
    for i, (boot_ms, tow, lat, lon) in enumerate(flight(5 * seconds)):
        us = boot_ms * 1000
        fix = {"Status": 3, "GMS": tow, "GWk": WEEK, "NSats": 8, "HDop": 0.9, "Lat": lat, "Lng": lon}
        msgs.append(gps.message(TimeUS=us, I=0, **fix, Alt=584, Spd=5, VZ=0.1, U=1))
        if i % 5 == 0:
            msgs.append(grxh.message(TimeUS=us + 1000, rcvTime=tow / 1000, week=WEEK, leapS=18, numMeas=8))
            for sv in range(1, 9):
                measured = {"prMes": 2.1e7 + 1e5 * sv, "cpMes": 1.1e8, "doMes": -500.0 + 100 * sv, "cno": 30 + 2 * sv}
                msgs.append(grxs.message(TimeUS=us + 1000, **measured, gnss=0, sv=sv, trk=7))
    return write_dataflash(path, [gps, grxh, grxs], msgs)


def test_raw_measurements_carry_the_jammers_c_n0_noise_and_lost_satellites(tmp_path: Path) -> None:
    src = _one_receiver_with_raw_measurements(tmp_path / "raw.bin")
    clean = read_log(src)
    jammed, truth = apply_attack(clean, parse_attack("jam:start=30,end=60"))
    assert truth.satellites == ["G01", "G02"]  # 32 and 34 dB-Hz, 15 dB down: below the 20 dB-Hz threshold
    note = rewrite_dataflash(src, tmp_path / "jam.bin", clean, jammed, True)
    assert "GRXS" in note
    copy = read_log(tmp_path / "jam.bin")
    assert unwritten_changes(clean, jammed, copy) == []
    a, b = jammed.observations, copy.observations
    np.testing.assert_array_equal(b[["t_s", "sv_id"]], a[["t_s", "sv_id"]])  # the lost satellites' rows gone
    np.testing.assert_allclose(b["cn0_dbhz"], a["cn0_dbhz"], atol=0.5)  # cno: whole dB-Hz
    np.testing.assert_array_equal(b["pseudorange_m"], a["pseudorange_m"])
    np.testing.assert_allclose(b["doppler_hz"], a["doppler_hz"], atol=1e-4)  # doMes: float32
    moved = b.merge(clean.observations, on=["t_s", "sv_id"], suffixes=("", "_clean"))
    noise = (moved["pseudorange_m"] - moved["pseudorange_m_clean"]).abs()
    assert noise.max() > 1.0  # the jammer's thermal noise, 0.5 m x sqrt(10^1.5 - 1) at full power
    (dropped,) = [s.count for s in copy.skipped if "pseudorange not valid" in s.reason]
    assert dropped == len(clean.observations) - len(jammed.observations)
