"""Growable column storage for streaming readers.

Rows are written into preallocated numpy blocks, so memory is the data itself (8 bytes a value) and
never a Python object per message, however long the log.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

_BLOCK_ROWS = 65536


class RowBuffer:
    """Appends (stamp_ns, values...) rows one at a time (`append`) or many at once (`extend`);
    `arrays()` returns them as one int64 and one float64 array.

    Values are held column by column, so `values[:, k]` is contiguous and the schema's columns can be
    the rows themselves. Given the stream's message count (`capacity`, e.g. from an MCAP summary) the
    rows go straight into one array of that size and `arrays()` copies nothing; otherwise they fill
    blocks of `_BLOCK_ROWS` joined at the end."""

    def __init__(self, columns: Sequence[str], capacity: int = 0) -> None:
        self.columns = tuple(columns)
        self._capacity = max(int(capacity), 0)
        self._stamps: list[NDArray[np.int64]] = []  # closed blocks, each exactly as long as its rows
        self._values: list[NDArray[np.float64]] = []  # (columns, rows) each
        self._open_stamps: NDArray[np.int64] | None = None  # the block being filled
        self._open_values: NDArray[np.float64] | None = None
        self._fill = 0
        self.count = 0

    def _close(self) -> None:
        if self._open_stamps is not None and self._open_values is not None and self._fill:
            self._stamps.append(self._open_stamps[: self._fill])
            self._values.append(self._open_values[:, : self._fill])
        self._open_stamps = self._open_values = None
        self._fill = 0

    def _room(self) -> int:
        """Rows the open block still takes, opening one when there is none or it is full."""
        if self._open_stamps is None or self._fill == len(self._open_stamps):
            self._close()
            size = self._capacity - self.count if self.count < self._capacity else _BLOCK_ROWS
            self._open_stamps = np.empty(size, dtype=np.int64)
            self._open_values = np.empty((len(self.columns), size), dtype=np.float64)
        return len(self._open_stamps) - self._fill

    def append(self, stamp_ns: int, values: Sequence[float]) -> None:
        self._room()
        assert self._open_stamps is not None and self._open_values is not None
        self._open_stamps[self._fill] = stamp_ns
        self._open_values[:, self._fill] = values
        self._fill += 1
        self.count += 1

    def extend(self, stamps: NDArray[np.int64], values: NDArray[np.float64]) -> None:
        """Append many rows at once ((rows, columns) values), after the rows appended so far."""
        values = np.asarray(values, dtype=np.float64).reshape(len(stamps), len(self.columns))
        done = 0
        while done < len(stamps):
            n = min(self._room(), len(stamps) - done)
            assert self._open_stamps is not None and self._open_values is not None
            self._open_stamps[self._fill : self._fill + n] = stamps[done : done + n]
            self._open_values[:, self._fill : self._fill + n] = values[done : done + n].T
            self._fill += n
            self.count += n
            done += n

    def arrays(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """All rows, in order, as (rows,) stamps and (rows, columns) values (a view of column storage);
        the buffer is emptied. One block is handed over as it is; several are joined, each freed as soon
        as it is copied, so the rows exist about once, not twice."""
        self._close()
        if len(self._stamps) == 1:
            stamps, values = self._stamps.pop(), self._values.pop()
            self.count = 0
            return stamps, values.T
        n = sum(len(b) for b in self._stamps)
        stamps = np.empty(n, dtype=np.int64)
        values = np.empty((len(self.columns), n), dtype=np.float64)
        pos = 0
        while self._stamps:
            block_t, block_v = self._stamps.pop(0), self._values.pop(0)
            stamps[pos : pos + len(block_t)] = block_t
            values[:, pos : pos + len(block_t)] = block_v
            pos += len(block_t)
            del block_t, block_v
        self.count = 0
        return stamps, values.T

    def column(self, values: NDArray[np.float64], name: str) -> NDArray[np.float64]:
        return values[:, self.columns.index(name)]


def release_freed_memory() -> None:
    """Hand the heap's free pages back to the system (glibc's malloc_trim; nothing elsewhere).

    A reader frees the decoded rows and chunk buffers as it builds the table, but glibc keeps much of
    that memory in its heap for reuse rather than returning it: 80 MB after a 4 h voyage, which the
    analysis's large arrays (allocated with mmap) never reuse. Returning it lowers the peak that follows.
    """
    import ctypes

    try:
        trim = ctypes.CDLL(None).malloc_trim  # the process's own symbols: libc's, when it is glibc
    except (OSError, AttributeError):  # not glibc
        return
    trim(0)
