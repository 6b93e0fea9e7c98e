"""Attacked copies of u-blox UBX captures: the messages the reader maps edited in place, every other byte kept.

The rest of its description: docs/interference.md ("Notes from the code")."""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from readers.ubx.frames import UbxFrame, fletcher, split_frames
from readers.ubx.messages import LEGACY_FIX, MSG, PVT_LIKE, RAWX_MEAS, sv_ids
from spooflens.epoch_table import EpochTable
from spooflens.errors import WriterError

WEEK_MS = 604_800_000
NAV_PVT, NAV_DOP, NAV_SAT, NAV_STATUS, NAV_TIMEGPS = (1, 0x07), (1, 0x04), (1, 0x35), (1, 0x03), (1, 0x20)
RXM_RAWX, MON_RF, MON_HW, SEC_SIG = (2, 0x15), (0x0A, 0x38), (0x0A, 0x09), (0x27, 0x09)
TIMED = {NAV_PVT, NAV_DOP, NAV_SAT, NAV_STATUS, NAV_TIMEGPS}
MONITORS = (MON_RF, MON_HW, SEC_SIG)
# the messages the reader opens a navigation epoch with (iTOW first in each): a monitor report is stamped
# with the last one's iTOW (the first one's before any), or by its output cycle in a capture without any
EPOCH_OPENERS = {
    key
    for key, name in MSG.items()
    if name in {*PVT_LIKE, *LEGACY_FIX, "NAV-SAT", "NAV-DOP", "NAV-STATUS", "NAV-TIMEGPS", "NAV-TIMEUTC"}
    and name != "LOG-BATCH"  # no iTOW first, and only ever beside fixes (no monitor rows then)
}
REPORT_COLUMNS = ["agc", "noise_per_ms", "jamming_indicator", "jamming_state"]
ReportKey = tuple[bool, int]  # (stamped by an epoch, its iTOW in ms) or (False, its output cycle)
Change = Callable[[str, float], float]  # (column, the message's own value) -> the value to write
FIX_COLUMNS = [
    "lat_deg",
    "lon_deg",
    "height_m",
    "vel_e_mps",
    "vel_n_mps",
    "vel_u_mps",
    "h_acc_m",
    "v_acc_m",
    "vel_acc_mps",
    "sats_used",
    "hdop",
    "vdop",
    "agc",
    "noise_per_ms",
    "jamming_indicator",
    "jamming_state",
]


@dataclass
class _Plan:
    fixes: dict[int, dict[str, float]] = field(default_factory=dict)  # iTOW -> the attacked fix (changed ones)
    before: dict[int, dict[str, float]] = field(default_factory=dict)  # iTOW -> the fix as read
    lost: set[int] = field(default_factory=set)  # iTOWs whose fix the attack removed
    kept: list[int] = field(default_factory=list)  # iTOWs of the attacked fixes, sorted
    sats: dict[tuple[int, str], float] = field(default_factory=dict)  # (iTOW, sv) -> C/N0 change, NaN lost
    raw: dict[tuple[int, str], tuple[float, float, float] | None] = field(default_factory=dict)
    edited: dict[str, int] = field(default_factory=dict)
    # the receiver's monitor reports (`receiver_status`) the attack moved: key -> (as read, as attacked)
    reports: dict[ReportKey, tuple[dict[str, float], dict[str, float]]] = field(default_factory=dict)

    def monitor(self, itow: int) -> dict[str, float] | None:
        """The attacked fix's values at this epoch (the nearest kept one for a lost fix)."""
        if itow in self.fixes:
            return self.fixes[itow]
        if itow in self.lost and self.kept:
            k = int(np.searchsorted(self.kept, itow))
            near = min((j for j in (k - 1, k) if 0 <= j < len(self.kept)), key=lambda j: abs(self.kept[j] - itow))
            return self.fixes.get(self.kept[near])
        return None


def _itow(abs_ns: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(abs_ns, dtype=np.float64) / 1e6).astype(np.int64) % WEEK_MS


def _plan(table: EpochTable, spoofed: EpochTable) -> _Plan:
    plan = _Plan()
    old, new = table.fixes, spoofed.fixes
    old_itow, new_itow = (
        _itow(table.absolute_ns(old["t_s"].to_numpy())),
        _itow(table.absolute_ns(new["t_s"].to_numpy())),
    )
    before = pd.DataFrame(old[FIX_COLUMNS].to_numpy(float), index=old_itow, columns=FIX_COLUMNS)
    after = pd.DataFrame(new[FIX_COLUMNS].to_numpy(float), index=new_itow, columns=FIX_COLUMNS)
    before, after = before[~before.index.duplicated()], after[~after.index.duplicated()]
    plan.lost = {int(i) for i in before.index.difference(after.index)}
    both = before.index.intersection(after.index)
    a, b = after.loc[both].to_numpy(), before.loc[both].to_numpy()
    changed = ~((a == b) | (np.isnan(a) & np.isnan(b))).all(axis=1)
    for itow, row, old_row in zip(both[changed].tolist(), a[changed], b[changed], strict=True):
        plan.fixes[int(itow)] = dict(zip(FIX_COLUMNS, row.tolist(), strict=True))
        plan.before[int(itow)] = dict(zip(FIX_COLUMNS, old_row.tolist(), strict=True))
    plan.kept = sorted(plan.fixes)
    plan.sats = _sky_changes(table, spoofed)
    plan.raw = _raw_changes(table, spoofed)
    plan.reports = _report_changes(table, spoofed)
    return plan


def _report_changes(
    table: EpochTable, spoofed: EpochTable
) -> dict[ReportKey, tuple[dict[str, float], dict[str, float]]]:
    """Each moved `receiver_status` row by the stamp the reader gave it: the iTOW of its epoch (timed
    captures), or its output cycle (its time in whole seconds, in a capture without any epoch); both keys
    are given, the rewriter picks the one its capture's messages were stamped by."""
    old, new = table.receiver_status, spoofed.receiver_status
    if not len(old) or not len(new):
        return {}
    before = old.drop_duplicates("t_s").set_index("t_s")[REPORT_COLUMNS].astype(float)
    after = new.drop_duplicates("t_s").set_index("t_s")[REPORT_COLUMNS].astype(float)
    both = before.index.intersection(after.index)
    a, b = after.loc[both].to_numpy(), before.loc[both].to_numpy()
    moved = ~((a == b) | (np.isnan(a) & np.isnan(b))).all(axis=1)
    ms = np.round(np.asarray(table.absolute_ns(both.to_numpy(float)[moved]), dtype=np.float64) / 1e6).astype(np.int64)
    out: dict[ReportKey, tuple[dict[str, float], dict[str, float]]] = {}
    for t_ms, row_b, row_a in zip(ms.tolist(), b[moved], a[moved], strict=True):
        pair = (
            dict(zip(REPORT_COLUMNS, row_b.tolist(), strict=True)),
            dict(zip(REPORT_COLUMNS, row_a.tolist(), strict=True)),
        )
        out[(True, int(t_ms) % WEEK_MS)] = pair
        if t_ms % 1000 == 0:
            out[(False, int(t_ms) // 1000)] = pair
    return out


def _sky_changes(table: EpochTable, spoofed: EpochTable) -> dict[tuple[int, str], float]:
    old, new = table.satellites, spoofed.satellites
    if not len(old) or not len(new):
        return {}
    keys = ["t_s", "sv_id"]
    joined = old[[*keys, "cn0_dbhz"]].merge(new[[*keys, "cn0_dbhz"]], on=keys, suffixes=("", "_new"))
    a, b = joined["cn0_dbhz_new"].to_numpy(float), joined["cn0_dbhz"].to_numpy(float)
    moved = np.isfinite(b) & ~(a == b)
    itow = _itow(table.absolute_ns(joined["t_s"].to_numpy(float)))
    return {
        (int(i), str(sv)): float(d)
        for i, sv, d in zip(itow[moved], joined["sv_id"].to_numpy()[moved], (a - b)[moved], strict=True)
    }


def _raw_changes(table: EpochTable, spoofed: EpochTable) -> dict[tuple[int, str], tuple[float, float, float] | None]:
    """(RAWX epoch in GPS ns, sv) -> the change of (pseudorange m, Doppler Hz, C/N0 dB), or None: removed."""
    old, new = table.observations, spoofed.observations
    if not len(old):
        return {}
    cols = ["pseudorange_m", "doppler_hz", "cn0_dbhz"]

    def keyed(df: pd.DataFrame) -> pd.DataFrame:
        ns = np.asarray(table.absolute_ns(df["t_s"].to_numpy(float)), dtype=np.int64)
        index = pd.MultiIndex.from_arrays([ns, df["sv_id"].astype(str).to_numpy()])
        out = pd.DataFrame(df[cols].to_numpy(float), index=index, columns=cols)
        return out[~out.index.duplicated()]

    a, b = keyed(new), keyed(old)
    out: dict[tuple[int, str], tuple[float, float, float] | None] = {
        (int(t), str(s)): None for t, s in b.index.difference(a.index)
    }
    both = a.index.intersection(b.index)
    d = np.nan_to_num(a.loc[both].to_numpy() - b.loc[both].to_numpy(), nan=0.0)
    for (t, s), row in zip(both[(d != 0).any(axis=1)], d[(d != 0).any(axis=1)], strict=True):
        out[(int(t), str(s))] = (float(row[0]), float(row[1]), float(row[2]))
    return out


def _frame_bytes(frame: UbxFrame, payload: bytes) -> bytes:
    head = bytes((frame.msg_class, frame.msg_id)) + len(payload).to_bytes(2, "little") + payload
    return b"\xb5\x62" + head + fletcher(head)


def _put(p: bytearray, fmt: str, offset: int, value: float) -> None:
    """A field of the payload set, clipped to its integer type."""
    kind = fmt[-1]
    if kind in "bhiq":
        bits = struct.calcsize(fmt) * 8
        value = min(max(round(value), -(2 ** (bits - 1))), 2 ** (bits - 1) - 1)
    elif kind in "BHIQ":
        bits = struct.calcsize(fmt) * 8
        value = min(max(round(value), 0), 2**bits - 1)
    struct.pack_into(fmt, p, offset, value)


def _scale(new: float, old: float) -> float:
    return new / old if math.isfinite(new) and math.isfinite(old) and old > 0 else 1.0


def _nav_pvt(p: bytearray, plan: _Plan, itow: int) -> bool:
    if len(p) < 80:
        return False
    if itow in plan.lost:
        p[20] = 0  # fixType: no fix
        p[21] &= 0xFE  # gnssFixOK clear
        return True
    fix, old = plan.fixes.get(itow), plan.before.get(itow)
    if fix is None or old is None:
        return False
    if math.isfinite(fix["lat_deg"]):
        dh = fix["height_m"] - old["height_m"]
        _put(p, "<i", 24, fix["lon_deg"] * 1e7)
        _put(p, "<i", 28, fix["lat_deg"] * 1e7)
        _put(p, "<i", 32, struct.unpack_from("<i", p, 32)[0] + dh * 1000)
        _put(p, "<i", 36, struct.unpack_from("<i", p, 36)[0] + dh * 1000)
    ve, vn, vu = fix["vel_e_mps"], fix["vel_n_mps"], fix["vel_u_mps"]
    if math.isfinite(ve) and math.isfinite(vn):
        _put(p, "<i", 48, vn * 1000)
        _put(p, "<i", 52, ve * 1000)
        _put(p, "<i", 60, math.hypot(ve, vn) * 1000)
        if math.isfinite(vu):
            _put(p, "<i", 56, -vu * 1000)
    for offset, col in ((40, "h_acc_m"), (44, "v_acc_m"), (68, "vel_acc_mps")):
        if math.isfinite(fix[col]):
            _put(p, "<I", offset, fix[col] * 1000)
    if math.isfinite(fix["sats_used"]):
        p[23] = int(min(max(fix["sats_used"], 0), 255))
    _put(p, "<H", 76, struct.unpack_from("<H", p, 76)[0] * _scale(fix["hdop"], old["hdop"]))
    return True


def _nav_dop(p: bytearray, plan: _Plan, itow: int) -> bool:
    fix, old = plan.fixes.get(itow), plan.before.get(itow)
    if fix is None or old is None or len(p) < 18:
        return False
    scale = _scale(fix["hdop"], old["hdop"])
    for offset in (4, 6, 8, 14, 16):
        _put(p, "<H", offset, struct.unpack_from("<H", p, offset)[0] * scale)
    for offset, col in ((10, "vdop"), (12, "hdop")):
        value = fix[col] * 100 if math.isfinite(fix[col]) else struct.unpack_from("<H", p, offset)[0] * scale
        _put(p, "<H", offset, value)
    return True


def _nav_sat(p: bytearray, plan: _Plan, itow: int) -> bool:
    if len(p) < 8 or len(p) != 8 + 12 * p[5]:
        return False
    blocks = np.frombuffer(bytes(p[8:]), dtype=np.uint8).reshape(-1, 12)
    ids, ok = sv_ids(blocks[:, 0], blocks[:, 1])
    changed = False
    for k, (sv, good) in enumerate(zip(ids.tolist(), ok.tolist(), strict=True)):
        change = plan.sats.get((itow, sv)) if good else None
        if change is None:
            continue
        at = 8 + 12 * k
        if math.isnan(change):
            p[at + 2] = 0
            flags = struct.unpack_from("<I", p, at + 8)[0]
            struct.pack_into("<I", p, at + 8, (flags & ~0x0F) | 0x01)  # searching, not used
        else:
            p[at + 2] = int(min(max(round(p[at + 2] + change), 0), 255))
        changed = True
    return changed


def _rawx(p: bytearray, plan: _Plan) -> bytearray | None:
    if len(p) < 16 or len(p) != 16 + 32 * p[11]:
        return None
    rcv_tow = struct.unpack_from("<d", p, 0)[0]
    week = struct.unpack_from("<H", p, 8)[0]
    t_ns = round((week * 604800 + rcv_tow) * 1e9)
    meas = np.frombuffer(bytes(p[16:]), dtype=RAWX_MEAS)
    ids, _ = sv_ids(meas["gnssId"], meas["svId"])
    keep = []
    changed = False
    for k, sv in enumerate(ids.tolist()):
        key = (t_ns, sv)
        if key not in plan.raw:
            keep.append(k)
            continue
        change = plan.raw[key]
        changed = True
        if change is None:
            continue
        keep.append(k)
        at = 16 + 32 * k
        d_pr, d_doppler, d_cn0 = change
        struct.pack_into("<d", p, at, struct.unpack_from("<d", p, at)[0] + d_pr)
        struct.pack_into("<f", p, at + 16, struct.unpack_from("<f", p, at + 16)[0] + d_doppler)
        p[at + 26] = int(min(max(round(p[at + 26] + d_cn0), 0), 255))
    if not changed:
        return None
    out = bytearray(p[:16])
    out[11] = len(keep)
    for k in keep:
        out += p[16 + 32 * k : 48 + 32 * k]
    return out


def _fix_values(values: dict[str, float]) -> Change:
    """The attacked fix's value of each column, whatever the message said (kept where it has none)."""

    def change(column: str, own: float) -> float:
        value = values[column]
        return value if math.isfinite(value) else own

    return change


def _report_moves(before: dict[str, float], after: dict[str, float]) -> Change:
    """The move of the message's own `receiver_status` row carried onto its own reading: AGC and noise
    scaled, the jamming indicator raised, by the row's; the monitor's state as the row now says. The row
    holds one message's reading (MON-RF's L1 block before MON-HW's), so another message of the same
    report, or MON-RF's other bands, keep their own level and get the same jammer."""

    def change(column: str, own: float) -> float:
        a, b = after[column], before[column]
        if not (math.isfinite(a) and math.isfinite(b)) or a == b:
            return own
        if column in ("agc", "noise_per_ms"):
            return own * a / b if b > 0 else a
        if column == "jamming_indicator":
            return own + a - b
        return a

    return change


def _monitor(p: bytearray, key: tuple[int, int], change: Change) -> bool:
    """MON-RF (every block), MON-HW, SEC-SIG: AGC, noise, jamming indicator and state moved by `change`."""

    def state_bits(byte: int, shift: int) -> int:
        state = change("jamming_state", float((byte >> shift) & 3))
        return byte if not math.isfinite(state) else (byte & ~(3 << shift)) | ((int(state) & 3) << shift)

    def counters(noise: int, agc: int, jam: int) -> None:
        for col, offset, fmt in (("noise_per_ms", noise, "<H"), ("agc", agc, "<H"), ("jamming_indicator", jam, "<B")):
            value = change(col, float(struct.unpack_from(fmt, p, offset)[0]))
            if math.isfinite(value):
                _put(p, fmt, offset, value)

    if key == MON_RF:
        n = min(p[1], (len(p) - 4) // 24) if len(p) >= 4 else 0
        for b in range(n):
            at = 4 + 24 * b
            p[at + 1] = state_bits(p[at + 1], 0)
            counters(at + 12, at + 14, at + 16)
        return n > 0
    if key == MON_HW and len(p) >= 46:
        p[22] = state_bits(p[22], 2)
        counters(16, 18, 45)
        return True
    if key == SEC_SIG and len(p) >= 2:
        if p[0] == 1 and len(p) >= 5:
            p[4] = state_bits(p[4], 1)
            return True
        if p[0] == 2:
            p[1] = state_bits(p[1], 1)
            return True
    return False


def _report_stamps(frames: list[UbxFrame]) -> dict[int, ReportKey]:
    """Each monitor message's (by its offset) report stamp, as the reader gives it (`readers/ubx`,
    `_State.untimed` and `_receiver_status`): the iTOW of the epoch it follows, the first epoch's before any;
    in a capture without any epoch its output cycle, a new one each time a message name repeats."""
    openers = [f for f in frames if (f.msg_class, f.msg_id) in EPOCH_OPENERS and len(f.payload) >= 4]
    if openers:
        current = struct.unpack_from("<I", openers[0].payload, 0)[0]
        timed: dict[int, ReportKey] = {}
        for f in frames:
            key = (f.msg_class, f.msg_id)
            if key in EPOCH_OPENERS and len(f.payload) >= 4:
                current = struct.unpack_from("<I", f.payload, 0)[0]
            elif key in MONITORS:
                timed[f.offset] = (True, current)
        return timed
    cycles: dict[int, ReportKey] = {}
    seen: set[tuple[int, int]] = set()
    cycle = -1
    for f in frames:
        key = (f.msg_class, f.msg_id)
        if key not in MONITORS:
            continue
        if key in seen or cycle < 0:
            seen.clear()
            cycle += 1
        seen.add(key)
        cycles[f.offset] = (False, cycle)
    return cycles


def _monitor_edit(
    p: bytearray, key: tuple[int, int], plan: _Plan, stamp: ReportKey | None, current: int | None
) -> bool:
    """A monitor message moved by its own report's row where the capture has such rows (no fix), else by
    the attacked fix of its epoch."""
    report = plan.reports.get(stamp) if stamp is not None else None
    if report is not None:
        return _monitor(p, key, _report_moves(*report))
    values = plan.monitor(current) if current is not None and not plan.reports else None
    return values is not None and _monitor(p, key, _fix_values(values))


def rewrite_ubx(src: Path, dst: Path, table: EpochTable, spoofed: EpochTable, velocities: bool) -> str:
    """Write `src` to `dst` with the attacked table's fixes, satellites and measurements in its messages."""
    src, dst = Path(src), Path(dst)
    try:
        data = src.read_bytes()
    except OSError as err:
        raise WriterError(f"{src}: cannot read: {err.strerror or err}") from err
    frames = split_frames(data)
    plan = _plan(table, spoofed)
    out = bytearray()
    pos = 0
    current: int | None = None
    counts: dict[str, int] = {}
    has_pvt = any((f.msg_class, f.msg_id) == NAV_PVT for f in frames.ubx)
    stamps = _report_stamps(frames.ubx)
    if not has_pvt and (plan.fixes or plan.lost):
        # a copy whose fixes were not moved would be an unattacked log with an attack's truth beside it
        raise WriterError(
            f"{src}: the capture's fixes are not NAV-PVT messages (NAV-POSLLH/SOL, its NMEA output or its stored "
            "log): an attack on them cannot be written in UBX"
        )
    for frame in frames.ubx:
        key = (frame.msg_class, frame.msg_id)
        p = bytearray(frame.payload)
        new: bytearray | None = None
        if key in TIMED and len(p) >= 4:
            current = struct.unpack_from("<I", p, 0)[0]
            edit = {NAV_PVT: _nav_pvt, NAV_DOP: _nav_dop, NAV_SAT: _nav_sat}.get(key)
            new = p if edit is not None and edit(p, plan, current) else None
        elif key == RXM_RAWX:
            new = _rawx(p, plan)
        elif key in MONITORS:
            new = p if _monitor_edit(p, key, plan, stamps.get(frame.offset), current) else None
        if new is None or bytes(new) == frame.payload:
            continue
        name = {NAV_PVT: "NAV-PVT", NAV_DOP: "NAV-DOP", NAV_SAT: "NAV-SAT", RXM_RAWX: "RXM-RAWX"}.get(key, "monitor")
        counts[name] = counts.get(name, 0) + 1
        out += data[pos : frame.offset] + _frame_bytes(frame, bytes(new))
        pos = frame.offset + frame.raw_length
    out += data[pos:]
    try:
        dst.write_bytes(bytes(out))
    except OSError as err:
        raise WriterError(f"{dst}: cannot write: {err.strerror or err}") from err
    edited = ", ".join(f"{n} {name}" for name, n in sorted(counts.items())) or "no message"
    note = f"{edited} rewritten ({len(plan.lost)} fixes lost), every other byte copied"
    return note
