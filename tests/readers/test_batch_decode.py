"""Whole-chunk (vectorised) decoding of fixed-layout ROS messages gives exactly the per-message table.

The log mixes every fixed-layout type (Imu, NavSatFix, both twists, Odometry) with frame ids of every
length mod 8 (so each CDR alignment case occurs), a type with arrays (gps_msgs/GPSFix: decoded one by
one), a big-endian CDR message and a message cut short (both must fall back to the per-message path,
the cut one counted as undecodable), in small chunks so messages of one topic span many chunks.
"""

from __future__ import annotations

from pathlib import Path
from unittest import mock

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.writer import CompressionType, Writer
from ros_support import GPS_FIX, GPS_STATUS
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

import readers.ros_messages
import readers.streams
from readers import read_log
from readers.ros_messages import RAW_COLUMNS

T0 = 1_700_000_000
N = 400


def _store(ros: int):
    store = get_typestore(Stores.ROS2_HUMBLE if ros == 2 else Stores.ROS1_NOETIC)
    store.register(
        get_types_from_msg(GPS_STATUS, "gps_msgs/msg/GPSStatus") | get_types_from_msg(GPS_FIX, "gps_msgs/msg/GPSFix")
    )
    return store


def _messages(store, ros: int, rng: np.random.Generator):
    """(topic, msgtype, stamp ns, message) in log order."""
    T = store.types
    V, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]

    def header(k: int, stamp: int, frame: str):
        extra = {"seq": k} if ros == 1 else {}
        time = T["builtin_interfaces/msg/Time"](sec=stamp // 10**9, nanosec=stamp % 10**9)
        return T["std_msgs/msg/Header"](**extra, stamp=time, frame_id=frame)

    out = []
    for k in range(N):
        stamp = (T0 + k // 10) * 10**9 + (k % 10) * 10**8
        if k == 7:
            stamp = 0  # a zero stamp: the log time is used (a repair), on both paths
        frame = "f" * (k % 9)  # every string length mod 8
        w, a = 0.1 * rng.normal(size=3), np.array([0.0, 0.0, 9.81]) + rng.normal(size=3)  # at rest, noisy
        ocov = np.zeros(9)
        ocov[0] = -1.0 if k % 5 == 0 else 0.01
        imu = T["sensor_msgs/msg/Imu"](
            header=header(k, stamp, frame),
            orientation=Q(x=0.1, y=0.2, z=0.3, w=float(np.sqrt(1 - 0.14))),
            orientation_covariance=ocov,
            angular_velocity=V(x=w[0], y=w[1], z=w[2]),
            angular_velocity_covariance=np.full(9, 1e-4),
            linear_acceleration=V(x=a[0], y=a[1], z=a[2]),
            linear_acceleration_covariance=np.full(9, 1e-2),
        )
        out.append(("/imu/data", "sensor_msgs/msg/Imu", stamp, imu))
        if k % 4 == 0:
            status = T["sensor_msgs/msg/NavSatStatus"](status=(k // 4) % 4 - 1, service=1)
            fix = T["sensor_msgs/msg/NavSatFix"](
                header=header(k, stamp, "g" * (k % 7)),
                status=status,
                latitude=45.0 + 1e-5 * k,
                longitude=7.0 + rng.normal(0, 1e-6),
                altitude=100.0 + k,
                position_covariance=np.diag([1.0 + k % 3, 2.0, 9.0]).ravel(),
                position_covariance_type=k % 4,
            )
            out.append(("/gps/fix", "sensor_msgs/msg/NavSatFix", stamp, fix))
            twist = T["geometry_msgs/msg/Twist"](linear=V(x=1.0, y=2.0 + k, z=0.1), angular=V(x=0.0, y=0.0, z=0.2))
            cov = np.zeros(36)
            cov[[0, 7, 14]] = 0.01 * (1 + k % 2)
            out.append(
                (
                    "/gps/fix_velocity",
                    "geometry_msgs/msg/TwistWithCovarianceStamped",
                    stamp,
                    T["geometry_msgs/msg/TwistWithCovarianceStamped"](
                        header=header(k, stamp, frame),
                        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov),
                    ),
                )
            )
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=float(k), y=-float(k), z=0.5),
                orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
            )
            odom = T["nav_msgs/msg/Odometry"](
                header=header(k, stamp, frame),
                child_frame_id="base" + "_" * (k % 5),
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
            )
            out.append(("/wheel/odom", "nav_msgs/msg/Odometry", stamp, odom))
        if k % 10 == 3:
            empty = np.array([], dtype=np.int32)
            gstatus = T["gps_msgs/msg/GPSStatus"](
                header(k, stamp, "gps"), 9, empty, 3, empty, empty, empty, np.array([40, 0, 42], np.int32), 0, 0, 0, 0
            )
            vals = dict.fromkeys(
                [
                    "latitude",
                    "longitude",
                    "altitude",
                    "track",
                    "speed",
                    "climb",
                    "pitch",
                    "roll",
                    "dip",
                    "time",
                    "gdop",
                    "pdop",
                    "hdop",
                    "vdop",
                    "tdop",
                    "err",
                    "err_horz",
                    "err_vert",
                    "err_track",
                    "err_speed",
                    "err_climb",
                    "err_time",
                    "err_pitch",
                    "err_roll",
                    "err_dip",
                ],
                1.0,
            )
            vals |= {"latitude": 45.001 + 1e-6 * k, "longitude": 7.0, "altitude": 90.0}
            gps = T["gps_msgs/msg/GPSFix"](
                header=header(k, stamp, "gps"),
                status=gstatus,
                **vals,
                position_covariance=np.zeros(9),
                position_covariance_type=0,
            )
            out.append(("/gps2/fix", "gps_msgs/msg/GPSFix", stamp, gps))
    return out


def _write(path: Path, ros: int) -> dict[str, np.ndarray]:
    store = _store(ros)
    serialize = store.serialize_cdr if ros == 2 else store.serialize_ros1
    msgs = _messages(store, ros, np.random.default_rng(7))
    with path.open("wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD, chunk_size=2048)
        w.start(profile=f"ros{ros}", library="test")
        channels: dict[str, int] = {}
        imu_ax = []
        for topic, msgtype, stamp, msg in msgs:
            if topic not in channels:
                text, _ = store.generate_msgdef(msgtype, ros_version=ros)
                sid = w.register_schema(msgtype, f"ros{ros}msg", text.encode())
                channels[topic] = w.register_channel(topic, "cdr" if ros == 2 else "ros1", sid)
            data = bytes(serialize(msg, msgtype))
            log_time = stamp or T0 * 10**9 + 75 * 10**7  # between its neighbours
            if topic == "/imu/data":
                imu_ax.append(msg.linear_acceleration.x)
                k = len(imu_ax) - 1
                if ros == 2 and k == 123:  # the same message, big-endian CDR: not for the fast path
                    data = bytes(store.serialize_cdr(msg, msgtype, little_endian=False))
                if k == 250:
                    data = data[:-20]  # cut short: undecodable on both paths
            w.add_message(channels[topic], log_time=log_time, data=data, publish_time=log_time)
        w.finish()
    return {"ax": np.asarray(imu_ax)}


@pytest.mark.parametrize("ros", [2, 1])
def test_vectorised_decoding_gives_the_per_message_table(ros: int, tmp_path: Path) -> None:
    path = tmp_path / f"mixed_ros{ros}.mcap"
    written = _write(path, ros)
    with mock.patch.object(readers.ros_messages, "decode_batch", wraps=readers.ros_messages.decode_batch) as spy:
        fast = read_log(path)
    batched = {len(c.args[4]) for c in spy.call_args_list}  # messages per call
    assert max(batched) >= N // 2  # the whole-chunk path ran, many messages a call
    with mock.patch.object(readers.streams, "batch_decoder", lambda kind, encoding: None):
        slow = read_log(path)
    for name in ("imu", "fixes", "odometry", "truth"):
        pd.testing.assert_frame_equal(getattr(fast, name), getattr(slow, name))
    assert fast.skipped == slow.skipped and fast.streams == slow.streams
    # and both are right: every IMU message but the cut one, its values as written
    ax = np.delete(written["ax"], 250)
    assert len(fast.imu) == N - 1
    np.testing.assert_array_equal(fast.imu["ax_mps2"].to_numpy(), ax)
    assert any(s.stream == "/imu/data" and "could not be decoded" in s.reason and s.count == 1 for s in fast.skipped)
    assert any(s.stream == "/imu/data" and s.action == "repaired" for s in fast.skipped)  # the zero stamp
    assert set(fast.fixes["receiver_id"]) == {"/gps/fix", "/gps2/fix"}
    assert fast.fixes["vel_n_mps"].notna().sum() > 0 and len(fast.odometry) == N // 4
    no_orientation = np.delete(np.arange(N) % 5 == 0, 250)  # orientation covariance -1: no orientation
    np.testing.assert_array_equal(np.isnan(fast.imu["qw"].to_numpy()), no_orientation)


@settings(max_examples=60, deadline=None)
@given(
    frames=st.lists(st.text(alphabet="abc_/", max_size=11), min_size=1, max_size=12),
    cuts=st.lists(st.integers(0, 400), max_size=4),
    encoding=st.sampled_from(["cdr", "ros1"]),
    noise=st.binary(min_size=0, max_size=64),
)
def test_batch_decoding_of_any_bytes_never_raises_and_reads_whole_messages(frames, cuts, encoding, noise) -> None:
    """Whole Imu messages (every frame id length) decode to their values; messages cut anywhere, and
    garbage, are only marked not ok (their container then decodes them one by one and counts them)."""
    from readers.ros_messages import batch_decoder, encode_imu

    msgs = [
        encode_imu(10**9 * (k + 1), f, (0.0, 0.0, 0.0, 1.0), (0.1 * k, 0.2, 0.3), (1.0, 2.0, 9.8 + k), encoding)
        for k, f in enumerate(frames)
    ]
    cut = set(cuts)
    parts = [
        m[: min(len(m) - 1, c)] if (c := next((c for c in cut if c % len(frames) == k), None)) is not None else m
        for k, m in enumerate(msgs)
    ] + [noise]
    lengths = np.array([len(p) for p in parts], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
    buf = np.frombuffer(b"".join(parts), dtype=np.uint8)
    decode = batch_decoder("imu", encoding)
    assert decode is not None
    stamps, values, ok = decode(buf, starts, lengths)
    for k, m in enumerate(msgs):
        if parts[k] == m:
            assert ok[k] and stamps[k] == 10**9 * (k + 1)
            wx, az = RAW_COLUMNS["imu"].index("wx"), RAW_COLUMNS["imu"].index("az")
            assert values[k, wx] == pytest.approx(0.1 * k) and values[k, az] == pytest.approx(9.8 + k)
        else:
            assert not ok[k]
