"""Topic roles and the streaming collection of messages into an EpochTable.

Shared by every container (MCAP with ROS1/ROS2/JSON/protobuf channels, ROS1 and ROS2 bags): the
container reader declares its topics with a decoder each and then only feeds (topic, log time, raw
bytes); this module decides each topic's role, decodes (fast path where the layout is fixed), buffers
rows and finally assembles the frames. Messages of a fixed-layout type are decoded many at a time
(`add_batch` for a container that holds them in one buffer, as an MCAP chunk does; `add` queues them
and decodes a batch at a time), the first message of each topic by the full decoder (its frame_id,
and a cross-check of the fast path).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from readers.buffers import RowBuffer
from readers.ros_messages import (
    RAW_COLUMNS,
    ROLE_BY_KIND,
    BatchDecoder,
    batch_decoder,
    decode_cdr,
    decode_ros1,
    extract,
    fix_columns,
    imu_columns,
    kind_of,
    normalise_type,
    odometry_columns,
    velocity_columns,
)
from spooflens.epoch_table import EpochTable, Skipped, StreamInfo, build_table, log_clock, time_offset_s
from spooflens.errors import ReaderError
from spooflens.schema import FixType, constant_strings

ROLES = ("fix", "fix2", "imu", "vel", "odom", "truth")
# --topic roles -> the kinds' own role (a second receiver and truth are fix kinds too)
_BASE_ROLE = {"fix": "fix", "fix2": "fix", "truth": "fix", "imu": "imu", "vel": "vel", "odom": "odom"}
_ROLE_KINDS = {role: tuple(k for k, r in ROLE_BY_KIND.items() if r == base) for role, base in _BASE_ROLE.items()}
TRUTH_TOPIC_HINTS = ("truth", "ground_truth", "groundtruth")

Deserialize = Callable[[bytes | memoryview, str], Any]
Decoded = tuple[int, tuple[float, ...]]
_QUEUE = 8192  # messages queued per topic before they are decoded as one batch
# a topic's frame_id is the first non-empty one of its first messages (all decoded in full, one by one)
_FRAME_ID_MESSAGES = 16
_MIN_MESSAGE_BYTES = 16  # no message record of any format we read is smaller


@dataclass(frozen=True)
class TopicDecl:
    """A topic as its container sees it, with the means to decode its messages into raw rows."""

    msgtype: str
    kind: str | None
    decode: Callable[[bytes | memoryview], tuple[Decoded, str]] | None = None  # -> ((stamp, values), frame_id)
    fast: Callable[[bytes | memoryview], Decoded | None] | None = None
    batch: BatchDecoder | None = None  # (buf, starts, lengths) -> (stamps, rows, ok) for fixed layouts
    problem: str = ""  # why a topic of a supported kind cannot be decoded (a damaged schema): its messages are lost


def ros_topic(msgtype: str, encoding: str, deserialize: Deserialize) -> TopicDecl:
    """Declaration of a ROS topic ('cdr' or 'ros1' encoded) decoded with `deserialize`."""
    kind = kind_of(msgtype)
    if kind is None:
        return TopicDecl(normalise_type(msgtype), None)

    def decode(raw: bytes | memoryview) -> tuple[Decoded, str]:
        msg = deserialize(raw, msgtype)
        return extract(kind, msg), str(msg.header.frame_id)

    fast_decoder = decode_cdr if encoding == "cdr" else decode_ros1
    return TopicDecl(
        normalise_type(msgtype), kind, decode, lambda raw: fast_decoder(kind, raw), batch_decoder(kind, encoding)
    )


@dataclass
class TopicStream:
    topic: str
    decl: TopicDecl
    role: str | None
    buffer: RowBuffer | None = None
    seen: int = 0
    stamp_fallbacks: int = 0
    bad: int = 0
    first_error: str = ""
    frame_id: str = ""
    queue: list[tuple[int, bytes | memoryview]] = field(default_factory=list)  # (log time, raw) to batch-decode

    @property
    def kind(self) -> str | None:
        return self.decl.kind

    @property
    def msgtype(self) -> str:
        return self.decl.msgtype


def assign_roles(
    path: Path, topics: Mapping[str, str | None], overrides: Mapping[str, str] | None
) -> dict[str, str | None]:
    """Role of every topic (None: not used). `topics` maps topic -> kind (None if unsupported)."""
    overrides = dict(overrides or {})
    unknown = sorted(set(overrides) - set(ROLES))
    if unknown:
        raise ReaderError(path, f"unknown topic role(s) {unknown}; roles are {list(ROLES)}")
    for wanted, topic in overrides.items():
        if topic not in topics:
            raise ReaderError(path, f"--topic {wanted}={topic}: no such topic; topics are {sorted(topics)}")
        if topics[topic] not in _ROLE_KINDS[wanted]:
            raise ReaderError(
                path, f"--topic {wanted}={topic}: a {topics[topic] or 'unsupported'} topic cannot be a {wanted}", topic
            )
    roles: dict[str, str | None] = {}
    chosen_fix = {overrides[r] for r in ("fix", "fix2") if r in overrides}
    for topic, kind in topics.items():
        role: str | None = ROLE_BY_KIND.get(kind) if kind else None
        if role == "fix":
            if topic == overrides.get("truth") or (
                "truth" not in overrides and any(h in topic.lower() for h in TRUTH_TOPIC_HINTS)
            ):
                role = "truth"
            elif chosen_fix and topic not in chosen_fix:
                role = None
        elif (
            (role == "imu" and "imu" in overrides and topic != overrides["imu"])
            or (role == "vel" and "vel" in overrides and topic != overrides["vel"])
            or (role == "odom" and "odom" in overrides and topic != overrides["odom"])
        ):
            role = None
        roles[topic] = role
    return roles


def _joined(raws: Sequence[bytes | memoryview]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(uint8 buffer, starts, lengths) of messages laid end to end."""
    parts = [bytes(r) for r in raws]
    lengths = np.fromiter(map(len, parts), dtype=np.int64, count=len(parts))
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
    return np.frombuffer(b"".join(parts), dtype=np.uint8), starts, lengths


@dataclass
class StreamCollector:
    """Collects the messages of one log; `finish` builds the EpochTable."""

    path: Path
    fmt: str
    overrides: Mapping[str, str] | None = None
    streams: dict[str, TopicStream] = field(default_factory=dict)
    skipped: list[Skipped] = field(default_factory=list)

    def add_topics(self, topics: Mapping[str, TopicDecl], counts: Iterable[tuple[str, int]] = ()) -> None:
        """Declare every topic of the log (roles depend on all of them, so all at once). `counts`, the
        (topic, messages) a file's index lists per channel or connection (a topic's are added up), lets
        each topic's rows be stored once, in place; a damaged count cannot ask for more rows than the
        file has bytes for."""
        roles = assign_roles(self.path, {t: d.kind for t, d in topics.items()}, self.overrides)
        listed: dict[str, int] = {}
        for topic, n in counts:
            listed[topic] = listed.get(topic, 0) + max(int(n), 0)
        try:
            most = self.path.stat().st_size // _MIN_MESSAGE_BYTES
        except OSError:
            most = 0
        for topic, decl in topics.items():
            role = roles[topic]
            capacity = min(listed.get(topic, 0), most)
            buf = RowBuffer(RAW_COLUMNS[decl.kind], capacity) if role and decl.kind and decl.decode else None
            self.streams[topic] = TopicStream(topic, decl, role, buf)

    def add(self, topic: str, log_time_ns: int, raw: bytes | memoryview) -> None:
        s = self.streams[topic]
        if s.buffer is None or s.decl.decode is None:
            s.seen += 1
            return
        if s.decl.batch is None or self._wants_frame_id(s):
            s.seen += 1
            self._decode_one(s, log_time_ns, raw)
            return
        s.seen += 1  # counted when queued: a reader compares counts before the last queue is decoded
        s.queue.append((log_time_ns, raw))
        if len(s.queue) >= _QUEUE:
            self._flush(s)

    def add_batch(
        self, topic: str, log_times_ns: np.ndarray, buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray
    ) -> None:
        """Messages of one topic, in log order, lying at buf[starts[i]:starts[i] + lengths[i]] (uint8 buf)."""
        s = self.streams[topic]
        if not len(starts):
            return
        if s.buffer is None or s.decl.decode is None:
            s.seen += len(starts)
            return
        if s.queue:
            self._flush(s)
        first = 0
        view = memoryview(buf.data)
        while first < len(starts) and (s.decl.batch is None or self._wants_frame_id(s)):
            s.seen += 1
            self._decode_one(s, int(log_times_ns[first]), view[starts[first] : starts[first] + lengths[first]])
            first += 1
        if first < len(starts):
            self._decode_many(s, log_times_ns[first:], buf, starts[first:], lengths[first:])

    @staticmethod
    def _wants_frame_id(s: TopicStream) -> bool:
        """Whether the next message is decoded in full for its frame_id (the first always is: a cross-check)."""
        return s.seen < _FRAME_ID_MESSAGES and not s.frame_id

    def add_many(self, topic: str, log_times_ns: Sequence[int], raws: Sequence[bytes | memoryview]) -> None:
        """Messages of one topic, in log order, each in bytes of its own (a container that yields them one
        at a time): decoded as `add` would, without its per-message bookkeeping."""
        if raws:
            self.add_batch(topic, np.asarray(log_times_ns, dtype=np.int64), *_joined(raws))

    def _flush(self, s: TopicStream) -> None:
        times = np.fromiter((t for t, _ in s.queue), dtype=np.int64, count=len(s.queue))
        buf, starts, lengths = _joined([r for _, r in s.queue])
        s.queue = []
        self._decode_many(s, times, buf, starts, lengths, counted=True)

    def _decode_one(self, s: TopicStream, log_time_ns: int, raw: bytes | memoryview) -> None:
        assert s.buffer is not None and s.decl.decode is not None
        row = self._decoded(s, raw)
        if row is None:
            return
        stamp, values = row
        if stamp == 0:
            stamp = log_time_ns
            s.stamp_fallbacks += 1
        s.buffer.append(stamp, values)

    def _decoded(self, s: TopicStream, raw: bytes | memoryview) -> Decoded | None:
        """One message's (stamp, values); None (counted) when it cannot be decoded."""
        assert s.decl.decode is not None
        early = s.seen <= _FRAME_ID_MESSAGES and not s.frame_id  # s.seen counts this message
        try:
            fast = s.decl.fast(raw) if s.decl.fast is not None and not early else None
            if fast is None:  # the first messages take the full decoder: frame_id, and a cross-check
                (stamp, values), frame_id = s.decl.decode(raw)
                if early:
                    s.frame_id = frame_id
                return stamp, values
            return fast
        except Exception as err:  # noqa: BLE001 - any decoding failure of one message is counted, not fatal
            s.bad += 1
            s.first_error = s.first_error or f"{type(err).__name__}: {err}"
            return None

    def _decode_many(
        self,
        s: TopicStream,
        log_times_ns: np.ndarray,
        buf: np.ndarray,
        starts: np.ndarray,
        lengths: np.ndarray,
        counted: bool = False,
    ) -> None:
        """Batch-decode; messages that do not fit the layout are decoded one by one, in place (order kept).
        `counted`: the messages were already counted as seen when queued."""
        assert s.buffer is not None and s.decl.batch is not None
        if not counted:
            s.seen += len(starts)
        stamps, values, ok = s.decl.batch(buf, starts, lengths)
        keep = ok.copy()
        if not ok.all():
            view = memoryview(buf.data)
            for i in np.flatnonzero(~ok):
                row = self._decoded(s, view[starts[i] : starts[i] + lengths[i]])
                if row is not None:
                    stamps[i], values[i], keep[i] = row[0], row[1], True
        zero = keep & (stamps == 0)
        if zero.any():
            stamps = np.where(zero, log_times_ns, stamps)
            s.stamp_fallbacks += int(zero.sum())
        s.buffer.extend(*((stamps, values) if keep.all() else (stamps[keep], values[keep])))

    def finish(self, time_reference: str = "unix") -> EpochTable:
        skipped = list(self.skipped)
        frames: dict[str, list[pd.DataFrame]] = {"fixes": [], "imu": [], "odometry": [], "truth": []}
        infos: list[StreamInfo] = []
        # rows attached to a receiver's fixes: GNSS velocity and time reference topics
        velocities: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]] = {}
        spans: dict[tuple[str, str], tuple[int, int]] = {}  # streams merged into another frame
        for s in self.streams.values():
            if s.queue:
                self._flush(s)
        for s in self.streams.values():
            if s.bad:
                skipped.append(Skipped(s.topic, f"{s.bad} message(s) could not be decoded ({s.first_error})", s.bad))
            if s.stamp_fallbacks:
                skipped.append(Skipped(s.topic, "header stamp zero: used the log time", s.stamp_fallbacks, "repaired"))
            if s.decl.problem:
                skipped.append(Skipped(s.topic, f"{s.msgtype}: {s.decl.problem}", s.seen, "lost"))
                continue
            if s.kind is None:
                skipped.append(Skipped(s.topic, f"unsupported message type {s.msgtype}", s.seen))
                continue
            if s.decl.decode is None:
                skipped.append(Skipped(s.topic, f"no decoder for {s.msgtype}", s.seen))
                continue
            if s.role is None:
                skipped.append(Skipped(s.topic, f"{s.msgtype} not selected by --topic", s.seen))
                continue
            assert s.buffer is not None
            stamps, values = s.buffer.arrays()
            if s.role in ("fix", "truth"):
                cols = fix_columns(s.kind, values)
                no_fix = cols["fix_type"] == FixType.NO_FIX
                if no_fix.any():
                    skipped.append(Skipped(s.topic, "status NO_FIX", int(no_fix.sum())))
                    stamps, cols = stamps[~no_fix], {k: v[~no_fix] for k, v in cols.items()}
                if s.role == "truth":
                    keep = ("lat_deg", "lon_deg", "height_m", "vel_e_mps", "vel_n_mps", "vel_u_mps")
                    frames["truth"].append(pd.DataFrame({"t_ns": stamps} | {k: cols[k] for k in keep if k in cols}))
                else:
                    frames["fixes"].append(
                        pd.DataFrame({"t_ns": stamps, "receiver_id": constant_strings(s.topic, len(stamps))} | cols)
                    )
                infos.append(
                    StreamInfo(
                        s.role if s.role == "truth" else "fix",
                        s.topic,
                        s.topic,
                        s.msgtype,
                        len(stamps),
                        frame_id=s.frame_id,
                    )
                )
            elif s.role == "imu":
                frames["imu"].append(
                    pd.DataFrame(
                        {"t_ns": stamps, "imu_id": constant_strings(s.topic, len(stamps))} | imu_columns(values),
                        copy=False,
                    )
                )
                infos.append(
                    StreamInfo("imu", s.topic, s.topic, s.msgtype, len(stamps), body_frame="FLU", frame_id=s.frame_id)
                )
            elif s.role == "vel":
                velocities[s.topic] = (stamps, velocity_columns(values))
                infos.append(StreamInfo("vel", s.topic, s.topic, s.msgtype, len(stamps), frame_id=s.frame_id))
                if len(stamps):
                    spans[("vel", s.topic)] = (int(np.min(stamps)), int(np.max(stamps)))
            elif s.role == "timeref":
                seconds, nanoseconds = values["ref_sec"], values["ref_nsec"]
                receiver_ns = seconds.astype(np.int64) * 1_000_000_000 + nanoseconds.astype(np.int64)
                velocities[s.topic] = (stamps, {"time_offset_s": time_offset_s(receiver_ns, stamps)})
                infos.append(StreamInfo("timeref", s.topic, s.topic, s.msgtype, len(stamps), frame_id=s.frame_id))
                if len(stamps):
                    spans[("timeref", s.topic)] = (int(np.min(stamps)), int(np.max(stamps)))
            elif s.role == "odom":
                frames["odometry"].append(
                    pd.DataFrame(
                        {"t_ns": stamps, "odometry_id": constant_strings(s.topic, len(stamps))}
                        | odometry_columns(values)
                    )
                )
                infos.append(StreamInfo("odometry", s.topic, s.topic, s.msgtype, len(stamps), frame_id=s.frame_id))
            del values  # the raw rows are in the frame now: free them before the next stream and build_table
        fixes, attached = merge_velocities(frames["fixes"], velocities, self.overrides, skipped)
        infos = [replace(i, receiver=attached.get(i.topic, "")) if i.role in ("vel", "timeref") else i for i in infos]
        out = {
            "fixes": fixes,
            "imu": _concat(frames["imu"]),
            "odometry": _concat(frames["odometry"]),
            "truth": _concat(frames["truth"]),
        }
        metadata = (
            log_clock("the header stamps (the host's clock)", False) if any(i.role == "timeref" for i in infos) else {}
        )
        return build_table(
            self.path, self.fmt, time_reference, out, infos, skipped, stream_spans_ns=spans, metadata=metadata
        )


def _concat(parts: list[pd.DataFrame]) -> pd.DataFrame | None:
    if len(parts) == 1:  # one stream: its frame as it is (a concat would copy a day of IMU)
        return parts[0]
    return pd.concat(parts, ignore_index=True) if parts else None


def _common_prefix(a: str, b: str) -> int:
    n = 0
    for x, y in zip(a, b, strict=False):
        if x != y:
            break
        n += 1
    return n


def velocity_receiver(vel_topic: str, receivers: list[str], overrides: Mapping[str, str] | None) -> str:
    """The receiver a velocity topic belongs to: the one named by `--topic fix=` when `--topic vel=`
    chose the velocity, else the one whose topic shares the longest prefix with it."""
    if overrides and "vel" in overrides and overrides.get("fix") in receivers:
        return overrides["fix"]
    return max(receivers, key=lambda r: _common_prefix(r, vel_topic))


def match_velocities(fix_ns: np.ndarray, vel_ns: np.ndarray) -> np.ndarray:
    """For each fix, the index of the velocity row nearest in time within half the median fix period,
    or -1. The one matching the reader and `inject`'s rewrite both use."""
    fix_ns = np.asarray(fix_ns, dtype=np.int64)
    vel_ns = np.asarray(vel_ns, dtype=np.int64)
    out = np.full(len(fix_ns), -1, dtype=np.int64)
    if not len(fix_ns) or not len(vel_ns):
        return out
    order = np.argsort(vel_ns, kind="stable")
    v = vel_ns[order]
    period = float(np.median(np.diff(np.sort(fix_ns)))) if len(fix_ns) > 1 else 1e9
    right = np.clip(np.searchsorted(v, fix_ns), 0, len(v) - 1)
    left = np.maximum(right - 1, 0)
    nearest = np.where(np.abs(fix_ns - v[left]) <= np.abs(v[right] - fix_ns), left, right)
    ok = np.abs(v[nearest] - fix_ns) <= period / 2
    out[ok] = order[nearest[ok]]
    return out


def _what(cols: Mapping[str, np.ndarray]) -> str:
    return "time reference" if "time_offset_s" in cols else "GNSS velocity"


def merge_velocities(
    fixes: list[pd.DataFrame],
    velocities: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]],
    overrides: Mapping[str, str] | None,
    skipped: list[Skipped],
) -> tuple[pd.DataFrame | None, dict[str, str]]:
    """Attach each velocity (or time reference) topic to one receiver (`velocity_receiver`) and its rows to
    that receiver's fixes (`match_velocities`); returns the fixes and topic -> receiver."""
    if not fixes:
        if velocities:
            skipped += [Skipped(t, f"{_what(v[1])} without any fix stream", len(v[0])) for t, v in velocities.items()]
        return None, {}
    by_topic = {str(f["receiver_id"].iloc[0]) if len(f) else "": f for f in fixes}
    attached: dict[str, str] = {}
    for vtopic, (vt, vcols) in velocities.items():
        target = velocity_receiver(vtopic, list(by_topic), overrides)
        attached[vtopic] = target
        f = by_topic[target]
        ft = f["t_ns"].to_numpy()
        if not len(ft) or not len(vt):
            continue
        match = match_velocities(ft, vt)
        ok = match >= 0
        f = f.copy()
        for name, col in vcols.items():
            vals = np.full(len(ft), np.nan)
            vals[ok] = col[match[ok]]
            f[name] = vals
        unmatched = len(vt) - len(np.unique(match[ok]))
        if unmatched > 0:
            skipped.append(
                Skipped(vtopic, f"{_what(vcols)} rows with no fix of {target} within half a fix period", unmatched)
            )
        by_topic[target] = f
    return pd.concat(list(by_topic.values()), ignore_index=True), attached
