"""Attacked copies of ArduPilot DataFlash logs: the receiver's messages patched in place, every other byte kept.

Each fix row of the table came from one GPS (or GPS2) message at a known offset in the file
(`readers.ardupilot.gps_fixes`); its Lat/Lng/Alt fields are rewritten with the spoofed position (the
attack's change is added to the logged AMSL altitude, so the ellipsoidal conversion cancels), and with
`velocities` its Spd/GCrs/VZ too, and where the attack moved the receiver's time (`time_offset_s`) its
GWk/GMS. Where the attack moved them, its NSats and HDop follow; a fix the attack lost gets Status 1 (no
fix), which the reader drops as it drops the receiver's own fix-less rows.

The messages the reader joins to each fix (`readers.ardupilot.gps_rows`) are written back to the same
message it read: GPA (VDop, HAcc, VAcc, SAcc), before 2016 UBX3 (hAcc, vAcc, sAcc). UBX1 (u-blox
MON-HW: noisePerMS, jamInd, agcCnt) is the receiver's own report, one `receiver_status` row each
(`readers.ardupilot.ubx1_reports`): every record gets the attacked values of its row, what the front end
saw when it was logged, whether the receiver had a fix then or the attack lost it. The fixes it is also
joined to read those values back.

The raw measurements the autopilot logs (GRXS, u-blox RXM-RAWX) get the attacked pseudorange (prMes),
Doppler (doMes) and C/N0 (cno); a measurement the attack removed (a satellite the jammer lost) gets trk
bit 0 clear, pseudorange not valid, as the receiver marks one it cannot use; the reader drops it.

A PX4 sdlog2 log (`.px4log`) is patched the same way through the names its fields had
(`readers.dataflash_eras.LOGGED_NAMES`): GPS Lat/Lon/Alt, VelN/VelE/VelD and Cog (radians), Fix, nSat,
and EPH/EPV (the accuracies it carries itself, joined as GPA's); a moved receiver time moves GPSTime
(UTC us) by the same amount, a GPSTime of 0 (no time yet) stays 0.

Messages keep their length and place, so pymavlink and every other DataFlash tool read the copy as they
read the original. A text log (Mission Planner `.log`) gets the same fields rewritten in the same lines:
only the rewritten values' text changes (integers as integers, scaled fields to their resolution, 0.01 or
1e-7, floats as the shortest text of the same float); every other line, and every other field of the
line with its spacing, is copied byte for byte.

The autopilot's own EKF messages (XKF*) are left as logged: the copy shows what the receiver was made to
report, not what the autopilot would have done with it.
"""

from __future__ import annotations

import math
import struct
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from readers.ardupilot import WEEK_MS, gps_clock, gps_fixes, gps_rows, grxs_rows, ubx1_reports
from readers.dataflash import DataFlash
from readers.dataflash_eras import logged_name
from readers.dataflash_text import TextDataFlash, open_any_dataflash
from spooflens.epoch_table import EpochTable
from spooflens.errors import WriterError
from spooflens.writers.fix_changes import fix_changes, moved

# DataFlash format letter -> (struct code, multiplier from the value to what is stored)
_PACK = {
    "L": ("<i", 1e7),
    "e": ("<i", 100.0),
    "E": ("<I", 100.0),
    "c": ("<h", 100.0),
    "C": ("<H", 100.0),
    "f": ("<f", 1.0),
    "Q": ("<Q", 1.0),
    "d": ("<d", 1.0),
    "b": ("<b", 1.0),
    "B": ("<B", 1.0),
    "h": ("<h", 1.0),
    "H": ("<H", 1.0),
    "i": ("<i", 1.0),
    "I": ("<I", 1.0),
}
NO_FIX = 1  # ArduPilot GPS_Status NO_FIX
HEADER_BYTES = 3  # 0xA3 0x95, then the message type
# the table's columns a GPS message carries beyond its position, velocity and time
GPS_INDICATORS = {"sats_used": "NSats", "hdop": "HDop"}
# messages joined to the fixes, by the reader's column of where the joined one sits: table column -> field
JOINED = {
    "gpa_ofs": {"vdop": "VDop", "h_acc_m": "HAcc", "v_acc_m": "VAcc", "vel_acc_mps": "SAcc"},
    "ubx3_ofs": {"h_acc_m": "hAcc", "v_acc_m": "vAcc", "vel_acc_mps": "sAcc"},
}
# UBX1 (u-blox MON-HW), one `receiver_status` row each: table column -> field. Written from those rows,
# not from the fixes it is also joined to, so a report logged while the fix was lost gets its own values
REPORTED = {"noise_per_ms": "noisePerMS", "jamming_indicator": "jamInd", "agc": "agcCnt"}
# a raw measurement's columns and the GRXS fields that carry them
MEASURED = {"pseudorange_m": "prMes", "doppler_hz": "doMes", "cn0_dbhz": "cno"}
PR_VALID = 1  # GRXS trk (RXM-RAWX trkStat) bit 0: the reader keeps a measurement only with it set
MOTION = ["lat_deg", "lon_deg", "height_m", "vel_e_mps", "vel_n_mps", "vel_u_mps"]
ATTACKED = [*MOTION, *GPS_INDICATORS, *dict.fromkeys(c for fields in JOINED.values() for c in fields)]

FieldWriter = tuple[int, str, float]


def _field_writer(log: DataFlash, name: str, column: str) -> FieldWriter | None:
    """(byte offset inside the message, struct code, scale) of one column (today's name) of one message type;
    None when this revision's message has no such field (GPS VZ before 2014, a GPA without VDop)."""
    found = _logged_column(log, name, column)
    if found is None:
        return None
    index, letter = found
    dt, _ = log.dtype(name)
    code, scale = _PACK[letter]
    if dt.fields is None or dt.names is None:
        raise WriterError(f"{log.path}: {name} has no field layout; cannot write it back")
    return HEADER_BYTES + int(dt.fields[dt.names[index]][1]), code, scale  # the dtype's names are the FMT's


def _logged_column(log: DataFlash, name: str, column: str) -> tuple[int, str] | None:
    """(index among the message's fields, format letter) of one column (today's name) of a message type, as
    this revision logs it; None when it has no such field. A letter no writer packs is refused."""
    fmt = log.reader.formats[log.reader.name_to_id[name]]
    columns = list(fmt.columns)
    column = logged_name(columns, column)
    if column not in columns:
        return None
    letter = fmt.format[columns.index(column)]
    if letter not in _PACK:
        raise WriterError(f"{log.path}: {name}.{column} has format letter {letter!r}; cannot write it back")
    return columns.index(column), letter


def _stored(code: str, value: float) -> float | int:
    """`value` (already scaled) as the field stores it: integers rounded and clipped to their type's range."""
    if code[1] in "fd":
        return value
    bits = struct.calcsize(code) * 8
    low, high = (0, 2**bits - 1) if code[1].isupper() else (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    return int(min(max(round(value), low), high))


class _Patcher:
    """The log's bytes with fields of its messages rewritten in place, each in its own type and scale."""

    def __init__(self, log: DataFlash) -> None:
        self.log = log
        self.data = bytearray(log.data)
        self.edited: Counter[str] = Counter()  # message name -> messages rewritten
        self._writers: dict[tuple[str, str], FieldWriter | None] = {}

    def name_at(self, ofs: int) -> str:
        return str(self.log.reader.formats[self.data[ofs + 2]].name)

    def _writer(self, name: str, column: str) -> FieldWriter | None:
        if (name, column) not in self._writers:
            self._writers[(name, column)] = _field_writer(self.log, name, column)
        return self._writers[(name, column)]

    def has(self, ofs: int, column: str) -> bool:
        """Whether the message at `ofs` has the field (today's name or this revision's)."""
        return self._writer(self.name_at(ofs), column) is not None

    def read(self, ofs: int, column: str) -> float:
        writer = self._writer(self.name_at(ofs), column)
        if writer is None:
            raise WriterError(f"{self.log.path}: {self.name_at(ofs)} at byte {ofs} has no {column}")
        pos, code, scale = writer
        return float(struct.unpack_from(code, self.data, ofs + pos)[0]) / scale

    def put(self, ofs: int, values: Mapping[str, float]) -> None:
        """The fields of the message at `ofs` that its revision has set to `values` (today's names)."""
        name = self.name_at(ofs)
        written = False
        for column, value in values.items():
            writer = self._writer(name, column)
            if writer is None:
                continue
            pos, code, scale = writer
            struct.pack_into(code, self.data, ofs + pos, _stored(code, value * scale))
            written = True
        if written:
            self.edited[name] += 1

    def output(self) -> bytes:
        return bytes(self.data)


def _text_value(letter: str, value: float) -> str:
    """`value` as a text log writes a field of format letter `letter` (the binary log's value, scaled)."""
    code, scale = _PACK[letter]
    if code[1] in "fd":
        if math.isnan(value):
            return "nan"
        number = np.float32(value) if code[1] == "f" else np.float64(value)
        return np.format_float_positional(number, trim="-")
    stored = _stored(code, value * scale)
    if scale == 1.0:
        return str(stored)
    decimals = round(math.log10(scale))
    return f"{stored / scale:.{decimals}f}"


class _TextPatcher:
    """A text DataFlash log with fields of its lines rewritten: only the rewritten values' text changes."""

    def __init__(self, log: TextDataFlash) -> None:
        self.log = log
        self.edited: Counter[str] = Counter()  # message name -> lines rewritten
        self._lines: dict[int, list[bytes]] = {}  # line offset -> its comma-separated parts, as rewritten
        self._ends: dict[int, int] = {}  # line offset -> where its text ends (before CR LF)
        self._fields: dict[tuple[str, str], tuple[int, str] | None] = {}

    def _parts(self, ofs: int) -> list[bytes]:
        if ofs not in self._lines:
            data = self.log.data
            end = data.find(b"\n", ofs)
            end = len(data) if end < 0 else end
            if end > ofs and data[end - 1 : end] == b"\r":
                end -= 1
            self._ends[ofs] = end
            self._lines[ofs] = data[ofs:end].split(b",")
        return self._lines[ofs]

    def name_at(self, ofs: int) -> str:
        return self._parts(ofs)[0].strip().decode("ascii")

    def _field(self, name: str, column: str) -> tuple[int, str] | None:
        """(index among the line's parts, format letter) of one column (today's name) of a message type."""
        if (name, column) not in self._fields:
            found = _logged_column(self.log, name, column)
            self._fields[(name, column)] = None if found is None else (1 + found[0], found[1])
        return self._fields[(name, column)]

    def has(self, ofs: int, column: str) -> bool:
        return self._field(self.name_at(ofs), column) is not None

    def read(self, ofs: int, column: str) -> float:
        field = self._field(self.name_at(ofs), column)
        if field is None:
            raise WriterError(f"{self.log.path}: {self.name_at(ofs)} at byte {ofs} has no {column}")
        return float(self._parts(ofs)[field[0]])

    def put(self, ofs: int, values: Mapping[str, float]) -> None:
        parts = self._parts(ofs)
        name = self.name_at(ofs)
        written = False
        for column, value in values.items():
            field = self._field(name, column)
            if field is None:
                continue
            i, letter = field
            old = parts[i]
            space = old[: len(old) - len(old.lstrip())]  # the delimiter's space, as the line had it
            parts[i] = space + _text_value(letter, value).encode("ascii")
            written = True
        if written:
            self.edited[name] += 1

    def output(self) -> bytes:
        data, out, pos = self.log.data, [], 0
        for ofs in sorted(self._lines):
            out += [data[pos:ofs], b",".join(self._lines[ofs])]
            pos = self._ends[ofs]
        out.append(data[pos:])
        return b"".join(out)


def _plan(gps: pd.DataFrame, table: EpochTable, spoofed: EpochTable) -> pd.DataFrame:
    """One row per GPS message of a fix of the table: where it and the messages joined to it sit, its values
    as read (`<column>_0`) and as attacked (NaN where the attack lost the fix: `lost`), and `shift_s`, how
    far the attack moved the receiver's time."""
    _, offset_ns, _ = gps_clock(gps)
    rows = gps_fixes(gps, offset_ns, [], {})[["receiver_id", "t_ns", "msg", "ofs"]]
    logged = [c for c in ("GWk", "GMS", *JOINED) if c in gps]
    rows = rows.merge(gps[["ofs", *logged]].rename(columns={"GWk": "GWk_log", "GMS": "GMS_log"}), on="ofs")
    change = fix_changes(table, spoofed, ATTACKED)
    return rows.merge(change, on=["receiver_id", "t_ns"], how="inner")


def _receiver_time(plan: pd.DataFrame) -> pd.DataFrame:
    """GPS week and ms of week of the fixes whose receiver time the attack moved (none when the log has no
    receiver time)."""
    clock_ms = np.round(plan["shift_s"].to_numpy(float) * 1000).astype(np.int64)
    moved = clock_ms != 0
    if not moved.any() or not {"GWk_log", "GMS_log"} <= set(plan.columns):
        return pd.DataFrame({"GWk": [], "GMS": []})
    logged = plan[moved]
    gps_ms = logged["GWk_log"].to_numpy(np.int64) * WEEK_MS + logged["GMS_log"].to_numpy(np.int64) + clock_ms[moved]
    return pd.DataFrame({"GWk": gps_ms // WEEK_MS, "GMS": gps_ms % WEEK_MS}, index=logged.index)


Patcher = _Patcher | _TextPatcher


def _gps_values(patcher: Patcher, r: Mapping[str, Any], velocities: bool) -> dict[str, float]:
    """What one kept fix's GPS message gets: what the attack moved of its position, its velocity (if asked)
    and its indicators. An unmoved velocity is left as logged: a stopped receiver's logged course would
    come back as atan2(0, 0)."""
    values: dict[str, float] = {}
    if any(moved(r[c], r[f"{c}_0"]) for c in ("lat_deg", "lon_deg", "height_m")):
        old_alt = patcher.read(int(r["ofs"]), "Alt")
        values |= {"Lat": r["lat_deg"], "Lng": r["lon_deg"], "Alt": old_alt + (r["height_m"] - r["height_m_0"])}
    ve, vn, vu = r["vel_e_mps"], r["vel_n_mps"], r["vel_u_mps"]
    velocity_moved = any(moved(r[c], r[f"{c}_0"]) for c in ("vel_e_mps", "vel_n_mps", "vel_u_mps"))
    if velocities and velocity_moved and math.isfinite(ve) and math.isfinite(vn):
        values |= {"Spd": math.hypot(ve, vn), "GCrs": math.degrees(math.atan2(ve, vn)) % 360.0}
        # PX4 sdlog2's GPS logs the velocity NED and the course in radians (no such fields in ArduPilot's)
        values |= {"VelN": vn, "VelE": ve, "Cog": math.atan2(ve, vn)}
        if math.isfinite(vu):  # unknown before VZ was logged (2014)
            values["VZ"] = -vu
    for column, field in GPS_INDICATORS.items():
        if moved(r[column], r[f"{column}_0"]):
            values[field] = r[column]
    return values


def _write_gps(patcher: Patcher, plan: pd.DataFrame, velocities: bool) -> None:
    times = _receiver_time(plan)
    for i, r in zip(plan.index, plan.to_dict("records"), strict=True):
        if r["lost"]:
            patcher.put(int(r["ofs"]), {"Status": NO_FIX})
            continue
        values = _gps_values(patcher, r, velocities)
        if i in times.index:  # the spoofer's time: GPS week and ms of week moved together
            values |= {"GWk": float(times.at[i, "GWk"]), "GMS": float(times.at[i, "GMS"])}
            if patcher.has(int(r["ofs"]), "GPSTime"):  # PX4 sdlog2: UTC us since 1970, 0 without time
                utc_us = patcher.read(int(r["ofs"]), "GPSTime")
                shift_us = round(float(r["shift_s"]) * 1000) * 1000
                values["GPSTime"] = utc_us + shift_us if utc_us > 0 else 0.0
        patcher.put(int(r["ofs"]), values)


def _joined_values(plan: pd.DataFrame, ofs_column: str, columns: list[str]) -> pd.DataFrame:
    """One row per message joined to the fixes through `ofs_column`: its `ofs`, the values it carried
    (`<column>_0`, those of the first fix joined to it) and the values it gets (`<column>`): the attacked
    values of the fix nearest it that the attack kept, which is that first fix unless it was lost."""
    joined = plan[plan[ofs_column].notna()].sort_values("t_ns", kind="stable")
    carried = joined.drop_duplicates(ofs_column)[["receiver_id", "t_ns", ofs_column, *(f"{c}_0" for c in columns)]]
    kept = plan.loc[~plan["lost"], ["receiver_id", "t_ns", *columns]].sort_values("t_ns", kind="stable")
    given = pd.merge_asof(carried, kept, on="t_ns", by="receiver_id", direction="nearest")
    return given.rename(columns={ofs_column: "ofs"})


def _write_joined(patcher: Patcher, plan: pd.DataFrame) -> None:
    for ofs_column, fields in JOINED.items():
        if ofs_column not in plan:
            continue
        for r in _joined_values(plan, ofs_column, list(fields)).to_dict("records"):
            values = {field: r[c] for c, field in fields.items() if moved(r[c], r[f"{c}_0"])}
            if values:
                patcher.put(int(r["ofs"]), values)


def _report_plan(log: DataFlash, gps: pd.DataFrame, table: EpochTable, spoofed: EpochTable) -> pd.DataFrame:
    """One row per UBX1 message of a `receiver_status` row of the table: `ofs`, its values as read
    (`<column>_0`) and as attacked. Reports of one receiver at one instant are told apart by their order."""
    _, offset_ns, _ = gps_clock(gps)
    rows = ubx1_reports(log, offset_ns)
    if rows is None or not len(table.receiver_status):
        return pd.DataFrame()
    key = ["receiver_id", "t_s"]
    before, after = (
        s[[*key, *REPORTED]].assign(nth=s.groupby(key, sort=False).cumcount())
        for s in (table.receiver_status, spoofed.receiver_status)
    )
    change = before.merge(after, on=[*key, "nth"], how="left", suffixes=("_0", ""))
    change["t_ns"] = table.absolute_ns(change["t_s"].to_numpy())
    logged = rows[["receiver_id", "t_ns", "ofs"]]
    logged = logged.assign(nth=logged.groupby(["receiver_id", "t_ns"], sort=False).cumcount())
    return logged.merge(change, on=["receiver_id", "t_ns", "nth"], how="inner")


def _write_reports(patcher: Patcher, plan: pd.DataFrame) -> None:
    for r in plan.to_dict("records"):
        values = {field: r[c] for c, field in REPORTED.items() if moved(r[c], r[f"{c}_0"])}
        if values:
            patcher.put(int(r["ofs"]), values)


def _measurement_plan(log: DataFlash, gps: pd.DataFrame, table: EpochTable, spoofed: EpochTable) -> pd.DataFrame:
    """One row per GRXS message of a raw measurement of the table: `ofs`, its values as read (`<column>_0`)
    and as attacked, and `lost` where the attack removed it. The measurements of one satellite at one
    epoch (one per signal) are told apart by their order, which the reader and the attack both keep."""
    reference, offset_ns, _ = gps_clock(gps)
    rows = grxs_rows(log, offset_ns, reference, [])
    if rows is None or not len(table.observations):
        return pd.DataFrame()
    key = ["receiver_id", "t_s", "sv_id"]
    before, after = (
        o[[*key, *MEASURED]].assign(nth=o.groupby(key, sort=False).cumcount())
        for o in (table.observations, spoofed.observations)
    )
    change = before.merge(after, on=[*key, "nth"], how="left", suffixes=("_0", ""), indicator=True)
    change["lost"] = (change.pop("_merge") == "left_only").to_numpy()
    change["t_ns"] = table.absolute_ns(change["t_s"].to_numpy())
    logged = rows[["receiver_id", "t_ns", "sv_id", "ofs"]]
    logged = logged.assign(nth=logged.groupby(["receiver_id", "t_ns", "sv_id"], sort=False).cumcount())
    return logged.merge(change, on=["receiver_id", "t_ns", "sv_id", "nth"], how="inner")


def _write_measurements(patcher: Patcher, plan: pd.DataFrame) -> None:
    """GRXS: what the attack moved of each pseudorange, Doppler and C/N0; a measurement it removed is
    marked as the receiver marks one it could not use (pseudorange not valid), which the reader drops."""
    for r in plan.to_dict("records"):
        ofs = int(r["ofs"])
        if r["lost"]:
            patcher.put(ofs, {"trk": float(int(patcher.read(ofs, "trk")) & ~PR_VALID)})
            continue
        values = {field: r[c] for c, field in MEASURED.items() if moved(r[c], r[f"{c}_0"])}
        if values:
            patcher.put(ofs, values)


def rewrite_dataflash(src: Path, dst: Path, table: EpochTable, spoofed: EpochTable, velocities: bool) -> str:
    """Write `src` to `dst` with the attacked table's fixes in its GPS messages and the messages joined to
    them; returns the note `inject` prints (what was rewritten)."""
    log = open_any_dataflash(Path(src))
    gps = gps_rows(log, [])
    if gps is None:
        raise WriterError(f"{src}: no GPS message to rewrite")
    plan = _plan(gps, table, spoofed)
    patcher: Patcher = _TextPatcher(log) if isinstance(log, TextDataFlash) else _Patcher(log)
    _write_gps(patcher, plan, velocities)
    _write_joined(patcher, plan)
    _write_reports(patcher, _report_plan(log, gps, table, spoofed))
    _write_measurements(patcher, _measurement_plan(log, gps, table, spoofed))
    Path(dst).write_bytes(patcher.output())
    gps_names = set(plan["msg"])
    n_gps = sum(n for name, n in patcher.edited.items() if name in gps_names)
    others = ", ".join(f"{n} {name}" for name, n in sorted(patcher.edited.items()) if name not in gps_names)
    lost = int(plan["lost"].sum())
    note = f"{n_gps} GPS messages rewritten ({len(spoofed.fixes)} fixes in the table"
    note += f"; {lost} lost: Status 1, no fix)" if lost else ")"
    copied = (
        ", every other line copied byte for byte" if isinstance(log, TextDataFlash) else ", every other byte copied"
    )
    return note + (f", {others}" if others else "") + copied
