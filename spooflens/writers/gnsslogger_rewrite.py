"""Spoofed copies of Android GnssLogger logs: GPS-provider Fix lines edited, every other line kept.

Each fix row of the table came from one `Fix` line of the GPS provider; its latitude, longitude and
altitude fields are replaced by the spoofed values (and, with `velocities`, its speed and bearing; where
the attack moved the receiver's time, its UnixTimeMillis), in the field positions the file's own
`# Fix,...` header gives. Lines are found as the reader placed them: by the phone's clock (`fix_clock`).
Raw measurement lines are left as logged: an attack on the fixes only is what a location-spoofing app
does; attacks on raw pseudoranges are written to RINEX or CSV copies (docs/simulation-and-attacks.md).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from readers.gnsslogger import FIX_NAMES, fix_clock, gps_fixes, split_file
from spooflens.epoch_table import EpochTable, gps_ns_of_unix_ns
from spooflens.errors import WriterError
from spooflens.writers.clock_shift import clock_shifts


def rewrite_gnsslogger(src: Path, dst: Path, table: EpochTable, spoofed: EpochTable, velocities: bool) -> str:
    text = Path(src).read_bytes().decode("utf-8", errors="replace")
    lines = text.splitlines(keepends=True)
    header: list[str] | None = None
    for line in lines:
        body = line.lstrip("#").strip()
        if line.startswith("#") and body.split(",", 1)[0].strip() == "Fix":
            header = [c.strip() for c in body.split(",")][1:]
    if header is None:
        raise WriterError(f"{src}: no '# Fix,...' header line: cannot place the spoofed fixes")

    def index(key: str) -> int | None:
        return next((header.index(n) for n in FIX_NAMES[key] if n in header), None)

    i_lat, i_lon, i_alt, i_time = index("lat"), index("lon"), index("alt"), index("time_ms")
    i_speed, i_bearing = index("speed"), index("bearing")
    if i_lat is None or i_lon is None or i_alt is None or i_time is None:
        raise WriterError(f"{src}: Fix header without latitude, longitude, altitude or time: {header}")
    if len(table.observations) and not spoofed.observations.equals(table.observations):
        raise WriterError(
            f"{src}: an attack on raw pseudoranges cannot be written back into a GnssLogger log (its Raw lines "
            "keep the receiver's clock fields); inject it into a RINEX or CSV copy instead"
        )
    fixes = spoofed.fixes
    stamps = table.absolute_ns(fixes["t_s"].to_numpy())
    values = dict(
        zip(
            stamps.tolist(),
            fixes[["lat_deg", "lon_deg", "height_m", "vel_e_mps", "vel_n_mps"]].to_numpy(float).tolist(),
            strict=True,
        )
    )
    # what the attack did to the receiver's time (ms, by row): the fix line's UnixTimeMillis moves with it
    shifts = clock_shifts(table, fixes)
    shift_ms = np.round(shifts["shift_s"].to_numpy() * 1000).astype(np.int64)
    clock_ms = dict(zip(shifts["t_ns"].tolist(), shift_ms.tolist(), strict=True))
    # each fix line's row, found as the reader placed it (by the phone's clock, `fix_clock`)
    read = gps_fixes(src, split_file(src, [])[0], [])
    row_of: dict[int, int] = {}
    if read is not None and len(read):
        phone_ns = fix_clock(read)[1]
        placed = gps_ns_of_unix_ns(phone_ns) if table.time_reference == "gps" else phone_ns
        row_of = dict(zip(read["unix_ms"].tolist(), np.asarray(placed).tolist(), strict=True))
    changed = 0
    out = []
    for line in lines:
        if not line.startswith("Fix,"):
            out.append(line)
            continue
        end = line[len(line.rstrip("\r\n")) :]
        fields = line.rstrip("\r\n").split(",")
        if fields[1].strip().upper() != "GPS":
            out.append(line)
            continue
        try:
            unix_ms = int(fields[1 + i_time])
        except ValueError:
            out.append(line)
            continue
        row = row_of.get(unix_ms)
        v = values.get(row) if row is not None else None
        if v is None or row is None:
            out.append(line)
            continue
        if clock_ms.get(row, 0):
            fields[1 + i_time] = str(unix_ms + clock_ms[row])
        lat, lon, h, ve, vn = v
        fields[1 + i_lat], fields[1 + i_lon], fields[1 + i_alt] = f"{lat:.10f}", f"{lon:.10f}", repr(h)
        if velocities and i_speed is not None and i_bearing is not None and np.isfinite([ve, vn]).all():
            fields[1 + i_speed] = repr(float(np.hypot(ve, vn)))
            fields[1 + i_bearing] = repr(float(np.degrees(np.arctan2(ve, vn)) % 360.0))
        out.append(",".join(fields) + end)
        changed += 1
    Path(dst).write_text("".join(out), encoding="utf-8")
    return f"{changed} GPS Fix lines rewritten ({len(fixes)} fixes in the table), Raw and every other line copied"
