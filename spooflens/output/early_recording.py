"""A log's recording begun while its analysis still runs.

Most of a recording's bytes are the log's own streams (an hour of 200 Hz IMU is 4.3 million values),
which need no analysis. `analyze` queues them as side work (`threads.side_work`): they are written on
the core that the navigation filter's final pass leaves idle, and only the results remain to be written
once the analysis ends. The file is written under a temporary name and moved into place when it is
complete, so a failed analysis leaves neither half a recording nor an earlier one overwritten.

This module does not import Rerun (begun as side work, that import is part of the work).
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from spooflens.epoch_table import EpochTable
    from spooflens.output.recording import RecordingWriter


class EarlyRecording:
    """The recording to be written at `path`, begun for one table at most, taken once."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._lock = threading.Lock()
        self._table: EpochTable | None = None
        self._writer: RecordingWriter | None = None
        self._closed = False

    def begin(self, table: EpochTable) -> None:
        """Open the recording and write `table`'s streams (side work: nothing once taken or abandoned)."""
        with self._lock:
            if self._closed or self._writer is not None:
                return
            from spooflens.output.recording import begin_recording

            self._writer, self._table = begin_recording(self.path, table), table

    def take(self, path: Path, table: EpochTable) -> RecordingWriter | None:
        """The writer begun for this path and table (waiting while it is being begun), else None; nothing
        begins after this. One begun for another table or path is abandoned."""
        with self._lock:
            self._closed = True
            writer, self._writer = self._writer, None
        if writer is not None and (path != self.path or table is not self._table):
            writer.abandon()
            return None
        return writer

    def abandon(self) -> None:
        """Drop what was begun and not taken (the analysis failed): its file is removed."""
        with self._lock:
            self._closed = True
            writer, self._writer = self._writer, None
        if writer is not None:
            writer.abandon()
