"""The readers' row storage: whatever mix of single rows and batches, and whatever the message count the
file's index claims, the rows come back once each, in order, column by column."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import readers.buffers
from readers.buffers import RowBuffer


def _rows(n: int, start: int = 0) -> tuple[np.ndarray, np.ndarray]:
    stamps = np.arange(start, start + n, dtype=np.int64) * 10
    values = np.column_stack([np.arange(start, start + n) + 0.5 * c for c in range(3)]).astype(float)
    return stamps, values


@pytest.mark.parametrize("capacity", [0, 1, 7, 50, 51, 500])
def test_rows_come_back_in_order_whatever_the_capacity_and_the_mix_of_appends_and_batches(
    capacity: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(readers.buffers, "_BLOCK_ROWS", 8)  # many blocks from few rows
    buf = RowBuffer(("a", "b", "c"), capacity)
    expected_t, expected_v = _rows(50)
    pos = 0
    for size in (1, 5, 1, 13, 2, 20, 1, 7):  # single rows (append) and batches (extend), 50 rows in all
        t, v = expected_t[pos : pos + size], expected_v[pos : pos + size]
        if size == 1:
            buf.append(int(t[0]), tuple(v[0]))
        else:
            buf.extend(t, v)
        pos += size
    assert buf.count == 50
    stamps, values = buf.arrays()
    np.testing.assert_array_equal(stamps, expected_t)
    assert list(values) == ["a", "b", "c"]
    for k, column in enumerate(values.values()):
        np.testing.assert_array_equal(column, expected_v[:, k])
        assert column.flags.c_contiguous
    columns = list(values.values())  # each in memory of its own: the schema's columns can be them
    assert not any(np.shares_memory(a, b) for i, a in enumerate(columns) for b in columns[i + 1 :])
    assert buf.count == 0


def test_an_exact_capacity_hands_over_the_one_array_it_filled() -> None:
    buf = RowBuffer(("a", "b", "c"), 40)
    t, v = _rows(40)
    buf.extend(t[:25], v[:25])
    buf.extend(t[25:], v[25:])
    stamps, values = buf.arrays()
    np.testing.assert_array_equal(stamps, t)
    np.testing.assert_array_equal(np.column_stack(list(values.values())), v)
    for column in values.values():  # no join, no copy: the very array it filled
        assert (column if column.base is None else column.base).shape == (40,)


def test_a_column_nothing_keeps_is_freed_while_the_others_live_on() -> None:
    import weakref

    buf = RowBuffer(("kept", "dropped"), 100)
    buf.extend(*_rows(100)[:1], np.ones((100, 2)))
    _, values = buf.arrays()
    kept, gone = values["kept"], weakref.ref(values["dropped"])
    del values
    assert gone() is None and kept.sum() == 100.0


def test_an_empty_buffer_gives_empty_arrays() -> None:
    stamps, values = RowBuffer(("a", "b"), 10).arrays()
    assert stamps.shape == (0,) and [c.shape for c in values.values()] == [(0,), (0,)]


def test_a_damaged_message_count_cannot_ask_for_more_rows_than_the_file_has_bytes(tmp_path: Path) -> None:
    from readers.streams import StreamCollector, ros_topic

    path = tmp_path / "log.mcap"
    path.write_bytes(b"\0" * 1600)
    collector = StreamCollector(path, "mcap")
    collector.add_topics({"/imu": ros_topic("sensor_msgs/msg/Imu", "cdr", lambda raw, t: None)}, [("/imu", 10**15)])
    buffer = collector.streams["/imu"].buffer
    assert buffer is not None
    buffer.append(1, tuple(float(i) for i in range(len(buffer.columns))))
    stamps, values = buffer.arrays()
    assert len(stamps) == 1 and all(len(c) == 1 for c in values.values())
    assert buffer._open_stamps is None and not buffer._values  # handed over and forgotten
    first = next(iter(values.values()))
    assert first.base is not None and first.base.shape[0] <= 1600 // 16  # the block asked for
