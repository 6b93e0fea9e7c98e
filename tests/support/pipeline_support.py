"""Small synthetic epoch tables for pipeline tests (no reader involved)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from spooflens.epoch_table import EpochTable, StreamInfo, build_table
from spooflens.geodesy import enu_to_geodetic

T0_NS = 1_700_000_000_000_000_000


def circling_table(ramp_mps: float = 0.0, ramp_start_s: float = 150.0, seconds: float = 300.0) -> EpochTable:
    """A vehicle circling at 10 m/s: 1 Hz fixes with velocity, 50 Hz IMU; optional position-only ramp."""
    rng = np.random.default_rng(7)
    t = np.arange(0.0, seconds, 1.0)
    p = np.c_[600 * np.sin(t / 60), 600 * (1 - np.cos(t / 60)), np.zeros_like(t)]
    v = np.c_[10 * np.cos(t / 60), 10 * np.sin(t / 60), np.zeros_like(t)] + rng.normal(0, 0.05, (len(t), 3))
    ramp = np.clip(t - ramp_start_s, 0, None)[:, None] * ramp_mps * np.array([0.7071, 0.7071, 0.0])
    lat, lon, h = enu_to_geodetic(p + rng.normal(0, 0.5, p.shape) + ramp, 45.0, 7.0, 300.0)
    n = len(t)
    fixes = pd.DataFrame(
        {
            "t_ns": T0_NS + (t * 1e9).astype(np.int64),
            "receiver_id": ["/gps/fix"] * n,
            "lat_deg": lat,
            "lon_deg": lon,
            "height_m": h,
            "vel_e_mps": v[:, 0],
            "vel_n_mps": v[:, 1],
            "vel_u_mps": v[:, 2],
            "h_acc_m": np.full(n, 2.5),
            "sats_used": np.full(n, 9.0),
            "fix_type": np.full(n, 2, dtype=np.int8),
        }
    )
    ti = np.arange(0.0, seconds, 0.02)
    m = len(ti)
    imu = pd.DataFrame(
        {
            "t_ns": T0_NS + (ti * 1e9).astype(np.int64),
            "imu_id": ["/imu"] * m,
            "ax_mps2": rng.normal(0, 0.05, m),
            "ay_mps2": np.full(m, 10 * 10 / 600),
            "az_mps2": np.full(m, 9.81),
            "wx_radps": np.zeros(m),
            "wy_radps": np.zeros(m),
            "wz_radps": np.full(m, 1 / 60),
        }
    )
    streams = [
        StreamInfo("fix", "/gps/fix", "/gps/fix", "sensor_msgs/msg/NavSatFix", n),
        StreamInfo("imu", "/imu", "/imu", "sensor_msgs/msg/Imu", m, body_frame="FLU"),
    ]
    return build_table(Path("circling.mcap"), "synthetic", "unix", {"fixes": fixes, "imu": imu}, streams, [])
