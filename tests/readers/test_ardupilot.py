"""ArduPilot DataFlash (.bin) and MAVLink telemetry (.tlog) readers on real logs and made-up damage.

The real logs are in ../shared/real/ardupilot_dataflash/ (GPL/LGPL test data, never copied here). No
real .tlog is available: the telemetry tests write one with pymavlink's own MAVLink encoder
(`mavlink_support.write_tlog`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from dataflash_support import WEEK, Fmt, flight, write_dataflash
from mavlink_support import write_tlog
from paths import REAL, real_log

from readers import read_log, sniff_format
from readers.ardupilot import attitude_quaternion
from spooflens.cli import main
from spooflens.detectors.receiver_time import run_receiver_time
from spooflens.geodesy import geodetic_to_enu
from spooflens.navigation.rotations import quat_to_matrix

DATAFLASH = REAL / "ardupilot_dataflash"
PLANE = DATAFLASH / "flightdata_center_0003.bin"
COPTER = DATAFLASH / "amc_backend_log_80k.bin"


def _pymavlink_rows(path: Path, kind: str) -> list[dict]:
    from pymavlink.DFReader import DFReader_binary

    r = DFReader_binary(str(path))
    out = []
    while (m := r.recv_match(type=kind)) is not None:
        out.append(m.to_dict())
    r.close()
    return out


def test_plane_log_fixes_clock_and_ekf() -> None:
    t = read_log(PLANE)
    assert sniff_format(PLANE) == "ardupilot" and t.format == "ardupilot"
    assert t.metadata["firmware"] == "ArduPlane V4.2.3 (55685c43)"
    assert t.metadata["board"].startswith("omnibusf4pro")
    assert t.time_reference == "gps"  # the first GPS row has week 0, the other 208 carry it
    fix = t.stream("fix", "GPS[0]")
    assert fix is not None and fix.count == 209
    assert 4.0 < fix.rate_hz < 5.2  # ~4.3 Hz as the source notes say
    # every row decoded column-wise equals pymavlink's own per-message decoding
    ref = _pymavlink_rows(PLANE, "GPS")
    np.testing.assert_allclose(t.fixes["lat_deg"], [m["Lat"] for m in ref], rtol=0, atol=1e-12)
    np.testing.assert_allclose(t.fixes["sats_used"], [m["NSats"] for m in ref])
    gpa = _pymavlink_rows(PLANE, "GPA")
    np.testing.assert_allclose(t.fixes["h_acc_m"], [m["HAcc"] for m in gpa], atol=1e-12)
    np.testing.assert_allclose(t.fixes["vdop"], [m["VDop"] for m in gpa], atol=1e-12)
    # ellipsoidal height = AMSL - undulation (h_msl - h_ellipsoid): the UK geoid is ~48.5 m above WGS84
    np.testing.assert_allclose(t.fixes["height_m"], [g["Alt"] - a["Und"] for g, a in zip(ref, gpa, strict=True)])
    assert 47.5 < -gpa[0]["Und"] < 49.5
    # velocity: Spd/GCrs/VZ -> ENU (VZ is down)
    spd = np.hypot(t.fixes["vel_e_mps"], t.fixes["vel_n_mps"])
    np.testing.assert_allclose(spd, [m["Spd"] for m in ref], atol=1e-6)
    np.testing.assert_allclose(t.fixes["vel_u_mps"], [-m["VZ"] for m in ref], atol=1e-6)
    # the first fix lies where the EKF origin (ORGN, another message) was set, and where the notes say
    orgn = _pymavlink_rows(PLANE, "ORGN")[0]
    d = geodetic_to_enu(
        t.fixes["lat_deg"][:5], t.fixes["lon_deg"][:5], t.fixes["height_m"][:5], orgn["Lat"], orgn["Lng"], 0
    )
    assert np.hypot(d[:, 0], d[:, 1]).min() < 1.0
    assert abs(t.fixes["lat_deg"].iloc[0] - 51.6416) < 1e-3 and abs(t.fixes["lon_deg"].iloc[0] + 2.5257) < 1e-3
    # the GPS clock: a fix's absolute GPS time is its week and ms of week (up to the logging latency spread)
    gps_s = t.gps_seconds(t.fixes["t_s"].to_numpy())
    assert gps_s is not None
    logged = np.array([m["GWk"] * 604800 + m["GMS"] / 1000 for m in ref])
    assert np.median(np.abs(gps_s[1:] - logged[1:])) < 0.05
    # no raw IMU in this log: the fixes are read all the same, the attitude is reported as unused
    assert len(t.imu) == 0
    assert any((s.stream == "ATT" and "no" in s.reason.lower()) or "without a raw IMU" in s.reason for s in t.skipped)
    # the autopilot's EKF3: innovations and test ratios, clean flight -> ratios well below 1
    ekf = t.autopilot_ekf
    assert set(ekf["source"]) == {"EKF3 core 0"} and len(ekf) == 1033
    assert ekf["pos_test_ratio"].max() < 0.5 and ekf["vel_test_ratio"].max() < 0.5
    xkf3 = _pymavlink_rows(PLANE, "XKF3")
    np.testing.assert_allclose(ekf["vel_innov_n_mps"], [m["IVN"] for m in xkf3], atol=1e-9)
    np.testing.assert_allclose(ekf["yaw_innov_rad"], np.radians([m["IYAW"] for m in xkf3]), atol=1e-9)


def test_copter_log_imu_attitude_and_receiver_indicators() -> None:
    t = read_log(COPTER)
    assert t.metadata["firmware"].startswith("ArduCopter V4.6.2")
    assert t.imus() == ["IMU[0]", "IMU[1]"] and "IMU[0]" in t.metadata["imu.primary"]
    imu0 = t.imu_of("IMU[0]")
    info = t.stream("imu", "IMU[0]")
    assert len(imu0) == 10 and info is not None and info.body_frame == "FRD"
    g = np.linalg.norm(imu0[["ax_mps2", "ay_mps2", "az_mps2"]].to_numpy(), axis=1)
    assert np.all(np.abs(g - 9.81) < 0.3) and np.all(imu0["az_mps2"] < -9.0)  # at rest, FRD: gravity reaction on -z
    # the ATT quaternion: the FRD body's x axis points along the logged yaw (99 deg: east-south-east)
    att = _pymavlink_rows(COPTER, "ATT")
    C = quat_to_matrix(imu0[["qw", "qx", "qy", "qz"]].to_numpy()[-1])
    heading = np.degrees(np.arctan2(C[0, 0], C[1, 0])) % 360
    assert abs(heading - att[-1]["Yaw"]) < 1.0
    # the body z axis (down) points down within the small roll/pitch
    assert C[2, 2] < -0.99
    # AEl is the ellipsoidal height; UBX1 (MON-HW) lands on the fix logged after it
    fx = t.fixes
    assert fx["height_m"].iloc[0] == pytest.approx(93.18)
    assert np.isnan(fx["agc"].iloc[0]) and fx["agc"].iloc[1] == 1872.0
    assert fx["jamming_indicator"].iloc[1] == 5.0 and fx["noise_per_ms"].iloc[1] == 113.0
    assert set(t.autopilot_ekf["source"]) == {"EKF3 core 0", "EKF3 core 1"}


def test_every_ubx1_report_reaches_receiver_status_with_or_without_a_fix() -> None:
    # log171 (ArduCopter 3.3): the receiver reports UBX1 every ~2 s from boot, and its GPS rows say
    # Status 1 (no fix) until its first fix 33.7 s in; the 17 reports of those 32 s joined no fix
    log = real_log("corpus/dronekit-la-testdata/log171.bin")
    t = read_log(log)
    logged = _pymavlink_rows(log, "UBX1")
    status = t.receiver_status
    assert len(logged) == 121 and len(status) == len(logged)
    assert set(status["receiver_id"]) == {"GPS[0]"}  # named as the fixes are
    for column, field in (("noise_per_ms", "noisePerMS"), ("jamming_indicator", "jamInd"), ("agc", "agcCnt")):
        np.testing.assert_array_equal(status[column].to_numpy(float), [float(m[field]) for m in logged])
    assert status["jamming_state"].isna().all()  # UBX1 carries no jamming state
    first_fix = float(t.fixes["t_s"].min())
    without_fix = status["t_s"].to_numpy() < first_fix - 1.0
    assert first_fix == pytest.approx(33.676) and without_fix.sum() == 17
    assert any(s.stream == "GPS[0]" and "no fix" in s.reason and s.count == 161 for s in t.skipped)
    info = t.stream("receiver_status", "GPS[0]")
    assert info is not None and info.count == 121 and info.topic == "UBX1"
    # the fixes still carry the latest report (receiver_evidence and the baseline read them there)
    assert t.fixes["agc"].notna().all() and t.fixes["jamming_indicator"].iloc[0] in set(status["jamming_indicator"])


def test_attitude_quaternion_conventions() -> None:
    """NED Euler (ZYX) of an FRD body -> quaternion FRD->ENU, against hand-written expectations."""
    level_north = quat_to_matrix(attitude_quaternion(np.array([0.0]), np.array([0.0]), np.array([0.0]))[0])
    np.testing.assert_allclose(level_north, [[0, 1, 0], [1, 0, 0], [0, 0, -1]], atol=1e-12)
    east = quat_to_matrix(attitude_quaternion(np.array([0.0]), np.array([0.0]), np.array([90.0]))[0])
    np.testing.assert_allclose(east @ [1, 0, 0], [1, 0, 0], atol=1e-12)  # nose east
    np.testing.assert_allclose(east @ [0, 1, 0], [0, -1, 0], atol=1e-12)  # right wing south
    nose_up = quat_to_matrix(attitude_quaternion(np.array([0.0]), np.array([30.0]), np.array([0.0]))[0])
    np.testing.assert_allclose(nose_up @ [1, 0, 0], [0, np.cos(np.radians(30)), 0.5], atol=1e-12)
    right_down = quat_to_matrix(attitude_quaternion(np.array([30.0]), np.array([0.0]), np.array([0.0]))[0])
    assert (right_down @ [0, 1, 0])[2] == pytest.approx(-0.5)  # roll right: the right wing goes down


@pytest.mark.parametrize("log", [PLANE, COPTER], ids=["plane", "copter"])
def test_inspect_and_analyze_real_logs(log: Path, tmp_path: Path, capsys) -> None:
    assert main(["inspect", str(log)]) == 0
    out = tmp_path / "a.rrd"
    summary = tmp_path / "a.json"
    assert main(["analyze", str(log), "-o", str(out), "--json", str(summary), "--quiet"]) == 0
    import json

    verdict = json.loads(summary.read_text())["verdict"]
    assert not verdict["spoofed"], verdict["headline"]


def test_damaged_logs_keep_what_can_be_read(tmp_path: Path) -> None:
    data = PLANE.read_bytes()
    rng = np.random.default_rng(7)
    cut = tmp_path / "cut.bin"
    cut.write_bytes(data[: len(data) // 2 + 7])
    t = read_log(cut)
    assert 60 < len(t.fixes) < 209 and t.fixes["t_s"].max() < 30
    corrupt = bytearray(data)
    for i in rng.integers(200_000, 700_000, 300):
        corrupt[i] = int(rng.integers(0, 256))
    bad = tmp_path / "corrupt.bin"
    bad.write_bytes(bytes(corrupt))
    t = read_log(bad)
    lost = [s for s in t.skipped if s.action == "lost"]
    assert lost and len(t.fixes) >= 200  # re-synchronised past a byte that looked like an undefined type
    assert t.fixes["t_s"].max() < 60  # a corrupted TimeUS (years off) is dropped, not plotted
    assert main(["inspect", str(bad)]) == 3  # damaged input: analysed, and said so
    garbage = tmp_path / "garbage.bin"
    garbage.write_bytes(data[:300_000] + rng.integers(0, 256, 5000, dtype=np.uint8).tobytes() + data[300_000:])
    assert len(read_log(garbage).fixes) == 209
    assert main(["inspect", str(tmp_path / "nothing.bin")]) == 2
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\xa3\x95\x80" + rng.integers(0, 256, 2000, dtype=np.uint8).tobytes())
    assert main(["inspect", str(junk)]) == 2  # one line, no traceback


def test_inject_round_trip_patches_only_gps_messages(tmp_path: Path) -> None:
    out = tmp_path / "spoofed.bin"
    assert main(["inject", str(PLANE), "--attack", "ramp:rate=2,axes=en,start=20", "-o", str(out)]) == 0
    a, b = read_log(PLANE), read_log(out)
    assert len(a.fixes) == len(b.fixes)
    d = geodetic_to_enu(b.fixes["lat_deg"], b.fixes["lon_deg"], b.fixes["height_m"], 0, 0, 0) - geodetic_to_enu(
        a.fixes["lat_deg"], a.fixes["lon_deg"], a.fixes["height_m"], 0, 0, 0
    )
    t = a.fixes["t_s"].to_numpy()
    before = t < 20
    assert np.abs(d[before]).max() < 0.02  # untouched, up to the 1e-7 deg storage step
    late = t > 30
    off = np.array(
        [
            geodetic_to_enu(lb, ob, hb, la, oa, ha)
            for lb, ob, hb, la, oa, ha in zip(
                b.fixes["lat_deg"][late],
                b.fixes["lon_deg"][late],
                b.fixes["height_m"][late],
                a.fixes["lat_deg"][late],
                a.fixes["lon_deg"][late],
                a.fixes["height_m"][late],
                strict=True,
            )
        ]
    )
    # 2 m/s on each chosen axis from 20 s on, stored to 1e-7 deg (~1 cm)
    np.testing.assert_allclose(off[:, 0], 2.0 * (t[late] - 20), atol=0.03)
    np.testing.assert_allclose(off[:, 1], 2.0 * (t[late] - 20), atol=0.03)
    np.testing.assert_allclose(off[:, 2], 0.0, atol=0.03)
    # every byte outside the GPS messages is the original's
    src, dst = PLANE.read_bytes(), out.read_bytes()
    assert len(src) == len(dst)
    diff = np.flatnonzero(np.frombuffer(src, np.uint8) != np.frombuffer(dst, np.uint8))
    from readers.dataflash import open_dataflash

    log = open_dataflash(PLANE)
    gps = log.offsets("GPS")
    k = np.searchsorted(gps, diff, side="right") - 1
    assert np.all(diff - gps[k] < log.reader.formats[log.reader.name_to_id["GPS"]].len)


def test_tlog_written_by_pymavlink_reads_back(tmp_path: Path) -> None:
    path = tmp_path / "flight.tlog"
    t0_unix_us, _ = write_tlog(path)
    assert sniff_format(path) == "tlog"
    t = read_log(path)
    assert t.time_reference == "unix" and t.t0_ns == t0_unix_us * 1000  # SYSTEM_TIME, not the GCS latency
    fix, imu = t.stream("fix", "GPS_RAW_INT"), t.stream("imu", "SCALED_IMU")
    assert fix is not None and imu is not None and fix.count == 150 and imu.count == 1500
    assert fix.rate_hz == pytest.approx(5.0, rel=0.01) and imu.rate_hz == pytest.approx(50.0, rel=0.01)
    np.testing.assert_allclose(t.fixes["vel_n_mps"], 2.0)
    np.testing.assert_allclose(t.fixes["height_m"], 145.0)
    assert t.fixes["h_acc_m"].iloc[0] == 0.8 and t.fixes["hdop"].iloc[0] == 0.9
    d = geodetic_to_enu(t.fixes["lat_deg"], t.fixes["lon_deg"], t.fixes["height_m"], 52.0, 10.0, 145.0)
    np.testing.assert_allclose(d[:, 1], 2.0 * t.fixes["t_s"], atol=0.02)  # position moves as the velocity says
    np.testing.assert_allclose(t.imu["az_mps2"], -9.80665)
    C = quat_to_matrix(t.imu[["qw", "qx", "qy", "qz"]].to_numpy()[0])
    np.testing.assert_allclose(C @ [1, 0, 0], [1, 0, 0], atol=1e-6)  # nose east (float32 yaw)


def test_tlog_gps_with_the_receivers_unix_time_is_placed_by_the_ground_station(tmp_path: Path) -> None:
    """ArduPilot's GPS_RAW_INT carries the receiver's UNIX time; a spoofer 7.5 s ahead from 60 s on leaves
    the fixes where the ground station received them and shows in `time_offset_s`."""
    path = tmp_path / "ardupilot.tlog"
    write_tlog(path, seconds=120.0, gps_unix_from_s=60.0)
    fixes = read_log(path).fixes
    np.testing.assert_allclose(np.diff(fixes["t_s"]), 0.2, atol=1e-6)  # no jump where the time jumps
    x = fixes["time_offset_s"].to_numpy()
    np.testing.assert_allclose(x - x[0], np.where(fixes["t_s"] >= 60.0, 7.5, 0.0), atol=1e-6)
    (alarm,) = run_receiver_time(fixes).alarms
    assert alarm.onset_s == pytest.approx(60.0)


def test_tlog_with_garbage_keeps_the_rest(tmp_path: Path) -> None:
    path = tmp_path / "flight.tlog"
    write_tlog(path)
    data = path.read_bytes()
    rng = np.random.default_rng(3)
    bad = tmp_path / "damaged.tlog"
    bad.write_bytes(
        data[: len(data) // 2] + rng.integers(0, 256, 3000, dtype=np.uint8).tobytes() + data[len(data) // 2 :]
    )
    t = read_log(bad)
    assert len(t.fixes) >= 145 and any(s.action == "lost" for s in t.skipped)
    assert main(["inspect", str(bad)]) == 3
    cut = tmp_path / "cut.tlog"
    cut.write_bytes(data[: len(data) // 3 + 5])
    assert 40 <= len(read_log(cut).fixes) <= 51


@pytest.mark.parametrize(
    ("log", "old", "new", "lost"),
    [(PLANE, b"Status", b"St?tus", "GPS"), (COPTER, b",Yaw,", b",Y?w,", "ATT")],
)
def test_a_message_whose_fmt_lost_a_field_is_counted_lost_not_an_error(
    tmp_path: Path, log: Path, old: bytes, new: bytes, lost: str
) -> None:
    """The 10^4 fuzz run overwrote characters of a FMT's column text, so a parsed GPS lacked `Status`
    or ATT lacked `Yaw` (KeyError before): such a message is lost, counted once, the rest is read."""
    data = log.read_bytes()
    fmt = data.index(lost.encode() + b"\0") - 5
    head, body = data[: fmt + 89], bytearray(data[fmt + 89 :])
    columns = bytearray(head[fmt + 25 :])
    assert old in columns
    columns[columns.index(old) : columns.index(old) + len(old)] = new
    damaged = tmp_path / "damaged.bin"
    damaged.write_bytes(head[: fmt + 25] + bytes(columns) + bytes(body))
    t = read_log(damaged)
    assert any(s.stream == lost and "lacks field" in s.reason and s.action == "lost" for s in t.skipped)
    if lost == "GPS":
        assert not len(t.fixes)
    else:
        assert len(t.fixes) and len(t.imu) and np.isnan(t.imu["qw"]).all()
    assert main(["inspect", str(damaged)]) == 3  # damaged: what could be read is analysed, and said so


GPS_2016 = Fmt(130, "GPS", "QBBIHBcLLeffffB", "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U")
GRXH = Fmt(161, "GRXH", "QdHbBB", "TimeUS,rcvTime,week,leapS,numMeas,recStat")
GRXS = Fmt(162, "GRXS", "QddfBBBHBBBBB", "TimeUS,prMes,cpMes,doMes,gnss,sv,freq,lock,cno,prD,cpD,doD,trk")


def test_grxs_carriers_the_receiver_says_are_not_continuous_are_marked(tmp_path: Path) -> None:
    """GRXS is RXM-RAWX as the autopilot logs it: its trkStat (`trk`) and lock time (`lock`) say where a
    carrier is not continuous (half-cycle unresolved, half-cycle correction toggled, lock restarted)."""
    trk = {1: [7] * 5, 2: [7, 3, 7, 7, 7], 3: [7, 7, 15, 15, 15], 4: [7] * 5}
    lock = {4: [64500, 64500, 64500, 300, 1300]}
    msgs = []
    for i, (boot_ms, tow, lat, lon) in enumerate(flight(25)):
        us = boot_ms * 1000
        fix = {"Status": 3, "GMS": tow, "GWk": WEEK, "NSats": 8, "HDop": 0.9, "Lat": lat, "Lng": lon}
        msgs.append(GPS_2016.message(TimeUS=us, I=0, **fix, Alt=584, Spd=5, VZ=0.1, U=1))
        if i % 5 == 0:
            s = i // 5
            msgs.append(GRXH.message(TimeUS=us + 1000, rcvTime=tow / 1000, week=WEEK, leapS=18, numMeas=4))
            for sv in trk:
                measured = {"prMes": 2.1e7 + 1e5 * sv, "cpMes": 1.1e8 + 10 * s, "doMes": -500.0, "cno": 40}
                status = {"trk": trk[sv][s], "lock": lock.get(sv, [64500] * 5)[s]}
                msgs.append(GRXS.message(TimeUS=us + 1000, **measured, gnss=0, sv=sv, **status))
    table = read_log(write_dataflash(tmp_path / "raw.bin", [GPS_2016, GRXH, GRXS], msgs))
    obs = table.observations
    assert len(obs) == 20
    assert obs["carrier_phase_cycles"].notna().all()  # kept as logged
    cleared = obs[obs["carrier_arc_start"] == 1]
    t1 = sorted(obs["t_s"].unique())
    assert sorted(zip(cleared["t_s"], cleared["sv_id"], strict=True)) == [
        (t1[1], "G02"),
        (t1[2], "G03"),
        (t1[3], "G04"),
    ]
    said = {s.reason.split(" (")[0]: s.count for s in table.skipped if "continuous" in s.reason}
    assert said == {
        "carriers across a loss of lock": 1,
        "carriers with an unresolved half-cycle ambiguity": 1,
        "carriers whose half-cycle correction changed since the previous epoch": 1,
    }
