"""Message types the sample logs do not carry: gps_msgs/GPSFix fixes and TwistStamped GNSS velocity."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from ros_support import GPS_FIX, GPS_STATUS
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from readers import read_log
from spooflens.schema import FixType

# the gps_umd interface definitions (gps_msgs/msg), fields only
T0 = 1_700_000_000
STATUS_CODES = [0, 18, 19, 20, 33, -1]


def _bag(path: Path, with_twist: bool) -> None:
    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(
        get_types_from_msg(GPS_STATUS, "gps_msgs/msg/GPSStatus") | get_types_from_msg(GPS_FIX, "gps_msgs/msg/GPSFix")
    )
    Header, Time = ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    Status, Fix = ts.types["gps_msgs/msg/GPSStatus"], ts.types["gps_msgs/msg/GPSFix"]
    Twist, TwistStamped = ts.types["geometry_msgs/msg/Twist"], ts.types["geometry_msgs/msg/TwistStamped"]
    Vector3 = ts.types["geometry_msgs/msg/Vector3"]
    empty = np.array([], dtype=np.int32)
    with Writer(path) as w:
        fix_conn = w.add_connection("/gps/fix", "gps_msgs/msg/GPSFix", typestore=ts)
        vel_conn = w.add_connection("/gps/vel", "geometry_msgs/msg/TwistStamped", typestore=ts)
        for k, code in enumerate(STATUS_CODES):
            header = Header(seq=k, stamp=Time(sec=T0 + k, nanosec=0), frame_id="gps")
            # 11 visible, 2 of them not tracked (snr 0): the mean C/N0 is over the 9 tracked
            snr = np.array([0, 0, *range(38, 47)], dtype=np.int32)
            status = Status(header, 9, empty, 11, empty, empty, empty, snr, code, 0, 0, 0)
            values = dict.fromkeys(
                (
                    "pitch",
                    "roll",
                    "dip",
                    "time",
                    "gdop",
                    "pdop",
                    "tdop",
                    "err",
                    "err_track",
                    "err_climb",
                    "err_time",
                    "err_pitch",
                    "err_roll",
                    "err_dip",
                ),
                0.0,
            )
            fix = Fix(
                header=header,
                status=status,
                latitude=42.0 + k * 1e-5,
                longitude=-71.0,
                altitude=30.0,
                track=90.0,
                speed=5.0,
                climb=float("nan") if k == 2 else 0.5,  # a receiver without vertical velocity
                err_horz=4.9,
                err_vert=7.84,
                err_speed=0.98,
                hdop=1.1 + 0.1 * k,
                vdop=0.0 if k == 1 else 1.7,  # gpsd writes 0 for a DOP it does not know
                position_covariance=np.zeros(9),
                position_covariance_type=0,
                **values,
            )
            w.write(fix_conn, (T0 + k) * 10**9, ts.serialize_ros1(fix, "gps_msgs/msg/GPSFix"))
            if not with_twist:
                continue
            twist = TwistStamped(header, Twist(Vector3(x=5.0, y=0.1, z=0.5), Vector3(x=0.0, y=0.0, z=0.0)))
            w.write(vel_conn, (T0 + k) * 10**9, ts.serialize_ros1(twist, "geometry_msgs/msg/TwistStamped"))


@pytest.fixture(scope="module")
def table(tmp_path_factory: pytest.TempPathFactory):
    path = tmp_path_factory.mktemp("types") / "gpsfix.bag"
    _bag(path, with_twist=False)
    return read_log(path)


@pytest.fixture(scope="module")
def with_twist(tmp_path_factory: pytest.TempPathFactory):
    path = tmp_path_factory.mktemp("types") / "gpsfix_twist.bag"
    _bag(path, with_twist=True)
    return read_log(path)


def test_gpsfix_positions_velocity_and_accuracies(table) -> None:
    fx = table.fixes
    assert len(fx) == len(STATUS_CODES) - 1  # the NO_FIX message is skipped, and said so
    assert any("NO_FIX" in sk.reason and sk.count == 1 for sk in table.skipped)
    np.testing.assert_allclose(fx["lat_deg"].iloc[:3], [42.0, 42.00001, 42.00002])
    # track 90 deg from north at 5 m/s is due east; climb is up
    np.testing.assert_allclose(fx[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].iloc[0], [5.0, 0.0, 0.5], atol=1e-12)
    # gps_msgs errors are 95 % bounds: 4.9 m horizontal is 2.0 m (1 sigma, 2-D), 7.84 m vertical 4.0 m
    assert fx["h_acc_m"].iloc[0] == pytest.approx(2.0, rel=1e-3)
    assert fx["v_acc_m"].iloc[0] == pytest.approx(4.0, rel=1e-3)
    assert (fx["sats_used"] == 9).all()


def test_gpsfix_east_north_velocity_without_climb_is_kept(table) -> None:
    row = table.fixes.iloc[2]
    assert np.isnan(row["vel_u_mps"])
    assert row["vel_e_mps"] == pytest.approx(5.0) and row["vel_n_mps"] == pytest.approx(0.0, abs=1e-12)


def test_gpsfix_dops_and_mean_cn0_are_receiver_evidence(table) -> None:
    fx = table.fixes
    np.testing.assert_allclose(fx["hdop"], 1.1 + 0.1 * np.arange(len(fx)))
    assert np.isnan(fx["vdop"].iloc[1]) and (fx["vdop"].drop(index=1) == 1.7).all()
    np.testing.assert_allclose(fx["cn0_mean_dbhz"], np.mean(np.arange(38, 47)))


def test_gpsfix_status_codes_map_to_fix_types(table) -> None:
    expected = {
        0: FixType.FIX_3D,
        18: FixType.DGNSS,
        19: FixType.RTK_FIXED,
        20: FixType.RTK_FLOAT,
        33: FixType.SBAS,
        -1: FixType.NO_FIX,
    }
    got = dict(zip(table.fixes["t_s"].round().astype(int), table.fixes["fix_type"], strict=True))
    for k, code in enumerate(STATUS_CODES):
        if k in got:
            assert got[k] == expected[code], code


def test_twist_stamped_is_gnss_velocity_of_that_receiver(with_twist) -> None:
    roles = {s.topic: s.role for s in with_twist.streams}
    assert roles["/gps/vel"] == "vel" and roles["/gps/fix"] == "fix"
    # a velocity topic of the receiver is its velocity (ENU, as GNSS drivers publish it)
    vel = with_twist.fixes[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy()
    np.testing.assert_allclose(vel, np.tile([5.0, 0.1, 0.5], (len(vel), 1)))
