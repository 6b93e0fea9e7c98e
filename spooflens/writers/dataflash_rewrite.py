"""Spoofed copies of ArduPilot DataFlash logs: the GPS messages patched in place, every other byte kept.

Each fix row of the table came from one GPS (or GPS2) message at a known offset in the file
(`readers.ardupilot.gps_fixes`); its Lat/Lng/Alt fields are rewritten with the spoofed position (the
attack's change is added to the logged AMSL altitude, so the ellipsoidal conversion cancels), and with
`velocities` its Spd/GCrs/VZ too, and where the attack moved the receiver's time (`time_offset_s`) its
GWk/GMS. Messages keep their length and place, so pymavlink and every other
DataFlash tool read the copy as they read the original. The autopilot's own EKF messages (XKF*) and
raw observations (GRXS) are left as logged: the copy shows what the receiver was made to report, not
what the autopilot would have done with it.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pandas as pd

from readers.ardupilot import WEEK_MS, gps_clock, gps_fixes, gps_rows
from readers.dataflash import open_dataflash
from readers.dataflash_eras import logged_name
from spooflens.epoch_table import EpochTable
from spooflens.errors import WriterError
from spooflens.writers.clock_shift import clock_shifts

_PACK = {
    "L": ("<i", 1e7),
    "e": ("<i", 100.0),
    "E": ("<I", 100.0),
    "f": ("<f", 1.0),
    "d": ("<d", 1.0),
    "i": ("<i", 1.0),
    "I": ("<I", 1.0),
    "H": ("<H", 1.0),
}


def _field_writer(log, name: str, column: str):  # type: ignore[no-untyped-def]
    """(byte offset inside the message, struct code, scale) of one column (today's name) of one message type."""
    fmt = log.reader.formats[log.reader.name_to_id[name]]
    dt, _ = log.dtype(name)
    column = logged_name(list(fmt.columns), column)
    letter = fmt.format[fmt.columns.index(column)]
    if letter not in _PACK:
        raise WriterError(f"{log.path}: {name}.{column} has format letter {letter!r}; cannot write it back")
    code, scale = _PACK[letter]
    return 3 + dt.fields[column][1], code, scale


def rewrite_dataflash(src: Path, dst: Path, table: EpochTable, spoofed: EpochTable, velocities: bool) -> str:
    log = open_dataflash(Path(src))
    gps = gps_rows(log, [])
    if gps is None:
        raise WriterError(f"{src}: no GPS message to rewrite")
    _, offset_ns, _ = gps_clock(gps)
    rows = gps_fixes(gps, offset_ns, [], {})
    key = ["receiver_id", "t_s"]
    before = table.fixes[[*key, "lat_deg", "lon_deg", "height_m"]]
    after = spoofed.fixes[[*key, "lat_deg", "lon_deg", "height_m", "vel_e_mps", "vel_n_mps", "vel_u_mps"]]
    change = before.merge(after, on=key, suffixes=("_0", ""))
    change["t_ns"] = table.absolute_ns(change["t_s"].to_numpy())
    change = change.merge(clock_shifts(table, spoofed.fixes), on=["receiver_id", "t_ns"], how="left")
    if {"GWk", "GMS"} <= set(gps.columns):
        rows = rows.merge(gps[["ofs", "GWk", "GMS"]], on="ofs", how="left")
    rows = rows.rename(columns={c: f"{c}_log" for c in rows.columns if c not in ("receiver_id", "t_ns", "msg", "ofs")})
    plan = rows.merge(change, on=["receiver_id", "t_ns"], how="inner")
    data = bytearray(log.data)
    clock_ms = np.round(plan["shift_s"].fillna(0.0).to_numpy() * 1000).astype(np.int64)
    timed = bool(np.any(clock_ms != 0)) and {"GWk_log", "GMS_log"} <= set(plan.columns)
    moved = ("GWk", "GMS") if timed else ()
    fields = {
        name: {c: _field_writer(log, name, c) for c in ("Lat", "Lng", "Alt", "Spd", "GCrs", "VZ", *moved)}
        for name in plan["msg"].unique()
    }
    if timed:  # the spoofer's time: GPS week and ms of week moved together
        gps_ms = plan["GWk_log"].to_numpy(np.int64) * WEEK_MS + plan["GMS_log"].to_numpy(np.int64) + clock_ms
        plan["GWk_new"], plan["GMS_new"] = gps_ms // WEEK_MS, gps_ms % WEEK_MS
    changed = 0
    for r in plan.itertuples(index=False):
        f = fields[r.msg]
        old_alt = struct.unpack_from(f["Alt"][1], data, r.ofs + f["Alt"][0])[0] / f["Alt"][2]
        values = {"Lat": r.lat_deg, "Lng": r.lon_deg, "Alt": old_alt + (r.height_m - r.height_m_0)}
        if velocities and np.isfinite([r.vel_e_mps, r.vel_n_mps, r.vel_u_mps]).all():
            values |= {
                "Spd": float(np.hypot(r.vel_e_mps, r.vel_n_mps)),
                "GCrs": float(np.degrees(np.arctan2(r.vel_e_mps, r.vel_n_mps)) % 360.0),
                "VZ": -float(r.vel_u_mps),
            }
        if timed:
            values |= {"GWk": float(r.GWk_new), "GMS": float(r.GMS_new)}
        for col, value in values.items():
            pos, code, scale = f[col]
            raw = round(value * scale) if code[1] in "iIH" else value
            struct.pack_into(code, data, r.ofs + pos, raw)
        changed += 1
    Path(dst).write_bytes(bytes(data))
    if len(spoofed.observations) and not pd.DataFrame.equals(spoofed.observations, table.observations):
        note = "; GRXS raw observations left as logged (only GPS fixes are rewritten)"
    else:
        note = ""
    return f"{changed} GPS messages rewritten ({len(spoofed.fixes)} fixes in the table), every other byte copied{note}"
