"""A binary DataFlash log written as the text log Mission Planner saves (`NAME, v1, v2, ...`, scaled fields
scaled, strings as text), in file order, so a test can read the same log both ways."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from readers.dataflash import open_dataflash

SCALED = "cCeEL"


def _formatter(letter: str) -> Callable[[object], str]:
    if letter in "nNZ":
        # a string as text; a newline in it (FILE messages carry files) would end the line: written as a space
        return lambda v: bytes(v).split(b"\0", 1)[0].decode("latin-1").replace("\r", " ").replace("\n", " ")  # type: ignore[call-overload]
    if letter == "a":
        return lambda v: " ".join(str(int(x)) for x in v)  # type: ignore[attr-defined]
    if letter in SCALED or letter == "d":
        return lambda v: repr(float(v))  # type: ignore[arg-type]
    if letter == "f":
        return lambda v: str(np.float32(v))  # type: ignore[arg-type]  # the shortest text that reads back as the same float
    return lambda v: str(int(v))  # type: ignore[call-overload]


def text_lines(src: Path) -> list[tuple[int, str]]:
    """(offset in the binary log, text line) of every message of `src` the binary reader can read."""
    log = open_dataflash(src)
    out: list[tuple[int, str]] = []
    for name in sorted(log.names()):
        found = log.logged(name)
        if found is None:
            continue
        ofs, cols = found
        fmt = log.reader.formats[log.reader.name_to_id[name]]
        texts = [list(map(_formatter(letter), cols[c])) for c, letter in zip(fmt.columns, fmt.format, strict=True)]
        out += [(int(o), name + ", " + ", ".join(row)) for o, row in zip(ofs, zip(*texts, strict=True), strict=True)]
    return sorted(out)


def write_text_log(
    src: Path, dst: Path, delimiter: str = ", ", newline: str = "\r\n", bom: bool = False, max_lines: int | None = None
) -> Path:
    """`src` (binary) as a Mission Planner text log at `dst`."""
    lines = [line for _, line in text_lines(src)][:max_lines]
    text = newline.join(line.replace(", ", delimiter) if delimiter != ", " else line for line in lines) + newline
    dst.write_bytes((b"\xef\xbb\xbf" if bom else b"") + text.encode("latin-1"))
    return dst
