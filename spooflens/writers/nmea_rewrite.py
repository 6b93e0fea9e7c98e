"""A spoofed (or jammed) copy of an NMEA 0183 log: positions and receiver indicators edited in place, every
other byte unchanged.

The log is read the way the reader reads it (`readers.nmea.decode_log` and `assemble`), so every fix
row of the table is tied to the sentences of its epoch. For each row the attack changed, every GGA,
GNS, RMC and GLL sentence of that epoch is moved by the attack's offset of that row (spoofed minus
clean latitude and longitude; each sentence keeps its own small disagreement with the others, as the
receiver wrote them), with the same number of decimals and hemisphere letters following the sign;
GGA/GNS altitudes move by the height offset where the sentence has one; when the attack moves the
reported velocity, RMC and VTG get their own velocity plus the offset, as speed and course. Where the
attack changed what the receiver reports about itself (interference): satellites used and HDOP in
GGA/GNS, the DOPs and the used satellites in GSA, the position sigmas in GST (scaled as the reported
accuracies), each satellite's C/N0 in GSV (every signal of it moved by the same dB, blank when lost);
a fix the attack removed becomes GGA quality 0, RMC/GLL status V, GNS mode N. Each edited sentence gets its
checksum recomputed; logger prefixes, TAG blocks, line endings and every other sentence are copied as they
were.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from pynmeagps.nmeahelpers import calc_checksum

from readers.nmea import decode_log
from readers.nmea.assembly import Epoch, assemble, nmea_sv_id
from readers.nmea.sentences import Decoded
from spooflens.constants import KNOT_MPS
from spooflens.epoch_table import EpochTable
from spooflens.errors import WriterError

Values = tuple[float, float, float, float, float, float]  # offsets of lat, lon (deg), h, ve, vn, vu
_COLS = ["lat_deg", "lon_deg", "height_m", "vel_e_mps", "vel_n_mps", "vel_u_mps"]


def _decimals(text: str) -> int:
    return len(text.partition(".")[2]) if "." in text else 0


def _angle(value: float, template: str, degree_digits: int) -> str:
    """An NMEA ddmm.mmmm / dddmm.mmmm field for |value| degrees, with the template's decimals."""
    k = _decimals(template)
    minutes_total = round(abs(value) * 60.0, k)
    degrees, minutes = divmod(minutes_total, 60.0)
    width = 3 + k if k else 2
    return f"{int(degrees):0{degree_digits}d}{minutes:0{width}.{k}f}"


def _number(value: float, template: str) -> str:
    return f"{value:.{_decimals(template)}f}"


def _with_checksum(body: str, old: bytes) -> bytes:
    check = calc_checksum(body[1:])
    lower = old[-2:].decode("latin-1").islower()  # written as the talker wrote its own
    return f"{body}*{check.lower() if lower else check}".encode("latin-1")


def _fields(d: Decoded) -> list[str]:
    text = d.sentence.text.decode("latin-1")
    star = text.rfind("*")
    return (text[:star] if star >= 0 else text).split(",")


def _degrees(field: str, hemisphere: str, degree_digits: int) -> float:
    value = float(field[:degree_digits]) + float(field[degree_digits:]) / 60.0
    return -value if hemisphere in ("S", "W") else value


def _move_position(f: list[str], i_lat: int, dlat: float, dlon: float) -> None:
    if f[i_lat] and f[i_lat + 2]:
        lat = _degrees(f[i_lat], f[i_lat + 1], 2) + dlat
        lon = (_degrees(f[i_lat + 2], f[i_lat + 3], 3) + dlon + 180.0) % 360.0 - 180.0
        f[i_lat] = _angle(lat, f[i_lat], 2)
        f[i_lat + 1] = "N" if lat >= 0 else "S"
        f[i_lat + 2] = _angle(lon, f[i_lat + 2], 3)
        f[i_lat + 3] = "E" if lon >= 0 else "W"


def _moved_velocity(speed_knots: str, course: str, dve: float, dvn: float) -> tuple[float, float]:
    """(speed m/s, course deg) of a sentence's own speed and course plus a velocity offset."""
    v = float(speed_knots) * KNOT_MPS
    c = math.radians(float(course)) if course else 0.0
    return _speed_course(v * math.sin(c) + dve, v * math.cos(c) + dvn)


def _speed_course(ve: float, vn: float) -> tuple[float, float]:
    return math.hypot(ve, vn), math.degrees(math.atan2(ve, vn)) % 360.0


def _moved(f: list[str], kind: str, offsets: Values, velocity: bool) -> None:
    """The sentence's fields moved by the attack's offsets (position, and the velocity if asked)."""
    dlat, dlon, dh, dve, dvn, _ = offsets
    if kind in ("GGA", "GNS"):
        _move_position(f, 2, dlat, dlon)
        if f[9] and dh:
            f[9] = _number(float(f[9]) + dh, f[9])
    elif kind == "RMC":
        _move_position(f, 3, dlat, dlon)
        if velocity and f[7]:
            speed, course = _moved_velocity(f[7], f[8], dve, dvn)
            f[7] = _number(speed / KNOT_MPS, f[7])
            if f[8]:
                f[8] = _number(course, f[8])
    elif kind == "GLL":
        _move_position(f, 1, dlat, dlon)
    elif kind == "VTG" and velocity and (f[5] or f[7]):
        knots = f[5] if f[5] else str(float(f[7]) / 3.6 / KNOT_MPS)
        speed, course = _moved_velocity(knots, f[1], dve, dvn)
        if f[1] and f[3]:  # the magnetic course turns with the true one
            f[3] = _number((float(f[3]) + course - float(f[1])) % 360.0, f[3])
        if f[1]:
            f[1] = _number(course, f[1])
        if f[5]:
            f[5] = _number(speed / KNOT_MPS, f[5])
        if f[7]:
            f[7] = _number(speed * 3.6, f[7])


def edited(d: Decoded, offsets: Values, velocity: bool) -> bytes | None:
    """The sentence moved by the attack's offsets, or None when it carries none of those values."""
    return _rewritten(d, lambda f: _moved(f, d.kind, offsets, velocity))


def _rewritten(d: Decoded, change: Callable[[list[str]], None]) -> bytes | None:
    f = _fields(d)
    try:
        change(f)
    except (ValueError, IndexError):
        return None
    new = _with_checksum(",".join(f), d.sentence.text)
    return None if new == d.sentence.text else new


def _epoch_sentence(d: Decoded, offsets: Values, velocity: bool, rep: Reported | None) -> bytes | None:
    """One sentence of an attacked epoch: moved, and its self-report as the attack left it."""

    def change(f: list[str]) -> None:
        _moved(f, d.kind, offsets, velocity)
        if rep is not None:
            _report(f, d, rep)

    return _rewritten(d, change)


@dataclass
class Reported:
    """What the attack changed in one epoch's self-report (NaN: unchanged, or not in the table)."""

    sats_used: float = math.nan
    hdop: float = math.nan
    vdop: float = math.nan
    h_scale: float = math.nan  # new / old reported horizontal accuracy
    v_scale: float = math.nan
    lost: bool = False  # the attack removed the fix
    cn0_change: dict[str, float] = field(default_factory=dict)  # sv id -> dB (NaN: lost)


def _count(value: float, template: str) -> str:
    n = round(value)
    return f"{n:0{len(template)}d}" if template.isdigit() else f"{n}"


def _report(f: list[str], d: Decoded, rep: Reported) -> None:
    """The epoch's self-report as the attack left it, in the sentence's own fields and formats."""
    kind = d.kind
    if kind in ("GGA", "GNS"):
        if rep.lost:
            if kind == "GGA":
                f[6] = "0"
            else:
                f[6] = "N" * max(len(f[6]), 1)
        if math.isfinite(rep.sats_used) and f[7]:
            f[7] = _count(rep.sats_used, f[7])
        if math.isfinite(rep.hdop) and f[8]:
            f[8] = _number(rep.hdop, f[8])
    elif kind in ("RMC", "GLL") and rep.lost:
        i = 2 if kind == "RMC" else 6
        f[i] = "V"
        mode = 12 if kind == "RMC" else 7
        if len(f) > mode and f[mode]:
            f[mode] = "N"
    elif kind == "GSA":
        if math.isfinite(rep.hdop) and f[16]:
            f[16] = _number(rep.hdop, f[16])
        if math.isfinite(rep.vdop) and len(f) > 17 and f[17]:
            f[17] = _number(rep.vdop, f[17])
        for i in range(3, 15):
            if f[i].isdigit() and math.isnan(rep.cn0_change.get(nmea_sv_id(d.talker, int(f[i])) or "", 0.0)):
                f[i] = ""  # a satellite the receiver lost is not used
    elif kind == "GST":
        for i, scale in ((6, rep.h_scale), (7, rep.h_scale), (8, rep.v_scale)):
            if math.isfinite(scale) and len(f) > i and f[i]:
                f[i] = _number(float(f[i]) * scale, f[i])
    elif kind == "GSV":
        for i in range(7, len(f), 4):
            if not f[i - 3].isdigit():
                continue
            sv = nmea_sv_id(d.talker, int(f[i - 3]))
            change = rep.cn0_change.get(sv or "")
            if change is None or not f[i]:
                continue
            f[i] = "" if math.isnan(change) else _count(min(max(float(f[i]) + change, 0.0), 99.0), f[i])


def _changed_rows(table: EpochTable, spoofed: EpochTable) -> dict[tuple[str, int], tuple[Values, bool]]:
    """(receiver, fix ns) -> (spoofed minus clean values, velocity changed) for every fix the attack moved."""
    out: dict[tuple[str, int], tuple[Values, bool]] = {}
    for rid, rows in spoofed.fixes.groupby("receiver_id", sort=False):
        orig = table.fixes_of(str(rid))
        t_ns = table.absolute_ns(rows["t_s"].to_numpy())
        before = orig.set_index(table.absolute_ns(orig["t_s"].to_numpy()))[_COLS]
        after = pd.DataFrame(rows[_COLS].to_numpy(float), index=t_ns, columns=_COLS)
        common = after.index.intersection(before.index)
        a, b = after.loc[common].to_numpy(float), before.loc[common].to_numpy(float)
        same = (a == b) | (np.isnan(a) & np.isnan(b))
        delta = np.where(same, 0.0, a - b)
        for t, row, eq in zip(common.tolist(), delta, same, strict=True):
            if not eq.all():
                d = np.nan_to_num(row, nan=0.0).tolist()
                out[(str(rid), int(t))] = ((d[0], d[1], d[2], d[3], d[4], d[5]), not eq[3:].all())
    return out


def _ratio(new: float, old: float) -> float:
    return new / old if math.isfinite(new) and math.isfinite(old) and old > 0 and new != old else math.nan


def _reported_changes(table: EpochTable, spoofed: EpochTable) -> dict[tuple[str, int], Reported]:
    """(receiver, fix ns) -> what the attack changed in that epoch's self-report, for every epoch it did."""
    out: dict[tuple[str, int], Reported] = {}
    cols = ["sats_used", "hdop", "vdop", "h_acc_m", "v_acc_m"]
    for rid in table.receivers():
        orig = table.fixes_of(rid)
        t_orig = table.absolute_ns(orig["t_s"].to_numpy())
        new = spoofed.fixes_of(rid) if rid in spoofed.receivers() else orig.iloc[:0]
        after = pd.DataFrame(new[cols].to_numpy(float), index=table.absolute_ns(new["t_s"].to_numpy()), columns=cols)
        before = pd.DataFrame(orig[cols].to_numpy(float), index=t_orig, columns=cols)
        for t in t_orig.tolist():
            if t not in after.index:
                out[(rid, int(t))] = Reported(lost=True)
                continue
            a, b = after.loc[t], before.loc[t]
            if isinstance(a, pd.DataFrame) or isinstance(b, pd.DataFrame):
                continue  # two fixes at one time: nothing to tell them apart by
            sats, hdop, vdop = (
                float(a[c]) if float(a[c]) != float(b[c]) and math.isfinite(a[c]) else math.nan for c in cols[:3]
            )
            h_scale = _ratio(float(a["h_acc_m"]), float(b["h_acc_m"]))
            rep = Reported(sats, hdop, vdop, h_scale, _ratio(float(a["v_acc_m"]), float(b["v_acc_m"])))
            if any(math.isfinite(x) for x in (rep.sats_used, rep.hdop, rep.vdop, rep.h_scale, rep.v_scale)):
                out[(rid, int(t))] = rep
    for (rid, t), change in _cn0_changes(table, spoofed).items():
        out.setdefault((rid, t), Reported()).cn0_change = change
    return out


def _cn0_changes(table: EpochTable, spoofed: EpochTable) -> dict[tuple[str, int], dict[str, float]]:
    """(receiver, epoch ns) -> sv id -> the C/N0 change the attack made (NaN: the satellite was lost)."""
    before, after = table.satellites, spoofed.satellites
    if not len(before) or not len(after):
        return {}
    keys = ["receiver_id", "t_s", "sv_id"]
    joined = before[[*keys, "cn0_dbhz"]].merge(after[[*keys, "cn0_dbhz"]], on=keys, suffixes=("", "_new"))
    old, new = joined["cn0_dbhz"].to_numpy(float), joined["cn0_dbhz_new"].to_numpy(float)
    moved = np.isfinite(old) & ~(new == old)
    joined = joined[moved].assign(
        change=(new - old)[moved], t_ns=table.absolute_ns(joined["t_s"].to_numpy(float)[moved])
    )
    out: dict[tuple[str, int], dict[str, float]] = {}
    for (rid, t), g in joined.groupby(["receiver_id", "t_ns"], sort=False):
        out[(str(rid), int(t))] = dict(zip(g["sv_id"].astype(str), g["change"].astype(float), strict=True))
    return out


def rewrite_nmea_log(src: Path, dst: Path, table: EpochTable, spoofed: EpochTable, velocities: bool) -> str:
    """Write `src` (a file or a directory of NMEA logs) to `dst` with the spoofed fixes in it."""
    src, dst = Path(src), Path(dst)
    files, skipped = decode_log(src)
    assembled = assemble(files, list(skipped))
    epochs: dict[tuple[str, int], tuple[Epoch, Path]] = {**assembled.fixless_epochs, **assembled.fix_epochs}
    edits: dict[Path, list[tuple[int, int, bytes]]] = {f.scan.path: [] for f in files}
    changed = _changed_rows(table, spoofed)
    reported = _reported_changes(table, spoofed)
    missing = 0
    for key in dict.fromkeys([*changed, *reported]):
        found = epochs.get(key)
        if found is None:
            missing += key in changed
            continue
        epoch, path = found
        values, velocity = changed.get(key, ((0.0, 0.0, 0.0, 0.0, 0.0, 0.0), False))
        for d in epoch.sentences:
            new = _epoch_sentence(d, values, velocity and velocities, reported.get(key))
            if new is not None:
                edits[path].append((d.sentence.start, d.sentence.end, new))
    n = 0
    if src.is_dir():
        dst.mkdir(parents=True, exist_ok=True)
    for f in files:
        data = f.scan.data
        out = bytearray()
        pos = 0
        for start, end, new in sorted(set(edits[f.scan.path])):
            out += data[pos:start] + new
            pos = end
            n += 1
        out += data[pos:]
        target = dst / f.scan.path.name if src.is_dir() else dst
        try:
            target.write_bytes(bytes(out))
        except OSError as err:
            raise WriterError(f"{target}: cannot write: {err}") from err
    lost = sum(r.lost for r in reported.values())
    note = f"{n} sentences rewritten for {len(changed) - missing} spoofed fixes"
    note += f" and {len(reported)} epochs' self-reports ({lost} fixes lost)" if reported else ""
    note += ", every other byte copied"
    return note + (f"; {missing} spoofed fixes matched no epoch of the log" if missing else "")
