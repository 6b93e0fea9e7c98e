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
    """Appends (stamp_ns, values...) rows; `arrays()` returns them as one int64 and one float64 array."""

    def __init__(self, columns: Sequence[str]) -> None:
        self.columns = tuple(columns)
        self._stamps: list[NDArray[np.int64]] = []
        self._values: list[NDArray[np.float64]] = []
        self._fill = _BLOCK_ROWS  # forces a block on first append
        self.count = 0

    def _new_block(self) -> None:
        self._stamps.append(np.empty(_BLOCK_ROWS, dtype=np.int64))
        self._values.append(np.empty((_BLOCK_ROWS, len(self.columns)), dtype=np.float64))
        self._fill = 0

    def append(self, stamp_ns: int, values: Sequence[float]) -> None:
        if self._fill == _BLOCK_ROWS:
            self._new_block()
        self._stamps[-1][self._fill] = stamp_ns
        self._values[-1][self._fill] = values
        self._fill += 1
        self.count += 1

    def arrays(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        if not self._stamps:
            return np.empty(0, dtype=np.int64), np.empty((0, len(self.columns)), dtype=np.float64)
        last = self._fill
        stamps = np.concatenate([*self._stamps[:-1], self._stamps[-1][:last]])
        values = np.concatenate([*self._values[:-1], self._values[-1][:last]])
        return stamps, values

    def column(self, values: NDArray[np.float64], name: str) -> NDArray[np.float64]:
        return values[:, self.columns.index(name)]
