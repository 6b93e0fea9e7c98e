"""PX4 ULogs of three eras: every receiver indicator, its unit and the meaning of its state codes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from px4_support import (
    BOOT_UTC_US,
    M8N_SERIAL2,
    SENSOR_COMBINED,
    VEHICLE_ATTITUDE,
    ULogFile,
    current_log,
    fill_imu,
    flight,
    v1_12_log,
    v1_14_two_receivers,
)

from readers import read_log
from readers.px4 import CURRENT_STATES, LEGACY_STATES, interpolate_attitude, ned_frd_to_enu_flu
from spooflens.attacks import apply_attack, parse_attack
from spooflens.cli import main
from spooflens.epoch_table import EpochTable
from spooflens.navigation.alignment import _imu_orientation
from spooflens.navigation.rotations import matrix_to_quat, quat_to_matrix
from spooflens.schema import FixType, SpoofingFlag
from spooflens.writers import write_log

INDICATORS = [
    "h_acc_m",
    "v_acc_m",
    "vel_acc_mps",
    "hdop",
    "vdop",
    "noise_per_ms",
    "jamming_indicator",
    "agc",
    "sats_used",
    "jamming_state",
    "spoofing_state",
]


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("px4")


def _expect(fixes: pd.DataFrame, f: dict[str, np.ndarray], columns: list[str], rtol: float = 1e-6) -> None:
    for c in columns:
        np.testing.assert_allclose(fixes[c].to_numpy(float), f[c], rtol=rtol, atol=1e-9, err_msg=c)


def test_v1_12_vehicle_gps_position_units_clock_and_jamming_meaning(logs: Path) -> None:
    path = logs / "v1_12.ulg"
    f = v1_12_log(path)
    table = read_log(path)
    assert table.receivers() == ["vehicle_gps_position/0"] and table.time_reference == "unix"
    fx = table.fixes
    keep = np.ones(len(f["t_s"]), bool)
    keep[:2] = False  # fix_type 1: no fix, skipped and said so
    exp = {k: v[keep] for k, v in f.items()}
    assert any("no fix" in s.reason and s.count == 2 for s in table.skipped)
    # the clock: boot + time_utc_usec offset, so UNIX time of the first fix is boot UTC + its boot time
    np.testing.assert_array_equal(table.absolute_ns(fx["t_s"].to_numpy()), (BOOT_UTC_US + exp["t_s"] * 1e6) * 1000)
    # int 1e-7 deg and mm: within one unit of the last digit
    np.testing.assert_allclose(fx["lat_deg"], exp["lat_deg"], rtol=0, atol=0.6e-7)
    np.testing.assert_allclose(fx["lon_deg"], exp["lon_deg"], rtol=0, atol=0.6e-7)
    np.testing.assert_allclose(fx["height_m"], exp["height_m"], rtol=0, atol=0.6e-3)
    _expect(fx, exp, ["h_acc_m", "v_acc_m", "vel_acc_mps", "hdop", "vdop", "noise_per_ms", "jamming_indicator"])
    _expect(fx, exp, ["sats_used", "jamming_state"])
    # NED -> ENU; the message with vel_ned_valid false has no velocity
    vel = fx[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy()
    bad = 12 - 2
    assert np.isnan(vel[bad]).all()
    np.testing.assert_allclose(np.delete(vel, bad, axis=0), np.tile([2.0, 1.0, 0.5], (len(vel) - 1, 1)), rtol=1e-6)
    assert fx["fix_type"].iloc[10 - 2] == FixType.UNKNOWN and (np.delete(fx["fix_type"], 8) == FixType.FIX_3D).all()
    # v1.12 has no spoofing_state, AGC or authentication: absent columns stay NaN, the flag UNKNOWN
    assert fx[["spoofing_state", "agc", "authentication_state", "cn0_mean_dbhz"]].isna().all().all()
    assert (fx["spoofing_flag"] == SpoofingFlag.UNKNOWN).all()
    m = table.metadata
    assert m["firmware"].startswith("PX4 v1.12.3 (release), git 1c0f2a7b") and "hardware PX4_FMU_V5" in m["firmware"]
    assert m["enum.jamming_state"].startswith(LEGACY_STATES.name) and "2 warning, 3 critical" in m["enum.jamming_state"]
    assert "authentication_state is absent in the log's vehicle_gps_position definition" in m["enum.jamming_state"]
    assert "enum.spoofing_state" not in m
    assert any("vehicle_air_data" in s.stream and "barometric" in s.reason for s in table.skipped)


def test_two_receivers_each_from_the_topic_that_logged_it_most(logs: Path) -> None:
    path = logs / "v1_14.ulg"
    made = v1_14_two_receivers(path)
    table = read_log(path)
    fixes = {s.stream_id: s for s in table.streams if s.role == "fix"}
    assert sorted(fixes) == ["sensor_gps/0", "sensor_gps/1"]
    # receiver 0 from vehicle_gps_position (5 Hz, its device_id) minus the three blended messages
    assert fixes["sensor_gps/0"].topic == "vehicle_gps_position" and fixes["sensor_gps/0"].count == 150 - 3
    assert fixes["sensor_gps/1"].topic == "sensor_gps" and fixes["sensor_gps/1"].count == 30
    assert any(s.stream == "vehicle_gps_position" and s.count == 3 for s in table.skipped)
    assert any(s.stream == "sensor_gps/0" and s.reason.startswith("not read") and s.count == 30 for s in table.skipped)
    rx0 = table.fixes_of("sensor_gps/0")
    keep = np.ones(150, bool)
    keep[[40, 41, 42]] = False
    exp = {k: v[keep] for k, v in made["f5"].items()}
    _expect(rx0, exp, INDICATORS)
    _expect(table.fixes_of("sensor_gps/1"), made["f1b"], INDICATORS)
    assert "sensor_gps/0: u-blox 8 (M8) on serial bus 2" in table.metadata["receiver"]
    assert "sensor_gps/1: u-blox 9 (M9) on serial bus 4" in table.metadata["receiver"]
    assert table.metadata["firmware"].startswith("PX4 v1.14.0 (release)")


def test_legacy_spoofing_state_raw_kept_flag_decoded_and_meaning_recorded(logs: Path) -> None:
    path = logs / "v1_14_attack.ulg"
    v1_14_two_receivers(path, attack_s=20.0)
    table = read_log(path)
    rx = table.fixes_of("sensor_gps/0")
    before = rx["t_s"] < rx["t_s"].iloc[0] + 19.0 - 1e-6
    assert set(rx.loc[before, "spoofing_state"]) == {1.0} and set(rx.loc[~before, "spoofing_state"]) == {2.0}
    assert (rx.loc[before, "spoofing_flag"] == SpoofingFlag.CLEAR).all()
    assert (rx.loc[~before, "spoofing_flag"] == SpoofingFlag.INDICATED).all()
    m = table.metadata
    assert m["enum.spoofing_state"].startswith(LEGACY_STATES.name)
    assert "1 none, 2 indicated, 3 multiple indications" in m["enum.spoofing_state"]
    assert "firmware PX4 v1.14.0 (release)" in m["enum.spoofing_state"]
    assert "1 OK, 2 warning, 3 critical" in m["enum.jamming_state"]
    assert "GPS spoofing detected! (state: 2)" in m["px4.gnss_log_messages"]
    assert "boot 20.400 s" in m["px4.gnss_log_messages"]
    # satellite_info (1 Hz): mean C/N0 over the `count` tracked satellites, 38 dB-Hz clean, 47 under
    # attack; a 5 Hz fix takes the message nearest in time, so check the fixes on whole seconds
    boot = rx["t_s"].to_numpy() + 1.0
    whole = np.abs(boot - np.round(boot)) < 1e-6
    np.testing.assert_allclose(rx["cn0_mean_dbhz"].to_numpy()[whole], np.where(boot[whole] >= 20.0, 47.0, 38.0))
    assert np.isnan(table.fixes_of("sensor_gps/1")["cn0_mean_dbhz"]).all()  # no satellite_info of receiver 1


def test_clean_log_has_steady_indicators(logs: Path) -> None:
    path = logs / "v1_14_clean.ulg"
    v1_14_two_receivers(path, attack_s=None)
    table = read_log(path)
    for c, value in {"spoofing_state": 1.0, "jamming_state": 1.0, "noise_per_ms": 95.0, "sats_used": 14.0}.items():
        assert (table.fixes[c] == value).all(), c
    assert (table.fixes["spoofing_flag"] == SpoofingFlag.CLEAR).all()
    assert "px4.gnss_log_messages" not in table.metadata


def test_current_definition_codes_mean_mitigated_and_detected(logs: Path) -> None:
    path = logs / "current.ulg"
    f = current_log(path)
    table = read_log(path)
    fx = table.fixes
    _expect(fx, f, [*INDICATORS, "authentication_state"])
    m = table.metadata
    assert m["enum.spoofing_state"].startswith(CURRENT_STATES.name)
    assert "1 OK, 2 mitigated, 3 detected" in m["enum.spoofing_state"]
    assert "1 OK, 2 mitigated, 3 detected" in m["enum.jamming_state"]
    assert "3 OK" in m["enum.authentication_state"]
    # mitigated and detected are both the receiver saying it saw spoofing
    flag = fx["spoofing_flag"].to_numpy()
    assert set(flag[fx["spoofing_state"] == 1]) == {SpoofingFlag.CLEAR}
    assert set(flag[fx["spoofing_state"] >= 2]) == {SpoofingFlag.INDICATED}
    assert {2.0, 3.0} <= set(fx["spoofing_state"])


def _write_renamed(path: Path) -> dict[str, np.ndarray]:
    """The SensorGnss rename: unit-free field names (`latitude`, `noise`, `vel_north`) on sensor_gnss."""
    fields = [
        ("uint64_t", "timestamp"),
        ("double", "latitude"),
        ("double", "longitude"),
        ("double", "altitude_ellipsoid"),
        ("float", "speed_accuracy"),
        ("float", "eph"),
        ("int32_t", "noise"),
        ("float", "vel_north"),
        ("float", "vel_east"),
        ("float", "vel_down"),
        ("bool", "vel_ned_valid"),
        ("uint8_t", "fix_type"),
        ("uint8_t", "spoofing_state"),
        ("uint8_t", "authentication_state"),
    ]
    log = ULogFile()
    t = np.arange(1.0, 11.0, 0.2)
    f = flight(t, attack_s=5.0)
    r = log.topic("sensor_gnss", fields, len(t))
    r["timestamp"] = np.round(t * 1e6)
    r["latitude"], r["longitude"], r["altitude_ellipsoid"] = f["lat_deg"], f["lon_deg"], f["height_m"]
    r["speed_accuracy"], r["eph"], r["noise"] = f["vel_acc_mps"], f["h_acc_m"], f["noise_per_ms"]
    r["vel_north"], r["vel_east"], r["vel_down"] = f["vel_n_mps"], f["vel_e_mps"], -f["vel_u_mps"]
    r["vel_ned_valid"], r["fix_type"], r["spoofing_state"] = 1, 3, f["spoofing_state"]
    log.write(path)
    return f


def test_renamed_sensor_gnss_fields(logs: Path) -> None:
    path = logs / "renamed.ulg"
    f = _write_renamed(path)
    table = read_log(path)
    assert table.receivers() == ["sensor_gnss/0"] and table.time_reference == "boot"
    _expect(table.fixes, f, ["lat_deg", "lon_deg", "height_m", "vel_e_mps", "vel_n_mps", "vel_u_mps"], rtol=1e-7)
    _expect(table.fixes, f, ["vel_acc_mps", "h_acc_m", "noise_per_ms", "spoofing_state"])
    assert table.metadata["enum.spoofing_state"].startswith(CURRENT_STATES.name)


def test_east_north_velocity_without_down_is_kept(logs: Path) -> None:
    fields = [
        ("uint64_t", "timestamp"),
        ("int32_t", "lat"),
        ("int32_t", "lon"),
        ("int32_t", "alt_ellipsoid"),
        ("float", "vel_n_m_s"),
        ("float", "vel_e_m_s"),
        ("uint8_t", "fix_type"),
    ]
    log = ULogFile()
    t = np.arange(1.0, 6.0, 0.5)
    r = log.topic("vehicle_gps_position", fields, len(t))
    r["timestamp"] = np.round(t * 1e6)
    r["lat"], r["lon"], r["alt_ellipsoid"] = 473977419, 85455939, 488250
    r["vel_n_m_s"], r["vel_e_m_s"], r["fix_type"] = 1.5, -0.5, 3
    log.write(logs / "en_only.ulg")
    fx = read_log(logs / "en_only.ulg").fixes
    assert len(fx) == len(t) and fx["vel_u_mps"].isna().all()
    assert (fx["vel_e_mps"] == -0.5).all() and (fx["vel_n_mps"] == 1.5).all()


def test_msl_altitude_where_the_driver_leaves_the_ellipsoidal_one_zero(logs: Path) -> None:
    fields = [("uint64_t", "timestamp"), ("int32_t", "lat"), ("int32_t", "lon"), ("int32_t", "alt")]
    fields += [("int32_t", "alt_ellipsoid"), ("uint8_t", "fix_type")]
    log = ULogFile()
    r = log.topic("vehicle_gps_position", fields, 4)
    r["timestamp"] = [1_000_000, 1_200_000, 1_400_000, 1_600_000]
    r["lat"], r["lon"], r["alt"], r["fix_type"] = 473977419, 85455939, 441250, 3
    r["alt_ellipsoid"] = [488250, 0, 488250, 0]
    log.write(logs / "msl.ulg")
    table = read_log(logs / "msl.ulg")
    np.testing.assert_allclose(table.fixes["height_m"], [488.25, 441.25, 488.25, 441.25])
    assert any("above mean sea level" in s.reason and s.count == 2 for s in table.skipped)


# --- attitude ---------------------------------------------------------------------------------------


def _ned_frd(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """PX4's body FRD -> NED rotation from Euler angles (yaw from north towards east, pitch nose up)."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def test_attitude_conversion_to_flu_enu() -> None:
    roll, pitch, yaw = np.radians([5.0, 10.0, 30.0])
    r = _ned_frd(roll, pitch, yaw)
    q = ned_frd_to_enu_flu(matrix_to_quat(r))
    c = quat_to_matrix(q)
    ned_to_enu = np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, -1]])
    np.testing.assert_allclose(c, ned_to_enu @ r @ np.diag([1.0, -1, -1]), atol=1e-12)
    # the nose points 30 deg east of north and 10 deg up
    forward = c @ [1.0, 0, 0]
    np.testing.assert_allclose(forward, [np.cos(pitch) * np.sin(yaw), np.cos(pitch) * np.cos(yaw), np.sin(pitch)])
    left = c @ [0.0, 1, 0]
    assert left[2] == pytest.approx(np.cos(pitch) * np.sin(roll))  # roll > 0 is right wing down: left wing up


def test_attitude_slerped_onto_imu_times_and_read_by_the_alignment(logs: Path) -> None:
    log = ULogFile()
    t_imu = np.arange(0.5, 10.0, 0.02)
    fill_imu(log.topic("sensor_combined", SENSOR_COMBINED, len(t_imu)), t_imu)
    t_att = np.r_[np.arange(1.0, 5.0, 0.1), np.arange(6.0, 9.0, 0.1)]  # 1 s gap from 5 to 6 s
    yaw = np.radians(30.0) + np.radians(10.0) * t_att  # 10 deg/s turn
    att = log.topic("vehicle_attitude", VEHICLE_ATTITUDE, len(t_att))
    att["timestamp"] = np.round(t_att * 1e6)
    att["q"] = [matrix_to_quat(_ned_frd(np.radians(5), np.radians(10), y)) for y in yaw]
    log.write(logs / "attitude.ulg")
    table = read_log(logs / "attitude.ulg")
    imu = table.imu
    info = next(s for s in table.streams if s.role == "imu")
    assert info.body_frame == "FRD" and "vehicle_attitude" in info.msgtype
    tu = np.round(imu["t_s"].to_numpy() * 1e6).astype(np.int64) + 500_000  # µs since boot
    t = tu / 1e6
    q = imu[["qw", "qx", "qy", "qz"]].to_numpy()
    inside = ((tu >= 1_000_000) & (tu <= 4_900_000)) | ((tu >= 6_000_000) & (tu <= 8_900_000))
    assert np.isfinite(q[inside]).all() and np.isnan(q[~inside]).all()
    # constant-rate yaw: slerp between 10 Hz samples gives the attitude at each 50 Hz IMU time exactly
    expect = ned_frd_to_enu_flu(
        np.array(
            [matrix_to_quat(_ned_frd(np.radians(5), np.radians(10), np.radians(30 + 10 * ti))) for ti in t[inside]]
        )
    )
    angle = 2 * np.arccos(np.clip(np.abs(np.sum(q[inside] * expect, axis=1)), 0, 1))
    assert angle.max() < 1e-5  # rad; the log holds float32
    k = int(np.argmin(np.abs(t - 2.51)))
    c = _imu_orientation(imu, float(imu["t_s"].iloc[k]))
    assert c is not None
    heading = np.degrees(np.arctan2(c[0, 0], c[1, 0]))  # of the nose, from north towards east
    assert heading == pytest.approx(30 + 10 * t[k], abs=1e-3)
    assert any(s.stream == "vehicle_attitude" and s.count == int((~inside).sum()) for s in table.skipped)


def test_interpolate_attitude_takes_the_short_way_round() -> None:
    q0 = np.array([np.cos(0.4), 0.0, 0.0, np.sin(0.4)])
    q1 = -np.array([np.cos(0.5), 0.0, 0.0, np.sin(0.5)])  # the same attitude family, opposite sign
    q = interpolate_attitude(np.array([0.0, 5.0, 10.0]), np.array([0.0, 10.0]), np.stack([q0, q1]), 20.0)
    half = np.array([np.cos(0.45), 0.0, 0.0, np.sin(0.45)])
    assert abs(float(q[1] @ half)) == pytest.approx(1.0, abs=1e-12)


# --- writer and inject ------------------------------------------------------------------------------


def test_writer_keeps_the_legacy_definition_for_legacy_codes(logs: Path) -> None:
    path = logs / "legacy_src.ulg"
    v1_14_two_receivers(path)
    table = read_log(path)
    out = logs / "legacy_out.ulg"
    write_log(table, out, "ulog")
    back = read_log(out)
    assert back.metadata["enum.spoofing_state"] == table.metadata["enum.spoofing_state"]
    assert back.metadata["receiver"] == table.metadata["receiver"] and back.metadata["firmware"].startswith(
        "PX4 v1.14.0"
    )
    cols = [*INDICATORS, "spoofing_flag"]
    pd.testing.assert_frame_equal(back.fixes[cols], table.fixes[cols])
    # the receiver's satellite_info goes with it: every satellite as read, and the mean C/N0 from it
    pd.testing.assert_frame_equal(back.satellites, table.satellites)
    pd.testing.assert_series_equal(back.fixes["cn0_mean_dbhz"], table.fixes["cn0_mean_dbhz"])
    assert back.fixes["cn0_mean_dbhz"].notna().any()


def test_writer_current_definition_from_a_table_without_px4_metadata(logs: Path) -> None:
    current_log(logs / "current_src.ulg")
    table = read_log(logs / "current_src.ulg")
    bare = EpochTable(**{**table.__dict__, "metadata": {}})
    write_log(bare, logs / "current_out.ulg", "ulog")
    back = read_log(logs / "current_out.ulg")
    assert back.metadata["enum.spoofing_state"].startswith(CURRENT_STATES.name)
    cols = [*INDICATORS, "authentication_state", "spoofing_flag"]
    pd.testing.assert_frame_equal(back.fixes[cols], table.fixes[cols])


def test_inject_round_trips_every_indicator_and_the_attitude(logs: Path) -> None:
    src = logs / "inject_src.ulg"
    v1_14_two_receivers(src)
    out = logs / "inject_out.ulg"
    assert main(["inject", str(src), "--attack", "ramp:rate=2,start=10", "-o", str(out)]) == 0
    original, spoofed = read_log(src), read_log(out)
    expected, _ = apply_attack(original, parse_attack("ramp:rate=2,start=10"))
    pos = ["lat_deg", "lon_deg", "height_m"]
    np.testing.assert_allclose(spoofed.fixes[pos], expected.fixes[pos], rtol=0, atol=1e-7)
    others = [c for c in original.fixes.columns if c not in (*pos, "cn0_mean_dbhz")]
    pd.testing.assert_frame_equal(spoofed.fixes[others], original.fixes[others])
    for key in ("enum.spoofing_state", "enum.jamming_state", "receiver", "firmware"):
        assert spoofed.metadata[key] == original.metadata[key], key
    q = ["qw", "qx", "qy", "qz"]
    np.testing.assert_allclose(spoofed.imu[q].to_numpy(), original.imu[q].to_numpy(), atol=1e-6)
    forward = quat_to_matrix(original.imu[q].to_numpy()[100]) @ [1.0, 0, 0]
    np.testing.assert_allclose(forward, [0.5, np.sqrt(0.75), 0.0], atol=1e-6)  # heading 30 deg, level


def test_inspect_lists_the_px4_streams(logs: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = logs / "inspect.ulg"
    v1_14_two_receivers(path)
    assert main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out
    assert "sensor_gps/0" in out and "sensor_gps/1" in out and "vehicle_attitude" in out
    assert "vehicle_air_data" in out and "battery_status" in out


def test_the_writer_receivers_keep_their_device(logs: Path) -> None:
    path = logs / "device.ulg"
    current_log(path)
    table = read_log(path)
    assert table.metadata["px4.device_id.sensor_gps/0"] == str(M8N_SERIAL2)


def test_px4_versions_devices_and_renamed_fields_decode() -> None:
    from readers.px4 import canonical_record, device_description, release_name

    assert release_name(0x010E00FF) == "v1.14.0 (release)"
    assert release_name(0x010F02C1) == "v1.15.2 (RC)" and release_name(0x01100000) == "v1.16.0 (dev)"
    assert device_description(M8N_SERIAL2) == "u-blox 8 (M8) on serial bus 2 (device_id 0xA80015)"
    assert device_description(0x85 << 16 | 0x7D << 8 | 3 << 3 | 3).startswith("DroneCAN GNSS node on DroneCAN bus 3")
    # the proposed vehicle_gnss nests the receiver's sample; its unit-free names map to SensorGps's
    rec = canonical_record({"timestamp": np.zeros(1), "receiver.latitude": np.ones(1), "receiver.noise": np.ones(1)})
    assert set(rec) == {"timestamp", "latitude_deg", "noise_per_ms"}


def test_satellite_info_gives_every_satellite_by_its_svinfo_number(logs: Path) -> None:
    """satellite_info per satellite: PX4's u-blox NAV-SVINFO numbering mapped to RINEX ids, the
    driver's wrapped negative elevation unwrapped, azimuth unscaled, entries beyond `count` left out."""
    path = logs / "v1_14_sky.ulg"
    v1_14_two_receivers(path, attack_s=20.0)
    table = read_log(path)
    sky = table.satellites
    assert set(sky["receiver_id"]) == {"sensor_gps/0"}  # satellite_info is receiver 0's
    ids = ["G02", "G05", "G07", "G09", "G13", "G15", "G20", "G24", "R03", "R05", "E11", "E12"]
    assert sorted(set(sky["sv_id"])) == sorted(ids) and len(sky) == 12 * 30
    first = sky[sky["t_s"] == sky["t_s"].min()].set_index("sv_id")
    assert first.loc["E12", "elevation_deg"] == -1.0 and first.loc["G02", "elevation_deg"] == 12.0
    assert first.loc["R05", "azimuth_deg"] == pytest.approx(180 * 360 / 255)
    assert (sky["used"] == 1.0).all() and sky["healthy"].isna().all()
    stream = next(s for s in table.streams if s.role == "satellites")
    assert stream.count == 30 and stream.topic == "satellite_info"


def test_satellite_info_numbers_shared_in_one_message_are_left_out_and_counted() -> None:
    """Older drivers wrote u-blox's per-constellation svId: G05 and E05 both 5 in one message."""
    from readers.px4 import satellite_rows

    rec = {"timestamp": np.array([1_000_000, 2_000_000]), "count": np.array([3, 3])}
    for name, values in (("svid", (5, 5, 7)), ("snr", (40, 35, 0)), ("used", (1, 0, 0))):
        for i in range(4):
            rec[f"{name}[{i}]"] = np.full(2, values[i] if i < 3 else 9)
    skipped: list = []
    rows = satellite_rows(rec, skipped, "satellite_info")
    assert rows is not None and list(rows["sv_id"]) == ["G07", "G07"]
    assert np.isnan(rows["cn0_dbhz"]).all()  # snr 0: not tracked
    assert rows["elevation_deg"].isna().all()  # a layout without elevation
    assert [(s.count, "identity unknown" in s.reason) for s in skipped] == [(4, True)]


def test_an_sdr_spoofer_locking_every_channel_shows_as_one_c_n0(logs: Path, tmp_path: Path) -> None:
    """Under the attack every satellite_info channel reads 47 dB-Hz (one transmitter); the clean sky
    spreads over 12 dB. The satellite-signal detector names the stretch; the clean log has no alarm."""
    from spooflens.pipeline.run import analyze_table

    for attack_s, expect in ((30.0, True), (None, False)):
        path = tmp_path / f"sky_{attack_s}.ulg"
        v1_14_two_receivers(path, attack_s=attack_s, seconds=60.0)
        result = analyze_table(read_log(path))
        signals = next(r for r in result.results if r.name == "satellite_signals")
        assert signals.ran
        uniform = [f for f in signals.findings if "at one C/N0" in f.text]
        assert bool(uniform) is expect, signals.findings
        if expect:
            assert 30.0 - 2.0 <= uniform[0].start_s <= 35.0


def test_svinfo_numbers_of_every_constellation() -> None:
    """PX4's u-blox driver: BeiDou B1-B4 -> 159-162, B5-B37 -> 33-65, SBAS as its PRN, QZSS 193-202."""
    from readers.px4 import _svinfo_sv_id

    pairs = {1: "G01", 32: "G32", 33: "C05", 64: "C36", 96: "R32", 120: "S20", 159: "C01", 202: "J10", 246: "E36"}
    assert {n: _svinfo_sv_id(n) for n in pairs} == pairs
    assert [_svinfo_sv_id(n) for n in (0, 100, 255)] == [None, None, None]
