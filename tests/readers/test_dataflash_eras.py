"""ArduPilot DataFlash logs of every format revision since 2013.

The corpus has one pre-2016 log, `dronekit-la-testdata/log171.bin` (ArduCopter 3.3-dev, 2015: `TimeMS`
clocks, GPS `Week`/`TimeMS`/`T`, the first EKF's EKF3/EKF4, UBX3 accuracies). No 2013-2014 log with a
licence was found, so those revisions are built here, in tmp_path, from the FMT definitions ArduPilot's
own headers of the time declared (libraries/DataFlash/DataFlash.h, LOG_COMMON_STRUCTURES, 2013-2015):
the bytes are what that firmware wrote, the values are made up.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from dataflash_support import WEEK, Fmt, flight, write_dataflash
from paths import real_log
from pymavlink.DFReader import DFReader_binary

from readers import read_log
from spooflens.cli import main
from spooflens.schema import FixType


def test_2014_revision_timems_clock_gps_week_and_board_time_t(tmp_path: Path) -> None:
    """Copter 3.1-3.2 (2014): GPS `Status,TimeMS,Week,...,VZ,T` (TimeMS = ms of week, T = boot ms), GPS2,
    IMU `TimeMS`, the first EKF's EKF3 innovations and EKF4 of that year (square-root variances, no ratios)."""
    gps = Fmt(130, "GPS", "BIHBcLLeeEefI", "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs,VZ,T")
    gps2 = Fmt(144, "GPS2", "BIHBcLLeEefIBI", "Status,TimeMS,Week,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,T,DSc,DAg")
    imu = Fmt(131, "IMU", "Iffffff", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
    ekf3 = Fmt(142, "EKF3", "Icccccchhhc", "TimeMS,IVN,IVE,IVD,IPN,IPE,IPD,IMX,IMY,IMZ,IVT")
    ekf4 = Fmt(143, "EKF4", "Icccccchhhc", "TimeMS,SVN,SVE,SVD,SPN,SPE,SPD,SMX,SMY,SMZ,SVT")
    msgs = []
    for boot_ms, tow, lat, lon in flight():
        for k in range(10):
            msgs.append(imu.message(TimeMS=boot_ms - 200 + 20 * k, AccZ=-9.81, GyrZ=0.01))
        fix = {"Status": 3, "TimeMS": tow, "Week": WEEK, "NSats": 9, "HDop": 1.2, "Lat": lat, "Lng": lon}
        msgs.append(gps.message(**fix, Alt=584.3, Spd=5.0, GCrs=0.0, VZ=-0.5, T=boot_ms))
        msgs.append(gps2.message(**fix, Alt=584.9, Spd=5.0, GCrs=0.0, VZ=-0.5, T=boot_ms + 3))
        msgs.append(ekf3.message(TimeMS=boot_ms + 5, IVN=0.12, IPN=-0.4))
        msgs.append(ekf4.message(TimeMS=boot_ms + 5, SVN=0.3))
    t = read_log(write_dataflash(tmp_path / "2014.bin", [gps, gps2, imu, ekf3, ekf4], msgs))
    assert t.time_reference == "gps"
    # the fixes sit at their boot time T on the GPS clock given by week and ms of week
    gps_s = t.gps_seconds(t.fixes["t_s"].to_numpy())
    assert gps_s is not None
    first = gps_s[(t.fixes["receiver_id"] == "GPS[0]").to_numpy()][:3]
    np.testing.assert_allclose(first, WEEK * 604800 + np.array([130040, 130040.2, 130040.4]), atol=0.004)
    assert set(t.fixes["receiver_id"]) == {"GPS[0]", "GPS[1]"} and (t.fixes["fix_type"] == FixType.FIX_3D).all()
    np.testing.assert_allclose(t.fixes["vel_n_mps"], 5.0)
    np.testing.assert_allclose(t.fixes["vel_u_mps"], 0.5)
    assert t.fixes["time_offset_s"].abs().max() < 0.01  # T and the GPS time agree
    # IMU on the same boot clock: the first IMU sample 0.2 s before the first fix
    assert t.imu["t_s"].min() == pytest.approx(t.fixes["t_s"].min() - 0.2)
    ekf = t.autopilot_ekf
    assert set(ekf["source"]) == {"EKF1 core 0"}
    np.testing.assert_allclose(ekf["vel_innov_n_mps"], 0.12)
    np.testing.assert_allclose(ekf["pos_innov_n_m"], -0.4)
    assert ekf["vel_test_ratio"].isna().all()  # that year's EKF4 held square-root variances, not test ratios


def test_2013_revision_gps_without_board_time_is_placed_by_the_message_before_it(tmp_path: Path) -> None:
    """Copter 3.0 (2013, APM2): GPS `Status,TimeMS,Week,...,GCrs` with neither VZ nor a boot time."""
    gps = Fmt(130, "GPS", "BIHBcLLeeEe", "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs")
    imu = Fmt(131, "IMU", "Iffffff", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
    msgs = []
    for boot_ms, tow, lat, lon in flight():
        msgs += [imu.message(TimeMS=boot_ms - 20 * k, AccZ=-9.81) for k in range(10, 0, -1)]
        msgs.append(gps.message(Status=3, TimeMS=tow, Week=WEEK, NSats=8, HDop=1.5, Lat=lat, Lng=lon, Alt=584, Spd=5))
    path = write_dataflash(tmp_path / "2013.bin", [gps, imu], msgs)
    t = read_log(path)
    assert t.time_reference == "gps" and len(t.fixes) == 20 and len(t.imu) == 200
    assert t.fixes["vel_u_mps"].isna().all()  # no VZ in this revision: vertical velocity unknown
    # each fix takes the boot time of the IMU message logged just before it (20 ms before its own)
    gps_s = t.gps_seconds(t.fixes["t_s"].to_numpy())
    assert gps_s is not None
    np.testing.assert_allclose(np.diff(gps_s), 0.2, atol=1e-6)
    assert "boot time of the message logged before" in t.metadata["dataflash.GPS.TimeUS"]
    assert main(["inspect", str(path)]) == 0


def test_early_2013_revision_without_week_or_clock_keeps_relative_time(tmp_path: Path) -> None:
    """Copter 2.9 (early 2013): GPS `Status,Time,NSats,...` (ms of week, no week) and an IMU with no time."""
    gps = Fmt(130, "GPS", "BIBcLLeeEe", "Status,Time,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs")
    imu = Fmt(131, "IMU", "ffffff", "GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
    msgs = []
    for _, tow, lat, lon in flight():
        msgs += [imu.message(AccZ=-9.81) for _ in range(10)]
        msgs.append(gps.message(Status=3, Time=tow, NSats=7, HDop=2.0, Lat=lat, Lng=lon, Alt=584, Spd=5))
    t = read_log(write_dataflash(tmp_path / "2013early.bin", [gps, imu], msgs))
    assert t.time_reference == "relative" and "time of week" in t.metadata["clock"]
    np.testing.assert_allclose(np.diff(t.fixes["t_s"]), 0.2, atol=1e-9)
    assert not len(t.imu)
    assert any(s.stream == "IMU" and "carries no time" in s.reason for s in t.skipped)


def test_2015_revision_timeus_with_the_first_ekfs_test_ratios(tmp_path: Path) -> None:
    """Plane/Copter 3.3-3.4 (2015): TimeUS, GPS `GMS,GWk,...,RAlt`, GPA `VDop,HAcc,VAcc,SAcc` without an
    instance, IMU with health flags, EKF4 `SV,SP,SH,SMX,SMY,SMZ,SVT,...` (test ratios per magnetometer axis)."""
    gps = Fmt(130, "GPS", "QBIHBcLLeeEefB", "TimeUS,Status,GMS,GWk,NSats,HDop,Lat,Lng,RAlt,Alt,Spd,GCrs,VZ,U")
    gpa = Fmt(152, "GPA", "QCCCC", "TimeUS,VDop,HAcc,VAcc,SAcc")
    imu = Fmt(131, "IMU", "QffffffIIfBB", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,ErrG,ErrA,Temp,GyHlt,AcHlt")
    ekf4 = Fmt(143, "EKF4", "QcccccccbbBBH", "TimeUS,SV,SP,SH,SMX,SMY,SMZ,SVT,OFN,EFE,FS,TS,SS")
    msgs = []
    for boot_ms, tow, lat, lon in flight():
        us = boot_ms * 1000
        msgs += [imu.message(TimeUS=us - 20_000 * k, AccZ=-9.81) for k in range(10, 0, -1)]
        fix = {"Status": 3, "GMS": tow, "GWk": WEEK, "NSats": 11, "HDop": 0.9, "Lat": lat, "Lng": lon}
        msgs.append(gps.message(TimeUS=us, **fix, Alt=584, Spd=5, VZ=0.1, U=1))
        msgs.append(gpa.message(TimeUS=us, VDop=1.4, HAcc=1.8, VAcc=2.5, SAcc=0.3))
        msgs.append(ekf4.message(TimeUS=us + 1000, SV=0.2, SP=0.1, SH=0.05, SMX=0.3, SMY=0.6, SMZ=0.1))
    t = read_log(write_dataflash(tmp_path / "2015.bin", [gps, gpa, imu, ekf4], msgs))
    np.testing.assert_allclose(t.fixes[["h_acc_m", "v_acc_m", "vel_acc_mps", "vdop"]].iloc[0], [1.8, 2.5, 0.3, 1.4])
    ekf = t.autopilot_ekf
    np.testing.assert_allclose(ekf["mag_test_ratio"], 0.6)  # the largest axis
    np.testing.assert_allclose(ekf["pos_test_ratio"], 0.1)


def test_arducopter_3_3_log171_reads_with_its_own_clocks() -> None:
    """The real 2015 log: refused before as holding "no GPS, IMU or EKF message" though it holds all three."""
    path = real_log("corpus/dronekit-la-testdata/log171.bin")
    t = read_log(path)
    r = DFReader_binary(str(path))
    ref = []
    while (m := r.recv_match(type="GPS")) is not None:
        ref.append(m.to_dict())
    fixed = [m for m in ref if m["Status"] >= 3]
    assert len(t.fixes) == len(fixed) == 1038 and t.time_reference == "gps"
    np.testing.assert_allclose(t.fixes["lat_deg"], [m["Lat"] for m in fixed], atol=1e-12)
    # on the GPS clock each fix is its week and ms of week, up to the logging latency
    gps_s = t.gps_seconds(t.fixes["t_s"].to_numpy())
    assert gps_s is not None
    logged = np.array([m["Week"] * 604800 + m["TimeMS"] / 1000 for m in fixed])
    assert np.median(np.abs(gps_s - logged)) < 0.05
    assert t.absolute_iso(0.0)[:10] == "2015-11-21"
    # UBX3 (before GPA) gives the receiver's accuracies; UBX1 its jamming indicator
    assert t.fixes["h_acc_m"].notna().mean() > 0.95 and t.fixes["jamming_indicator"].notna().mean() > 0.9
    assert t.imus() == ["IMU[0]", "IMU[1]", "IMU[2]"] and len(t.imu_of("IMU[0]")) == 11916
    ekf = t.autopilot_ekf
    assert set(ekf["source"]) == {"EKF1 core 0"} and ekf["vel_test_ratio"].notna().sum() == 2383


def test_columns_are_typed_by_size_so_pandas_can_join_them_in_any_order() -> None:
    """A 'Q' field was numpy's `ulonglong`, a type of its own beside `uint64` that pandas' hash join does
    not know: a log whose GPS rows were not in time order (a fuzzed DataFlash log) failed joining GPA."""
    from readers.dataflash import open_dataflash

    log = open_dataflash(real_log("ardupilot_dataflash/amc_backend_log_80k.bin"))
    cols = log.columns("GPS")
    assert cols is not None and cols["TimeUS"].dtype.type is np.uint64
    frame = pd.DataFrame({"TimeUS": cols["TimeUS"][::-1], "inst": 0})
    joined = frame.merge(frame.drop_duplicates(), on=["TimeUS", "inst"], how="left")
    assert len(joined) == len(frame)
