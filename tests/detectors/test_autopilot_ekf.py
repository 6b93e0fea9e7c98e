"""The autopilot's own EKF innovations and test ratios as an inertial reference (real ArduPilot flight)."""

from __future__ import annotations

import contextlib
import io
import struct
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import px4_support
import pytest
from paths import real_log
from pyulog.ulog2csv import convert_ulog2csv

from readers import read_log
from spooflens.detectors.autopilot_ekf import run_autopilot_ekf
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.run import analyze_table
from spooflens.writers.ulog_writer import SENSOR_GPS, Fields, ULogFile


@pytest.fixture(scope="module")
def flight():
    return read_log(real_log("ardupilot_dataflash/flightdata_center_0003.bin"))


def _dragged(ekf: pd.DataFrame, start_s: float, rate_mps: float = 2.0, tau_s: float = 5.0) -> pd.DataFrame:
    """What an EKF shows when its GNSS is dragged north at `rate_mps` from `start_s` (a consistent
    spoofer: position and velocity move together): the velocity innovation (prediction minus
    measurement) steps by -rate and decays as the filter follows GNSS (time constant `tau_s`); the
    position innovation grows by the part of the drag not followed yet."""
    out = ekf.copy()
    dt = np.clip(out["t_s"].to_numpy(dtype=float) - start_s, 0.0, None)
    on = out["t_s"].to_numpy(dtype=float) >= start_s
    out.loc[on, "vel_innov_n_mps"] -= rate_mps * np.exp(-dt[on] / tau_s)
    out.loc[on, "pos_innov_n_m"] -= rate_mps * tau_s * (1.0 - np.exp(-dt[on] / tau_s))
    return out


def test_the_clean_real_flight_raises_nothing_with_a_wide_margin(flight) -> None:
    result = run_autopilot_ekf(flight.frame("autopilot_ekf"))
    assert result.ran and result.evidence == Evidence.INERTIAL
    assert not result.alarms
    strength = next(s for s in result.series if s.name == "strength").values
    assert np.nanmax(strength) < 0.5  # at most half the alarm level anywhere in the real flight


def test_a_drag_the_autopilot_filter_followed_is_found_from_its_onset(flight) -> None:
    ekf = _dragged(flight.frame("autopilot_ekf"), start_s=25.0)
    result = run_autopilot_ekf(ekf)
    assert len(result.alarms) == 1
    alarm = result.alarms[0]
    # the filter follows the drag, so the position innovation needs 2.6 s to pass 8 x 0.5 m; the onset
    # is where its rise began
    assert 25.0 <= alarm.start_s <= 28.0 and alarm.end_s - alarm.start_s >= 2.0
    assert 24.9 <= (alarm.onset_s or 0.0) <= 25.3
    assert "EKF3 core 0 position innovation up to" in result.findings[0].text


def test_gnss_rejected_by_the_autopilot_for_seconds_alarms_a_glitch_does_not(flight) -> None:
    ekf = flight.frame("autopilot_ekf").copy()
    t = ekf["t_s"].to_numpy(dtype=float)
    ekf.loc[(t >= 30.0) & (t <= 36.0), "vel_test_ratio"] = 2.5
    rejected = run_autopilot_ekf(ekf)
    assert [round(a.start_s) for a in rejected.alarms] == [30]
    assert "velocity test ratio up to 2.5" in rejected.findings[0].text
    for seconds in (0.3, 3.0):  # one fix, a few seconds of multipath
        glitch = flight.frame("autopilot_ekf").copy()
        glitch.loc[(t >= 30.0) & (t <= 30.0 + seconds), ["vel_test_ratio", "vel_innov_n_mps"]] = (4.0, 6.0)
        assert not run_autopilot_ekf(glitch).alarms


def test_one_core_of_two_out_of_line_is_no_alarm_both_are(flight) -> None:
    core0 = flight.frame("autopilot_ekf")
    core1 = core0.assign(source="EKF3 core 1")
    odd = pd.concat([_dragged(core0, 25.0), core1], ignore_index=True)
    assert not run_autopilot_ekf(odd).alarms
    both = pd.concat([_dragged(core0, 25.0), _dragged(core1, 25.0)], ignore_index=True)
    assert len(run_autopilot_ekf(both).alarms) == 1


def test_the_autopilot_filter_counts_as_the_inertial_class_in_the_verdict(flight) -> None:
    """The real flight logs no IMU, so spooflens' own filter cannot run; the autopilot's can speak."""
    assert not len(flight.imu)
    clean = analyze_table(flight)
    assert not clean.verdict.spoofed
    attacked = analyze_table(replace(flight, autopilot_ekf=_dragged(flight.frame("autopilot_ekf"), 25.0)))
    assert attacked.verdict.spoofed
    incident = attacked.verdict.incidents[0]
    assert Evidence.INERTIAL in incident.evidence and "autopilot_ekf" in incident.detectors
    assert 24.9 <= incident.onset_s <= 25.3


# PX4's EstimatorInnovations / EstimatorInnovationTestRatios layouts (the GNSS part and what follows it)
ESTIMATOR_FIELDS: Fields = [
    ("uint64_t", "timestamp"),
    ("uint64_t", "timestamp_sample"),
    ("float[2]", "gps_hvel"),
    ("float", "gps_vvel"),
    ("float[2]", "gps_hpos"),
    ("float", "gps_vpos"),
    ("float[2]", "ev_hvel"),
    ("float", "heading"),
]


def _px4_log(path: Path, drag_from_s: float | None) -> None:
    """30 s of PX4 at 5 Hz GNSS with two EKF2 instances logging their GNSS innovations at 10 Hz (noise
    0.15 m/s, 0.3 m), and from `drag_from_s` the drag `_dragged` models on both."""
    rng = np.random.default_rng(5)
    log = ULogFile()
    log.info("sys_name", "PX4")
    t = np.round(np.arange(1.0, 31.0, 0.2), 6)
    px4_support.fill_gps(log.topic("sensor_gps", SENSOR_GPS, len(t)), px4_support.flight(t), px4_support.M8N_SERIAL2)
    te = np.round(np.arange(1.0, 31.0, 0.1), 6)
    for k in (0, 1):
        frame = pd.DataFrame(
            {
                "t_s": te,
                "vel_innov_n_mps": rng.normal(0, 0.15, len(te)),
                "pos_innov_n_m": rng.normal(0, 0.3, len(te)),
            }
        )
        if drag_from_s is not None:
            frame = _dragged(frame, drag_from_s)
        innov = log.topic("estimator_innovations", ESTIMATOR_FIELDS, len(te), multi_id=k)
        ratios = log.topic("estimator_innovation_test_ratios", ESTIMATOR_FIELDS, len(te), multi_id=k)
        for rows in (innov, ratios):
            rows["timestamp"] = rows["timestamp_sample"] = np.round(te * 1e6).astype(np.int64)
        innov["gps_hvel"][:, 0] = frame["vel_innov_n_mps"]
        innov["gps_hvel"][:, 1] = rng.normal(0, 0.15, len(te))
        innov["gps_hpos"][:, 0] = frame["pos_innov_n_m"]
        innov["gps_hpos"][:, 1] = rng.normal(0, 0.3, len(te))
        # PX4's ratio: innovation^2 / (gate^2 variance), gate 5, its variance from the reported accuracy
        ratios["gps_hvel"][:, 0] = frame["vel_innov_n_mps"] ** 2 / (25 * 0.5**2)
        ratios["gps_hpos"][:, 0] = frame["pos_innov_n_m"] ** 2 / (25 * 1.6**2)
    log.write(path)


def test_px4_ekf2_innovations_and_test_ratios_are_read_per_instance_and_judged(tmp_path: Path) -> None:
    clean_path, dragged_path = tmp_path / "clean.ulg", tmp_path / "dragged.ulg"
    _px4_log(clean_path, None)
    _px4_log(dragged_path, 20.0)
    clean = read_log(clean_path)
    ekf = clean.frame("autopilot_ekf")
    assert sorted(ekf["source"].unique()) == ["EKF2 instance 0", "EKF2 instance 1"]
    assert len(ekf) == 2 * 300
    assert np.isfinite(ekf[["vel_innov_n_mps", "vel_innov_e_mps", "pos_innov_n_m", "vel_test_ratio"]]).all().all()
    first = ekf[ekf["source"] == "EKF2 instance 0"]["t_s"].to_numpy()
    np.testing.assert_allclose(first[:2] - clean.fixes["t_s"].to_numpy()[0], [0.0, 0.1], atol=1e-6)  # one clock
    assert any(s.role == "autopilot_ekf" for s in clean.streams)
    assert not run_autopilot_ekf(ekf).alarms
    attacked = run_autopilot_ekf(read_log(dragged_path).frame("autopilot_ekf"))
    drag_s = 20.0 - 1.0  # boot 20 s on the log's clock (it starts at the first message, boot 1 s)
    assert len(attacked.alarms) == 1
    alarm = attacked.alarms[0]
    assert drag_s - 0.5 <= (alarm.onset_s or 0.0) <= drag_s + 0.3 and alarm.start_s <= drag_s + 5.0
    assert "EKF2 instance 0" in attacked.findings[0].text and "EKF2 instance 1" in attacked.findings[0].text


def test_a_ulog2csv_export_of_the_px4_innovations_reads_like_the_ulog(tmp_path: Path) -> None:
    ulg, out = tmp_path / "log_7_2024-5-17-10-22-41.ulg", tmp_path / "csv"
    _px4_log(ulg, 20.0)
    out.mkdir()
    with contextlib.redirect_stdout(io.StringIO()):
        convert_ulog2csv(str(ulg), None, str(out), ",", None, None)
    assert (out / "log_7_2024-5-17-10-22-41_estimator_innovation_test_ratios_1.csv").exists()
    a, b = read_log(ulg).frame("autopilot_ekf"), read_log(out).frame("autopilot_ekf")
    columns = ["t_s", "vel_innov_n_mps", "pos_innov_e_m", "vel_test_ratio", "pos_test_ratio"]
    pd.testing.assert_frame_equal(a[columns], b[columns], check_exact=False, rtol=1e-6)
    assert list(a["source"]) == list(b["source"])
    assert len(run_autopilot_ekf(b).alarms) == 1


def test_px4_1_10_ekf2_innovations_with_estimator_status_ratios_are_read(tmp_path: Path) -> None:
    """PX4 <= 1.10 logged `ekf2_innovations.vel_pos_innov[6]` (velocity then position, NED) and the
    ratios only in `estimator_status`."""
    rng = np.random.default_rng(8)
    log = ULogFile()
    log.info("sys_name", "PX4")
    t = np.round(np.arange(1.0, 31.0, 0.2), 6)
    px4_support.fill_gps(
        log.topic("vehicle_gps_position", px4_support.V1_12_VEHICLE_GPS_POSITION, len(t)), px4_support.flight(t)
    )
    te = np.round(np.arange(1.0, 31.0, 0.1), 6)
    frame = _dragged(
        pd.DataFrame({"t_s": te, "vel_innov_n_mps": rng.normal(0, 0.15, len(te)), "pos_innov_n_m": 0.0}), 20.0
    )
    innov = log.topic("ekf2_innovations", [("uint64_t", "timestamp"), ("float[6]", "vel_pos_innov")], len(te))
    status_fields: Fields = [("uint64_t", "timestamp")] + [
        ("float", f"{n}_test_ratio") for n in ("vel", "pos", "hgt", "mag")
    ]
    status = log.topic("estimator_status", status_fields, len(te))
    innov["timestamp"] = status["timestamp"] = np.round(te * 1e6).astype(np.int64)
    innov["vel_pos_innov"][:, 0] = frame["vel_innov_n_mps"]
    innov["vel_pos_innov"][:, 3] = frame["pos_innov_n_m"]
    status["pos_test_ratio"] = np.abs(frame["pos_innov_n_m"]) / (5 * 1.6)
    path = tmp_path / "v1_10.ulg"
    log.write(path)
    ekf = read_log(path).frame("autopilot_ekf")
    assert set(ekf["source"]) == {"EKF2 instance 0"} and len(ekf) == len(te)
    np.testing.assert_allclose(ekf["pos_innov_n_m"], frame["pos_innov_n_m"], atol=1e-5)
    np.testing.assert_allclose(ekf["pos_test_ratio"], status["pos_test_ratio"], atol=1e-6)
    assert [round(a.onset_s or 0.0) for a in run_autopilot_ekf(ekf).alarms] == [19]


def test_a_tlog_carries_the_autopilot_test_ratios_and_seconds_of_rejected_gnss_alarm(tmp_path: Path) -> None:
    """Telemetry has no innovations, only ArduPilot's EKF_STATUS_REPORT (square roots of the test ratios)."""
    from mavlink_support import write_tlog
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    path = tmp_path / "flight.tlog"
    t0_unix_us, _ = write_tlog(path)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    times = np.arange(0.0, 30.0, 0.5)
    with path.open("ab") as f:
        for t in times:
            velocity = 2.0 if 15.0 <= t < 22.0 else 0.1  # the EKF rejecting GNSS velocity for 7 s
            f.write(struct.pack(">Q", t0_unix_us + round(t * 1e6) + 150_000))
            f.write(mav.ekf_status_report_encode(0x1FF, velocity, 0.2, 0.1, 0.05, 0.0).pack(mav))
    table = read_log(path)
    ekf = table.frame("autopilot_ekf")
    assert len(ekf) == len(times) and set(ekf["source"]) == {"autopilot (EKF_STATUS_REPORT)"}
    assert ekf["vel_innov_n_mps"].isna().all()
    result = run_autopilot_ekf(ekf)
    assert len(result.alarms) == 1
    assert 14.5 <= result.alarms[0].start_s - table.fixes["t_s"].iloc[0] <= 15.5
    assert "velocity test ratio up to 2.0" in result.findings[0].text
