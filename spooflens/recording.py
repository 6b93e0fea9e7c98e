"""The Rerun recording: trajectories on the map and in local metres, sensor and detector series, events.

Everything time-indexed is sent column-wise with `send_columns` (one call per entity, never a
per-sample `log`), on two timelines: `time` (seconds since the log start, every log has it) and
`log_time` (the log's own UTC clock, when it has one). Statistics over candidate onsets are sent on a
timeline of their own, `candidate_onset`. Histograms are static bar charts under `histograms/`, one
bar-chart view per histogram, each set of bars (data or a fitted distribution's expected counts) an
entity of its own with its own colour.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import rerun as rr
import rerun.blueprint as rrb
from numpy.typing import NDArray

from spooflens.detectors.base import Alarm, DetectorResult, Histogram, Track
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import geodetic_to_enu

APP_ID = "spooflens"
COLOURS = {"reported": (230, 60, 50), "reconstructed": (40, 180, 90), "truth": (60, 120, 230)}
# bars of a histogram in order: data sets first (clean, flagged), fitted distributions after
BAR_COLOURS = ((60, 120, 230), (230, 60, 50), (120, 120, 120), (200, 160, 40), (40, 180, 90), (150, 80, 200))
_UNSAFE = re.compile(r"[^A-Za-z0-9_\-./]")


def entity(*parts: str) -> str:
    """An entity path from names that may be topics ('/gps/fix') or contain odd characters."""
    clean = [_UNSAFE.sub("_", p.strip("/")) for p in parts if p.strip("/")]
    return "/".join(clean)


class RecordingWriter:
    """Writes one .rrd file; `close` writes the footer."""

    def __init__(
        self,
        path: Path,
        table: EpochTable,
        panels: Sequence[tuple[str, list[str]]] = (),
        bar_views: Sequence[tuple[str, str]] = (),
    ) -> None:
        self.table = table
        self.rec = rr.RecordingStream(APP_ID, recording_id=f"spooflens:{table.source.name}")
        self.rec.save(str(path), default_blueprint=default_blueprint(panels, bar_views))
        self.origin = _reference_point(table)

    def close(self) -> None:
        self.rec.disconnect()

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
        self.rec.send_columns(path, indexes=self._indexes(t), columns=rr.Scalars.columns(scalars=v))

    def track(
        self,
        name: str,
        t: NDArray[np.float64],
        lat: NDArray[np.float64],
        lon: NDArray[np.float64],
        h: NDArray[np.float64],
        colour: tuple[int, int, int],
    ) -> None:
        """A trajectory: whole line on the map and in local ENU, plus a moving point over time."""
        if not len(t):
            return
        latlon = np.c_[lat, lon]
        self.rec.log(
            entity("map", name, "track"),
            rr.GeoLineStrings(lat_lon=[latlon], colors=[colour], radii=rr.Radius.ui_points(2.0)),
            static=True,
        )
        self.rec.send_columns(
            entity("map", name, "position"), indexes=self._indexes(t), columns=rr.GeoPoints.columns(positions=latlon)
        )
        enu = geodetic_to_enu(lat, lon, h, *self.origin)
        self.rec.log(entity("local", name, "track"), rr.LineStrips3D([enu], colors=[colour]), static=True)
        self.rec.send_columns(
            entity("local", name, "position"), indexes=self._indexes(t), columns=rr.Points3D.columns(positions=enu)
        )

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


def default_blueprint(
    panels: Sequence[tuple[str, list[str]]] = (), bar_views: Sequence[tuple[str, str]] = ()
) -> rrb.Blueprint:
    detectors: rrb.Tabs | rrb.TimeSeriesView = (
        rrb.Tabs(*[rrb.TimeSeriesView(origin="/", contents=paths, name=title) for title, paths in panels])
        if panels
        else rrb.TimeSeriesView(origin="detectors", name="Detector statistics")
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.MapView(origin="map", name="Map: reported (red), reconstructed (green), truth (blue)"),
                rrb.Spatial3DView(origin="local", name="Local ENU (m)"),
            ),
            rrb.Vertical(
                detectors,
                rrb.Tabs(
                    rrb.TimeSeriesView(origin="gnss", name="GNSS quality"),
                    rrb.TimeSeriesView(origin="imu", name="IMU"),
                    rrb.TimeSeriesView(origin="curves", name="Statistic over candidate onsets", time_ranges=None),
                    *[rrb.BarChartView(origin=origin, name=title) for title, origin in bar_views],
                ),
                rrb.TextLogView(origin="events", name="Events"),
                row_shares=[3, 2, 1],
            ),
            column_shares=[1, 1],
        ),
        collapse_panels=False,
    )


def _fix_series(w: RecordingWriter, rid: str, fx: pd.DataFrame) -> None:
    t = fx["t_s"].to_numpy(dtype=float)
    for col, label in (
        ("h_acc_m", "horizontal accuracy (m)"),
        ("v_acc_m", "vertical accuracy (m)"),
        ("sats_used", "satellites used"),
        ("jamming_indicator", "jamming indicator"),
    ):
        v = fx[col].to_numpy(dtype=float)
        if np.isfinite(v).any():
            w.scalars(entity("gnss", rid, col), t, v, [label])
    w.scalars(entity("gnss", rid, "fix_type"), t, fx["fix_type"].to_numpy(dtype=float), ["fix type"])
    vel = fx[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy(dtype=float)
    if np.isfinite(vel).any():
        w.scalars(entity("gnss", rid, "velocity_mps"), t, vel, ["east", "north", "up"])


def _imu_series(w: RecordingWriter, iid: str, imu: pd.DataFrame) -> None:
    t = imu["t_s"].to_numpy(dtype=float)
    w.scalars(
        entity("imu", iid, "specific_force_mps2"),
        t,
        imu[["ax_mps2", "ay_mps2", "az_mps2"]].to_numpy(dtype=float),
        ["x", "y", "z"],
    )
    w.scalars(
        entity("imu", iid, "angular_rate_radps"),
        t,
        imu[["wx_radps", "wy_radps", "wz_radps"]].to_numpy(dtype=float),
        ["x", "y", "z"],
    )


def _alarm_events(name: str, alarms: Sequence[Alarm]) -> tuple[list[float], list[str], list[str]]:
    t, text, level = [], [], []
    for a in alarms:
        t.append(a.start_s)
        text.append(
            f"{name}: ALARM from {a.start_s:.2f} s to {a.end_s:.2f} s, peak {a.peak_statistic:.3g} at {a.peak_s:.2f} s"
        )
        level.append("WARN")
        if a.onset_s is not None:
            t.append(a.onset_s)
            ci = f" (interval {a.onset_interval_s[0]:.2f}-{a.onset_interval_s[1]:.2f} s)" if a.onset_interval_s else ""
            text.append(f"{name}: estimated attack onset {a.onset_s:.2f} s{ci}")
            level.append("WARN")
    return t, text, level


def write_recording(
    path: Path,
    table: EpochTable,
    results: Sequence[DetectorResult],
    verdict_lines: Sequence[tuple[float, str, str]] = (),
) -> None:
    """Write the whole recording of one analysed log."""
    w = RecordingWriter(path, table, detector_panels(results), histogram_views(results))
    try:
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
        for iid in table.imus():
            _imu_series(w, iid, table.imu_of(iid))
        ev_t: list[float] = [0.0] * len(table.skipped)
        ev_text = [f"reader: {s}" for s in table.skipped]
        ev_level = ["INFO"] * len(table.skipped)
        for res in results:
            _detector(w, res)
            t, text, level = _alarm_events(res.name, res.alarms)
            ev_t += t
            ev_text += text
            ev_level += level
        for t_s, text, level in verdict_lines:
            ev_t.append(t_s)
            ev_text.append(text)
            ev_level.append(level)
        w.events(ev_t, ev_text, ev_level)
    finally:
        w.close()


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
