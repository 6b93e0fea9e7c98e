"""Attacked copies of MAVLink telemetry logs (`.tlog`): the vehicle's GPS packets re-encoded, every other byte kept.

A tlog record is the ground station's 8-byte big-endian UNIX microsecond receive time, then one MAVLink
packet. Each fix row of the table came from one GPS_RAW_INT or GPS2_RAW packet (`readers.tlog.gps_rows`,
which also says where the packet sits); the rows are matched to the packets by the stamp the reader gave
them. A packet whose values the attack moved is decoded with pymavlink, its fields set and packed again
with its own sequence number, system and component ids and the message's CRC_EXTRA, in its own framing:
a v2 packet stays v2 (trailing zeros of the payload cut, as every v2 sender does), a v1 packet stays v1
and keeps its payload length (a MAVLink1 sender sends no extension fields). Its record's receive time
is kept, and every byte outside the rewritten packets is copied.

What a packet gets, where the attack moved it: lat/lon (1e-7 deg); the height's change added to `alt`
and, when sent, `alt_ellipsoid` (the reader reads the ellipsoidal one when there is one); with
`velocities`, ground speed `vel` (cm/s) and course `cog` (cdeg) from the horizontal velocity (MAVLink's
GPS messages carry no vertical one); `eph`/`epv` (DOP x 100), `h_acc`/`v_acc`/`vel_acc` (mm, mm/s),
`satellites_visible`; `time_usec` moved with the receiver's time when it is the receiver's UNIX time
(ArduPilot's). A fix the attack lost gets `fix_type` 1 (no fix), which the reader drops as it drops the
receiver's own fix-less packets. The messages carry no C/N0, AGC, noise or jamming indicator, so a
jammer's copy shows only what it does to the fixes.

Packets copied unchanged although the attack moved their fix, and counted in the note: signed v2 packets
(a new signature needs the link's secret key), packets longer than pymavlink's definition of the message
(fields it does not know would be lost), and packets that are not where the parse said (pymavlink joined
bytes across damage). A packet that fails its CRC is no fix of the table: it is copied as it is.
"""

from __future__ import annotations

import math
import struct
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from readers.tlog import UNIX_US_MIN, gps_rows, packet_length, read_telemetry, tlog_clock, vehicle_of
from spooflens.epoch_table import EpochTable
from spooflens.errors import WriterError
from spooflens.schema import FixType
from spooflens.writers.fix_changes import fix_changes, moved

V1, V2 = 0xFE, 0xFD
SIGNED = 0x01  # MAVLink 2 incompat flag: a signature follows the CRC
NO_FIX = 1  # GPS_FIX_TYPE_NO_FIX
MOTION = ["lat_deg", "lon_deg", "height_m", "vel_e_mps", "vel_n_mps"]
# table column -> (field, scale to the field's unit, its range without the values that mean "unknown":
# 65535 DOP, 255 satellites, 0 accuracy)
INDICATORS = {
    "hdop": ("eph", 100.0, 0, 65534),
    "vdop": ("epv", 100.0, 0, 65534),
    "h_acc_m": ("h_acc", 1000.0, 1, 2**32 - 1),
    "v_acc_m": ("v_acc", 1000.0, 1, 2**32 - 1),
    "vel_acc_mps": ("vel_acc", 1000.0, 1, 2**32 - 1),
    "sats_used": ("satellites_visible", 1.0, 0, 254),
}
ATTACKED = [*MOTION, *INDICATORS]
INT32 = (-(2**31), 2**31 - 1)

# why an attacked fix's packet was copied unchanged -> the note's words
NOT_REWRITTEN = {
    "signed": "signed (a new signature needs the link's key)",
    "longer": "longer than pymavlink's definition of the message",
    "displaced": "not where the parse placed them (damage around them)",
}


def _dialect() -> Any:
    """pymavlink's ardupilotmega dialect, the one the reader parses with (v2: it parses v1 packets too)."""
    from pymavlink.dialects.v20 import ardupilotmega

    return ardupilotmega


def _plan(src: Path, table: EpochTable, spoofed: EpochTable) -> pd.DataFrame:
    """One row per GPS packet of a fix of the table: `ofs`, the fields the reader read (`fields`), the
    fix's values as read (`<column>_0`) and as attacked (NaN where the attack lost it: `lost`), and
    `shift_s`, how far the attack moved the receiver's time. Fixes of one receiver at one stamp are told
    apart by their order, which the reader and the attack both keep."""
    telemetry = read_telemetry(src)
    mine = telemetry.of_system(vehicle_of(src, telemetry.messages))
    rows = gps_rows(mine.messages, tlog_clock(src, mine.messages))
    if not len(rows):
        raise WriterError(f"{src}: no GPS_RAW_INT or GPS2_RAW message to rewrite")
    rows = rows[rows["fix_type"] != FixType.NO_FIX]
    kinds, index = rows["receiver_id"].tolist(), rows["packet"].tolist()
    rows = rows[["receiver_id", "t_ns"]].assign(
        ofs=[mine.offsets[k][i] for k, i in zip(kinds, index, strict=True)],
        fields=[mine.messages[k][i][2] for k, i in zip(kinds, index, strict=True)],
    )
    rows["nth"] = rows.groupby(["receiver_id", "t_ns"], sort=False).cumcount()
    change = fix_changes(table, spoofed, ATTACKED, by_order=True)
    return rows.merge(change, on=["receiver_id", "t_ns", "nth"], how="inner")


def _clipped(value: float, low: int, high: int) -> int:
    return int(min(max(round(value), low), high))


def _position(r: Mapping[str, Any], fields: Mapping[str, Any]) -> dict[str, int]:
    """lat/lon, and the height's change on both altitudes (the reader read the ellipsoidal one if sent)."""
    if not any(moved(r[c], r[f"{c}_0"]) for c in ("lat_deg", "lon_deg", "height_m")):
        return {}
    out = {"lat": _clipped(r["lat_deg"] * 1e7, *INT32), "lon": _clipped(r["lon_deg"] * 1e7, *INT32)}
    dh_mm = round((r["height_m"] - r["height_m_0"]) * 1000.0) if moved(r["height_m"], r["height_m_0"]) else 0
    if dh_mm:
        out["alt"] = _clipped(int(fields["alt"]) + dh_mm, *INT32)
        if int(fields.get("alt_ellipsoid", 0) or 0):
            out["alt_ellipsoid"] = _clipped(int(fields["alt_ellipsoid"]) + dh_mm, *INT32)
    return out


def _velocity(r: Mapping[str, Any]) -> dict[str, int]:
    """Ground speed and course of the attacked horizontal velocity; an unmoved one is left as sent (a stopped
    receiver's course would come back as atan2(0, 0))."""
    ve, vn = r["vel_e_mps"], r["vel_n_mps"]
    if not any(moved(r[c], r[f"{c}_0"]) for c in ("vel_e_mps", "vel_n_mps")):
        return {}
    if not (math.isfinite(ve) and math.isfinite(vn)):
        return {}
    cog = round(math.degrees(math.atan2(ve, vn)) % 360.0 * 100.0) % 36000
    return {"vel": _clipped(math.hypot(ve, vn) * 100.0, 0, 65534), "cog": cog}


def _new_fields(r: Mapping[str, Any], fields: Mapping[str, Any], velocities: bool) -> dict[str, int]:
    """The fields one attacked fix's packet gets (only those the attack moved)."""
    if r["lost"]:
        return {"fix_type": NO_FIX}
    out = _position(r, fields) | (_velocity(r) if velocities else {})
    for column, (field, scale, low, high) in INDICATORS.items():
        if moved(r[column], r[f"{column}_0"]):
            out[field] = _clipped(r[column] * scale, low, high)
    time_usec = int(fields.get("time_usec", 0))
    shift_us = round(float(r["shift_s"]) * 1e6)
    if shift_us and time_usec >= UNIX_US_MIN:  # the receiver's own UNIX time, moved with the spoofer's clock
        out["time_usec"] = time_usec + shift_us
    return {k: v for k, v in out.items() if v != fields.get(k)}


def _framed(header: bytes, payload: bytes, crc_extra: int) -> bytes:
    """A packet of `header` and `payload` with its X.25 checksum (CRC_EXTRA folded in)."""
    crc = _dialect().x25crc(header[1:] + payload)
    crc.accumulate(bytes([crc_extra]))
    return header + payload + struct.pack("<H", crc.crc)


def _repacked(packet: bytes, msg: Any) -> bytes:
    """`msg` (decoded from `packet`, its fields since changed) packed as `packet` was sent: same sequence
    number, system and component, v1 or v2; a v1 payload keeps its length, a v2 header its compat flags."""
    mav = _dialect().MAVLink(None, srcSystem=msg.get_srcSystem(), srcComponent=msg.get_srcComponent())
    mav.seq = msg.get_seq()
    v1 = packet[0] == V1
    new = bytes(msg.pack(mav, force_mavlink1=v1))
    if v1 and len(new) != len(packet):
        # pymavlink packs the extension fields into v1 too; a MAVLink1 sender's packet has none
        return _framed(packet[:6], new[6 : 6 + packet[1]], msg.crc_extra)
    if not v1 and packet[3] != new[3]:
        return _framed(new[:3] + packet[3:4] + new[4:10], new[10:-2], msg.crc_extra)
    return new


def _decoded(data: bytes, ofs: int, fields: Mapping[str, Any]) -> tuple[bytes, Any] | str:
    """The packet at `ofs` and its message, or why it is not rewritten (a key of NOT_REWRITTEN)."""
    n = packet_length(data, ofs)
    if n is None or ofs < 0 or ofs + n > len(data):
        return "displaced"
    packet = data[ofs : ofs + n]
    if packet[0] == V2 and packet[2] & SIGNED:
        return "signed"
    dialect = _dialect()
    try:
        msg = dialect.MAVLink(None).decode(bytearray(packet))
    except dialect.MAVError:  # pymavlink wraps its struct errors in it: not the packet the parse decoded
        return "displaced"
    if msg.to_dict() != dict(fields):
        return "displaced"
    if packet[1] > type(msg).unpacker.size:
        return "longer"
    return packet, msg


def _edits(data: bytes, plan: pd.DataFrame, velocities: bool) -> tuple[dict[int, tuple[int, bytes]], Counter[str]]:
    """Packet offset -> (its length, the packet that replaces it); and how many attacked fixes' packets were
    copied unchanged, by why."""
    edits: dict[int, tuple[int, bytes]] = {}
    skipped: Counter[str] = Counter()
    for r in plan.to_dict("records"):
        values = _new_fields(r, r["fields"], velocities)
        if not values:
            continue
        found = _decoded(data, int(r["ofs"]), r["fields"])
        if isinstance(found, str):
            skipped[found] += 1
            continue
        packet, msg = found
        for field, value in values.items():
            setattr(msg, field, value)
        edits[int(r["ofs"])] = (len(packet), _repacked(packet, msg))
    return edits, skipped


def _spliced(data: bytes, edits: Mapping[int, tuple[int, bytes]]) -> bytes:
    out = bytearray()
    at = 0
    for ofs in sorted(edits):
        n, packet = edits[ofs]
        out += data[at:ofs]
        out += packet
        at = ofs + n
    out += data[at:]
    return bytes(out)


def rewrite_tlog(src: Path, dst: Path, table: EpochTable, spoofed: EpochTable, velocities: bool) -> str:
    """Write `src` to `dst` with the attacked table's fixes in its GPS packets; returns the note `inject`
    prints (what was rewritten, and what was not)."""
    src = Path(src)
    data = src.read_bytes()
    plan = _plan(src, table, spoofed)
    edits, skipped = _edits(data, plan, velocities)
    Path(dst).write_bytes(_spliced(data, edits))
    lost = int(plan["lost"].sum())
    note = f"{len(edits)} GPS packets rewritten ({len(spoofed.fixes)} fixes in the table"
    note += f"; {lost} lost: fix_type 1, no fix)" if lost else ")"
    for why, n in sorted(skipped.items()):
        note += f", {n} attacked fixes' packets copied unchanged: {NOT_REWRITTEN[why]}"
    note += ", every other byte copied"
    if lost or _self_reportmoved(plan):
        note += " (its GPS messages have no C/N0, AGC, noise or jamming indicator to carry a jammer's other marks)"
    return note


def _self_reportmoved(plan: pd.DataFrame) -> bool:
    """Whether the attack moved what the receiver reports of itself (satellites, DOP, accuracies)."""
    return any(bool((plan[c].notna() & plan[f"{c}_0"].notna() & (plan[c] != plan[f"{c}_0"])).any()) for c in INDICATORS)
