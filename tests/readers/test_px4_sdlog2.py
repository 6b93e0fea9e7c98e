"""PX4 sdlog2 logs (`.px4log`, PX4 2013-2017): the DataFlash container with PX4's messages.

No licensed sdlog2 log is in the corpus, so they are built in tmp_path (`sdlog2_writer`) from the FMT
definitions of PX4's src/modules/sdlog2/sdlog2_messages.h: the 2016-2017 revision and that of 2013.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from sdlog2_writer import FW_GIT, IMU, NEW, PITCH, ROLL, SPEED, TIME, G, write_sdlog2

from readers import read_log, sniff_format
from readers.ardupilot import attitude_quaternion
from readers.dataflash import open_dataflash
from spooflens.cli import main
from spooflens.epoch_table import GPS_EPOCH_UNIX_NS
from spooflens.schema import FixType

LEAP_2016_S = 17  # GPS - UTC in June 2016


def test_sniffed_by_content_and_read_at_the_logged_place_and_time(tmp_path: Path) -> None:
    flight = write_sdlog2(tmp_path / "log001.bin", seconds=20, no_time_fixes=3)  # not named .px4log
    assert sniff_format(flight.path) == "px4_sdlog2"
    t = read_log(flight.path)
    assert t.format == "px4_sdlog2"
    assert t.time_reference == "gps"
    fixes = t.fixes
    assert set(fixes["receiver_id"]) == {"GPS[0]"} and (fixes["fix_type"] == FixType.FIX_3D).all()
    assert len(fixes) == len(flight.lat)
    np.testing.assert_allclose(fixes["lat_deg"], flight.lat, atol=1e-7)
    np.testing.assert_allclose(fixes["lon_deg"], flight.lon, atol=1e-7)
    np.testing.assert_allclose(fixes["height_m"], flight.alt, atol=1e-3)  # AMSL: sdlog2 logs no undulation
    assert "AMSL" in t.metadata["height"]
    np.testing.assert_allclose(fixes["vel_n_mps"], SPEED, atol=1e-5)
    np.testing.assert_allclose(fixes["vel_e_mps"], 0.0, atol=1e-5)
    np.testing.assert_allclose(fixes["vel_u_mps"], 0.0, atol=1e-6)
    np.testing.assert_allclose(fixes["h_acc_m"], 1.2, rtol=1e-6)
    np.testing.assert_allclose(fixes["v_acc_m"], 2.0, rtol=1e-6)
    np.testing.assert_allclose(fixes["sats_used"], 12)
    np.testing.assert_allclose(fixes["noise_per_ms"], 90)
    np.testing.assert_allclose(fixes["jamming_indicator"], 20)
    np.testing.assert_allclose(fixes["cn0_mean_dbhz"], 40)
    assert fixes["hdop"].isna().all()  # no DOP in sdlog2
    # every fix sits at the StartTime of its loop's TIME, on the GPS clock from GPSTime (UTC) + 17 leap
    # seconds; the first 3 fixes had no time yet (GPSTime 0) and are placed by the same boot clock
    gps_s = t.gps_seconds(fixes["t_s"].to_numpy())
    assert gps_s is not None
    timed = flight.utc_us > 0
    expected = (flight.utc_us[timed] * 1000 - GPS_EPOCH_UNIX_NS) / 1e9 + LEAP_2016_S
    np.testing.assert_allclose(gps_s[timed], expected, atol=1e-3)
    np.testing.assert_allclose(np.diff(gps_s), np.diff(flight.boot_us) / 1e6, atol=1e-6)
    assert np.isnan(fixes["time_offset_s"].to_numpy()[:3]).all()
    assert np.nanmax(np.abs(fixes["time_offset_s"])) < 1e-3


def test_imu_units_attitude_from_radians_and_metadata(tmp_path: Path) -> None:
    yaw = 1.0  # rad (57.3 deg): read as degrees it would be 1 deg
    flight = write_sdlog2(tmp_path / "f.px4log", seconds=5, imu_hz=200, yaw=yaw)
    t = read_log(flight.path)
    imu = t.imu
    assert set(imu["imu_id"]) == {"IMU[0]", "IMU[1]"}
    first = imu[imu["imu_id"] == "IMU[0]"]
    assert len(first) == 5 * 200
    np.testing.assert_allclose(np.diff(first["t_s"]), 1 / 200, atol=1e-6)  # each IMU at its TIME
    np.testing.assert_allclose(first["ax_mps2"], G * np.sin(PITCH), rtol=1e-6)
    np.testing.assert_allclose(first["az_mps2"], -G * np.cos(PITCH) * np.cos(ROLL), rtol=1e-6)
    norm = np.linalg.norm(first[["ax_mps2", "ay_mps2", "az_mps2"]].to_numpy(), axis=1)
    np.testing.assert_allclose(norm, G, rtol=1e-6)  # m/s^2, not g
    np.testing.assert_allclose(first[["wx_radps", "wy_radps", "wz_radps"]], 0.0)
    q = first[["qw", "qx", "qy", "qz"]].to_numpy()
    want = attitude_quaternion(np.degrees([ROLL]), np.degrees([PITCH]), np.degrees([yaw]))[0]
    np.testing.assert_allclose(np.abs(q @ want), 1.0, atol=1e-6)
    meta = t.metadata
    assert meta["firmware"] == f"PX4 sdlog2, git {FW_GIT}"
    assert meta["board"] == "PX4FMU_V2" and meta["airframe"] == "SYS_AUTOSTART 4001"
    assert meta["log_format"].startswith("PX4 sdlog2")
    assert {s.msgtype for s in t.streams if s.role in ("fix", "imu")} == {"px4_sdlog2/GPS", "px4_sdlog2/IMU"}
    skipped = {s.stream: s for s in t.skipped}
    assert skipped["GPOS"].count == skipped["LPOS"].count == len(flight.lat)


def test_imu_gyro_is_rad_per_s(tmp_path: Path) -> None:
    """A gyro rate written in rad/s reads back unscaled (ArduPilot's GyrX is rad/s too)."""
    msgs = [f.fmt_message() for f in NEW]
    for k in range(50):
        msgs.append(TIME.message(StartTime=1_000_000 + 10_000 * k))
        msgs.append(IMU.message(AccZ=-G, GyroX=0.1, GyroY=-0.2, GyroZ=0.3))
    path = tmp_path / "gyro.px4log"
    path.write_bytes(b"".join(msgs))
    t = read_log(path)
    np.testing.assert_allclose(t.imu[["wx_radps", "wy_radps", "wz_radps"]].to_numpy()[0], [0.1, -0.2, 0.3], rtol=1e-6)
    np.testing.assert_allclose(np.diff(t.imu["t_s"]), 0.01, atol=1e-9)


def test_2013_revision_without_snr_temperatures_or_satellites(tmp_path: Path) -> None:
    flight = write_sdlog2(tmp_path / "old.px4log", seconds=10, old=True)
    assert sniff_format(flight.path) == "px4_sdlog2"
    t = read_log(flight.path)
    assert t.time_reference == "gps" and len(t.fixes) == len(flight.lat)
    np.testing.assert_allclose(t.fixes["lat_deg"], flight.lat, atol=1e-7)
    np.testing.assert_allclose(t.fixes["height_m"], flight.alt, atol=1e-3)
    assert (t.fixes["fix_type"] == FixType.FIX_3D).all()  # `FixType`, later `Fix`
    assert t.fixes["sats_used"].isna().all()
    assert "noise_per_ms" not in t.fixes or t.fixes["noise_per_ms"].isna().all()
    assert set(t.imu["imu_id"]) == {"IMU[0]"}
    np.testing.assert_allclose(t.imu["az_mps2"], -G * np.cos(PITCH) * np.cos(ROLL), rtol=1e-6)
    assert t.imu["qw"].notna().all()


def test_truncated_log_counts_the_lost_bytes(tmp_path: Path) -> None:
    flight = write_sdlog2(tmp_path / "whole.px4log", seconds=10)
    data = flight.path.read_bytes()
    cut = tmp_path / "cut.px4log"
    cut.write_bytes(data[: len(data) - 2000 - 7])  # mid-message
    t = read_log(cut)
    assert 0 < len(t.fixes) <= len(flight.lat)
    lost = [(s.stream, s.count) for s in t.skipped if "cut off at the end" in s.reason and s.action == "lost"]
    assert lost == [("TIME", 1)], [(s.stream, s.reason) for s in t.skipped]
    assert main(["inspect", str(cut)]) == 3  # damaged input: read, and said so


def test_inspect_and_analyze_a_clean_flight(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    flight = write_sdlog2(tmp_path / "clean.px4log", seconds=30)
    assert main(["inspect", str(flight.path)]) == 0
    assert "px4_sdlog2" in capsys.readouterr().out
    summary = tmp_path / "a.json"
    assert main(["analyze", str(flight.path), "-o", str(tmp_path / "a.rrd"), "--json", str(summary), "--quiet"]) == 0
    result = json.loads(summary.read_text())
    assert not result["verdict"]["spoofed"], result["verdict"]["headline"]
    assert result["format"] == "px4_sdlog2"


def test_inject_patches_the_gps_messages_through_their_sdlog2_fields(tmp_path: Path) -> None:
    """ramp with a consistent velocity (vel=1): Lat/Lon and VelN/VelE/Cog of PX4's GPS are rewritten, every
    byte outside the GPS messages is the original's, and the copy reads back as px4_sdlog2."""
    flight = write_sdlog2(tmp_path / "f.px4log", seconds=20)
    out = tmp_path / "spoofed.px4log"
    assert main(["inject", str(flight.path), "--attack", "ramp:rate=2,axes=n,vel=1,start=5", "-o", str(out)]) == 0
    assert sniff_format(out) == "px4_sdlog2"
    a, b = read_log(flight.path), read_log(out)
    assert len(a.fixes) == len(b.fixes)
    t = a.fixes["t_s"].to_numpy()
    north = (b.fixes["lat_deg"] - a.fixes["lat_deg"]).to_numpy() * np.radians(1) * 6_367_000
    np.testing.assert_allclose(north[t <= 5], 0.0, atol=0.02)
    np.testing.assert_allclose(north[t > 6], 2.0 * (t[t > 6] - 5), rtol=0.01, atol=0.03)
    np.testing.assert_allclose(b.fixes["lon_deg"], a.fixes["lon_deg"], atol=1e-7)
    np.testing.assert_allclose(b.fixes["vel_n_mps"].to_numpy()[t > 6], SPEED + 2.0, atol=1e-4)
    np.testing.assert_allclose(b.fixes["t_s"], a.fixes["t_s"])
    src, dst = flight.path.read_bytes(), out.read_bytes()
    assert len(src) == len(dst)
    log = open_dataflash(flight.path)
    gps = log.offsets("GPS")
    diff = np.flatnonzero(np.frombuffer(src, np.uint8) != np.frombuffer(dst, np.uint8))
    k = np.searchsorted(gps, diff, side="right") - 1
    assert len(diff) and np.all(diff - gps[k] < log.reader.formats[log.reader.name_to_id["GPS"]].len)
