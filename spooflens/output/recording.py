"""The Rerun recording: trajectories on the map and in local metres, sensor and detector series, events.

In depth: docs/outputs.md."""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import rerun as rr
import rerun.blueprint as rrb
from numpy.typing import NDArray

from spooflens.detectors.base import Alarm, DetectorResult, Histogram, Track
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import geodetic_to_enu
from spooflens.inventory import quality_columns
from spooflens.navigation.product import NAVIGATION
from spooflens.pipeline.evidence import ORDER, Evidence, label
from spooflens.pipeline.verdict import KIND_LABELS, Kind, Verdict

APP_ID = "spooflens"
COLOURS = {"reported": (230, 60, 50), "reconstructed": (40, 180, 90), "truth": (60, 120, 230)}
# bars of a histogram in order: data sets first (clean, flagged), fitted distributions after
BAR_COLOURS = ((60, 120, 230), (230, 60, 50), (120, 120, 120), (200, 160, 40), (40, 180, 90), (150, 80, 200))
_UNSAFE = re.compile(r"[^A-Za-z0-9_\-./]")
BLOCK_ROWS = 100_000  # rows per send_columns call
# Rerun writes the file in threads of its own, slower than the columns are sent: without waiting for it
# now and then, a day of 100 Hz IMU series queued in memory (0.6 GB) until the end
FLUSH_BYTES = 64_000_000
# a recording begun during the analysis waits more often: what Rerun holds then adds to the analysis' peak
EARLY_FLUSH_BYTES = 8_000_000


def entity(*parts: str) -> str:
    """An entity path from names that may be topics ('/gps/fix') or contain odd characters."""
    clean = [_UNSAFE.sub("_", p.strip("/")) for p in parts if p.strip("/")]
    return "/".join(clean)


class RecordingWriter:
    """Writes one .rrd file; `close` writes the footer. With `final`, the file is written under `path`
    and moved to `final` when closed (a recording begun before its analysis ends: a failed analysis
    leaves no half recording, and none in place of an earlier one)."""

    def __init__(
        self,
        path: Path,
        table: EpochTable,
        panels: Sequence[tuple[str, list[str]]] = (),
        keys: Sequence[KeyStatistic] = (),
        bar_views: Sequence[tuple[str, str]] = (),
        final: Path | None = None,
    ) -> None:
        self.table = table
        self.path, self.final = path, final
        self.rec = rr.RecordingStream(APP_ID, recording_id=f"spooflens:{table.source.name}")
        # a recording begun early gets its blueprint when the results are known (`set_blueprint`)
        blueprint = None if final is not None else default_blueprint(panels, keys, bar_views)
        self.rec.save(str(path), default_blueprint=blueprint)
        self.origin = _reference_point(table)
        self._queued_bytes = 0
        self._flush_bytes = FLUSH_BYTES if final is None else EARLY_FLUSH_BYTES

    def set_blueprint(self, blueprint: rrb.Blueprint) -> None:
        """The default blueprint, as `save(default_blueprint=...)` gives it (the default, not forced active)."""
        rr.send_blueprint(blueprint, make_active=False, make_default=True, recording=self.rec)

    def _sent(self, nbytes: int) -> None:
        """Count what was sent; past the writer's limit, wait for Rerun to write it (bounded memory)."""
        self._queued_bytes += nbytes
        if self._queued_bytes >= self._flush_bytes:
            self.rec.flush()
            self._queued_bytes = 0

    def close(self) -> None:
        self.rec.disconnect()
        if self.final is not None:
            self.path.replace(self.final)

    def abandon(self) -> None:
        """Close without keeping the file (a recording begun for an analysis that did not end)."""
        self.rec.disconnect()
        self.path.unlink(missing_ok=True)

    def _indexes(self, t_s: NDArray[np.float64]) -> list[rr.TimeColumn]:
        t = np.asarray(t_s, dtype=float)
        idx = [rr.TimeColumn("time", duration=t)]
        unix = self.table.unix_ns(t)
        if unix is not None:
            idx.append(rr.TimeColumn("log_time", timestamp=unix.astype("datetime64[ns]")))
        return idx

    def scalars(
        self, path: str, t: NDArray[np.float64], values: NDArray[np.float64], names: Sequence[str] = ()
    ) -> None:
        v = np.asarray(values, dtype=float)
        if not len(t):
            return
        if names:
            self.rec.log(path, rr.SeriesLines(names=list(names)), static=True)
        for a in range(0, len(t), BLOCK_ROWS):
            b = a + BLOCK_ROWS
            self.rec.send_columns(path, indexes=self._indexes(t[a:b]), columns=rr.Scalars.columns(scalars=v[a:b]))
            self._sent(v[a:b].nbytes + 16 * len(t[a:b]))

    def track(
        self,
        name: str,
        t: NDArray[np.float64],
        lat: NDArray[np.float64],
        lon: NDArray[np.float64],
        h: NDArray[np.float64],
        colour: tuple[int, int, int],
    ) -> None:
        """A trajectory: whole line on the map and in local ENU, plus a moving point over time. A NaN row
        breaks the line (a track the navigation made on each stretch between an IMU's gaps)."""
        known = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(h)
        t, lat, lon, h = (np.asarray(x, dtype=float)[known] for x in (t, lat, lon, h))
        if not len(t):
            return
        pieces = np.split(np.arange(len(t)), np.flatnonzero(np.diff(np.cumsum(~known)[known]) > 0) + 1)
        latlon = np.c_[lat, lon]
        self.rec.log(
            entity("map", name, "track"),
            rr.GeoLineStrings(
                lat_lon=[latlon[k] for k in pieces], colors=[colour] * len(pieces), radii=rr.Radius.ui_points(2.0)
            ),
            static=True,
        )
        enu = geodetic_to_enu(lat, lon, h, *self.origin)
        self.rec.log(
            entity("local", name, "track"),
            rr.LineStrips3D([enu[k] for k in pieces], colors=[colour] * len(pieces)),
            static=True,
        )
        for a in range(0, len(t), BLOCK_ROWS):
            b = a + BLOCK_ROWS
            index = self._indexes(t[a:b])
            self.rec.send_columns(
                entity("map", name, "position"), indexes=index, columns=rr.GeoPoints.columns(positions=latlon[a:b])
            )
            self.rec.send_columns(
                entity("local", name, "position"), indexes=index, columns=rr.Points3D.columns(positions=enu[a:b])
            )
            self._sent(latlon[a:b].nbytes + enu[a:b].nbytes + 32 * len(t[a:b]))

    def histogram(self, origin: str, hist: Histogram) -> None:
        """Each set of bars of `hist` as a static bar chart under `origin`."""
        edges = np.asarray(hist.edges, dtype=float)
        if len(edges) < 2:
            return
        centres, widths = 0.5 * (edges[1:] + edges[:-1]), np.diff(edges)
        for i, bars in enumerate(hist.bars):
            self.rec.log(
                entity(origin, bars.label),
                rr.BarChart(
                    np.asarray(bars.counts, dtype=float),
                    abscissa=centres,
                    widths=widths,
                    color=BAR_COLOURS[i % len(BAR_COLOURS)],
                ),
                static=True,
            )

    def events(self, t: Sequence[float], texts: Sequence[str], levels: Sequence[str]) -> None:
        if not t:
            return
        order = np.argsort(np.asarray(t, dtype=float), kind="stable")
        self.rec.send_columns(
            "events",
            indexes=self._indexes(np.asarray(t, dtype=float)[order]),
            columns=rr.TextLog.columns(text=[texts[i] for i in order], level=[levels[i] for i in order]),
        )


def _reference_point(table: EpochTable) -> tuple[float, float, float]:
    for frame in (table.fixes, table.truth):
        if len(frame):
            return float(frame["lat_deg"].iloc[0]), float(frame["lon_deg"].iloc[0]), float(frame["height_m"].iloc[0])
    return 0.0, 0.0, 0.0


def detector_panels(results: Sequence[DetectorResult]) -> list[tuple[str, list[str]]]:
    """(title, entity paths) of one time-series panel per detector and unit, alarming detectors first.

    A NIS in the thousands, a probability and an innovation in metres on one axis would hide each
    other; a statistic and its threshold line share a panel.
    """
    panels: list[tuple[bool, str, list[str]]] = []
    for res in results:
        if not res.ran:
            continue
        groups: dict[str, list[str]] = {}
        for s in res.series:
            path = "/" + entity("detectors", res.name, s.name)
            groups.setdefault(s.unit, []).append(path)
            if s.threshold is not None:
                groups[s.unit].append(path + "_threshold")
        for unit, paths in groups.items():
            title = res.name + (f" ({unit})" if len(groups) > 1 and unit else "")
            panels.append((bool(res.alarms) and not res.advisory, title, paths))
    return [(title, paths) for _, title, paths in sorted(panels, key=lambda p: not p[0])]


def histogram_origin(detector: str, hist: Histogram) -> str:
    return entity("histograms", detector, hist.name)


def histogram_views(results: Sequence[DetectorResult]) -> list[tuple[str, str]]:
    """(title, origin) of one bar-chart view per histogram of every detector that ran."""
    return [
        (f"{res.name}: {h.x_label}", "/" + histogram_origin(res.name, h))
        for res in results
        if res.ran
        for h in res.histograms
    ]


@dataclass(frozen=True)
class KeyStatistic:
    """The statistic that speaks for one evidence class on the Overview tab."""

    evidence: Evidence
    detector: str
    paths: tuple[str, ...]  # the series and its threshold line


def key_statistics(results: Sequence[DetectorResult]) -> list[KeyStatistic]:
    """Per evidence class that ran, in ORDER: the first counted detector that alarmed (else the first that
    ran) and its first series with a threshold (else its first series)."""
    out = []
    for c in ORDER:
        ran = [r for r in results if r.ran and r.evidence == c and r.series]
        if not ran:
            continue
        lead = next((r for r in ran if r.alarms and not r.advisory), ran[0])
        s = next((x for x in lead.series if x.threshold is not None), lead.series[0])
        path = "/" + entity("detectors", lead.name, s.name)
        out.append(KeyStatistic(c, lead.name, (path, path + "_threshold") if s.threshold is not None else (path,)))
    return out


def default_blueprint(
    panels: Sequence[tuple[str, list[str]]] = (),
    keys: Sequence[KeyStatistic] = (),
    bar_views: Sequence[tuple[str, str]] = (),
) -> rrb.Blueprint:
    """Tabs: Overview first (map, incident timeline, the key statistic of each evidence class, events),
    then one tab per detector panel, then local metres, GNSS quality, IMU, odometry, curves and
    histograms."""
    key_views = [
        rrb.TimeSeriesView(origin="/", contents=list(k.paths), name=f"{label(k.evidence)}: {k.detector}") for k in keys
    ]
    overview = rrb.Horizontal(
        rrb.Vertical(
            rrb.MapView(origin="map", name="Map: reported (red), reconstructed (green), truth (blue)"),
            rrb.TextLogView(origin="events", name="Events"),
            row_shares=[3, 1],
        ),
        rrb.Vertical(
            rrb.TimeSeriesView(origin="overview", name="Incidents and alarms by evidence class"),
            *key_views,
        ),
        column_shares=[1, 1],
        name="Overview",
    )
    detector_tabs = [rrb.TimeSeriesView(origin="/", contents=paths, name=title) for title, paths in panels]
    return rrb.Blueprint(
        rrb.Tabs(
            overview,
            *detector_tabs,
            rrb.Spatial3DView(origin="local", name="Local ENU (m)"),
            rrb.TimeSeriesView(origin="gnss", name="GNSS quality"),
            rrb.TimeSeriesView(origin="imu", name="IMU"),
            rrb.Horizontal(
                rrb.TimeSeriesView(origin="odometry", contents="$origin/**/speed_mps", name="Wheel speed (m/s)"),
                rrb.Spatial3DView(origin="odometry", name="Odometry path (its own frame)"),
                name="Odometry",
            ),
            rrb.TimeSeriesView(origin="curves", name="Statistic over candidate onsets", time_ranges=None),
            *[rrb.BarChartView(origin=origin, name=title) for title, origin in bar_views],
            active_tab=0,
        ),
        collapse_panels=False,
    )


def overview_lanes(
    results: Sequence[DetectorResult], verdict: Verdict | None, duration_s: float
) -> list[tuple[str, NDArray[np.float64], NDArray[np.float64]]]:
    """(name, t, level) step series for the Overview timeline: one lane per evidence class that ran, at
    height i, raised by 0.8 while any of its counted detectors alarms; incidents on the lane below 0."""
    lanes = []

    def steps(intervals: Sequence[tuple[float, float]], base: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        t, v = [0.0], [base]
        for a, b in sorted(intervals):
            t += [a, a, b, b]
            v += [base, base + 0.8, base + 0.8, base]
        t.append(max(duration_s, t[-1]))
        v.append(base)
        return np.asarray(t, dtype=float), np.asarray(v, dtype=float)

    classes = [c for c in ORDER if any(r.ran and r.evidence == c for r in results)]
    for i, c in enumerate(classes):
        counted = [r for r in results if r.ran and r.evidence == c and not r.advisory]
        alarms = [(a.start_s, a.end_s) for r in counted for a in r.alarms]
        lanes.append((label(c), *steps(alarms, float(i))))
    if verdict is not None:
        spans = [(inc.onset_s, inc.end_s) for inc in verdict.incidents if inc.is_spoofing]
        lanes.append(("spoofing incidents", *steps(spans, -1.0)))
        for k, kind in enumerate(OTHER_KINDS):
            spans = [(min(e.onset_s, e.start_s), e.end_s) for e in verdict.events_of(kind)]
            if spans:
                lanes.append((f"events: {kind.value}", *steps(spans, -2.0 - k)))
    return lanes


# the lanes below the spoofing incidents, one per other kind of event, each at a height of its own
OTHER_KINDS = (Kind.JAMMING, Kind.DEGRADATION, Kind.RECEIVER_FAULT, Kind.UNKNOWN)


def interference_marks(
    table: EpochTable, verdict: Verdict
) -> list[tuple[str, NDArray[np.float64], NDArray[np.float64]]]:
    """(receiver, t, level) per receiver with satellite C/N0 and a jamming / interference event: a step from
    just below its weakest satellite's C/N0 to just above its strongest while the interference lasted,
    drawn beside each satellite's C/N0."""
    events = verdict.events_of(Kind.JAMMING)
    sats = table.satellites if len(table.satellites) else table.observations
    if not events or not len(sats):
        return []
    out = []
    for rid, rows in sats.groupby(sats["receiver_id"].astype(str), sort=True):
        cn0 = rows["cn0_dbhz"].to_numpy(dtype=float)
        mine = [e for e in events if not e.receivers or rid in e.receivers]
        if not np.isfinite(cn0).any() or not mine:
            continue
        low, high = float(np.nanmin(cn0)) - 2.0, float(np.nanmax(cn0)) + 2.0
        t, v = [0.0], [low]
        for e in sorted(mine, key=lambda e: e.start_s):
            a = min(e.onset_s, e.start_s)
            t += [a, a, e.end_s, e.end_s]
            v += [low, high, high, low]
        t.append(max(table.duration_s, t[-1]))
        v.append(low)
        out.append((str(rid), np.asarray(t, dtype=float), np.asarray(v, dtype=float)))
    return out


def _fix_series(w: RecordingWriter, rid: str, fx: pd.DataFrame) -> None:
    t = fx["t_s"].to_numpy(dtype=float)
    for col, text in quality_columns(fx):
        w.scalars(entity("gnss", rid, col), t, fx[col].to_numpy(dtype=float), [text])
    vel = fx[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy(dtype=float)
    if np.isfinite(vel).any():
        w.scalars(entity("gnss", rid, "velocity_mps"), t, vel, ["east", "north", "up"])


def _odometry(w: RecordingWriter, oid: str, od: pd.DataFrame) -> None:
    """Wheel odometry: its speed over ground, and its path in its own (not geo-referenced) frame."""
    t = od["t_s"].to_numpy(dtype=float)
    speed = np.hypot(od["vx_mps"].to_numpy(dtype=float), od["vy_mps"].to_numpy(dtype=float))
    w.scalars(entity("odometry", oid, "speed_mps"), t, speed, [f"wheel speed {oid} (m/s)"])
    w.scalars(entity("odometry", oid, "yaw_rate_radps"), t, od["wz_radps"].to_numpy(dtype=float), ["yaw rate (rad/s)"])
    xyz = od[["x_m", "y_m", "z_m"]].to_numpy(dtype=float)
    if len(xyz) and np.isfinite(xyz).all(axis=1).any():
        path = xyz[np.isfinite(xyz).all(axis=1)]
        w.rec.log(entity("odometry", oid, "path"), rr.LineStrips3D([path], colors=[(40, 140, 60)]), static=True)


def _satellite_series(w: RecordingWriter, table: EpochTable) -> None:
    """Each satellite's C/N0 (and the receiver's elevation for it) over time: where a counterfeit
    satellite shows, one line apart from the others."""
    sats = table.satellites if len(table.satellites) else table.observations
    if not len(sats) or not np.isfinite(sats["cn0_dbhz"].to_numpy(dtype=float)).any():
        return
    for (rid, sv), rows in sats.groupby([sats["receiver_id"].astype(str), sats["sv_id"].astype(str)], sort=True):
        t = rows["t_s"].to_numpy(dtype=float)
        w.scalars(entity("gnss", str(rid), "cn0_dbhz", str(sv)), t, rows["cn0_dbhz"].to_numpy(dtype=float), [str(sv)])
        if "elevation_deg" in rows and np.isfinite(rows["elevation_deg"].to_numpy(dtype=float)).any():
            el = rows["elevation_deg"].to_numpy(dtype=float)
            w.scalars(entity("gnss", str(rid), "elevation_deg", str(sv)), t, el, [str(sv)])


def _imu_series(w: RecordingWriter, iid: str, imu: pd.DataFrame) -> None:
    """Specific force and angular rate, taken from the table a block at a time (a day at 100 Hz is 8.6
    million rows: no whole-length stacked copy)."""
    series = (
        ("specific_force_mps2", ["ax_mps2", "ay_mps2", "az_mps2"]),
        ("angular_rate_radps", ["wx_radps", "wy_radps", "wz_radps"]),
    )
    for name, _ in series:
        w.rec.log(entity("imu", iid, name), rr.SeriesLines(names=["x", "y", "z"]), static=True)
    for a in range(0, len(imu), BLOCK_ROWS):
        rows = imu.iloc[a : a + BLOCK_ROWS]
        t = rows["t_s"].to_numpy(dtype=float)
        for name, cols in series:
            w.scalars(entity("imu", iid, name), t, rows[cols].to_numpy(dtype=float))


def _alarm_events(
    name: str, alarms: Sequence[Alarm], advisory: bool = False
) -> tuple[list[float], list[str], list[str]]:
    """Event-log lines of one detector's alarms. An advisory rule's alarms (drawn, not counted in the
    verdict) say so, at INFO level, so they cannot be read as a warning."""
    t, text, level = [], [], []
    kind = "ADVISORY alarm (not counted in the verdict)" if advisory else "ALARM"
    lvl = "INFO" if advisory else "WARN"
    for a in alarms:
        t.append(a.start_s)
        text.append(
            f"{name}: {kind} from {a.start_s:.2f} s to {a.end_s:.2f} s, peak {a.peak_statistic:.3g} at {a.peak_s:.2f} s"
        )
        level.append(lvl)
        if a.onset_s is not None:
            t.append(a.onset_s)
            ci = f" (interval {a.onset_interval_s[0]:.2f}-{a.onset_interval_s[1]:.2f} s)" if a.onset_interval_s else ""
            text.append(f"{name}: {'advisory: ' if advisory else ''}estimated attack onset {a.onset_s:.2f} s{ci}")
            level.append(lvl)
    return t, text, level


def write_recording(
    path: Path,
    table: EpochTable,
    results: Sequence[DetectorResult],
    verdict_lines: Sequence[tuple[float, str, str]] = (),
    verdict: Verdict | None = None,
    begun: RecordingWriter | None = None,
) -> None:
    """Write the whole recording of one analysed log (with the verdict, the Overview timeline shows its
    incidents too). `begun`: a writer that already holds the log's streams (`begin_recording`)."""
    panels, keys, bars = detector_panels(results), key_statistics(results), histogram_views(results)
    if begun is None:
        w = RecordingWriter(path, table, panels, keys, bars)
    else:
        w = begun
        w.set_blueprint(default_blueprint(panels, keys, bars))
    try:
        for lane, lane_t, lane_level in overview_lanes(results, verdict, table.duration_s):
            w.scalars(entity("overview", lane), lane_t, lane_level, [lane])
        if begun is None:
            write_streams(w, table)
        for rid, mark_t, mark_level in interference_marks(table, verdict) if verdict is not None else ():
            w.scalars(entity("gnss", rid, "cn0_dbhz", "interference"), mark_t, mark_level, ["interference"])
        ev_t: list[float] = [0.0] * len(table.skipped)
        ev_text = [f"reader: {s}" for s in table.skipped]
        ev_level = ["INFO"] * len(table.skipped)
        for res in results:
            _detector(w, res)
            t, text, level = _alarm_events(res.name, res.alarms, res.advisory)
            ev_t += t
            ev_text += text
            ev_level += level
        for tr in verdict.reconstructed if verdict is not None else ():
            _track(w, NAVIGATION, tr)  # beside the navigation's own tracks, the INS the verdict coasted
        for e in verdict.events if verdict is not None else ():
            ev_t.append(min(e.onset_s, e.start_s))
            ev_text.append(f"EVENT {KIND_LABELS[e.kind]}: {e.text}")
            ev_level.append("WARN" if e.kind in (Kind.SPOOFING, Kind.JAMMING) else "INFO")
        for line_t, line_text, line_level in verdict_lines:
            ev_t.append(line_t)
            ev_text.append(line_text)
            ev_level.append(line_level)
        w.events(ev_t, ev_text, ev_level)
    finally:
        w.close()


def begin_recording(path: Path, table: EpochTable) -> RecordingWriter:
    """A recording of `table` begun before its analysis ends: written beside `path` (moved there when
    `write_recording` closes it), with the log's streams, which need no analysis (`write_streams`)."""
    w = RecordingWriter(path.with_name(path.name + ".part"), table, final=path)
    try:
        write_streams(w, table)
        w.rec.flush()  # written out now, not held in Rerun's queue through the analysis' peak of memory
    except BaseException:
        w.abandon()
        raise
    return w


def write_streams(w: RecordingWriter, table: EpochTable) -> None:
    """What the log itself holds: odometry, each receiver's fixes and their quality, truth, the
    satellites' C/N0, the IMU."""
    for oid in dict.fromkeys(table.odometry["odometry_id"].astype(str)):
        _odometry(w, oid, table.odometry[table.odometry["odometry_id"].astype(str) == oid])
    for rid in table.receivers():
        fx = table.fixes_of(rid)
        w.track(
            entity("reported", rid),
            fx["t_s"].to_numpy(),
            fx["lat_deg"].to_numpy(),
            fx["lon_deg"].to_numpy(),
            fx["height_m"].to_numpy(),
            COLOURS["reported"],
        )
        _fix_series(w, rid, fx)
    if len(table.truth):
        tr = table.truth
        w.track(
            "truth",
            tr["t_s"].to_numpy(),
            tr["lat_deg"].to_numpy(),
            tr["lon_deg"].to_numpy(),
            tr["height_m"].to_numpy(),
            COLOURS["truth"],
        )
    _satellite_series(w, table)
    for iid in table.imus():
        _imu_series(w, iid, table.imu_of(iid))


def _detector(w: RecordingWriter, res: DetectorResult) -> None:
    if not res.ran:
        return
    for s in res.series:
        path = entity("detectors", res.name, s.name)
        label = f"{res.name} {s.name}" + (f" ({s.unit})" if s.unit else "")
        names = [f"{label} {c}" for c in s.components] if s.components else [label]
        w.scalars(path, s.t, s.values, names)
        if s.threshold is not None and len(s.t):
            w.scalars(path + "_threshold", s.t, np.full(len(s.t), s.threshold), [f"{res.name} {s.name} threshold"])
    for c in res.curves:
        if len(c.x):
            path = entity("curves", res.name, c.name)
            w.rec.log(path, rr.SeriesLines(names=[f"{res.name} {c.name} over {c.x_label}"]), static=True)
            w.rec.send_columns(
                path,
                indexes=[rr.TimeColumn("candidate_onset", duration=np.asarray(c.x, float))],
                columns=rr.Scalars.columns(scalars=np.asarray(c.y, float)),
            )
    for tr in res.tracks:
        _track(w, res.name, tr)
    for h in res.histograms:
        w.histogram(histogram_origin(res.name, h), h)


def _track(w: RecordingWriter, detector: str, tr: Track) -> None:
    colour = COLOURS["reconstructed"] if "reconstructed" in tr.name else (200, 160, 40)
    w.track(entity(detector, tr.name), tr.t, tr.lat_deg, tr.lon_deg, tr.height_m, colour)
