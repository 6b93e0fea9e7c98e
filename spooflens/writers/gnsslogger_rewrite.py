"""Spoofed copies of Android GnssLogger logs: GPS-provider Fix lines edited, every other line kept.

Each fix row of the table came from one `Fix` line of the GPS provider; its latitude, longitude and altitude
fields are replaced by the spoofed values (and, with `velocities`, its speed and bearing; where the attack
moved the receiver's time, its UnixTimeMillis; where it inflated the reported accuracies, its accuracy
fields), in the field positions the file's own `# Fix,...` header gives; a fix the attack removed (lost under
interference) loses its line. Lines are found as the reader placed them: by the phone's clock (`fix_clock`).
A pseudorange the attack moved (a counterfeit satellite's delay, a weakened signal's code noise) is written
into its Raw line's ReceivedSvTimeNanos, the satellite's own transmit time as received: `d` metres later is
`d / c` ns earlier (whole nanoseconds: 0.3 m; the receiver's clock fields stay as logged). What interference
does to the signals is written: each satellite's Cn0DbHz moved by the attack's change (Raw lines of every
signal of it, and its Status lines), lost satellites' Raw lines removed (Status: Cn0DbHz 0, not used in the
fix), the AgcDb of the Raw and Agc lines moved as the fixes' AGC was.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from readers.gnsslogger import FIX_NAMES, android_sv_ids, android_systems, fix_clock, gps_fixes, split_file
from spooflens.constants import SPEED_OF_LIGHT_MPS
from spooflens.epoch_table import EpochTable, gps_ns_of_unix_ns
from spooflens.errors import WriterError
from spooflens.writers.fix_changes import clock_shifts


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
    signals, ranges = _signal_changes(table, spoofed)
    sky = _sky_changes(table, spoofed)
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
    fix_edits = _fix_changes(table, spoofed)
    headers = _headers(lines)
    changed = 0
    out = []
    signal_lines = [0, 0]  # edited, removed
    for line in lines:
        if line.startswith(("Raw,", "Status,", "Agc,")):
            new = _signal_line(line, headers, signals, ranges, sky, fix_edits, table.time_reference)
            signal_lines[0] += new is not None and new != line
            signal_lines[1] += new is None
            if new is not None:
                out.append(new)
            continue
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
        if row is not None and row in fix_edits.removed:
            changed += 1
            continue
        v = values.get(row) if row is not None else None
        if v is None or row is None:
            out.append(line)
            continue
        for key, scale in fix_edits.accuracy.get(row, {}).items():
            i = index(key)
            if i is not None and fields[1 + i].strip():
                fields[1 + i] = repr(float(fields[1 + i]) * scale)
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
    note = f"{changed} GPS Fix lines rewritten ({len(fixes)} fixes in the table"
    note += f", {len(fix_edits.removed)} lost)" if fix_edits.removed else ")"
    if signal_lines[0] or signal_lines[1]:
        note += f"; {signal_lines[0]} Raw/Status/Agc lines with their C/N0 or AGC moved, {signal_lines[1]} removed"
        if ranges:
            note += f" ({len(ranges)} pseudoranges moved in their ReceivedSvTimeNanos)"
        return note + ", every other line copied"
    return note + ", Raw and every other line copied"


Key = tuple[int, str]  # (ns on the table's clock, sv id)


def _keys(frame: pd.DataFrame, table: EpochTable) -> list[Key]:
    ns = table.absolute_ns(frame["t_s"].to_numpy(float))
    return list(zip(np.asarray(ns).tolist(), frame["sv_id"].astype(str).tolist(), strict=True))


def _signal_changes(table: EpochTable, spoofed: EpochTable) -> tuple[dict[Key, float | None], dict[Key, float]]:
    """(epoch, satellite) -> the C/N0 change of its Raw measurements (None: the satellite was lost), and
    -> the pseudorange change (m) where the attack moved it."""
    before, after = table.observations, spoofed.observations
    if not len(before) or after.equals(before):
        return {}, {}
    old = pd.DataFrame(before[["pseudorange_m", "cn0_dbhz"]].to_numpy(float), index=_keys(before, table))
    new = pd.DataFrame(after[["pseudorange_m", "cn0_dbhz"]].to_numpy(float), index=_keys(after, table))
    old = old[~old.index.duplicated()]
    new = new[~new.index.duplicated()]
    out: dict[Key, float | None] = {k: None for k in old.index.difference(new.index)}
    both = old.index.intersection(new.index)
    o, n = old.loc[both].to_numpy(), new.loc[both].to_numpy()
    moved_range = np.isfinite(o[:, 0]) & np.isfinite(n[:, 0]) & (n[:, 0] != o[:, 0])
    moved_cn0 = np.isfinite(o[:, 1]) & np.isfinite(n[:, 1]) & (n[:, 1] != o[:, 1])
    for key, d in zip(both[moved_cn0], (n[:, 1] - o[:, 1])[moved_cn0], strict=True):
        out[key] = float(d)
    ranges = {k: float(d) for k, d in zip(both[moved_range], (n[:, 0] - o[:, 0])[moved_range], strict=True)}
    return out, ranges


def _sky_changes(table: EpochTable, spoofed: EpochTable) -> dict[Key, float]:
    """(time, satellite) of the Status records -> the C/N0 change (dB; NaN: lost) where the attack made
    one, for every signal of the satellite."""
    before, after = table.satellites, spoofed.satellites
    if not len(before) or not len(after) or after.equals(before):
        return {}
    old = pd.Series(before["cn0_dbhz"].to_numpy(float), index=_keys(before, table))
    new = pd.Series(after["cn0_dbhz"].to_numpy(float), index=_keys(after, table))
    new = new[~new.index.duplicated()]
    old = old[~old.index.duplicated()].reindex(new.index)
    moved = old.notna() & ~(new == old)
    return {k: float(v) for k, v in (new - old)[moved].items()}


class _FixChanges:
    """What the attack did to the fixes besides moving them: lost ones, inflated accuracies, AGC."""

    def __init__(self, removed: set[int], accuracy: dict[int, dict[str, float]], agc: pd.Series) -> None:
        self.removed, self.accuracy, self.agc = removed, accuracy, agc

    def agc_change(self, t_ns: int) -> float:
        """The AGC change (dB) of the fix nearest this raw epoch within 1 s (0 if none), as the reader
        joins a raw epoch's AgcDb to the fixes."""
        if not len(self.agc):
            return 0.0
        stamps = self.agc.index.to_numpy(np.int64)
        k = int(np.searchsorted(stamps, t_ns))
        near = min((j for j in (k - 1, k) if 0 <= j < len(stamps)), key=lambda j: abs(int(stamps[j]) - t_ns))
        return float(self.agc.iloc[near]) if abs(int(stamps[near]) - t_ns) <= 1_000_000_000 else 0.0


def _fix_changes(table: EpochTable, spoofed: EpochTable) -> _FixChanges:
    cols = {"accuracy": "h_acc_m", "v_acc": "v_acc_m", "speed_acc": "vel_acc_mps"}
    old = table.fixes.set_index(table.absolute_ns(table.fixes["t_s"].to_numpy(float)))
    new = spoofed.fixes.set_index(table.absolute_ns(spoofed.fixes["t_s"].to_numpy(float)))
    old, new = old[~old.index.duplicated()], new[~new.index.duplicated()]
    removed = {int(t) for t in old.index.difference(new.index)}
    both = old.index.intersection(new.index)
    accuracy: dict[int, dict[str, float]] = {}
    for key, col in cols.items():
        a, b = new.loc[both, col].to_numpy(float), old.loc[both, col].to_numpy(float)
        ratio = np.where(np.isfinite(a) & np.isfinite(b) & (b > 0) & (a != b), a / np.where(b > 0, b, 1.0), np.nan)
        for t, r in zip(both.tolist(), ratio.tolist(), strict=True):
            if math.isfinite(r):
                accuracy.setdefault(int(t), {})[key] = r
    agc = (new.loc[both, "agc"] - old.loc[both, "agc"]).dropna()
    return _FixChanges(removed, accuracy, agc[agc != 0].sort_index())


def _headers(lines: list[str]) -> dict[str, list[str]]:
    out = {}
    for line in lines:
        if line.startswith("#"):
            body = line[1:].strip()
            name = body.split(",", 1)[0].strip()
            if name in ("Raw", "Status", "Agc") and "," in body:
                out[name] = [c.strip() for c in body.split(",")][1:]
    return out


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return math.nan


def _signal_line(
    line: str,
    headers: dict[str, list[str]],
    signals: dict[Key, float | None],
    ranges: dict[Key, float],
    sky: dict[Key, float],
    fixes: _FixChanges,
    reference: str,
) -> str | None:
    """One Raw, Status or Agc line as the attack left it; None to remove it."""
    end = line[len(line.rstrip("\r\n")) :]
    fields = line.rstrip("\r\n").split(",")
    kind = fields[0]
    cols = headers.get(kind)
    if cols is None or len(fields) - 1 < len(cols):
        return line

    def at(name: str) -> int | None:
        return 1 + cols.index(name) if name in cols else None

    def value(name: str) -> float:
        i = at(name)
        return _number(fields[i]) if i is not None else math.nan

    if kind in ("Raw", "Agc"):
        try:
            tag = int(fields[at("TimeNanos") or 0]) - int(fields[at("FullBiasNanos") or 0])
        except ValueError:
            return line
        bias = value("BiasNanos")
        tag -= round(bias) if math.isfinite(bias) else 0
        if not signals and not ranges and not len(fixes.agc):
            return line
        i_agc = at("AgcDb")
        change = fixes.agc_change(tag)
        if i_agc is not None and change and math.isfinite(value("AgcDb")):
            fields[i_agc] = repr(round(value("AgcDb") + change, 3))
        if kind == "Raw":
            sv = str(
                android_sv_ids(android_systems(np.array([value("ConstellationType")])), np.array([value("Svid")]))[0]
            )
            key = (tag, sv)
            if key in signals:
                d = signals[key]
                if d is None:
                    return None
                i = at("Cn0DbHz")
                if i is not None and math.isfinite(value("Cn0DbHz")):
                    fields[i] = repr(round(value("Cn0DbHz") + d, 3))
            i_sv = at("ReceivedSvTimeNanos")
            if key in ranges and i_sv is not None:
                try:  # d metres later: the signal left the satellite d / c earlier
                    sent = int(fields[i_sv])
                except ValueError:
                    return line
                fields[i_sv] = str(sent - round(ranges[key] / SPEED_OF_LIGHT_MPS * 1e9))
    else:  # Status: GnssStatus by the UTC millisecond
        unix_ns = int(value("UnixTimeMillis") * 1_000_000) if math.isfinite(value("UnixTimeMillis")) else 0
        t_ns = int(gps_ns_of_unix_ns(np.array([unix_ns]))[0]) if reference == "gps" else unix_ns
        sv = str(android_sv_ids(android_systems(np.array([value("ConstellationType")])), np.array([value("Svid")]))[0])
        new = sky.get((t_ns, sv))
        i = at("Cn0DbHz")
        if new is None or i is None:
            return line
        old = value("Cn0DbHz")
        if math.isnan(new):
            fields[i] = "0.0"
            used = at("UsedInFix")
            if used is not None:
                fields[used] = "false" if fields[used].strip().lower() in ("true", "false") else "0"
        elif math.isfinite(old) and old > 0:
            fields[i] = repr(round(old + new, 3))
    return ",".join(fields) + end
