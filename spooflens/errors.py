"""One exception hierarchy for the whole tool.

Every message names the file, the stream and the problem, so the CLI can print it as one line.
"""

from __future__ import annotations

from pathlib import Path


class SpooflensError(Exception):
    """Base of every error spooflens raises on purpose."""


class ReaderError(SpooflensError):
    """A log file could not be read (missing, empty, corrupt, unsupported)."""

    def __init__(self, path: Path | str, problem: str, stream: str | None = None) -> None:
        self.path = Path(path)
        self.stream = stream
        self.problem = problem
        where = f"{self.path}" + (f" [{stream}]" if stream else "")
        super().__init__(f"{where}: {problem}")


class UnsupportedFormatError(ReaderError):
    """No reader knows this file."""


class NoGnssError(ReaderError):
    """The log holds no GNSS stream, so nothing about spoofing can be said."""


class SchemaError(SpooflensError):
    """A frame handed over by a reader breaks the epoch-table schema."""


class AnalysisError(SpooflensError):
    """An analysis could not run on the table it was given."""


class WriterError(SpooflensError):
    """A log could not be written in the requested format."""


def one_line(err: BaseException | str, limit: int = 300) -> str:
    """An error (type and message) or a text as one line of at most `limit` characters.

    Library errors can carry a whole schema or a traceback-like message over many lines; the CLI
    promises one line on stderr.
    """
    text = err if isinstance(err, str) else (f"{type(err).__name__}: {err}" if str(err) else type(err).__name__)
    flat = " ".join(text.split())
    return flat if len(flat) <= limit else flat[: limit - 3] + "..."
