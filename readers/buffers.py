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
    `arrays()` returns the stamps and each column as an array of its own.

    Every column is its own array, so the schema's columns can be the rows themselves and a raw column
    no schema column keeps (an orientation covariance read only to tell whether there is an
    orientation) is freed once its rows are read. Given the stream's message count (`capacity`, e.g.
    from an MCAP summary) the rows go straight into arrays of that size and `arrays()` copies nothing;
    otherwise they fill blocks of `_BLOCK_ROWS` joined at the end."""

    def __init__(self, columns: Sequence[str], capacity: int = 0) -> None:
        self.columns = tuple(columns)
        self._capacity = max(int(capacity), 0)
        self._stamps: list[NDArray[np.int64]] = []  # closed blocks, each exactly as long as its rows
        self._values: list[list[NDArray[np.float64]]] = []  # a column each
        self._open_stamps: NDArray[np.int64] | None = None  # the block being filled
        self._open_values: list[NDArray[np.float64]] = []
        self._fill = 0
        self.count = 0

    def _close(self) -> None:
        if self._open_stamps is not None and self._fill:
            self._stamps.append(self._open_stamps[: self._fill])
            self._values.append([column[: self._fill] for column in self._open_values])
        self._open_stamps, self._open_values = None, []
        self._fill = 0

    def _room(self) -> int:
        """Rows the open block still takes, opening one when there is none or it is full."""
        if self._open_stamps is None or self._fill == len(self._open_stamps):
            self._close()
            size = self._capacity - self.count if self.count < self._capacity else _BLOCK_ROWS
            self._open_stamps = np.empty(size, dtype=np.int64)
            self._open_values = [np.empty(size, dtype=np.float64) for _ in self.columns]
        return len(self._open_stamps) - self._fill

    def append(self, stamp_ns: int, values: Sequence[float]) -> None:
        self._room()
        assert self._open_stamps is not None
        self._open_stamps[self._fill] = stamp_ns
        for column, value in zip(self._open_values, values, strict=True):
            column[self._fill] = value
        self._fill += 1
        self.count += 1

    def extend(self, stamps: NDArray[np.int64], values: NDArray[np.float64]) -> None:
        """Append many rows at once ((rows, columns) values), after the rows appended so far."""
        values = np.asarray(values, dtype=np.float64).reshape(len(stamps), len(self.columns))
        done = 0
        while done < len(stamps):
            n = min(self._room(), len(stamps) - done)
            assert self._open_stamps is not None
            self._open_stamps[self._fill : self._fill + n] = stamps[done : done + n]
            for k, column in enumerate(self._open_values):
                column[self._fill : self._fill + n] = values[done : done + n, k]
            self._fill += n
            self.count += n
            done += n

    def arrays(self) -> tuple[NDArray[np.int64], dict[str, NDArray[np.float64]]]:
        """All rows, in order: (rows,) stamps and {column name: (rows,) values}; the buffer is emptied.
        One block is handed over as it is; several are joined a column at a time, each block's column
        freed as soon as it is copied, so the rows exist about once, not twice."""
        self._close()
        blocks, self._values = self._values, []
        stamp_blocks, self._stamps = self._stamps, []
        stamps = stamp_blocks[0] if len(stamp_blocks) == 1 else np.concatenate([_NO_STAMPS, *stamp_blocks])
        columns: dict[str, NDArray[np.float64]] = {}
        for k, name in enumerate(self.columns):
            parts = [block[k] for block in blocks]
            for block in blocks:
                block[k] = _EMPTY  # the block's column lives on only in `parts`, freed once joined
            columns[name] = parts[0] if len(parts) == 1 else np.concatenate(parts or [_EMPTY])
            del parts
        self.count = 0
        return stamps, columns


_EMPTY = np.empty(0, dtype=np.float64)
_NO_STAMPS = np.empty(0, dtype=np.int64)


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
