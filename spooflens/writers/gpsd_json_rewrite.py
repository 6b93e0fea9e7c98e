"""A spoofed copy of a gpsd JSON log: TPV positions edited in place, every other byte unchanged.

The log is read the way the reader reads it (`readers.gpsd_json.scan_reports` and `assemble`), so each fix
row is tied to its TPV line. For each row the attack moved, that line's `lat` and `lon` are set to the
spoofed values and its altitudes (`altHAE`, `altMSL`, `alt`) moved by the height offset, each number with
the decimals gpsd wrote; with `velocities`, `velN`/`velE`/`velD`, `speed`, `track` and `climb` are set
from the spoofed velocity. The line's time prefix, its other fields, its line end and every other line
(SKY, VERSION, ...) are copied as they were. What the attack did to the self-reports (lost fixes, C/N0,
accuracies) is not written: `inject` names it.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from readers.gpsd_json import assemble, scan_reports
from spooflens.epoch_table import EpochTable
from spooflens.errors import WriterError

_COLS = ["lat_deg", "lon_deg", "height_m", "vel_e_mps", "vel_n_mps", "vel_u_mps"]


def _field(key: str) -> re.Pattern[bytes]:
    return re.compile(rb'("' + key.encode() + rb'"\s*:\s*)(-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?)')


_FIELDS = {
    k: _field(k) for k in ("lat", "lon", "altHAE", "altMSL", "alt", "velN", "velE", "velD", "speed", "track", "climb")
}


def _decimals(text: bytes) -> int:
    return len(text.partition(b".")[2]) if b"." in text and b"e" not in text.lower() else 9


def _set(text: bytes, key: str, value: float, shift: bool = False) -> bytes:
    m = _FIELDS[key].search(text)
    if m is None or not math.isfinite(value):
        return text
    old = m.group(2)
    new = float(old) + value if shift else value
    k = _decimals(old)
    return text[: m.start(2)] + f"{new:.{k}f}".encode() + text[m.end(2) :]


def rewrite_gpsd_json(src: Path, dst: Path, table: EpochTable, spoofed: EpochTable, velocities: bool) -> str:
    """Write `src` to `dst` with the spoofed fixes in its TPV lines."""
    src, dst = Path(src), Path(dst)
    scan = scan_reports(src)
    a = assemble(scan)
    line_of: dict[tuple[str, int], tuple[int, int]] = {}
    for f in a.fixes:
        t = f.report.host_ns if a.logger else f.gnss_ns
        if t is not None:
            line_of.setdefault((f.rid, int(t)), (f.report.start, f.report.end))
    before = table.fixes
    after = spoofed.fixes
    old = {
        (str(r), int(t)): v
        for r, t, v in zip(
            before["receiver_id"],
            table.absolute_ns(before["t_s"].to_numpy()),
            before[_COLS].to_numpy(float),
            strict=True,
        )
    }
    edits: list[tuple[int, int, bytes]] = []
    missing = 0
    moved = 0
    for rid, t, new in zip(
        after["receiver_id"], table.absolute_ns(after["t_s"].to_numpy()), after[_COLS].to_numpy(float), strict=True
    ):
        key = (str(rid), int(t))
        was = old.get(key)
        if was is None or np.array_equal(was, new, equal_nan=True):
            continue
        place = line_of.get(key)
        if place is None:
            missing += 1
            continue
        start, end = place
        text = scan.data[start:end]
        lat, lon, h, ve, vn, vu = new
        text = _set(text, "lat", lat)
        text = _set(text, "lon", (lon + 180.0) % 360.0 - 180.0)
        dh = h - was[2]
        if math.isfinite(dh) and dh != 0:
            for k in ("altHAE", "altMSL", "alt"):
                text = _set(text, k, dh, shift=True)
        if velocities and math.isfinite(ve) and math.isfinite(vn):
            text = _set(text, "velN", vn)
            text = _set(text, "velE", ve)
            text = _set(text, "speed", math.hypot(ve, vn))
            text = _set(text, "track", math.degrees(math.atan2(ve, vn)) % 360.0)
            if math.isfinite(vu):
                text = _set(text, "velD", -vu)
                text = _set(text, "climb", vu)
        edits.append((start, end, text))
        moved += 1
    out = bytearray()
    pos = 0
    for start, end, text in sorted(edits):
        out += scan.data[pos:start] + text
        pos = end
    out += scan.data[pos:]
    try:
        dst.write_bytes(bytes(out))
    except OSError as err:
        raise WriterError(f"{dst}: cannot write: {err}") from err
    note = f"{moved} TPV lines rewritten, every other byte copied"
    return note + (f"; {missing} spoofed fixes matched no TPV line of the log" if missing else "")
