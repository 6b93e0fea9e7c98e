"""DataFlash logs built in tmp_path from FMT definitions, for the revisions and messages the corpus has no
licensed log of: the bytes are what that firmware wrote, the values are made up."""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

from pymavlink.DFReader import FORMAT_TO_STRUCT

HEAD = b"\xa3\x95"


@dataclass(frozen=True)
class Fmt:
    type: int
    name: str
    format: str
    columns: str

    def size(self) -> int:
        return 3 + struct.calcsize("<" + "".join(FORMAT_TO_STRUCT[c][0] for c in self.format))

    def fmt_message(self) -> bytes:
        body = struct.pack(
            "<BB4s16s64s", self.type, self.size(), self.name.encode(), self.format.encode(), self.columns.encode()
        )
        return HEAD + b"\x80" + body

    def message(self, **values: float) -> bytes:
        """One message; values in the units the log shows (scaled fields multiplied back, as logged)."""
        out = []
        for letter, col in zip(self.format, self.columns.split(","), strict=True):
            code, mult, _ = FORMAT_TO_STRUCT[letter]
            v = values.get(col, 0)
            out.append(round(v / mult) if mult is not None else (int(v) if code not in "fd" else float(v)))
        return HEAD + bytes([self.type]) + struct.pack("<" + "".join(FORMAT_TO_STRUCT[c][0] for c in self.format), *out)


FMT_FMT = Fmt(128, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns")
WEEK, TOW0_MS = 1770, 130_040_000  # 2013-12-08
LAT0, LON0 = -35.3547178, 149.1696673


def write_dataflash(path: Path, fmts: list[Fmt], messages: list[bytes]) -> Path:
    path.write_bytes(b"".join(f.fmt_message() for f in [FMT_FMT, *fmts]) + b"".join(messages))
    return path


def flight(n_gps: int = 20) -> list[tuple[int, int, float, float]]:
    """(boot ms, ms of week, lat, lon) of a 5 Hz receiver moving north at 5 m/s."""
    return [(40_000 + 200 * i, TOW0_MS + 200 * i, LAT0 + 5 * 0.2 * i / 111_320, LON0) for i in range(n_gps)]
