"""The readers' row storage: whatever mix of single rows and batches, and whatever the message count the
file's index claims, the rows come back once each, in order, column by column."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
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


@pytest.mark.parametrize("batch", [1, 7, 5000])
def test_messages_handed_over_a_topic_at_a_time_decode_as_one_at_a_time(husky_bag: Path, batch: int) -> None:
    """`add_many` (a container yielding messages one by one, gathered per topic) against `add`: the same
    table and the same counts, the first messages decoded in full for their frame_id either way, a
    damaged message counted alike."""
    from rosbags.highlevel import AnyReader

    from readers.streams import StreamCollector, ros_topic

    with AnyReader([husky_bag]) as reader:  # open while the collectors decode: its types deserialise
        messages = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
        decls = {
            c.topic: ros_topic(c.msgtype, "ros1", lambda raw, msgtype: reader.deserialize(bytes(raw), msgtype))
            for c in reader.connections
        }
        k = next(i for i, m in enumerate(messages) if m[0] == "/imu/data" and i > 100)
        messages[k] = (messages[k][0], messages[k][1], messages[k][2][:20])  # cut: cannot be decoded
        one, many = StreamCollector(husky_bag, "ros1bag"), StreamCollector(husky_bag, "ros1bag")
        one.add_topics(decls)
        many.add_topics(decls)
        pending: dict[str, tuple[list[int], list[bytes]]] = {}
        for topic, t, raw in messages:
            one.add(topic, t, raw)
            times, raws = pending.setdefault(topic, ([], []))
            times.append(t)
            raws.append(raw)
            if len(raws) >= batch:
                many.add_many(topic, *pending.pop(topic))
        for topic, (times, raws) in pending.items():
            many.add_many(topic, times, raws)
        a, b = one.finish(), many.finish()
    for name in ("imu", "fixes", "odometry"):
        pd.testing.assert_frame_equal(getattr(a, name), getattr(b, name))
    assert a.streams == b.streams and a.skipped == b.skipped
    assert any("could not be decoded" in s.reason and s.count == 1 for s in b.skipped)
