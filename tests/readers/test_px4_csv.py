"""PX4 GPS data exported as tables: ulog2csv directories and single GPS files with PX4's field names."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from px4_support import BOOT_UTC_US, flight, v1_14_two_receivers
from pyulog.ulog2csv import convert_ulog2csv

from readers import read_log
from readers.px4 import LEGACY_STATES
from spooflens.cli import main
from spooflens.schema import SpoofingFlag

INDICATORS = ["h_acc_m", "v_acc_m", "vel_acc_mps", "hdop", "vdop", "noise_per_ms", "jamming_indicator", "agc"]
INDICATORS += ["sats_used", "jamming_state", "spoofing_state", "cn0_mean_dbhz"]


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A v1.14 ULog with two receivers under attack, and its ulog2csv export (one file per topic)."""
    root = tmp_path_factory.mktemp("px4csv")
    ulg = root / "log_3_2024-5-17-10-22-41.ulg"
    v1_14_two_receivers(ulg, attack_s=20.0)
    out = root / "csv"
    out.mkdir()
    with contextlib.redirect_stdout(io.StringIO()):
        convert_ulog2csv(str(ulg), None, str(out), ",", None, None)
    return ulg, out


def test_ulog2csv_export_reads_like_the_ulog(exported: tuple[Path, Path]) -> None:
    ulg, out = exported
    assert (out / "log_3_2024-5-17-10-22-41_sensor_gps_1.csv").exists()
    a, b = read_log(ulg), read_log(out)
    assert b.format == "csv" and b.time_reference == "unix" and b.t0_ns == a.t0_ns
    assert b.receivers() == a.receivers() == ["sensor_gps/0", "sensor_gps/1"]
    assert [(s.role, s.stream_id, s.count) for s in b.streams] == [(s.role, s.stream_id, s.count) for s in a.streams]
    np.testing.assert_array_equal(b.fixes["t_s"], a.fixes["t_s"])
    np.testing.assert_array_equal(
        b.fixes[["lat_deg", "lon_deg", "height_m"]], a.fixes[["lat_deg", "lon_deg", "height_m"]]
    )
    # float32 values go through text with their shortest decimal form: equal to 1e-7 relative
    np.testing.assert_allclose(b.fixes[INDICATORS], a.fixes[INDICATORS], rtol=1e-7)
    np.testing.assert_allclose(
        b.fixes[["vel_e_mps", "vel_n_mps", "vel_u_mps"]], a.fixes[["vel_e_mps", "vel_n_mps", "vel_u_mps"]], rtol=1e-7
    )
    np.testing.assert_array_equal(b.fixes["spoofing_flag"], a.fixes["spoofing_flag"])
    pd.testing.assert_frame_equal(b.satellites, a.satellites)  # satellite_info per satellite
    q = ["qw", "qx", "qy", "qz"]
    np.testing.assert_allclose(b.imu[q], a.imu[q], atol=1e-7)
    assert next(s for s in b.streams if s.role == "imu").body_frame == "FRD"
    m = b.metadata
    assert m["enum.spoofing_state"].startswith(LEGACY_STATES.name)
    assert "absent in the columns of log_3_2024-5-17-10-22-41_sensor_gps_1.csv" in m["enum.spoofing_state"]
    assert "vehicle_gps_position" in m["px4.gps_source"]
    assert m["receiver"] == a.metadata["receiver"] and "u-blox 9 (M9) on serial bus 4" in m["receiver"]


def test_ulog2csv_export_says_what_was_converted_and_what_was_not_used(exported: tuple[Path, Path]) -> None:
    table = read_log(exported[1])
    notes = {s.stream: s for s in table.skipped}
    gps = notes["log_3_2024-5-17-10-22-41_vehicle_gps_position_0.csv"]
    assert gps.action == "repaired" and gps.count == 150
    assert "timestamp µs since boot" in gps.reason and "velocity NED -> ENU" in gps.reason
    assert "clock UNIX from time_utc_usec (boot + 1700000000.000 s)" in gps.reason
    # receiver 0 came from vehicle_gps_position (5 Hz): its 1 Hz sensor_gps table is not read, and said so
    assert (
        notes["sensor_gps/0"].reason == "not read: this receiver's 147 rows in vehicle_gps_position were read instead"
    )
    assert "log_3_2024-5-17-10-22-41_sensor_gps_0.csv" not in notes
    assert notes["log_3_2024-5-17-10-22-41_sensor_gps_1.csv"].action == "repaired"
    assert "body FRD" in notes["log_3_2024-5-17-10-22-41_sensor_combined_0.csv"].reason
    unused = next(s for s in table.skipped if s.reason.startswith("PX4 topics not used"))
    assert "battery_status" in unused.reason and "vehicle_global_position" in unused.reason
    assert any("vehicle_air_data" in s.stream and "barometric" in s.reason for s in table.skipped)
    # the EKF's vehicle_global_position has lat/lon/eph too, but it is no receiver
    assert not any("global" in r for r in table.receivers())


def _single(path: Path, f: dict[str, np.ndarray], lat_scale: float, alt_scale: float, utc: bool) -> None:
    t_us = np.round(f["t_s"] * 1e6).astype(np.int64)
    frame = {
        "timestamp": t_us,
        "lat": np.round(f["lat_deg"] / lat_scale, 7 if lat_scale == 1 else 0),
        "lon": np.round(f["lon_deg"] / lat_scale, 7 if lat_scale == 1 else 0),
        "alt_ellipsoid": np.round(f["height_m"] / alt_scale, 3 if alt_scale == 1 else 0),
        "vel_n_m_s": f["vel_n_mps"],
        "vel_e_m_s": f["vel_e_mps"],  # no vel_d_m_s: east/north velocity alone
        "eph": f["h_acc_m"],
        "epv": f["v_acc_m"],
        "hdop": f["hdop"],
        "vdop": f["vdop"],
        "noise_per_ms": f["noise_per_ms"].astype(int),
        "jamming_indicator": f["jamming_indicator"].astype(int),
        "jamming_state": f["jamming_state"].astype(int),
        "spoofing_state": f["spoofing_state"].astype(int),
        "s_variance_m_s": f["vel_acc_mps"],
        "satellites_used": f["sats_used"].astype(int),
        "fix_type": 3,
        "vel_ned_valid": np.where(np.arange(len(t_us)) == 3, "False", "True"),
    }
    if utc:
        frame["time_utc_usec"] = BOOT_UTC_US + t_us
    pd.DataFrame(frame).to_csv(path, index=False)


def test_single_gps_table_in_degrees_and_metres(tmp_path: Path) -> None:
    f = flight(np.round(np.arange(2.0, 12.0, 0.5), 6), attack_s=7.0)
    path = tmp_path / "gps_export.csv"
    _single(path, f, lat_scale=1.0, alt_scale=1.0, utc=False)
    table = read_log(path)
    fx = table.fixes
    assert table.time_reference == "boot" and table.receivers() == ["gps_export"]
    np.testing.assert_allclose(fx["lat_deg"], f["lat_deg"], atol=1e-7)
    np.testing.assert_allclose(fx["height_m"], f["height_m"], atol=1e-3)
    note = next(s for s in table.skipped if s.stream == "gps_export.csv")
    assert "lat/lon in degrees (|lat| <= 90)" in note.reason
    assert "alt_ellipsoid in metres (fractional values)" in note.reason
    assert "clock: seconds since boot" in note.reason
    # east/north velocity without down is kept; the row marked vel_ned_valid False has none
    assert fx["vel_u_mps"].isna().all()
    assert np.isnan(fx["vel_e_mps"].iloc[3]) and np.isfinite(np.delete(fx["vel_e_mps"].to_numpy(), 3)).all()
    for c in ("h_acc_m", "vel_acc_mps", "hdop", "noise_per_ms", "jamming_indicator", "sats_used", "spoofing_state"):
        np.testing.assert_allclose(fx[c], f[c], rtol=1e-9, err_msg=c)
    flag = fx["spoofing_flag"].to_numpy()
    assert set(flag[f["t_s"] < 7.0]) == {SpoofingFlag.CLEAR} and set(flag[f["t_s"] >= 7.0]) == {SpoofingFlag.INDICATED}
    assert "absent in the columns of gps_export.csv" in table.metadata["enum.spoofing_state"]


@pytest.mark.parametrize(
    ("lat_scale", "alt_scale", "alt_note"),
    [
        (1e-7, 1e-3, "alt_ellipsoid in mm (integers beside 1e-7 deg positions)"),
        (1.0, 1e-3, "alt_ellipsoid in mm (|median| 491625 is not a plausible height in m)"),
        (1.0, 1.0, "alt_ellipsoid in metres (fractional values)"),
    ],
)
def test_single_gps_table_units_decided_by_magnitude(
    tmp_path: Path, lat_scale: float, alt_scale: float, alt_note: str
) -> None:
    f = flight(np.round(np.arange(2.0, 12.0, 0.5), 6))
    path = tmp_path / "gps.csv"
    _single(path, f, lat_scale=lat_scale, alt_scale=alt_scale, utc=True)
    table = read_log(path)
    assert table.time_reference == "unix" and table.t0_ns == (BOOT_UTC_US + 2_000_000) * 1000
    np.testing.assert_allclose(table.fixes["lat_deg"], f["lat_deg"], atol=0.6e-7)
    np.testing.assert_allclose(table.fixes["height_m"], f["height_m"], atol=0.6e-3)
    note = next(s for s in table.skipped if s.stream == "gps.csv").reason
    assert alt_note in note
    assert ("lat/lon in 1e-7 deg" in note) == (lat_scale == 1e-7)


def test_spooflens_csv_with_a_unix_timestamp_column_is_not_px4(tmp_path: Path) -> None:
    """`timestamp` (UNIX seconds), `lat` in degrees and the aliases eph/satellites_used: the spooflens CSV."""
    t = 1_700_000_000.0 + np.arange(10.0)
    df = pd.DataFrame(
        {"timestamp": t, "lat": 45.0, "lon": 7.0, "alt": 300.0, "eph": 2.0, "satellites_used": 9, "hdop": 1.1}
    )
    df.to_csv(tmp_path / "fixes.csv", index=False)
    table = read_log(tmp_path / "fixes.csv")
    assert table.time_reference == "unix" and table.t0_ns == 1_700_000_000 * 10**9
    assert (table.fixes["h_acc_m"] == 2.0).all() and (table.fixes["hdop"] == 1.1).all()
    assert not any("PX4" in s.reason for s in table.skipped)


def test_spooflens_csv_keeps_east_north_velocity_without_up(tmp_path: Path) -> None:
    df = pd.DataFrame(
        {"t_s": np.arange(5.0), "lat": 45.0, "lon": 7.0, "alt": 300.0, "vel_e_mps": 1.0, "vel_n_mps": 2.0}
    )
    df.to_csv(tmp_path / "fixes.csv", index=False)
    fx = read_log(tmp_path / "fixes.csv").fixes
    assert len(fx) == 5 and fx["vel_u_mps"].isna().all() and (fx["vel_n_mps"] == 2.0).all()


def test_inspect_the_export(exported: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(exported[1])]) == 0
    out = capsys.readouterr().out
    assert "sensor_gps/0" in out and "PX4 CSV dialect" in out


def test_inject_into_an_export_keeps_indicators_and_their_meaning(exported: tuple[Path, Path], tmp_path: Path) -> None:
    """inject writes a spooflens CSV log; the enum meanings travel in its `# metadata` comments."""
    out = tmp_path / "spoofed_csv"
    assert main(["inject", str(exported[1]), "--attack", "ramp:rate=2,start=10", "-o", str(out)]) == 0
    original, spoofed = read_log(exported[1]), read_log(out)
    np.testing.assert_array_equal(spoofed.fixes[INDICATORS], original.fixes[INDICATORS])
    for key in ("enum.spoofing_state", "enum.jamming_state", "receiver", "firmware"):
        assert spoofed.metadata.get(key) == original.metadata.get(key), key


def test_single_gps_table_with_timestamps_in_seconds(tmp_path: Path) -> None:
    f = flight(np.round(np.arange(2.0, 12.0, 0.5), 6))
    path = tmp_path / "gps_seconds.csv"
    _single(path, f, lat_scale=1e-7, alt_scale=1e-3, utc=False)
    df = pd.read_csv(path)
    df["timestamp"] = df["timestamp"] / 1e6
    df.to_csv(path, index=False)
    table = read_log(path)
    note = next(s for s in table.skipped if s.stream == "gps_seconds.csv").reason
    assert "timestamp in seconds (sample spacing under 100): scaled to µs" in note
    assert table.time_reference == "boot" and table.t0_ns == 2_000_000_000
    np.testing.assert_allclose(table.fixes["t_s"], f["t_s"] - 2.0, atol=1e-9)
