"""Sound autopilot logs that hold nothing a detector reads (a ground station's telemetry with no vehicle on
its link, a vehicle streaming status alone, a ULog logged without sensors or GPS, a DataFlash log of
a bench session): read, and analysed to
a NO VERDICT naming what they hold, as sound NMEA and UBX logs of the same kind are; damaged ones are
still refused."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from dataflash_support import Fmt, write_dataflash

from readers import read_log
from spooflens.cli import main
from spooflens.epoch_table import HOLDS
from spooflens.writers.ulog_writer import ULogFile


def _tlog(path: Path, packets: list[tuple[int, bytes]]) -> Path:
    """A tlog: each packet behind its ground station receive time (us since 1970, big-endian)."""
    path.write_bytes(b"".join(t.to_bytes(8, "big") + p for t, p in packets))
    return path


def _mavlink(system: int) -> object:
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    return mavlink.MAVLink(None, srcSystem=system, srcComponent=1)


def _status_only(path: Path, gcs_only: bool) -> Path:
    """Heartbeats and SYS_STATUS at 1 Hz for 20 s: of a ground station (type 6), or of a copter too."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    gcs, copter = _mavlink(255), _mavlink(1)
    packets = []
    for k in range(20):
        t = 1_700_000_000_000_000 + k * 1_000_000
        packets.append((t, gcs.heartbeat_encode(mavlink.MAV_TYPE_GCS, 8, 0, 0, 0).pack(gcs)))  # type: ignore[attr-defined]
        if not gcs_only:
            packets.append((t + 10, copter.heartbeat_encode(2, 3, 81, 0, 4).pack(copter)))  # type: ignore[attr-defined]
            status = copter.sys_status_encode(0, 0, 0, 500, 12000, 300, 80, 0, 0, 0, 0, 0, 0)  # type: ignore[attr-defined]
            packets.append((t + 20, status.pack(copter)))
    return _tlog(path, packets)


@pytest.mark.parametrize(
    ("gcs_only", "holds"),
    [
        (True, "MAVLink telemetry without a vehicle's heartbeat, GPS or IMU (HEARTBEAT x20)"),
        (False, "MAVLink telemetry without a GPS or IMU message (HEARTBEAT x40, SYS_STATUS x20)"),
    ],
)
def test_telemetry_of_no_vehicle_or_of_status_alone_is_nothing_to_judge(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], gcs_only: bool, holds: str
) -> None:
    log = _status_only(tmp_path / "link.tlog", gcs_only)
    table = read_log(log)
    assert table.metadata[HOLDS] == holds and not table.streams
    assert main(["analyze", str(log), "-o", str(tmp_path / "a.rrd"), "--quiet"]) == 0
    assert f"NO VERDICT: no GNSS data to judge: {holds}" in capsys.readouterr().out
    assert main(["inject", str(log), "--attack", "step:offset=50,start=5", "-o", str(tmp_path / "x.tlog")]) == 2


def test_a_damaged_telemetry_log_of_status_alone_is_still_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = _status_only(tmp_path / "link.tlog", gcs_only=False)
    data = bytearray(log.read_bytes())
    data[40:48] = b"\xfd\xff\x00\x00\x00\x00\x00\x00"  # a packet's bytes overwritten: no valid packet there
    log.write_bytes(bytes(data))
    assert main(["inspect", str(log)]) == 2
    err = capsys.readouterr().err
    assert "link.tlog" in err and "Traceback" not in err


def _ulog_without_sensors(path: Path) -> Path:
    """A ULog of battery_status alone (a bench session's logging profile)."""
    log = ULogFile()
    log.info("sys_name", "PX4")
    rows = log.topic("battery_status", [("uint64_t", "timestamp"), ("float", "voltage_v")], 50)
    rows["timestamp"] = 1_000_000 + np.arange(50) * 100_000
    rows["voltage_v"] = 16.4
    log.write(path)
    return path


def test_a_ulog_without_sensors_or_gps_is_nothing_to_judge(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = _ulog_without_sensors(tmp_path / "bench.ulg")
    holds = "PX4 ULog with no sensor_combined or GPS topic"
    assert read_log(log).metadata[HOLDS].startswith(holds) and "battery_status" in read_log(log).metadata[HOLDS]
    assert main(["inspect", str(log)]) == 0
    assert f"no GNSS data to judge: {holds}" in capsys.readouterr().out


def test_a_damaged_ulog_without_sensors_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = _ulog_without_sensors(tmp_path / "bench.ulg")
    data = log.read_bytes()
    log.write_bytes(data[:-700] + bytes(range(256)) * 2 + data[-188:])  # data messages overwritten
    assert main(["inspect", str(log)]) == 2
    err = capsys.readouterr().err
    assert "bench.ulg" in err and "Traceback" not in err


BAT = Fmt(129, "BAT", "Qfff", "TimeUS,Volt,Curr,CurrTot")
MODE = Fmt(130, "MODE", "QMB", "TimeUS,Mode,ModeNum")


def _dataflash_of_a_bench_session(path: Path) -> Path:
    """A DataFlash log of a bench session: battery and mode, no GPS, IMU or EKF message."""
    messages = [BAT.message(TimeUS=1000 + k, Volt=16.4) for k in range(30)]
    messages.append(MODE.message(TimeUS=2000))
    return write_dataflash(path, [BAT, MODE], messages)


def test_a_dataflash_log_of_a_bench_session_is_nothing_to_judge(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = _dataflash_of_a_bench_session(tmp_path / "bench.bin")
    holds = "DataFlash log without a GPS, IMU or EKF message (BAT x30, MODE x1)"
    assert read_log(log).metadata[HOLDS] == holds
    assert main(["analyze", str(log), "-o", str(tmp_path / "a.rrd"), "--quiet"]) == 0
    assert f"NO VERDICT: no GNSS data to judge: {holds}" in capsys.readouterr().out


def test_a_damaged_dataflash_log_without_gps_or_imu_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = _dataflash_of_a_bench_session(tmp_path / "bench.bin")
    log.write_bytes(log.read_bytes()[:-5])  # the last message cut off
    assert main(["inspect", str(log)]) == 2
    err = capsys.readouterr().err
    assert "bench.bin: no GPS, IMU or EKF message in this DataFlash log" in err and "Traceback" not in err
