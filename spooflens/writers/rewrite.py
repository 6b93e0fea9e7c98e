"""Rewrite a log in its own format with new fix values, every other message untouched.

This is how `spooflens inject` makes a spoofed copy of a real log: fix (and, if asked, GNSS velocity)
messages, and time references where the attack moved the receiver's time, are matched to rows of the
modified fixes frame by the stamp the reader used (header stamp, or log time when the stamp is zero),
decoded, changed and re-encoded; everything else is copied byte for byte, with its original log time.
Containers: MCAP (ROS1, ROS2, JSON, protobuf channels), ROS1 bags, ROS2 bags (sqlite3 or MCAP
storage). CSV and ULog logs are rewritten through their writers (a ULog keeps only the streams
spooflens maps, which the caller reports); RINEX observation files by editing their fields in place
(`rinex_rewrite.py`), so attacks on raw pseudoranges land too.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

from readers import formats, foxglove_messages, ros_messages, sniff_format
from readers.streams import match_velocities, velocity_receiver
from spooflens.epoch_table import EpochTable
from spooflens.errors import WriterError, one_line
from spooflens.writers.fix_changes import clock_shifts

# stamp ns -> (lat, lon, h, ve, vn, vu) per receiver topic
Replacement = dict[int, tuple[float, float, float, float, float, float]]


@dataclasses.dataclass
class _Plan:
    fixes: dict[str, Replacement]
    # velocity topic -> (receiver topic, velocity stamp -> the fix stamp whose values it carries)
    velocity_of: dict[str, tuple[str, dict[int, int]]]
    # time reference topic -> its message stamp -> ns the attack moved the receiver's time (inject's `clock`)
    clock_of: dict[str, dict[int, int]] = dataclasses.field(default_factory=dict)
    changed: int = 0


def _plan(table: EpochTable, spoofed: pd.DataFrame, velocities: bool, velocity_stamps: dict[str, np.ndarray]) -> _Plan:
    """What to write: each receiver's fix values by stamp, and each velocity message's fix, matched as
    the reader matched them (`readers.streams.match_velocities`, to the receiver the reader chose)."""
    fixes: dict[str, Replacement] = {}
    for rid, rows in spoofed.groupby("receiver_id", sort=False):
        t_ns = table.absolute_ns(rows["t_s"].to_numpy())
        vals = rows[["lat_deg", "lon_deg", "height_m", "vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy(float)
        fixes[str(rid)] = {int(t): tuple(v) for t, v in zip(t_ns, vals, strict=True)}
    velocity_of: dict[str, tuple[str, dict[int, int]]] = {}
    if velocities:
        for s in table.streams:
            if s.role != "vel" or s.topic not in velocity_stamps or not fixes:
                continue
            target = s.receiver if s.receiver in fixes else velocity_receiver(s.topic, list(fixes), None)
            fix_ns = np.array(sorted(fixes[target]), dtype=np.int64)
            vel_ns = velocity_stamps[s.topic]
            match = match_velocities(fix_ns, vel_ns)
            velocity_of[s.topic] = (target, {int(vel_ns[j]): int(fix_ns[i]) for i, j in enumerate(match) if j >= 0})
    return _Plan(fixes, velocity_of, _clock_plan(table, spoofed, velocity_stamps))


def _clock_plan(table: EpochTable, spoofed: pd.DataFrame, stamps: dict[str, np.ndarray]) -> dict[str, dict[int, int]]:
    """For each time reference topic, the change of the receiver's time at each of its messages, matched to
    the fixes as the reader matched them; only the messages the attack moved."""
    shifts = clock_shifts(table, spoofed)
    out: dict[str, dict[int, int]] = {}
    for s in table.streams:
        if s.role != "timeref" or s.topic not in stamps:
            continue
        mine = shifts[shifts["receiver_id"] == s.receiver]
        fix_ns = mine["t_ns"].to_numpy()
        ref_ns = stamps[s.topic]
        match = match_velocities(fix_ns, ref_ns)
        d_ns = np.round(mine["shift_s"].to_numpy() * 1e9).astype(np.int64)
        out[s.topic] = {int(ref_ns[j]): int(d_ns[i]) for i, j in enumerate(match) if j >= 0 and d_ns[i] != 0}
    return out


def _ros_stamp(msg: Any) -> int:
    return ros_messages.stamp_ns(msg.header)


class _RosEditor:
    """Re-encodes the ROS messages a plan changes; `edit` returns None for messages left alone."""

    def __init__(self, plan: _Plan, deserialize: Callable[[bytes, str], Any], serialize: Callable[[Any, str], Any]):
        self.plan, self.deserialize, self.serialize = plan, deserialize, serialize

    def edit(self, topic: str, msgtype: str, raw: bytes, log_time: int) -> bytes | None:
        kind = ros_messages.kind_of(msgtype)
        if kind in ("navsatfix", "gpsfix") and topic in self.plan.fixes:
            msg = self.deserialize(raw, msgtype)
            stamp = _ros_stamp(msg) or log_time
            values = self.plan.fixes[topic].get(stamp)
            if values is None:
                return None
            self.plan.changed += 1
            return bytes(self.serialize(ros_messages.edit(kind, msg, values, bool(self.plan.velocity_of)), msgtype))
        if kind in ("twist", "twist_cov") and topic in self.plan.velocity_of:
            msg = self.deserialize(raw, msgtype)
            target, fix_of = self.plan.velocity_of[topic]
            match = fix_of.get(_ros_stamp(msg) or log_time)
            if match is None:
                return None
            self.plan.changed += 1
            return bytes(self.serialize(ros_messages.edit(kind, msg, self.plan.fixes[target][match], True), msgtype))
        if kind == "time_reference" and self.plan.clock_of.get(topic):
            msg = self.deserialize(raw, msgtype)
            shift = self.plan.clock_of[topic].get(_ros_stamp(msg) or log_time)
            if shift is None:
                return None
            ref = int(msg.time_ref.sec) * 1_000_000_000 + int(msg.time_ref.nanosec) + shift
            time_ref = dataclasses.replace(msg.time_ref, sec=ref // 1_000_000_000, nanosec=ref % 1_000_000_000)
            self.plan.changed += 1
            return bytes(self.serialize(dataclasses.replace(msg, time_ref=time_ref), msgtype))
        return None


def _rewrite_bag(src: Path, dst: Path, plan: _Plan) -> None:
    is_ros1 = src.is_file()
    with AnyReader([src]) as reader:
        store = reader.typestore
        if is_ros1:
            dst.unlink(missing_ok=True)
            writer: Any = Writer1(dst)
            editor = _RosEditor(plan, lambda r, t: store.deserialize_ros1(r, t), store.serialize_ros1)
        else:
            if dst.exists():
                shutil.rmtree(dst)
            storage = StoragePlugin.MCAP if any(src.glob("*.mcap")) else StoragePlugin.SQLITE3
            writer = Writer2(dst, version=9, storage_plugin=storage)
            editor = _RosEditor(plan, lambda r, t: store.deserialize_cdr(r, t), store.serialize_cdr)
        with writer:
            conns = {}
            for c in reader.connections:
                if c.topic in conns:
                    continue
                if is_ros1:
                    conns[c.topic] = writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
                else:
                    conns[c.topic] = writer.add_connection(c.topic, c.msgtype, typestore=store)
            for c, t, raw in reader.messages():
                new = editor.edit(c.topic, c.msgtype, raw, t)
                writer.write(conns[c.topic], t, new if new is not None else raw)


def _mcap_typestores(src: Path, summary: Any) -> tuple[Any, Any]:
    """ROS2 and ROS1 typestores with every ROS schema of an MCAP registered."""
    ros2, ros1 = get_typestore(Stores.EMPTY), get_typestore(Stores.EMPTY)
    try:
        for s in summary.schemas.values():
            if s.encoding in ("ros2msg", "ros2idl"):
                text = s.data.decode()
                ros2.register(get_types_from_msg(text, s.name) if s.encoding == "ros2msg" else get_types_from_idl(text))
            elif s.encoding == "ros1msg":
                ros1.register(get_types_from_msg(s.data.decode(), s.name))
    except Exception as err:
        raise WriterError(f"{src}: a message schema cannot be read ({one_line(err)}); no spoofed copy made") from err
    return ros2, ros1


def _mcap_summary(src: Path, reader: Any) -> Any:
    summary = reader.get_summary()
    if summary is None:
        raise WriterError(
            f"{src}: MCAP without a summary section cannot be rewritten; "
            "read it and write a fresh copy with `spooflens simulate`-style writers"
        )
    return summary


def _velocity_stamps_mcap(src: Path, topics: list[str]) -> dict[str, np.ndarray]:
    """The stamp the reader gave each message of the velocity (and time reference) topics (header stamp,
    else log time)."""
    stamps: dict[str, list[int]] = {t: [] for t in topics}
    with src.open("rb") as f:
        reader = make_reader(f)
        ros2, ros1 = _mcap_typestores(src, _mcap_summary(src, reader))
        for schema, channel, message in reader.iter_messages(topics=topics, log_time_order=False):
            if schema is None or channel.message_encoding not in ("cdr", "ros1"):
                continue
            store = ros2.deserialize_cdr if channel.message_encoding == "cdr" else ros1.deserialize_ros1
            stamps[channel.topic].append(_ros_stamp(store(message.data, schema.name)) or message.log_time)
    return {t: np.array(v, dtype=np.int64) for t, v in stamps.items()}


def _velocity_stamps_bag(src: Path, topics: list[str]) -> dict[str, np.ndarray]:
    stamps: dict[str, list[int]] = {t: [] for t in topics}
    with AnyReader([src]) as reader:
        conns = [c for c in reader.connections if c.topic in stamps]
        for c, t, raw in reader.messages(connections=conns):
            stamps[c.topic].append(_ros_stamp(reader.deserialize(raw, c.msgtype)) or t)
    return {t: np.array(v, dtype=np.int64) for t, v in stamps.items()}


def _rewrite_mcap(src: Path, dst: Path, plan: _Plan) -> None:
    protobuf = ProtobufDecoderFactory()
    with src.open("rb") as f, dst.open("wb") as out:
        reader = make_reader(f)
        summary = _mcap_summary(src, reader)
        ros2, ros1 = _mcap_typestores(src, summary)
        cdr_editor = _RosEditor(plan, lambda r, t: ros2.deserialize_cdr(r, t), ros2.serialize_cdr)
        ros1_editor = _RosEditor(plan, lambda r, t: ros1.deserialize_ros1(r, t), ros1.serialize_ros1)
        w = Writer(out, compression=CompressionType.ZSTD)
        header = reader.get_header()
        w.start(profile=header.profile, library="spooflens inject")
        schema_ids = {sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        channel_ids = {
            cid: w.register_channel(c.topic, c.message_encoding, schema_ids.get(c.schema_id, 0), dict(c.metadata))
            for cid, c in summary.channels.items()
        }
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            data = message.data
            if schema is not None:
                new = None
                if channel.message_encoding == "cdr":
                    new = cdr_editor.edit(channel.topic, schema.name, data, message.log_time)
                elif channel.message_encoding == "ros1":
                    new = ros1_editor.edit(channel.topic, schema.name, data, message.log_time)
                elif schema.name == "foxglove.LocationFix" and channel.topic in plan.fixes:
                    new = _edit_location_fix(plan, channel.topic, channel.message_encoding, schema, data, protobuf)
                data = new if new is not None else data
            w.add_message(
                channel_ids[channel.id],
                log_time=message.log_time,
                data=data,
                publish_time=message.publish_time,
                sequence=message.sequence,
            )
        w.finish()


def _edit_location_fix(
    plan: _Plan, topic: str, encoding: str, schema: Any, data: bytes, protobuf: ProtobufDecoderFactory
) -> bytes | None:
    if encoding == "json":
        msg = json.loads(data)
        values = plan.fixes[topic].get(foxglove_messages.extract("navsatfix", msg)[0])
        if values is None:
            return None
        msg["latitude"], msg["longitude"], msg["altitude"] = values[:3]
        plan.changed += 1
        return json.dumps(msg).encode()
    if encoding == "protobuf":
        decoder = protobuf.decoder_for("protobuf", schema)
        if decoder is None:
            return None
        msg = decoder(data)
        values = plan.fixes[topic].get(foxglove_messages.extract("navsatfix", msg)[0])
        if values is None:
            return None
        msg.latitude, msg.longitude, msg.altitude = values[:3]
        plan.changed += 1
        return bytes(msg.SerializeToString())
    return None


def rewrite_log(src: Path, dst: Path, table: EpochTable, spoofed: EpochTable, velocities: bool) -> str:
    """Write `src` to `dst` in the same format with the spoofed table's fixes (and observations) in it.

    `table` is what the readers made of `src` (it carries the clock that maps rows to stamps). Returns a
    one-line note on what was written. The format's reader declares how (`ReaderFormat.rewrite`).
    """
    src, dst = Path(src), Path(dst)
    fmt = formats()[sniff_format(src)]
    if fmt.rewrite is None:
        raise WriterError(f"{src}: inject cannot write {fmt.description} back; no spoofed copy made")
    module, _, func = fmt.rewrite.partition(":")
    note: str = getattr(importlib.import_module(module), func)(src, dst, table, spoofed, velocities)
    return note


# what an attack may change beyond the fixes' positions: (frame, column, how the note names it)
CARRIED: tuple[tuple[str, str, str], ...] = (
    ("fixes", "h_acc_m", "reported accuracies"),
    ("fixes", "sats_used", "satellites used"),
    ("fixes", "hdop", "DOP"),
    ("fixes", "cn0_mean_dbhz", "mean C/N0"),
    ("fixes", "agc", "AGC"),
    ("fixes", "noise_per_ms", "noise level"),
    ("fixes", "jamming_indicator", "jamming indicator"),
    ("fixes", "jamming_state", "jamming state"),
    ("receiver_status", "agc", "the monitor reports' AGC"),
    ("receiver_status", "noise_per_ms", "the monitor reports' noise level"),
    ("receiver_status", "jamming_indicator", "the monitor reports' jamming indicator"),
    ("receiver_status", "jamming_state", "the monitor reports' jamming state"),
    ("satellites", "cn0_dbhz", "each satellite's C/N0"),
    ("observations", "cn0_dbhz", "the raw measurements' C/N0"),
    ("observations", "pseudorange_m", "the raw pseudoranges"),
)


def _keyed(df: pd.DataFrame, column: str) -> pd.DataFrame:
    """One value of `column` per receiver, time (ms) and satellite."""
    keys = ["receiver_id", "_ms"] + (["sv_id"] if "sv_id" in df else [])
    out = df.assign(_ms=np.round(df["t_s"].to_numpy(float) * 1000).astype(np.int64))
    return out[[*keys, column]].drop_duplicates(keys).set_index(keys)[column]


def _carried(before: pd.DataFrame, attacked: pd.DataFrame, copy: pd.DataFrame, column: str) -> bool | None:
    """Whether the copy carries the attack's change of `column`: at most of the rows the attack moved, the
    copy has a value and it moved too. None when the attack moved nothing there."""
    if not len(before) or not len(attacked) or column not in before:
        return None
    old = _keyed(before, column)
    new = _keyed(attacked, column).reindex(old.index)
    moved = new.notna() & old.notna() & ((new - old).abs() > 1e-3)
    if not moved.any():
        return None
    if not len(copy):
        return False
    got = _keyed(copy, column).reindex(old.index[moved.to_numpy()])
    followed = got.notna() & ((got - old[moved]).abs() > 1e-3)
    return bool(followed.mean() >= 0.5)


def unwritten_changes(table: EpochTable, attacked: EpochTable, copy: EpochTable) -> list[str]:
    """What the attack changed that its copy, read back, does not carry (the format has no place for it,
    or its writer does not edit it): named for `inject`'s note."""
    out = [
        label
        for frame, column, label in CARRIED
        if _carried(table.frame(frame), attacked.frame(frame), copy.frame(frame), column) is False
    ]
    if len(attacked.fixes) < len(table.fixes) and len(copy.fixes) >= len(table.fixes):
        out.append("the lost fixes")
    lost = len(attacked.observations) < len(table.observations)
    if lost and len(copy.observations) >= len(table.observations):
        out.append("the lost satellites' measurements")
    return out


def rewrite_with_writer(src: Path, dst: Path, table: EpochTable, spoofed: EpochTable, velocities: bool) -> str:
    """Formats spooflens writes whole (CSV, ULog): the spoofed table written anew."""
    from spooflens.writers import write_log

    fmt = sniff_format(src)
    write_log(spoofed, dst, fmt)
    note = (
        "ULog rewritten with only sensor_combined, vehicle_attitude and sensor_gps"
        if fmt == "ulog"
        else "CSV log rewritten"
    )
    extra = f", {len(spoofed.observations)} observations" if len(spoofed.observations) else ""
    return f"{note}: {len(spoofed.fixes)} fixes{extra}"


def rewrite_packed(src: Path, dst: Path, table: EpochTable, spoofed: EpochTable, velocities: bool) -> str:
    """A log inside gzip, zip ...: the log unpacked and rewritten in its own format, written unpacked."""
    from readers.packed import unpacked

    with unpacked(src) as content:
        note = rewrite_log(content.log, dst, table, spoofed, velocities)
    return f"{note} (from the {content.label} log, written unpacked)"


def rewrite_container(src: Path, dst: Path, table: EpochTable, spoofed: EpochTable, velocities: bool) -> str:
    """MCAP files and ROS bags: every message copied, the fix messages edited in place."""
    is_mcap = sniff_format(src) == "mcap"
    topics = [s.topic for s in table.streams if (s.role == "vel" and velocities) or s.role == "timeref"]
    stamps = (_velocity_stamps_mcap if is_mcap else _velocity_stamps_bag)(src, topics) if topics else {}
    plan = _plan(table, spoofed.fixes, velocities, stamps)
    if is_mcap:
        _rewrite_mcap(src, dst, plan)
    else:
        _rewrite_bag(src, dst, plan)
    expected = sum(len(v) for v in plan.fixes.values())
    return f"{plan.changed} messages rewritten ({expected} fixes in the table), every other message copied"
