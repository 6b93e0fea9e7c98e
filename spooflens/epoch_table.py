"""The unified epoch table: every stream of a log on one time base, plus what was skipped.

Readers collect rows with absolute timestamps in the log's own clock (integer nanoseconds) and hand
them to `build_table`, which is the only place that sets the time base, sorts, removes duplicates,
drops unusable rows and records each repair. So every format gets the same treatment.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from spooflens.errors import SchemaError
from spooflens.gnss.ephemeris import GpsEphemerides, Klobuchar
from spooflens.schema import FRAMES, STREAM_KEY, empty_frame, make_frame, schema_problems

GPS_EPOCH_UNIX_NS = 315_964_800_000_000_000  # 1980-01-06T00:00:00Z
# GPS time (ns since the GPS epoch) at which each leap second took effect, and GPS-UTC after it.
_LEAP_SECONDS = [
    (ts, n)
    for ts, n in zip(
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
        * 1_000_000_000,
        range(1, 19),
        strict=True,
    )
]


def gps_utc_offset_ns(gps_ns: np.ndarray) -> np.ndarray:
    """GPS minus UTC (leap seconds) at the given GPS times, in ns."""
    starts = np.array([ts for ts, _ in _LEAP_SECONDS], dtype=np.int64)
    return np.searchsorted(starts, np.asarray(gps_ns, dtype=np.int64), side="right").astype(np.int64) * 1_000_000_000


def gps_seconds_of_unix_ns(unix_ns: np.ndarray | int) -> np.ndarray:
    """UTC nanoseconds since 1970 -> GPS seconds since 1980-01-06 (leap seconds added)."""
    gps_ns = np.asarray(unix_ns, dtype=np.int64) - GPS_EPOCH_UNIX_NS
    return (gps_ns + gps_utc_offset_ns(gps_ns)) / 1e9


def unix_ns_of_gps_seconds(gps_s: np.ndarray | float) -> np.ndarray:
    """GPS seconds since 1980-01-06 -> UTC nanoseconds since 1970."""
    gps_ns = np.round(np.asarray(gps_s, dtype=float) * 1e9).astype(np.int64)
    return gps_ns + GPS_EPOCH_UNIX_NS - gps_utc_offset_ns(gps_ns)


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

    @property
    def rate_hz(self) -> float:
        span = self.last_s - self.first_s
        return (self.count - 1) / span if self.count > 1 and span > 0 else float("nan")


@dataclass(frozen=True)
class Skipped:
    """Messages or rows a reader skipped or repaired, with the reason and how many."""

    stream: str
    reason: str
    count: int
    action: str = "skipped"

    def __str__(self) -> str:
        return f"{self.stream}: {self.action} {self.count} ({self.reason})"


@dataclass
class EpochTable:
    """All frames of one log, times in seconds since `t0_ns` of the log's own clock."""

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
    streams: list[StreamInfo] = field(default_factory=list)
    skipped: list[Skipped] = field(default_factory=list)
    # the broadcast ephemerides behind the satellite states (a RINEX navigation file, a simulated
    # constellation): what a RINEX copy of the log needs, and the ionosphere model for solutions
    ephemerides: GpsEphemerides | None = None
    # provenance a reader found: firmware and receiver versions, and the meaning applied to each logged
    # enum ("enum.spoofing_state": "PX4 SensorGps >= 1.15: 1 OK, 2 mitigated, 3 detected")
    metadata: dict[str, str] = field(default_factory=dict)

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
        return list(dict.fromkeys(self.fixes["receiver_id"].astype(str)))

    def imus(self) -> list[str]:
        return list(dict.fromkeys(self.imu["imu_id"].astype(str)))

    def fixes_of(self, receiver_id: str) -> pd.DataFrame:
        return self.fixes[self.fixes["receiver_id"] == receiver_id].reset_index(drop=True)

    def imu_of(self, imu_id: str) -> pd.DataFrame:
        return self.imu[self.imu["imu_id"] == imu_id].reset_index(drop=True)

    def stream(self, role: str, stream_id: str) -> StreamInfo | None:
        return next((s for s in self.streams if s.role == role and s.stream_id == stream_id), None)

    def absolute_ns(self, t_s: float | np.ndarray) -> np.ndarray:
        """Map table times back to the log's own clock (integer nanoseconds)."""
        return self.t0_ns + np.round(np.asarray(t_s, dtype=float) * 1e9).astype(np.int64)

    def unix_ns(self, t_s: float | np.ndarray) -> np.ndarray | None:
        """Table times as UTC nanoseconds since 1970, or None if the log has no absolute clock."""
        ns = self.absolute_ns(t_s)
        if self.time_reference == "unix":
            return ns
        if self.time_reference == "gps":
            return ns + GPS_EPOCH_UNIX_NS - gps_utc_offset_ns(ns)
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
    if end_ns is not None and end_ns - t[-1] > factor * period:
        missing += (end_ns - t[-1]) / period - 1.0
    return int(np.round(missing))


def _repair_stream(frame: str, sid: str, df: pd.DataFrame, skipped: list[Skipped]) -> pd.DataFrame:
    """Sort one stream by time, drop unusable rows, then duplicate stamps; record each repair."""
    t = df["t_ns"].to_numpy()
    if len(t) > 1 and np.any(np.diff(t) < 0):
        n_back = int(np.sum(np.diff(t) < 0))
        skipped.append(Skipped(sid, f"time went backwards {n_back} times; rows sorted by time", n_back, "repaired"))
        df = df.sort_values("t_ns", kind="stable")
    if frame in ("fixes", "truth"):
        lat = df["lat_deg"].to_numpy(dtype=float)
        lon = df["lon_deg"].to_numpy(dtype=float)
        h = df["height_m"].to_numpy(dtype=float)
        bad = ~np.isfinite(lat) | ~np.isfinite(lon) | ~np.isfinite(h) | ((lat == 0) & (lon == 0))
        if bad.any():
            skipped.append(Skipped(sid, "NaN or zero latitude/longitude/height (no fix)", int(bad.sum())))
            df = df[~bad]
        wrong = (np.abs(df["lat_deg"]) > 90) | (np.abs(df["lon_deg"]) > 180)
        if wrong.any():
            skipped.append(Skipped(sid, "latitude/longitude out of range", int(wrong.sum())))
            df = df[~wrong]
    if frame == "imu":
        vals = df[["ax_mps2", "ay_mps2", "az_mps2", "wx_radps", "wy_radps", "wz_radps"]].to_numpy(dtype=float)
        bad = ~np.all(np.isfinite(vals), axis=1)
        if bad.any():
            skipped.append(Skipped(sid, "NaN specific force or angular rate", int(bad.sum())))
            df = df[~bad]
    # an observation epoch has one row per satellite: a duplicate is the same satellite twice
    key = ["t_ns", "sv_id"] if frame == "observations" else ["t_ns"]
    dup = df.duplicated(subset=key, keep="first").to_numpy()
    if dup.any():
        what = "duplicate (timestamp, satellite) rows" if frame == "observations" else "duplicate timestamps"
        skipped.append(Skipped(sid, f"{what}; kept the first", int(dup.sum())))
        df = df[~dup]
    return df


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
    is repaired independently; stream infos get their first/last time and final row count (for an
    observation stream: its epochs, one per receiver time, whatever the satellites per epoch).
    `stream_spans_ns` gives the first and last stamp, in the same clock, of streams that fill no
    frame of their own ((role, stream_id) -> (first_ns, last_ns); e.g. a velocity topic merged into
    the fixes), so their span and rate are on the table's time base too.
    """
    skipped = list(skipped)
    repaired: dict[str, pd.DataFrame] = {}
    for name, df in frames_ns.items():
        if df is None or not len(df):
            continue
        key = STREAM_KEY[name]
        parts = [("truth", df)] if key is None else [(str(sid), g) for sid, g in df.groupby(key, sort=False)]
        fixed = [_repair_stream(name, sid, g, skipped) for sid, g in parts]
        repaired[name] = pd.concat(fixed, ignore_index=True) if fixed else df.iloc[:0]
    if t0_ns is None:
        firsts = [int(df["t_ns"].min()) for df in repaired.values() if len(df)]
        t0_ns = min(firsts) if firsts else 0
    table_frames: dict[str, pd.DataFrame] = {}
    for name, df in repaired.items():
        cols = {c: df[c].to_numpy() for c in df.columns if c != "t_ns"}
        cols["t_s"] = (df["t_ns"].to_numpy(dtype=np.int64) - t0_ns) / 1e9
        table_frames[name] = make_frame(name, cols, len(df))
    final_streams: list[StreamInfo] = []
    for s in streams:
        frame = {
            "imu": "imu",
            "fix": "fixes",
            "truth": "truth",
            "odometry": "odometry",
            "observations": "observations",
            "heading": "headings",
            "autopilot_ekf": "autopilot_ekf",
        }.get(s.role)
        if frame is None or frame not in table_frames:
            span = (stream_spans_ns or {}).get((s.role, s.stream_id))
            if span is not None:
                s = replace(s, first_s=(span[0] - t0_ns) / 1e9, last_s=(span[1] - t0_ns) / 1e9)
            final_streams.append(s)
            continue
        df = table_frames[frame]
        key = STREAM_KEY[frame]
        rows = df if key is None else df[df[key] == s.stream_id]
        t = rows["t_s"].to_numpy()
        final_streams.append(
            StreamInfo(
                s.role,
                s.stream_id,
                s.topic,
                s.msgtype,
                len(np.unique(t)) if s.role == "observations" else len(rows),
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
        **table_frames,
    )
    table.validate()
    return table
