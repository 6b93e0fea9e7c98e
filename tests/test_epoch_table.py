"""The epoch table's time base, repairs and schema check."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from spooflens.epoch_table import Skipped, StreamInfo, build_table
from spooflens.errors import SchemaError
from spooflens.schema import FRAMES, empty_frame, make_frame, schema_markdown


def _fixes(t_ns: list[int], lat: list[float]) -> pd.DataFrame:
    n = len(t_ns)
    return pd.DataFrame(
        {
            "t_ns": np.array(t_ns, dtype=np.int64),
            "receiver_id": ["/fix"] * n,
            "lat_deg": lat,
            "lon_deg": [-71.0] * n,
            "height_m": [10.0] * n,
            "fix_type": np.full(n, 2, dtype=np.int8),
        }
    )


def test_time_base_starts_at_the_earliest_stamp_and_maps_back() -> None:
    t0 = 1_432_235_497_000_000_000
    table = build_table(
        Path("x.bag"),
        "test",
        "unix",
        {"fixes": _fixes([t0 + 10**9, t0 + 2 * 10**9], [42.0, 42.1])},
        [StreamInfo("fix", "/fix", "/fix", "sensor_msgs/NavSatFix", 2)],
        [],
        t0_ns=t0,
    )
    assert table.fixes["t_s"].tolist() == [1.0, 2.0]
    assert int(table.absolute_ns(2.0)) == t0 + 2 * 10**9
    assert table.absolute_iso(0.0).startswith("2015-05-21T19:11:37")
    assert table.streams[0].count == 2 and table.streams[0].rate_hz == pytest.approx(1.0)


def test_backwards_time_duplicates_and_empty_fixes_are_repaired_and_reported() -> None:
    df = _fixes([3, 1, 2, 2, 5, 5, 6], [42.0, 42.1, float("nan"), 42.2, 42.3, 42.4, 0.0])
    df.loc[6, "lon_deg"] = 0.0
    table = build_table(Path("x.csv"), "test", "relative", {"fixes": df}, [], [])
    assert table.fixes["t_s"].tolist() == [0.0, 1e-9, 2e-9, 4e-9]
    assert table.fixes["lat_deg"].tolist() == [42.1, 42.2, 42.0, 42.3]
    reasons = " | ".join(str(s) for s in table.skipped)
    assert "backwards" in reasons and "duplicate" in reasons and "NaN or zero" in reasons


def test_a_recording_lists_the_skipped_lines_of_its_own_span_only() -> None:
    """A log joining two recordings (its clock goes back a minute): a reader's line with a span goes to
    the recording it covers (the nearest where it covers none); a line without one to both."""
    t0 = 1_553_076_516_000_000_000  # 2019-03-20T10:08:36Z
    first = [t0 + k * 10**9 for k in range(30)]
    second = [t0 - 60 * 10**9 + k * 10**9 for k in range(30)]
    own = Skipped("/fix", "the first's", 1, "repaired", span_ns=(first[2], first[3]))
    near = Skipped("/fix", "near the second", 1, span_ns=(second[-1] + 10**9, second[-1] + 2 * 10**9))
    table = build_table(
        Path("x.nmea"),
        "test",
        "unix",
        {"fixes": _fixes(first + second, [42.0] * 60)},
        [StreamInfo("fix", "/fix", "/fix", "NMEA", 60)],
        [own, near, Skipped("/fix", "everywhere", 2)],
    )
    assert len(table.segments) == 2
    assert [s.reason for s in table.segment(0).skipped] == ["the first's", "everywhere"]
    assert [s.reason for s in table.segment(1).skipped] == ["near the second", "everywhere"]
    assert own.as_dict() == {"stream": "/fix", "reason": "the first's", "count": 1, "action": "repaired"}


def test_schema_check_names_every_problem() -> None:
    table = build_table(Path("x"), "test", "relative", {}, [], [])
    table.fixes = make_frame(
        "fixes",
        {"t_s": [0.0], "receiver_id": ["a"], "lat_deg": [1.2], "lon_deg": [300.0], "height_m": [0.0], "fix_type": [2]},
    )
    table.imu = empty_frame("imu").drop(columns=["ax_mps2"])
    with pytest.raises(SchemaError, match=r"imu: missing columns \['ax_mps2'\].*out of range"):
        table.validate()


def test_make_frame_rejects_unknown_columns_and_fills_optional_ones() -> None:
    with pytest.raises(KeyError, match="unknown columns"):
        make_frame("imu", {"t_s": [0.0], "acc_x": [1.0]})
    df = make_frame(
        "fixes",
        {"t_s": [0.0], "receiver_id": ["a"], "lat_deg": [1.0], "lon_deg": [2.0], "height_m": [3.0], "fix_type": [2]},
    )
    assert list(df.columns) == [c.name for c in FRAMES["fixes"]]
    assert np.isnan(df["vel_e_mps"].iloc[0]) and int(df["spoofing_flag"].iloc[0]) == 2


def test_schema_markdown_lists_every_column() -> None:
    md = schema_markdown()
    assert all(f"`{c.name}`" in md for spec in FRAMES.values() for c in spec)


def test_stream_rows_are_the_groups_of_the_stream_key_in_order_of_first_appearance() -> None:
    from spooflens.schema import stream_rows, string_array

    ids = ["/b", "/a", "/b", None, "/c", "/a", "/b"]
    df = pd.DataFrame({"imu_id": pd.Series(string_array(np.array(ids, dtype=object))), "x": np.arange(7.0)})
    got = stream_rows(df, "imu_id")
    expected = df.groupby("imu_id", sort=False).indices
    assert [sid for sid, _ in got] == list(expected) == ["/b", "/a", "/c"]
    for sid, rows in got:
        np.testing.assert_array_equal(rows, expected[sid])
    one = pd.DataFrame({"imu_id": pd.Series(string_array(np.array(["/imu"] * 5, dtype=object)))})
    ((sid, rows),) = stream_rows(one, "imu_id")
    assert sid == "/imu"
    np.testing.assert_array_equal(rows, np.arange(5))


def test_a_constant_stream_id_column_reads_as_its_rows_and_holds_one_shared_block() -> None:
    from spooflens.schema import _SHARED_ROWS, constant_strings, schema_problems, stream_rows

    n = 3 * _SHARED_ROWS + 17
    ids = pd.Series(constant_strings("/imu/data", n))
    assert isinstance(ids.dtype, pd.StringDtype) and len(ids) == n and not ids.hasnans
    assert (ids == "/imu/data").all() and ids.iloc[-1] == "/imu/data" and ids.iloc[_SHARED_ROWS] == "/imu/data"
    chunks = ids.array._pa_array.chunks
    assert len(chunks) == 4 and all(c.buffers()[2].address == chunks[0].buffers()[2].address for c in chunks)
    for empty_or_short in (0, 1, 5):
        assert list(constant_strings("/gps", empty_or_short)) == ["/gps"] * empty_or_short
    other = pd.DataFrame({"t_s": np.arange(4.0), "imu_id": constant_strings("/imu2", 4)})
    both = pd.concat([pd.DataFrame({"t_s": np.arange(float(n)), "imu_id": ids}), other], ignore_index=True)
    got = dict(stream_rows(both, "imu_id"))
    np.testing.assert_array_equal(got["/imu2"], np.arange(n, n + 4))
    assert len(got["/imu/data"]) == n
    assert not [p for p in schema_problems("imu", both) if "imu_id" in p]
