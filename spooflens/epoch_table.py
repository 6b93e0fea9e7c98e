"""The unified epoch table: every stream of a log on one time base, plus what was skipped.

Readers collect rows with absolute timestamps in the log's own clock (integer nanoseconds) and hand
them to `build_table`, which is the only place that sets the time base, sorts, removes duplicates,
drops unusable rows and records each repair. So every format gets the same treatment.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from spooflens import plausibility
from spooflens.errors import SchemaError
from spooflens.gnss.ephemeris import GpsEphemerides, Klobuchar
from spooflens.schema import FRAMES, STREAM_KEY, empty_frame, make_frame, schema_problems, single_stream, stream_rows

GPS_EPOCH_UNIX_NS = 315_964_800_000_000_000  # 1980-01-06T00:00:00Z
NS = 1_000_000_000
# GPS time (ns since the GPS epoch) of each leap second (23:59:60 UTC); GPS - UTC is k s from the k-th
# entry on, so the leap second itself reads as a second 23:59:59, as a UNIX clock shows it.
_LEAP_GPS_NS = (
    np.array(
        [
            46828800,
            78364801,
            109900802,
            173059203,
            252028804,
            315187205,
            346723206,
            393984007,
            425520008,
            457056009,
            504489610,
            551750411,
            599184012,
            820108813,
            914803214,
            1025136015,
            1119744016,
            1167264017,
        ],
        dtype=np.int64,
    )
    * NS
)
# the midnights after them on the UTC scale (UTC ns since the GPS epoch, as a UNIX clock counts them)
_LEAP_UTC_NS = _LEAP_GPS_NS - np.arange(len(_LEAP_GPS_NS), dtype=np.int64) * NS


def gps_utc_offset_ns(gps_ns: np.ndarray | int) -> np.ndarray:
    """GPS minus UTC (leap seconds) at the given GPS times (ns since the GPS epoch), in ns."""
    return np.searchsorted(_LEAP_GPS_NS, np.asarray(gps_ns, dtype=np.int64), side="right").astype(np.int64) * NS


def utc_gps_offset_ns(utc_ns: np.ndarray | int) -> np.ndarray:
    """GPS minus UTC at the given UTC times (ns since the GPS epoch on the UTC scale), in ns.

    Looked up by UTC, not by GPS time: during the 18 s after a leap second the two lookups differ by one.
    """
    return np.searchsorted(_LEAP_UTC_NS, np.asarray(utc_ns, dtype=np.int64), side="right").astype(np.int64) * NS


def time_offset_s(receiver_ns: np.ndarray, clock_ns: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """The `time_offset_s` fixes column: the receiver's time minus the log's clock (both ns, any epochs),
    less the median over the valid rows, in seconds (NaN where not valid). Differenced in integers, so
    a UNIX time of 1.7e18 ns against a boot clock keeps its nanoseconds."""
    diff = np.asarray(receiver_ns, dtype=np.int64) - np.asarray(clock_ns, dtype=np.int64)
    ok = np.ones(len(diff), dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    if not ok.any():
        return np.full(len(diff), np.nan)
    centre = int(np.median(diff[ok]))
    return np.where(ok, (diff - centre) / 1e9, np.nan)


def log_clock(description: str, monotonic: bool) -> dict[str, str]:
    """Metadata saying which clock `time_offset_s` is against: a monotonic boot clock cannot step, a host's
    wall clock can (NTP), which `receiver_time` tells apart from the receiver's own steps."""
    return {"time_offset.clock": description, "time_offset.monotonic": "yes" if monotonic else "no"}


def gps_ns_of_unix_ns(unix_ns: np.ndarray | int) -> np.ndarray:
    """UTC nanoseconds since 1970 -> GPS nanoseconds since 1980-01-06 (leap seconds added)."""
    utc = np.asarray(unix_ns, dtype=np.int64) - GPS_EPOCH_UNIX_NS
    return utc + utc_gps_offset_ns(utc)


def unix_ns_of_gps_ns(gps_ns: np.ndarray | int) -> np.ndarray:
    """GPS nanoseconds since 1980-01-06 -> UTC nanoseconds since 1970 (a leap second reads as the
    UTC second before it, as a UNIX clock shows it)."""
    gps = np.asarray(gps_ns, dtype=np.int64)
    return gps + GPS_EPOCH_UNIX_NS - gps_utc_offset_ns(gps)


def gps_seconds_of_unix_ns(unix_ns: np.ndarray | int) -> np.ndarray:
    """UTC nanoseconds since 1970 -> GPS seconds since 1980-01-06 (leap seconds added)."""
    return gps_ns_of_unix_ns(unix_ns) / 1e9


def unix_ns_of_gps_seconds(gps_s: np.ndarray | float) -> np.ndarray:
    """GPS seconds since 1980-01-06 -> UTC nanoseconds since 1970."""
    return unix_ns_of_gps_ns(np.round(np.asarray(gps_s, dtype=float) * 1e9).astype(np.int64))


TIME_REFERENCES = {
    "unix": "UTC seconds since 1970 (ROS stamps, MCAP log times)",
    "gps": "GPS time, seconds since 1980-01-06",
    "boot": "seconds since the vehicle's boot (PX4 without a GPS time fix)",
    "relative": "no absolute clock in the log",
}


@dataclass(frozen=True)
class StreamInfo:
    """One stream found in a log and where it went in the table."""

    role: str
    stream_id: str
    topic: str
    msgtype: str
    count: int
    first_s: float = float("nan")
    last_s: float = float("nan")
    body_frame: str | None = None
    frame_id: str = ""
    receiver: str = ""  # a velocity stream: the receiver whose fixes carry its rows

    @property
    def rate_hz(self) -> float:
        span = self.last_s - self.first_s
        return (self.count - 1) / span if self.count > 1 and span > 0 else float("nan")


@dataclass(frozen=True)
class Skipped:
    """Messages or rows a reader skipped or repaired, with the reason and how many. `span_ns`: where a
    reader knows it, the first and last time (the log's own clock, as its rows are stamped) of what the
    line is about, so that a log joining several recordings lists it in its own recording only (it is not
    part of the JSON summary: a recording's summary lists its own lines)."""

    stream: str
    reason: str
    count: int
    action: str = "skipped"
    span_ns: tuple[int, int] | None = field(default=None, compare=False)

    def __str__(self) -> str:
        return f"{self.stream}: {self.action} {self.count} ({self.reason})"

    def as_dict(self) -> dict[str, Any]:
        """The line as the JSON summary lists it."""
        return {"stream": self.stream, "reason": self.reason, "count": self.count, "action": self.action}


@dataclass(frozen=True)
class Segment:
    """One recording of a log that joins several (its clock jumped back): where it sits on the table's
    time axis, and where its own clock starts."""

    index: int
    start_s: float
    end_s: float
    t0_ns: int  # the recording's own clock at start_s


SEGMENT_GAP_S = 60.0  # recordings are laid out one after another on the time axis, this far apart


@dataclass
class EpochTable:
    """All frames of one log, times in seconds since `t0_ns` of the log's own clock.

    A log that joins several recordings (its time jumps back) keeps them apart as `segments`: each lies
    on the time axis after the one before, and maps back to its own clock (`absolute_ns`)."""

    source: Path
    format: str
    t0_ns: int
    time_reference: str
    imu: pd.DataFrame = field(default_factory=lambda: empty_frame("imu"))
    fixes: pd.DataFrame = field(default_factory=lambda: empty_frame("fixes"))
    observations: pd.DataFrame = field(default_factory=lambda: empty_frame("observations"))
    truth: pd.DataFrame = field(default_factory=lambda: empty_frame("truth"))
    odometry: pd.DataFrame = field(default_factory=lambda: empty_frame("odometry"))
    headings: pd.DataFrame = field(default_factory=lambda: empty_frame("headings"))
    autopilot_ekf: pd.DataFrame = field(default_factory=lambda: empty_frame("autopilot_ekf"))
    satellites: pd.DataFrame = field(default_factory=lambda: empty_frame("satellites"))
    receiver_status: pd.DataFrame = field(default_factory=lambda: empty_frame("receiver_status"))
    streams: list[StreamInfo] = field(default_factory=list)
    skipped: list[Skipped] = field(default_factory=list)
    # the broadcast ephemerides behind the satellite states (a RINEX navigation file, a simulated
    # constellation): what a RINEX copy of the log needs, and the ionosphere model for solutions
    ephemerides: GpsEphemerides | None = None
    # provenance a reader found: firmware and receiver versions, and the meaning applied to each logged
    # enum ("enum.spoofing_state": "PX4 SensorGps >= 1.15: 1 OK, 2 mitigated, 3 detected")
    metadata: dict[str, str] = field(default_factory=dict)
    segments: list[Segment] = field(default_factory=list)

    def segment(self, index: int) -> EpochTable:
        """One recording of a joined log as a table of its own (time from its start, its own clock)."""
        seg = self.segments[index]
        out = EpochTable(
            self.source,
            self.format,
            seg.t0_ns,
            self.time_reference,
            streams=[],
            skipped=[x for x in self.skipped if x.action != "segmented" and self._in_segment(x, index)],
            ephemerides=self.ephemerides,
            metadata={**self.metadata, "segment": f"{index + 1} of {len(self.segments)}"},
        )
        self._rows_into(out, seg.start_s, seg.end_s, seg.start_s)
        return out

    def _in_segment(self, line: Skipped, index: int) -> bool:
        """Whether a skipped line belongs to recording `index`: a line without a span to every recording,
        one with a span to the recording its span overlaps most, else to the nearest."""
        if line.span_ns is None:
            return True
        a, b = line.span_ns
        own = [(sg.t0_ns, sg.t0_ns + round((sg.end_s - sg.start_s) * NS)) for sg in self.segments]
        overlap = [min(b, hi) - max(a, lo) for lo, hi in own]
        return int(np.argmax(overlap)) == index

    def between(self, start_s: float, end_s: float) -> EpochTable:
        """The rows from `start_s` to `end_s` on the same time axis, as a log of their own (the navigation
        runs on each stretch between an IMU's gaps like this: `spooflens.navigation.segments`)."""
        out = replace(self, streams=[], metadata=dict(self.metadata), segments=list(self.segments))
        self._rows_into(out, start_s, end_s, 0.0)
        return out

    def _rows_into(self, out: EpochTable, start_s: float, end_s: float, shift_s: float) -> None:
        """`out`'s frames: this table's rows from `start_s` to `end_s`, their times less `shift_s`; its
        streams: this table's, counted over them (a stream without a row there left out)."""
        for name in FRAMES:
            df = self.frame(name)
            sel = (df["t_s"] >= start_s - 1e-9) & (df["t_s"] <= end_s + 1e-9)
            part = df[sel].reset_index(drop=True)
            part["t_s"] = part["t_s"] - shift_s
            setattr(out, name, part)
        for st in self.streams:
            frame = _ROLE_FRAME.get(st.role)
            if frame is None:
                out.streams.append(st)
                continue
            df = out.frame(frame)
            key = STREAM_KEY[frame]
            rows = df if key is None else df[df[key] == st.stream_id]
            t = rows["t_s"].to_numpy()
            count = len(np.unique(t)) if st.role in EPOCH_ROLES else len(rows)
            if count:
                out.streams.append(replace(st, count=count, first_s=float(t[0]), last_s=float(t[-1])))

    @property
    def ionosphere(self) -> Klobuchar | None:
        """Broadcast ionosphere coefficients of the log's navigation data, if it has any."""
        return self.ephemerides.iono if self.ephemerides is not None else None

    def frame(self, name: str) -> pd.DataFrame:
        if name not in FRAMES:
            raise KeyError(f"unknown frame {name!r}; frames are {list(FRAMES)}")
        df: pd.DataFrame = getattr(self, name)
        return df

    def validate(self) -> None:
        """Raise SchemaError listing every schema violation of every frame."""
        problems = [p for name in FRAMES for p in schema_problems(name, self.frame(name))]
        if self.time_reference not in TIME_REFERENCES:
            problems.append(f"time_reference {self.time_reference!r} not in {list(TIME_REFERENCES)}")
        if problems:
            raise SchemaError(f"{self.source}: epoch table breaks the schema: " + "; ".join(problems))

    @property
    def duration_s(self) -> float:
        ends = [float(self.frame(n)["t_s"].max()) for n in FRAMES if len(self.frame(n))]
        return max(ends) if ends else 0.0

    def receivers(self) -> list[str]:
        return _ids(self.fixes["receiver_id"])

    def imus(self) -> list[str]:
        return _ids(self.imu["imu_id"])

    def fixes_of(self, receiver_id: str) -> pd.DataFrame:
        return _rows_of(self.fixes, "receiver_id", receiver_id)

    def imu_of(self, imu_id: str) -> pd.DataFrame:
        return _rows_of(self.imu, "imu_id", imu_id)

    def stream(self, role: str, stream_id: str) -> StreamInfo | None:
        return next((s for s in self.streams if s.role == role and s.stream_id == stream_id), None)

    def absolute_ns(self, t_s: float | np.ndarray) -> np.ndarray:
        """Map table times back to the log's own clock (integer nanoseconds), each segment to its own."""
        t = np.asarray(t_s, dtype=float)
        if len(self.segments) < 2:
            return self.t0_ns + np.round(t * 1e9).astype(np.int64)
        starts = np.array([sg.start_s for sg in self.segments])
        t0s = np.array([sg.t0_ns for sg in self.segments], dtype=np.int64)
        k = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)
        return np.asarray(t0s[k] + np.round((t - starts[k]) * 1e9).astype(np.int64))

    def unix_ns(self, t_s: float | np.ndarray) -> np.ndarray | None:
        """Table times as UTC nanoseconds since 1970, or None if the log has no absolute clock."""
        ns = self.absolute_ns(t_s)
        if self.time_reference == "unix":
            return ns
        if self.time_reference == "gps":
            return unix_ns_of_gps_ns(ns)
        return None

    def gps_seconds(self, t_s: float | np.ndarray) -> np.ndarray | None:
        """Table times as GPS seconds since 1980-01-06 (what satellite orbits need), None without a clock."""
        ns = self.absolute_ns(t_s)
        if self.time_reference == "gps":
            return ns / 1e9
        if self.time_reference == "unix":
            return gps_seconds_of_unix_ns(ns)
        return None

    def absolute_iso(self, t_s: float) -> str:
        """A table time as an ISO-8601 string: UTC for unix/gps clocks, seconds otherwise."""
        unix = self.unix_ns(t_s)
        if unix is not None:
            return pd.Timestamp(int(unix), unit="ns", tz="UTC").isoformat()
        return f"{int(self.absolute_ns(t_s)) / 1e9:.3f} s ({self.time_reference})"


HOLDS = "holds"  # metadata key: what a sound log with nothing to judge holds instead (`holding_nothing`)


def holding_nothing(source: Path, fmt: str, holds: str, skipped: list[Skipped] | None = None) -> EpochTable:
    """The table of a log with nothing any detector reads: no stream, what it holds said, and what the
    reader skipped or lost listed."""
    return EpochTable(
        source=Path(source),
        format=fmt,
        t0_ns=0,
        time_reference="relative",
        skipped=list(skipped or []),
        metadata={HOLDS: holds},
    )


def _ids(column: pd.Series) -> list[str]:
    """The distinct stream ids of a column, in order of appearance (hashing, not a string per row)."""
    return [str(v) for v in column.unique()]


def _rows_of(frame: pd.DataFrame, key: str, value: str) -> pd.DataFrame:
    """The rows of one stream; the whole frame (no copy: pandas copies on write) when it is the only one."""
    match = (frame[key] == value).to_numpy(dtype=bool, na_value=False)
    return (frame if match.all() else frame[match]).reset_index(drop=True)


def gap_losses(t_ns: np.ndarray, factor: float = 3.0, end_ns: int | None = None) -> int:
    """How many samples a stream is missing in its gaps: each step longer than `factor` median periods
    stands for step/period - 1 samples (a damaged stretch of a file is a stretch of time without rows);
    with `end_ns`, the time the file's data really ends, the samples after the stream's last one too."""
    t = np.sort(np.asarray(t_ns, dtype=np.int64))
    if len(t) < 3:
        return 0
    steps = np.diff(t).astype(float)
    period = float(np.median(steps))
    if period <= 0:
        return 0
    gaps = steps[steps > factor * period]
    missing = float(np.sum(gaps / period - 1.0))
    if end_ns is not None and abs(end_ns) < 2**62 and end_ns - int(t[-1]) > factor * period:
        missing += (end_ns - int(t[-1])) / period - 1.0
    return int(np.round(missing))


@dataclass
class _Stream:
    """One stream of a frame while it is repaired: its rows (positions in the reader's frame) and the
    unit scales found for it."""

    sid: str
    rows: np.ndarray
    scales: list[plausibility.Scale] = field(default_factory=list)


def _stream_rows(frame: str, df: pd.DataFrame) -> list[_Stream]:
    key = STREAM_KEY[frame]
    if key is None:
        return [_Stream("truth", np.arange(len(df)))]
    column = df[key]
    only = single_stream(column)
    if only is not None:
        return [_Stream(only, np.arange(len(df)))]
    codes, uniques = pd.factorize(column.astype(str), sort=False)  # a row without an id: stream "nan"
    order = np.argsort(codes, kind="stable")
    bounds = np.searchsorted(codes[order], np.arange(len(uniques) + 1))
    return [_Stream(str(u), order[bounds[i] : bounds[i + 1]]) for i, u in enumerate(uniques)]


def _repair_stream(frame: str, df: pd.DataFrame, stream: _Stream, skipped: list[Skipped]) -> None:
    """Sort one stream by time, find its units, drop rows no sensor produces, then duplicate stamps;
    record each repair. Works on row positions only: the values are taken once, at the end."""
    sid, rows = stream.sid, stream.rows
    t = df["t_ns"].to_numpy()[rows]
    steps = np.diff(t)
    if len(t) > 1 and np.any(steps < 0):
        n_back = int(np.sum(steps < 0))
        skipped.append(Skipped(sid, f"time went backwards {n_back} times; rows sorted by time", n_back, "repaired"))
        order = np.argsort(t, kind="stable")
        rows, t = rows[order], t[order]
    stray = plausibility.stray_stamps(t)
    if stray.any():
        skipped.append(
            Skipped(sid, "rows whose time lies an hour or more from the rest of the stream", int(stray.sum()))
        )
        rows, t = rows[~stray], t[~stray]
    cols = _Gathered(df, rows, exclude=("t_ns", STREAM_KEY[frame]))
    if frame == "imu":
        stream.scales, refusal = plausibility.imu_unit(cols)
        if refusal:
            skipped.append(Skipped(sid, refusal, len(rows), "lost"))
            stream.rows = rows[:0]
            return
    elif frame in ("fixes", "truth"):
        stream.scales = plausibility.fix_units(cols, (t - t[0]) / 1e9 if len(t) else t.astype(float))
    cols.scales = {c: scale.factor for scale in stream.scales for c in scale.columns}
    keep = np.ones(len(rows), dtype=bool)
    for mask, reason in plausibility.bad_rows(frame, cols):
        hit = mask & keep
        if hit.any():
            skipped.append(Skipped(sid, reason, int(hit.sum())))
            keep &= ~mask
    rows, t = rows[keep], t[keep]
    # an observation epoch has one row per satellite: a duplicate is the same satellite twice
    if frame in EPOCH_ROLES:
        dup = pd.DataFrame({"t": t, "sv": df["sv_id"].to_numpy()[rows]}).duplicated(keep="first").to_numpy()
    else:
        dup = np.concatenate(([False], t[1:] == t[:-1])) if len(t) else np.zeros(0, dtype=bool)
    if dup.any():
        what = "duplicate (timestamp, satellite) rows" if frame in EPOCH_ROLES else "duplicate timestamps"
        skipped.append(Skipped(sid, f"{what}; kept the first", int(dup.sum())))
        rows = rows[~dup]
    stream.rows = rows


def _run(rows: np.ndarray) -> slice | None:
    """The slice `rows` are, when they are one contiguous run (one sorted stream: the usual case)."""
    if len(rows) and rows[-1] - rows[0] == len(rows) - 1 and (len(rows) < 2 or bool(np.all(np.diff(rows) == 1))):
        return slice(int(rows[0]), int(rows[-1]) + 1)
    return None


def _at(values: np.ndarray, rows: np.ndarray, run: slice | None) -> np.ndarray:
    """values[rows]: a view when they are one contiguous run (`run`, which is `_run(rows)`)."""
    return values[run] if run is not None else values[rows]


class _Gathered(Mapping[str, np.ndarray]):
    """The columns of a frame at some rows, gathered when asked for (a stream's checks touch a few
    columns; copying all of them for every stream would double a large log's memory)."""

    def __init__(self, df: pd.DataFrame, rows: np.ndarray, exclude: tuple[str | None, ...] = ()) -> None:
        self.df, self.rows, self.run = df, rows, _run(rows)
        self.names = [c for c in df.columns if c not in exclude]
        self.scales: dict[str, float] = {}

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self.names:
            raise KeyError(name)
        values = _at(self.df[name].to_numpy(), self.rows, self.run)
        return values * self.scales[name] if name in self.scales else values

    def __iter__(self) -> Iterator[str]:
        return iter(self.names)

    def __len__(self) -> int:
        return len(self.names)


def _take(frame: str, df: pd.DataFrame, streams: list[_Stream], t0_ns: int, skipped: list[Skipped]) -> pd.DataFrame:
    """The repaired frame: each column taken once at the kept rows (a view when nothing was dropped or
    reordered; the reader's column released as soon as it is copied), unit scales applied, optional
    values out of range cleared, t_s set."""
    idx = np.concatenate([s.rows for s in streams]) if streams else np.zeros(0, dtype=np.int64)
    run = _run(idx)
    cols: dict[str, Any] = {}
    for c in list(df.columns):
        if isinstance(df[c].dtype, pd.StringDtype):  # stream ids: kept as strings, not made Python objects
            cols[c] = _at(df[c].array, idx, run)
            del df[c]
            continue
        values = _at(df[c].to_numpy(), idx, run)
        if not values.flags.writeable:  # pandas hands out read-only views; the table's frames are its own
            try:
                values.flags.writeable = True
            except ValueError:
                values = values.copy()
        if c == "t_ns":
            cols["t_s"] = (values.astype(np.int64, copy=False) - t0_ns) / 1e9
        else:
            cols[c] = values
        del df[c]
    start = 0
    for s in streams:
        part = slice(start, start + len(s.rows))
        start += len(s.rows)
        # (columns, rows or None for all, factor or NaN to set, the note)
        changes: list[tuple[tuple[str, ...], np.ndarray | None, float, Skipped]] = [
            (scale.columns, None, scale.factor, Skipped(s.sid, scale.reason, len(s.rows), "repaired"))
            for scale in s.scales
        ]
        view = {c: v[part] for c, v in cols.items() if v.dtype.kind == "f" and c != "t_s"}
        for c, x in view.items():  # clean_optional judges the scaled values
            factor = next((f for names, _, f, _ in changes if c in names), 1.0)
            view[c] = x * factor if factor != 1.0 else x
        changes += [
            (names, bad, np.nan, Skipped(s.sid, f.reason, f.count, f.action))
            for names, bad, f in plausibility.clean_optional(frame, view)
        ]
        for names, bad, value, note in changes:
            skipped.append(note)
            for c in names:
                if not cols[c].flags.writeable or cols[c].base is not None:
                    cols[c] = np.array(cols[c], dtype=np.float64)  # a view of the reader's array: copy once
                target = cols[c][part]
                if bad is None:
                    target *= value
                else:
                    target[bad] = value
    return make_frame(frame, cols, len(idx), copy=False)


def _cross_check(frames: dict[str, pd.DataFrame], skipped: list[Skipped]) -> bool:
    """An IMU whose yaw rate turns 57 times the GNSS course (deg/s logged as rad/s) is scaled; one whose
    time span shares nothing with the fixes' (another clock) is left out."""
    imu, fixes = frames.get("imu"), frames.get("fixes")
    if imu is None or fixes is None or not len(imu) or not len(fixes):
        return False
    receiver = fixes[fixes["receiver_id"] == fixes["receiver_id"].iloc[0]]
    fix_cols = {c: receiver[c].to_numpy(dtype=float) for c in ("lat_deg", "lon_deg", "vel_e_mps", "vel_n_mps")}
    t_fix = receiver["t_s"].to_numpy(dtype=float)
    drop = np.zeros(len(imu), dtype=bool)
    for sid in pd.unique(imu["imu_id"]):
        rows = np.flatnonzero((imu["imu_id"] == sid).to_numpy(dtype=bool))
        run = _run(rows)
        t = _at(imu["t_s"].to_numpy(), rows, run)
        gap = max(t[0] - t_fix[-1], t_fix[0] - t[-1])
        if gap > 3600.0:
            skipped.append(
                Skipped(
                    str(sid),
                    f"IMU time span {t[0]:.0f}..{t[-1]:.0f} s lies {gap:.0f} s away from the fixes' "
                    f"{t_fix[0]:.0f}..{t_fix[-1]:.0f} s (another clock): IMU left out",
                    len(rows),
                    "lost",
                )
            )
            drop[rows] = True
            continue
        if any(n.stream == str(sid) and "angular rate in deg/s" in n.reason for n in skipped):
            continue  # its range already said deg/s: scaled once
        motion = {c: _at(imu[c].to_numpy(), rows, run) for c in plausibility.IMU_MOTION}
        ratio = plausibility.gyro_turn_ratio(t, motion, t_fix, fix_cols)
        if ratio is not None and 40.0 < ratio < 80.0:
            skipped.append(
                Skipped(
                    str(sid),
                    f"angular rate in deg/s (the gyro turns {ratio:.1f} times the GNSS course): scaled to rad/s",
                    len(rows),
                    "repaired",
                )
            )
            for c in plausibility.IMU_MOTION[3:]:
                imu.iloc[rows, imu.columns.get_loc(c)] = imu[c].to_numpy()[rows] * (np.pi / 180.0)
    if drop.any():
        frames["imu"] = imu[~drop].reset_index(drop=True)
    return bool(drop.any())


EPOCH_ROLES = ("observations", "satellites")  # streams of several rows per epoch: counted in epochs

_ROLE_FRAME = {
    "imu": "imu",
    "fix": "fixes",
    "truth": "truth",
    "odometry": "odometry",
    "observations": "observations",
    "heading": "headings",
    "autopilot_ekf": "autopilot_ekf",
    "satellites": "satellites",
    "receiver_status": "receiver_status",
}


def clock_runs(
    t_ns: np.ndarray, min_jump_ns: int = 2_000_000_000, periods: float = 20.0, max_gap_ns: int | None = None
) -> np.ndarray:
    """Run index of every row (in the order read): a new run where the clock jumps back by more than
    `min_jump_ns` and `periods` typical steps (smaller steps back are jitter, repaired by sorting), and, given
    `max_gap_ns`, where it goes on by more than that (the NMEA reader's stretches of a time of day)."""
    if len(t_ns) < 2:
        return np.zeros(len(t_ns), dtype=np.int64)
    d = np.diff(t_ns.astype(np.int64, copy=False))
    gap = d > max_gap_ns if max_gap_ns is not None else np.zeros(len(d), dtype=bool)
    if d.min() >= -min_jump_ns and not gap.any():  # no step back as long as the shortest jump: one run
        return np.zeros(len(t_ns), dtype=np.int64)
    pos = d[d > 0]
    step = int(np.median(pos)) if len(pos) else 0
    back = d < -max(min_jump_ns, int(periods * step))
    return np.r_[0, np.cumsum(back | gap)].astype(np.int64)


MAX_STAMP_NS = 1 << 62  # 146 years either side of any clock's zero: differences of stamps fit in int64


def _drop_impossible_stamps(frames_ns: dict[str, pd.DataFrame], skipped: list[Skipped]) -> None:
    """Rows whose stamp no clock can hold (a corrupt length or time field read as a 2^63-scale count, or
    a non-finite float) are dropped per stream before anything subtracts stamps."""
    for name, df in list(frames_ns.items()):
        if df is None or not len(df):
            continue
        t = df["t_ns"].to_numpy()
        with np.errstate(invalid="ignore"):
            bad = ~((t > -MAX_STAMP_NS) & (t < MAX_STAMP_NS))  # comparisons, not abs(): abs(int64 min) < 0
        if not bad.any():
            continue
        key = STREAM_KEY[name]
        sids = ["truth"] * int(bad.sum()) if key is None else df[key].to_numpy()[bad].astype(str)
        for sid, n in zip(*np.unique(sids, return_counts=True), strict=True):
            skipped.append(Skipped(str(sid), "time stamp beyond any clock (corrupt time field)", int(n), "lost"))
        frames_ns[name] = df[~bad].reset_index(drop=True)


RECORDING_GAP_NS = 86_400 * 1_000_000_000  # a day in which no stream has a stamp: separate recordings
GNSS_FRAMES = ("fixes", "observations")  # a recording has GNSS of its own
MAX_SILENT_RECORDINGS = 16  # more day-long silences than this are scattered corrupt stamps, not recordings


def _covered(t_sorted: np.ndarray) -> list[tuple[int, int]]:
    """The spans of a stream's sorted stamps, cut where it is silent for more than RECORDING_GAP_NS."""
    if not len(t_sorted):
        return []
    cut = np.flatnonzero(np.diff(t_sorted) > RECORDING_GAP_NS)
    starts, ends = t_sorted[np.r_[0, cut + 1]], t_sorted[np.r_[cut, len(t_sorted) - 1]]
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def _silence_bounds(spans: list[tuple[int, int]], ranges: list[tuple[int, int]]) -> np.ndarray:
    """The first stamp of each recording after the first: where the union of every stream's spans is
    broken by more than RECORDING_GAP_NS and no stream (first to last stamp, `ranges`) goes on across
    the silence. A stream on both sides is one source whose own clock jumped (a receiver's time spoofed
    forward, its date set wrong): evidence for the detectors, kept in one recording."""
    bounds = []
    end = None
    for a, b in sorted(spans):
        if end is not None and a - end > RECORDING_GAP_NS and not any(lo < a <= hi for lo, hi in ranges):
            bounds.append(a)
        end = b if end is None else max(end, b)
    return np.array(bounds, dtype=np.int64)


def _match_recordings(
    frames_ns: dict[str, pd.DataFrame],
    runs: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]],
    n_seg: int,
    seg_of: dict[str, np.ndarray],
) -> None:
    """Each row's recording (into `seg_of`) when the clock went back: a stream split as often as the most
    split one keeps its runs; another stream's runs go to the recordings their time spans overlap."""
    ref_key = max((k for k, (_, r) in runs.items() if len(r) and r.max() == n_seg - 1), key=lambda k: len(runs[k][1]))
    ref_pos, ref_runs = runs[ref_key]
    ref_t = frames_ns[ref_key[0]]["t_ns"].to_numpy()[ref_pos]
    ref_ranges = [(ref_t[ref_runs == k].min(), ref_t[ref_runs == k].max()) for k in range(n_seg)]
    for (name, _), (pos, r) in runs.items():
        if not len(r):
            continue
        if int(r.max()) == n_seg - 1:
            seg_of[name][pos] = r
            continue
        t = frames_ns[name]["t_ns"].to_numpy()[pos]
        for k in range(int(r.max()) + 1):
            a, b = t[r == k].min(), t[r == k].max()
            overlap = [min(b, hi) - max(a, lo) for lo, hi in ref_ranges]
            seg_of[name][pos[r == k]] = int(np.argmax(overlap))


def _segment_frames(
    frames_ns: dict[str, pd.DataFrame], skipped: list[Skipped]
) -> tuple[dict[str, pd.DataFrame], list[tuple[int, int, int]]]:
    """Split a log that joins recordings at each time reversal: the frames with the stamps of recording
    k moved after recording k-1 (gap SEGMENT_GAP_S), and (offset_ns, own t0_ns, end_ns) per recording.
    Streams are matched recording by recording in the order read; a stream with fewer recordings than
    the most-split one goes to those its time span overlaps. A log whose time never goes back but in
    which every stream is silent for more than a day (RECORDING_GAP_NS), and no stream has stamps on
    both sides of the silence (a folder of NMEA files from different years), is split there the same
    way."""
    # (frame, stream) -> (row positions, recording index of each); a stray stamp (a corrupt time far from
    # the rest, dropped later by the stream's repair) makes no recording of its own
    runs: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}
    spans: list[tuple[int, int]] = []
    ranges: list[tuple[int, int]] = []  # each stream's first and last stamp
    gnss_starts: list[int] = []  # where each span of a GNSS stream begins
    for name, df in frames_ns.items():
        if df is None or not len(df):
            continue
        key = STREAM_KEY[name]
        t_all = df["t_ns"].to_numpy()
        groups = [("truth", np.arange(len(df)))] if key is None else stream_rows(df, key)
        for sid, pos in groups:
            t = t_all if len(pos) == len(t_all) else t_all[pos]  # positions in order: all of them, or some
            # a day of samples is a copy of 70 MB each time: none made for a stream already in order
            order = None if bool(np.all(t[1:] >= t[:-1])) else np.argsort(t, kind="stable")
            t_sorted = t if order is None else t[order]
            stray_sorted = plausibility.stray_stamps(t_sorted)
            kept = t_sorted[~stray_sorted] if stray_sorted.any() else t_sorted
            covered = _covered(kept.astype(np.int64, copy=False))
            spans += covered
            if covered:
                ranges.append((covered[0][0], covered[-1][1]))
            if name in GNSS_FRAMES:
                gnss_starts += [a for a, _ in covered]
            if stray_sorted.any():
                stray = np.zeros(len(pos), dtype=bool)
                stray[slice(None) if order is None else order] = stray_sorted
                pos, t = np.asarray(pos)[~stray], t[~stray]
            runs[(name, str(sid))] = (pos, clock_runs(t))
    n_seg = 1 + max((int(r.max()) for _, r in runs.values() if len(r)), default=0)
    seg_of: dict[str, np.ndarray] = {
        name: np.full(len(df), -1, dtype=np.int64) for name, df in frames_ns.items() if df is not None
    }  # -1: a stray stamp, left where it is
    if n_seg > 1:
        why = f"time jumps back: the log joins {n_seg} recordings; each is analysed on its own"
        _match_recordings(frames_ns, runs, n_seg, seg_of)
    else:
        bounds = _silence_bounds(spans, ranges)
        if not len(bounds):
            return frames_ns, []
        if len(np.unique(np.searchsorted(bounds, gnss_starts, side="right"))) < len(bounds) + 1:
            # a stretch without GNSS is no recording to analyse but a stream on another clock (an IMU
            # years off: the cross-check leaves it out)
            return frames_ns, []
        if len(bounds) >= MAX_SILENT_RECORDINGS:  # stamps scattered over years: corrupt time fields
            why = f"no stream has a stamp for more than a day {len(bounds)} times: corrupt time fields, not split"
            skipped.append(Skipped("<log>", why, len(bounds) + 1, "not segmented"))
            return frames_ns, []
        n_seg = len(bounds) + 1
        why = (
            f"no stream has a stamp for more than a day {len(bounds)} time(s): the log holds {n_seg} "
            "recordings; each is analysed on its own"
        )
        for (name, _), (pos, _) in runs.items():
            seg_of[name][pos] = np.searchsorted(bounds, frames_ns[name]["t_ns"].to_numpy()[pos], side="right")
    starts = np.full(n_seg, np.iinfo(np.int64).max, dtype=np.int64)
    ends = np.full(n_seg, np.iinfo(np.int64).min, dtype=np.int64)
    for name, df in frames_ns.items():
        if df is None or not len(df):
            continue
        t = df["t_ns"].to_numpy().astype(np.int64)
        for k in range(n_seg):
            sel = seg_of[name] == k
            if sel.any():
                starts[k] = min(starts[k], t[sel].min())
                ends[k] = max(ends[k], t[sel].max())
    layout = []
    offset = int(starts[0])
    for k in range(n_seg):
        layout.append((offset, int(starts[k]), int(ends[k])))
        offset += int(ends[k]) - int(starts[k]) + int(SEGMENT_GAP_S * 1e9)  # Python ints: no wrap-around
    if offset >= MAX_STAMP_NS:  # spans no clock holds laid end to end: corrupt time fields, not a join
        skipped.append(
            Skipped(
                "<log>",
                f"time jumps back {n_seg - 1} time(s), but the recordings' spans add up beyond any clock "
                "(corrupt time fields): not split into recordings",
                n_seg,
                "not segmented",
            )
        )
        return frames_ns, []
    out = {}
    for name, df in frames_ns.items():
        if df is None or not len(df):
            out[name] = df
            continue
        df = df.copy()
        t = df["t_ns"].to_numpy().astype(np.int64)
        shift = np.array([layout[k][0] - layout[k][1] for k in range(n_seg)] + [0], dtype=np.int64)
        df["t_ns"] = t + shift[np.where(seg_of[name] < 0, n_seg, seg_of[name])]
        out[name] = df
    skipped.append(Skipped("<log>", why, n_seg, "segmented"))
    return out, layout


def build_table(
    source: Path,
    fmt: str,
    time_reference: str,
    frames_ns: dict[str, pd.DataFrame],
    streams: list[StreamInfo],
    skipped: list[Skipped],
    t0_ns: int | None = None,
    metadata: dict[str, str] | None = None,
    stream_spans_ns: Mapping[tuple[str, str], tuple[int, int]] | None = None,
) -> EpochTable:
    """Turn frames stamped in absolute nanoseconds (`t_ns` instead of `t_s`) into an EpochTable.

    The log start (t_s = 0) is the earliest stamp of any stream unless `t0_ns` is given. Each stream
    is repaired independently (`spooflens.plausibility`: units, impossible rows, optional values out of
    range); stream infos get their first/last time and final row count (for an
    observation stream: its epochs, one per receiver time, whatever the satellites per epoch).
    `stream_spans_ns` gives the first and last stamp, in the same clock, of streams that fill no
    frame of their own ((role, stream_id) -> (first_ns, last_ns); e.g. a velocity topic merged into
    the fixes), so their span and rate are on the table's time base too. The reader's frames are
    consumed (their columns released as they are copied), so a large log is held about once.
    """
    skipped = list(skipped)
    frames_ns = dict(frames_ns)
    _drop_impossible_stamps(frames_ns, skipped)
    frames_ns, layout = _segment_frames(frames_ns, skipped)
    kept: dict[str, tuple[pd.DataFrame, list[_Stream]]] = {}
    for name in list(frames_ns):
        df = frames_ns.pop(name)
        if df is None or not len(df):
            continue
        parts = _stream_rows(name, df)
        for part in parts:
            _repair_stream(name, df, part, skipped)
        kept[name] = (df, parts)
    auto_start = t0_ns is None
    if layout:
        t0_ns = layout[0][0]
    if t0_ns is None:
        firsts = [int(df["t_ns"].to_numpy()[p.rows].min()) for df, parts in kept.values() for p in parts if len(p.rows)]
        t0_ns = min(firsts) if firsts else 0
    table_frames: dict[str, pd.DataFrame] = {}
    for name, (df, parts) in kept.items():
        table_frames[name] = _take(name, df, parts, t0_ns, skipped)
    dropped = _cross_check(table_frames, skipped)
    if auto_start or dropped:  # a stream left out by the cross-check may have held the earliest stamp
        firsts_s = [float(df["t_s"].min()) for df in table_frames.values() if len(df)]
        shift_ns = round(min(firsts_s) * 1e9) if firsts_s else 0
        if shift_ns:
            t0_ns += shift_ns
            for df in table_frames.values():
                df["t_s"] = df["t_s"].to_numpy() - shift_ns / 1e9
    final_streams: list[StreamInfo] = []
    for s in streams:
        frame = _ROLE_FRAME.get(s.role)
        if frame is None or frame not in table_frames:
            span = (stream_spans_ns or {}).get((s.role, s.stream_id))
            if span is not None:
                s = replace(s, first_s=(span[0] - t0_ns) / 1e9, last_s=(span[1] - t0_ns) / 1e9)
            final_streams.append(s)
            continue
        df = table_frames[frame]
        key = STREAM_KEY[frame]
        t = df["t_s"].to_numpy()
        if key is not None:  # the stream's times only (a selection of the whole frame: 0.9 GB a day of IMU)
            t = t[(df[key] == s.stream_id).to_numpy(dtype=bool, na_value=False)]
        final_streams.append(
            StreamInfo(
                s.role,
                s.stream_id,
                s.topic,
                s.msgtype,
                len(np.unique(t)) if s.role in EPOCH_ROLES else len(t),
                float(t[0]) if len(t) else float("nan"),
                float(t[-1]) if len(t) else float("nan"),
                s.body_frame,
                s.frame_id,
            )
        )
    table = EpochTable(
        source=Path(source),
        format=fmt,
        t0_ns=int(t0_ns),
        time_reference=time_reference,
        streams=final_streams,
        skipped=skipped,
        metadata=dict(metadata or {}),
        segments=[
            Segment(k, (offset - t0_ns) / 1e9, (offset + end - start - t0_ns) / 1e9, start)
            for k, (offset, start, end) in enumerate(layout)
        ],
        **table_frames,
    )
    table.validate()
    return table


def checked(table: EpochTable) -> EpochTable:
    """`table` with the rows no sensor produces dropped from every frame, each drop listed.

    `build_table` already does this for what a reader hands over; frames added later (fixes solved
    from pseudoranges, a truth file beside the log) pass here before any analysis sees them.
    """
    out: EpochTable | None = None
    for name in FRAMES:
        df = table.frame(name)
        if not len(df):
            continue
        key = STREAM_KEY[name]
        drop = np.zeros(len(df), dtype=bool)
        groups = [("truth", np.arange(len(df)))] if key is None else stream_rows(df, key)
        notes = []
        for sid, rows in groups:
            cols = _Gathered(df, np.asarray(rows), exclude=("t_s", key))
            for mask, reason in plausibility.bad_rows(name, cols):
                hit = mask & ~drop[rows]
                if hit.any():
                    notes.append(Skipped(str(sid), reason, int(hit.sum())))
                    drop[rows[hit]] = True
        if drop.any():
            out = out or replace(table, skipped=list(table.skipped))
            setattr(out, name, df[~drop].reset_index(drop=True))
            out.skipped += notes
    return out or table
