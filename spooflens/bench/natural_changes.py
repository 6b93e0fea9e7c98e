"""Natural changes to a real clean log, never an attack: what other vehicles' logs differ by (an IMU logged at
half the rate, fixes stamped late, a receiver at 1 Hz, an uncalibrated IMU). `bench windows --natural NAME`
cuts the changed log into stretches: a false SPOOFING there is a false accusation on a log the project was
not tuned on (log171's IMU at 25 Hz found an alignment that refused to run)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pandas as pd

from spooflens.epoch_table import EpochTable


def _kept_times(frame: pd.DataFrame, key: str, pick: Callable[[np.ndarray], np.ndarray]) -> pd.DataFrame:
    """The rows of the distinct times `pick` keeps of each stream's (all rows of a kept time), as a slower
    logger keeps them."""
    keep = np.zeros(len(frame), dtype=bool)
    for _, rows in frame.groupby(key, sort=False):
        t = rows["t_s"].to_numpy(dtype=float)
        keep[rows.index[np.isin(t, pick(np.unique(t)))]] = True
    return frame[keep].reset_index(drop=True)


def _first_of_each_second(t: np.ndarray) -> np.ndarray:
    return t[np.r_[True, np.diff(np.floor(t)) > 0]]


def imu_half_rate(table: EpochTable) -> EpochTable | None:
    """Every other IMU sample (a 50 Hz log's IMU at 25 Hz, as 2014-era ArduPilot logs carry it)."""
    if not len(table.imu):
        return None
    return replace(table, imu=_kept_times(table.imu, "imu_id", lambda t: t[::2]))


def fixes_one_hz(table: EpochTable) -> EpochTable | None:
    """The first fix epoch of each second per receiver (a receiver set to 1 Hz); logs at 1 Hz or slower: none."""
    if not len(table.fixes):
        return None
    t = np.unique(table.fixes["t_s"].to_numpy(dtype=float))
    if len(t) < 2 or float(np.median(np.diff(t))) > 0.75:
        return None
    return replace(table, fixes=_kept_times(table.fixes, "receiver_id", _first_of_each_second))


def fixes_late(table: EpochTable, lag_s: float = 0.2) -> EpochTable | None:
    """Fixes stamped `lag_s` late (a receiver's output latency the logger does not take off)."""
    if not len(table.fixes) or not len(table.imu):
        return None
    return replace(table, fixes=table.fixes.assign(t_s=table.fixes["t_s"] + lag_s))


def gyro_biased(table: EpochTable) -> EpochTable | None:
    """Gyros off by 0.57 deg/s in yaw and half that in roll (an uncalibrated consumer IMU, a warm one)."""
    if not len(table.imu):
        return None
    return replace(
        table, imu=table.imu.assign(wz_radps=table.imu["wz_radps"] + 0.01, wx_radps=table.imu["wx_radps"] + 0.005)
    )


def accelerometer_scaled(table: EpochTable) -> EpochTable | None:
    """Accelerometers reading 3 % high and 0.3 m/s^2 off forward (an uncalibrated consumer IMU)."""
    if not len(table.imu):
        return None
    imu = table.imu.assign(**{c: table.imu[c] * 1.03 for c in ("ax_mps2", "ay_mps2", "az_mps2")})
    return replace(table, imu=imu.assign(ax_mps2=imu["ax_mps2"] + 0.3))


CHANGES: dict[str, Callable[[EpochTable], EpochTable | None]] = {
    "imu-half-rate": imu_half_rate,
    "fixes-1hz": fixes_one_hz,
    "fixes-late": fixes_late,
    "gyro-bias": gyro_biased,
    "accelerometer-scale": accelerometer_scaled,
}


def changed(table: EpochTable, name: str) -> EpochTable | None:
    """`table` with the natural change `name`, its streams counted again; None when it does not apply (an IMU
    change to a log without an IMU)."""
    out = CHANGES[name](table)
    return None if out is None else out.between(-np.inf, np.inf)


__all__ = ["CHANGES", "changed"]
