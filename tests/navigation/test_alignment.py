"""The log's orientation nearest a time, looked for near it first: the same sample as a search of the
whole stream, whether the orientations are dense, sparse or absent."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from paths import real_log

from spooflens.navigation.alignment import _imu_orientation, align
from spooflens.navigation.loosely_coupled import prepare
from spooflens.navigation.rotations import quat_to_matrix
from spooflens.service import read_table


def test_the_nearest_orientation_is_the_whole_streams_nearest() -> None:
    rng = np.random.default_rng(1)
    for _ in range(200):
        n = int(rng.integers(1, 5000))
        ts = np.sort(rng.uniform(0.0, 100.0, n))
        q = rng.normal(size=(n, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        q[rng.random(n) < rng.choice([0.0, 0.5, 0.99, 0.9999, 1.0])] = np.nan
        imu = pd.DataFrame({"t_s": ts, "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3]})
        t = float(rng.uniform(-10.0, 110.0))
        ok = np.isfinite(q).all(axis=1)
        got = _imu_orientation(imu, t, near=int(rng.integers(1, 50)))
        if not ok.any():
            assert got is None
            continue
        assert got is not None
        np.testing.assert_array_equal(got, quat_to_matrix(q[ok][int(np.argmin(np.abs(ts[ok] - t)))]))


def test_body_axes_to_flu_from_rows_or_columns_equal_the_convention_matrix() -> None:
    from spooflens.navigation.alignment import TO_FLU, flu_axes

    rows = np.random.default_rng(3).normal(size=(50, 3))
    for frame, M in TO_FLU.items():
        expected = rows @ M.T
        np.testing.assert_array_equal(np.stack(flu_axes(rows, frame), axis=1), expected)
        np.testing.assert_array_equal(np.stack(flu_axes([rows[:, 0], rows[:, 1], rows[:, 2]], frame), axis=1), expected)


def test_an_imu_logged_at_half_the_rate_still_aligns_on_log171() -> None:
    """log171's IMU at every other sample (25 Hz, the rate many 2014-era ArduPilot logs carry) beside its
    5 Hz fixes, which jitter by 20 ms: two fixes then fell on one IMU sample, the velocity between them was
    infinite and the alignment refused with "values ... not finite"; the INS never ran. The velocity of the
    earth-rate terms is the fixes' own, over their own times."""
    table = read_table(real_log("corpus/dronekit-la-testdata/log171.bin"), {}, False)
    imu = table.imu_of("IMU[0]")
    every_other = imu[np.isin(imu["t_s"], np.unique(imu["t_s"])[::2])].reset_index(drop=True)
    half = replace(table, imu=every_other).between(63.16, 243.0)  # after the IMU's gap at 61.1 s
    inputs = prepare(half, "IMU[0]", "GPS[0]")
    assert float(np.median(np.diff(inputs.pre.t))) == pytest.approx(0.04, abs=2e-3)
    alignment = align(inputs.pre, inputs.imu, inputs.fixes, 0.0)
    assert alignment.method.startswith("velocity matching over")
    assert np.isfinite(alignment.C0).all() and np.isfinite(alignment.v0).all()
    # a vibrating IMU sampled at half its rate aliases: the window is wider and the yaw less certain than
    # from every sample, and the alignment says so
    assert alignment.residual_m > 1.0 and "yaw sigma" in alignment.method
