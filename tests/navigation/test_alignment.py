"""The log's orientation nearest a time, looked for near it first: the same sample as a search of the
whole stream, whether the orientations are dense, sparse or absent."""

from __future__ import annotations

import numpy as np
import pandas as pd

from spooflens.navigation.alignment import _imu_orientation
from spooflens.navigation.rotations import quat_to_matrix


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
