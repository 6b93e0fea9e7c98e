"""Decode many fixed-layout ROS messages at once: numpy over the raw bytes, no Python per message.

A *layout* lists a message's fields after its `std_msgs/Header` (`readers.ros_messages` declares one per
type that has one: Imu, NavSatFix, the twists, Odometry). Strings may vary in length from message to
message, so every field's byte offset is an array over the messages, advanced field by field with the
serialisation's alignment rule: CDR aligns each primitive to its own size, counted from the payload
start after the 4-byte encapsulation header; ROS1 packs. The values asked for (`picks`) are gathered
in one fancy-indexing step each. A message whose bytes do not fit its layout (wrong encapsulation, a
length that runs past the payload) is marked not ok, and its container decodes it the slow way, so
damage is counted exactly as before.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

IntArray = NDArray[np.int64]
FloatArray = NDArray[np.float64]
ByteArray = NDArray[np.uint8]


@dataclass(frozen=True)
class Field:
    """One field after the header: `dtype` a numpy type code ('f8', 'i1', 'u1', 'u2', ...) or 'string'."""

    name: str
    dtype: str
    count: int = 1


Pick = tuple[str, int] | None  # (field, index) of a raw value; None: the type has no such value (NaN)


def gather(buf: ByteArray, offsets: IntArray, dtype: str) -> NDArray[np.generic]:
    """The little-endian `dtype` value at each byte offset of `buf` (offsets + itemsize must lie inside `buf`)."""
    dt = np.dtype(dtype).newbyteorder("<")
    size = dt.itemsize
    if size == 1:
        return buf[offsets].view(dt)
    # a typed view of the buffer per byte alignment, indexed by whole items: one index per value, not per byte
    residue = offsets % size
    rows: IntArray | None = residue if residue.ndim == 1 else residue[:, 0]
    if residue.ndim > 1 and rows is not None and np.any(residue != rows[:, None]):
        rows = None  # values of one message differently aligned: sort value by value
    out = np.empty(offsets.shape, dtype=dt)
    for r in np.flatnonzero(np.bincount(residue.ravel(), minlength=size)):
        view = np.frombuffer(buf, dtype=dt, count=(len(buf) - int(r)) // size, offset=int(r))
        sel = np.flatnonzero(rows == r) if rows is not None else residue == r  # whole messages when we can
        out[sel] = view[(offsets[sel] - r) // size]
    return out


def _gather_rows(buf: ByteArray, first: IntArray, items: IntArray, dtype: str) -> FloatArray:
    """Values at first[i] + items[j] * itemsize for every message i and pick j, as float64 (k, m): a
    pick's values side by side, as the row buffers keep them."""
    dt = np.dtype(dtype).newbyteorder("<")
    size = dt.itemsize
    out = np.empty((len(items), len(first)))
    residue = first % size
    for r in np.flatnonzero(np.bincount(residue, minlength=size)):
        view = np.frombuffer(buf, dtype=dt, count=(len(buf) - int(r)) // size, offset=int(r))
        rows = np.flatnonzero(residue == r) if np.any(residue != r) else slice(None)
        # rows of messages that did not fit start at 0: clipped, their values are never used
        out[:, rows] = view[np.minimum(items[:, None] + ((first[rows] - r) // size), len(view) - 1)]
    return out


def decode_batch(
    layout: Sequence[Field],
    picks: Sequence[Pick],
    encoding: str,
    buf: ByteArray,
    starts: IntArray,
    lengths: IntArray,
) -> tuple[IntArray, FloatArray, NDArray[np.bool_]]:
    """(header stamps ns, raw values (m, len(picks)), ok) of the messages at buf[starts:starts+lengths].

    Rows that are not ok hold garbage: decode those messages one by one.
    """
    m = len(starts)
    if m == 0 or len(buf) < 16:
        return np.zeros(m, dtype=np.int64), np.full((m, len(picks)), np.nan), np.zeros(m, dtype=np.bool_)
    starts = np.asarray(starts, dtype=np.int64)
    ends = starts + np.asarray(lengths, dtype=np.int64)
    last = len(buf) - 1
    cdr = encoding == "cdr"
    ok = ends <= len(buf)
    if cdr:
        ok &= ends - starts >= 4
        head = np.where(ok, starts, 0)
        ok &= (buf[np.minimum(head, last)] == 0) & (buf[np.minimum(head + 1, last)] == 1)  # CDR little endian
        base = starts + 4
        pos = np.full(m, 8, dtype=np.int64)  # int32 sec, uint32 nanosec
    else:
        base = starts
        pos = np.full(m, 12, dtype=np.int64)  # uint32 seq, uint32 sec, uint32 nsec

    def at(rel: IntArray, size: int) -> IntArray:
        """Absolute offsets of `size`-byte reads at `rel`; marks messages whose read runs past their end."""
        nonlocal ok
        absolute = base + rel
        ok &= absolute + size <= ends
        return np.where(ok, absolute, 0)

    def align(rel: IntArray, size: int) -> IntArray:
        return (rel + size - 1) & ~(size - 1) if cdr and size > 1 else rel

    stamp_sec = gather(buf, at(np.full(m, 4 if not cdr else 0, dtype=np.int64), 8), "u4" if not cdr else "i4")
    stamp_nsec = gather(buf, at(np.full(m, 8 if not cdr else 4, dtype=np.int64), 4), "u4")
    offsets: dict[str, IntArray] = {}
    for f in (Field("frame_id", "string"), *layout):
        if f.dtype == "string":
            pos = align(pos, 4)
            n = gather(buf, at(pos, 4), "u4").astype(np.int64)
            pos = pos + 4 + n
            ok &= base + pos <= ends
            continue
        size = np.dtype(f.dtype).itemsize
        pos = align(pos, size)
        offsets[f.name] = pos
        pos = pos + size * f.count
        ok &= base + pos <= ends
    stamps = stamp_sec.astype(np.int64) * 1_000_000_000 + stamp_nsec.astype(np.int64)
    values = np.full((len(picks), m), np.nan).T  # (m, k) whose columns are contiguous, as the buffers keep them
    dtypes = {f.name: f.dtype for f in layout}
    safe = ok[:, None]
    for dtype in dict.fromkeys(dtypes[p[0]] for p in picks if p is not None):
        cols = [i for i, p in enumerate(picks) if p is not None and dtypes[p[0]] == dtype]
        size = np.dtype(dtype).itemsize
        picked = {picks[i][0] for i in cols}  # type: ignore[index]
        fields = [f.name for f in layout if f.name in picked]  # in the message's order: the first lies first
        lead = offsets[fields[0]]
        shift = {f: int(offsets[f][0] - lead[0]) for f in fields}  # each field's place after the first field
        if size > 1 and all(
            shift[f] % size == 0 and (f == fields[0] or bool(np.all(offsets[f] - lead == shift[f]))) for f in fields
        ):
            # the usual case: every value a whole number of items after the first field, in every message
            items = np.array([(shift[picks[i][0]] + size * picks[i][1]) // size for i in cols])  # type: ignore[index]
            values.T[cols] = _gather_rows(buf, np.where(ok, base + lead, 0), items, dtype)
        else:
            rel = np.stack([offsets[picks[i][0]] + size * picks[i][1] for i in cols], axis=1)  # type: ignore[index]
            absolute = np.where(safe, base[:, None] + rel, 0)
            values[:, cols] = gather(buf, absolute, dtype).astype(np.float64)
    return np.where(ok, stamps, 0), values, ok
