"""A day-long voyage written in blocks: memory of one block, whatever the voyage's length.

The ship scenario (100 Hz IMU, 1 Hz GNSS, tactical IMU) is simulated block by block: the first block
is the scenario itself (an hour of slow course changes, then straight on), every later block a straight
leg starting exactly where, when, at the speed and on the course the previous one ended (the scenario's
own trajectory continued: after its first hour the ship goes straight). Each block's messages are
appended to one ROS2 MCAP. Sensor errors are drawn per block (seeded by the block number); each
block's IMU samples are shifted so its gyro and accelerometer biases start where the previous block's
ended (the bias random walk goes on across blocks, no step). The receiver's time-correlated errors do
restart at each block (a step of the order of their 2 m sigma). The truth is not written.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, Writer

from spooflens.epoch_table import EpochTable
from spooflens.simulation.simulate import SCENARIOS, simulate
from spooflens.simulation.trajectories import Profile, Segment
from spooflens.writers.encoders import RosEncoder
from spooflens.writers.messages import in_time_order, out_streams


def _next_profile(first: Profile, lat_rad: float, lon_rad: float, h: float, v_enu: np.ndarray) -> Profile:
    return replace(
        first,
        lat_deg=math.degrees(lat_rad),
        lon_deg=math.degrees(lon_rad),
        height_m=float(h),
        speed_mps=float(np.hypot(v_enu[0], v_enu[1])),
        course_deg=math.degrees(math.atan2(v_enu[1], v_enu[0])),
        segments=(Segment(3600.0),),
    )


def _shifted(
    table: EpochTable, offset_s: float, drop_first: bool, d_gyro: np.ndarray, d_accel: np.ndarray
) -> EpochTable:
    """The block's table on the voyage's clock (a later block's first instant is the previous block's
    last), its IMU biases moved by (d_gyro, d_accel) to continue the previous block's."""
    table.t0_ns += round(offset_s * 1e9)
    imu = table.imu.copy()
    for i, axis in enumerate("xyz"):
        imu[f"w{axis}_radps"] += d_gyro[i]
        imu[f"a{axis}_mps2"] += d_accel[i]
    table.imu = imu
    if drop_first:
        table.imu = table.imu[table.imu["t_s"] > 0].reset_index(drop=True)
        table.fixes = table.fixes[table.fixes["t_s"] > 0].reset_index(drop=True)
    table.truth = table.truth.iloc[:0]
    return table


def write_blocks(path: Path, hours: float, block_h: float = 2.0) -> int:
    """Write `hours` of the voyage to `path` (ROS2 MCAP); returns the number of IMU samples."""
    scenario = SCENARIOS["ship"]
    total_s, block_s = hours * 3600.0, block_h * 3600.0
    ros = RosEncoder(2)
    n_imu = 0
    with path.open("wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="ros2", library="spooflens bench voyage")
        channels: dict[str, int] = {}
        schemas: dict[str, int] = {}
        profile, start_s, block = scenario.profile, 0.0, 0
        end_bias: tuple[np.ndarray, np.ndarray] | None = None  # (gyro, accel) at the previous block's end
        while start_s < total_s - 1e-9:
            length = min(block_s, total_s - start_s)
            sim = simulate(replace(scenario, profile=profile), seed=block, duration_s=length)
            d_gyro, d_accel = (
                (end_bias[0] - sim.imu_gyro_bias[0], end_bias[1] - sim.imu_accel_bias[0])
                if end_bias is not None
                else (np.zeros(3), np.zeros(3))
            )
            end_bias = (sim.imu_gyro_bias[-1] + d_gyro, sim.imu_accel_bias[-1] + d_accel)
            table = _shifted(sim.table, start_s, block > 0, d_gyro, d_accel)
            streams = out_streams(table)
            for s in streams:
                if s.kind not in schemas:
                    schemas[s.kind] = w.register_schema(ros.msgtype(s.kind), "ros2msg", ros.msgdef(s.kind).encode())
                if s.topic not in channels:
                    channels[s.topic] = w.register_channel(s.topic, ros.encoding, schemas[s.kind])
            for s, i, t in in_time_order(streams):
                w.add_message(channels[s.topic], log_time=t, data=ros.encode(s, i, t), publish_time=t)
            n_imu += len(table.imu)
            truth = sim.truth
            profile = _next_profile(scenario.profile, truth.lat[-1], truth.lon[-1], truth.h[-1], truth.v_enu[-1])
            start_s += length
            block += 1
            del sim, table, streams
        w.finish()
    return n_imu
