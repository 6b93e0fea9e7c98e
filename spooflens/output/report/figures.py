"""The report's figures, drawn with matplotlib and inlined as SVG.

In depth: docs/outputs.md."""

from __future__ import annotations

import io
import math
import re
from collections import defaultdict
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import matplotlib as mpl
import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.figure import Figure
from numpy.typing import NDArray

from spooflens.detectors.base import SIGMA_SUFFIX, Curve, DetectorResult, Series, Track
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import geodetic_to_enu
from spooflens.inventory import quality_columns
from spooflens.output.report.decimate import minmax, stride
from spooflens.pipeline.departure import reconstructed_tracks
from spooflens.pipeline.evidence import ORDER, Evidence, label
from spooflens.pipeline.registry import DetectorInfo
from spooflens.pipeline.verdict import KIND_LABELS, Incident, Kind, Verdict

FloatArray = NDArray[np.float64]
WIDTH_IN = 10.0
BAND_POINTS = 400
COLOURS = {"reported": "#e63c32", "reconstructed": "#28b45a", "truth": "#3c78e6", "other": "#9a8a50"}
INCIDENT_COLOURS = ("#d9480f", "#7048e8", "#c2255c", "#1098ad", "#5c940d", "#e67700")
ANOMALY_COLOUR = "#fab005"
# incidents beyond this many (a log with hundreds of anomalies) are shaded and marked without a word
# each: their labels only pile up; the verdict's table above the figures numbers them all
MAX_LABELLED = 12
# one colour per evidence class, in ORDER; a class added later is drawn dark grey until it gets one
_CLASS_PALETTE = ("#0ca678", "#e67700", "#7048e8", "#2b8a3e", "#1c7ed6", "#0b7285", "#c2255c", "#5f3dc4")
CLASS_COLOURS = dict(zip(ORDER, _CLASS_PALETTE, strict=False))
KIND_COLOURS = {
    Kind.SPOOFING: "#c92a2a",
    Kind.JAMMING: "#d9480f",
    Kind.DEGRADATION: "#1971c2",
    Kind.RECEIVER_FAULT: "#6741d9",
    Kind.UNKNOWN: ANOMALY_COLOUR,
}
INTERFERENCE_COLOUR = KIND_COLOURS[Kind.JAMMING]
STYLE: Any = {
    "svg.fonttype": "none",  # text stays text: small, searchable, selectable
    "font.size": 8.5,
    "axes.titlesize": 9.5,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "legend.fontsize": 7.5,
    "legend.framealpha": 0.8,
    "lines.linewidth": 1.0,
    "path.simplify": True,
}


@dataclass(frozen=True)
class Plot:
    key: str  # stable id in the page
    title: str
    caption: str
    svg: str
    section: str  # "timeline" | "track" | "evidence" | "receiver" | "curves"


@contextmanager
def style() -> Iterator[None]:
    with mpl.rc_context(STYLE):
        yield


def _svg(fig: Figure, salt: str) -> str:
    """The figure as an inline <svg> element. A salt per figure keeps its element ids unique in the page."""
    buf = io.StringIO()
    with mpl.rc_context({"svg.hashsalt": salt}):
        fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None})
    text = buf.getvalue()
    return _PATH_DATA.sub(_compact_path, text[text.index("<svg") :])


_PATH_DATA = re.compile(r'(?<= d=")[^"]*')
_NUMBER = re.compile(r"-?\d+\.\d+")


def _compact_path(m: re.Match[str]) -> str:
    """Path coordinates to 0.1 pt (matplotlib writes 6 decimals, one vertex per line): a third of the size."""
    d = _NUMBER.sub(lambda n: f"{float(n.group()):.1f}".removesuffix(".0"), m.group())
    return " ".join(d.split())


def _figure(rows: int = 1, height_per_row: float = 2.3, sharex: bool = True) -> tuple[Figure, list[Axes]]:
    fig = Figure(figsize=(WIDTH_IN, max(1.6, height_per_row * rows)), layout="constrained")
    axes = fig.subplots(rows, 1, sharex=sharex, squeeze=False)[:, 0]
    return fig, list(axes)


def incident_colour(i: int, inc: Incident) -> str:
    return INCIDENT_COLOURS[i % len(INCIDENT_COLOURS)] if inc.is_spoofing else ANOMALY_COLOUR


def _bands(ax: Axes, bands: Iterable[tuple[float, float, str, float]]) -> None:
    """Vertical bands (start, end, colour, alpha) over the axes' height, one collection per colour and
    alpha: a patch per band took 4 ms, 12 s of the report of a log with two hundred anomalies."""
    groups: dict[tuple[str, float], list[list[tuple[float, float]]]] = defaultdict(list)
    for a, b, colour, alpha in bands:
        groups[(colour, alpha)].append([(a, 0.0), (a, 1.0), (b, 1.0), (b, 0.0)])
    for (colour, alpha), verts in groups.items():
        band = PolyCollection(verts, facecolors=colour, alpha=alpha, linewidths=0, transform=ax.get_xaxis_transform())
        ax.add_collection(band, autolim=False)
        _widen_x(ax, [x for v in verts for x in (v[0][0], v[2][0])])


def _vlines(ax: Axes, xs: Sequence[float], colour: str, **style: Any) -> None:
    """Vertical lines over the axes' height at `xs`, as one collection."""
    if xs:
        segments = [[(x, 0.0), (x, 1.0)] for x in xs]
        lines = LineCollection(segments, colors=colour, transform=ax.get_xaxis_transform(), **style)
        ax.add_collection(lines, autolim=False)
        _widen_x(ax, xs)


def _widen_x(ax: Axes, xs: Sequence[float]) -> None:
    """The x range takes in `xs`, as a band or line drawn one by one (axvspan, axvline) made it do."""
    ax.update_datalim([(x, 0.0) for x in xs], updatey=False)
    ax.autoscale_view(scaley=False)


def _shade_incidents(ax: Axes, incidents: Sequence[Incident], label_them: bool = False) -> None:
    colours = [incident_colour(i, inc) for i, inc in enumerate(incidents)]
    alphas = [0.10 if inc.is_spoofing else 0.08 for inc in incidents]
    _bands(ax, ((inc.onset_s, inc.end_s, c, a) for inc, c, a in zip(incidents, colours, alphas, strict=True)))
    if label_them:
        onsets: dict[str, list[float]] = defaultdict(list)
        for inc, c in zip(incidents, colours, strict=True):
            onsets[c].append(inc.onset_s)
        for c, xs in onsets.items():
            _vlines(ax, xs, c, linestyles="--", linewidths=0.9)


def _shade_alarms(ax: Axes, res: DetectorResult) -> None:
    colour = "#868e96" if res.advisory else "#e03131"
    _bands(ax, ((a.start_s, a.end_s, colour, 0.15) for a in res.alarms if a.end_s > a.start_s))
    _vlines(ax, [a.start_s for a in res.alarms if not a.end_s > a.start_s], colour, alpha=0.5, linewidths=1.5)
    _vlines(ax, [a.onset_s for a in res.alarms if a.onset_s is not None], colour, linestyles=":", linewidths=1.0)


def _finite(v: FloatArray) -> bool:
    return bool(np.isfinite(np.asarray(v, dtype=float)).any())


def _log_scale(values: Sequence[FloatArray]) -> bool:
    """Log y when a positive statistic spans decades (a NIS of thousands under attack, ~3 otherwise)."""
    v = np.concatenate([np.ravel(np.asarray(x, dtype=float)) for x in values]) if values else np.array([])
    v = v[np.isfinite(v)]
    if len(v) < 10 or v.min() <= 0:
        return False
    return bool(np.percentile(v, 99.5) / max(np.percentile(v, 50), 1e-300) > 300)


def _components(s: Series) -> tuple[FloatArray, list[str]]:
    v = np.asarray(s.values, dtype=float)
    if v.ndim == 1:
        return v[:, None], [s.name]
    names = list(s.components) or [f"{s.name}[{k}]" for k in range(v.shape[1])]
    return v, [f"{s.name} {c}" if len(names) > 1 else s.name for c in names]


# ---------------------------------------------------------------------------------------------- timeline


def evidence_classes(results: Sequence[DetectorResult], infos: dict[str, DetectorInfo]) -> list[Evidence]:
    """Every evidence class some registered detector declares or some result carries, in ORDER."""
    declared = {i.evidence for i in infos.values() if i.evidence is not None}
    declared |= {r.evidence for r in results if r.evidence is not None}
    return [c for c in ORDER if c in declared]


def _event_lane(ax: Axes, verdict: Verdict, end: float) -> None:
    """One row per kind of event the verdict found: each event a bar from its onset to its end."""
    kinds = [k for k in Kind if verdict.events_of(k)]
    for y, kind in enumerate(kinds):
        colour = KIND_COLOURS[kind]
        bars = [
            (min(e.onset_s, e.start_s), max(e.end_s - min(e.onset_s, e.start_s), end / 800))
            for e in verdict.events_of(kind)
        ]
        ax.broken_barh(bars, (-y - 0.32, 0.64), facecolors=colour, edgecolors=colour)
    for e in verdict.events:
        if e.followed_by is not None:  # one attack sequence: jamming, then the takeover
            then = verdict.events[e.followed_by]
            y0, y1 = -kinds.index(e.kind), -kinds.index(then.kind)
            ax.annotate("", (min(then.onset_s, then.start_s), y1), (e.end_s, y0), arrowprops={"arrowstyle": "->"})
    names = [KIND_LABELS[k] for k in kinds] or ["(no event)"]
    ax.set_yticks([-k for k in range(len(names))], names)
    ax.yaxis.tick_right()
    ax.set_ylim(-len(names) + 0.4, 0.6)
    ax.set_ylabel("events by kind", rotation=0, ha="right", va="center", fontweight="bold")
    ax.grid(axis="y", visible=False)
    ax.spines["left"].set_visible(False)


def timeline(
    table: EpochTable, results: Sequence[DetectorResult], verdict: Verdict, infos: dict[str, DetectorInfo]
) -> Plot:
    classes = [c for c in evidence_classes(results, infos) if any(r.ran and r.evidence == c for r in results)]
    lanes: dict[Evidence, list[DetectorResult]] = {
        c: [r for r in results if r.evidence == c and r.ran] for c in classes
    }
    kinds = max(1, sum(1 for k in Kind if verdict.events_of(k)))
    heights = [kinds] + [max(1, len(lanes[c])) for c in classes]
    rows = len(heights)
    fig = Figure(figsize=(WIDTH_IN, 0.9 + 0.42 * sum(heights) + 0.25 * rows), layout="constrained")
    axes = fig.subplots(rows, 1, sharex=True, squeeze=False, gridspec_kw={"height_ratios": heights})[:, 0]
    end = max(table.duration_s, 1e-3)
    _event_lane(axes[0], verdict, end)
    for ax, c in zip(axes[1:], classes, strict=True):
        detectors = lanes[c]
        colour = CLASS_COLOURS.get(c, "#495057")
        _shade_incidents(ax, verdict.incidents, label_them=True)
        names = []
        for k, r in enumerate(detectors):
            y = -k
            names.append(r.name + (" (advisory)" if r.advisory else ""))
            bars = [(a.start_s, max(a.end_s - a.start_s, end / 800)) for a in r.alarms]
            face = "#ced4da" if r.advisory else colour
            ax.broken_barh(bars, (y - 0.32, 0.64), facecolors=face, edgecolors=face, hatch="//" if r.advisory else None)
            for f in r.findings:
                ax.plot([f.start_s], [y], marker="D", ms=4, color="#212529", ls="none")
            if not r.alarms:
                ax.plot([0, end], [y, y], color=colour, alpha=0.25, lw=0.8)
        ax.set_yticks([-k for k in range(len(names))], names)
        ax.yaxis.tick_right()
        ax.set_ylim(-len(names) + 0.4, 0.6)
        ax.set_ylabel(label(c), rotation=0, ha="right", va="center", color=colour, fontweight="bold")
        ax.grid(axis="y", visible=False)
        ax.spines["left"].set_visible(False)
    axes[-1].set_xlim(0, end)
    axes[-1].set_xlabel(_time_label(table))
    if len(verdict.incidents) <= MAX_LABELLED:
        for i, inc in enumerate(verdict.incidents):
            kind = inc.kind if inc.kind is not None else Kind.SPOOFING if inc.is_spoofing else Kind.UNKNOWN
            what = {Kind.SPOOFING: f"incident {i + 1} ({inc.confidence})", Kind.UNKNOWN: f"anomaly {i + 1}"}.get(
                kind, f"{i + 1}: {KIND_LABELS[kind]}"
            )
            tag = what if kind == Kind.SPOOFING else f"{what} (not spoofing)"
            axes[0].annotate(tag, (inc.onset_s, 1.0), xycoords=("data", "axes fraction"), va="bottom", fontsize=7.5)
    else:
        tag = f"{len(verdict.incidents)} incidents and anomalies shaded: the verdict's table numbers them"
        axes[0].annotate(tag, (0.0, 1.0), xycoords="axes fraction", va="bottom", fontsize=7.5)
    caption = (
        "Top: one lane per kind of event (spoofing, jamming / interference, degradation, receiver fault, "
        "unexplained anomaly), an arrow where a takeover followed interference. Below, one strip per evidence "
        "class whose analyses ran: each detector's alarms as bars (advisory rules hatched grey, not counted), "
        "receiver findings as diamonds. Incidents are shaded across the strips from their estimated onset "
        "(dashed) to their end."
    )
    return Plot(
        "timeline", "Timeline of events and of alarms by evidence class", caption, _svg(fig, "timeline"), "timeline"
    )


def _time_label(table: EpochTable) -> str:
    start = table.absolute_iso(0.0) if table.unix_ns(0.0) is not None else f"clock {table.time_reference}"
    return f"time since the log start (s); start {start}"


# ------------------------------------------------------------------------------------------------ tracks


def _origin(table: EpochTable) -> tuple[float, float, float] | None:
    for frame in (table.fixes, table.truth):
        if len(frame):
            return float(frame["lat_deg"].iloc[0]), float(frame["lon_deg"].iloc[0]), float(frame["height_m"].iloc[0])
    return None


def _enu(lat: FloatArray, lon: FloatArray, h: FloatArray, origin: tuple[float, float, float]) -> FloatArray:
    return np.asarray(geodetic_to_enu(lat, lon, h, *origin), dtype=float)


def _at(t: FloatArray, xy: FloatArray, when: float) -> tuple[float, float] | None:
    if not len(t) or when < t[0] or when > t[-1]:
        return None
    return float(np.interp(when, t, xy[:, 0])), float(np.interp(when, t, xy[:, 1]))


def track(table: EpochTable, results: Sequence[DetectorResult], verdict: Verdict) -> Plot | None:
    origin = _origin(table)
    if origin is None:
        return None
    fig = Figure(figsize=(WIDTH_IN, 6.2), layout="constrained")
    ax = fig.subplots()
    incidents = [i for i in verdict.incidents if i.is_spoofing] or verdict.incidents
    recon = reconstructed_tracks(results, verdict)
    drawn: list[tuple[FloatArray, FloatArray, str]] = []  # (t, enu) for onset/end markers
    if len(table.truth):
        tr = table.truth
        xy = _enu(tr["lat_deg"].to_numpy(), tr["lon_deg"].to_numpy(), tr["height_m"].to_numpy(), origin)
        k = stride(len(xy))
        ax.plot(xy[k, 0], xy[k, 1], color=COLOURS["truth"], lw=1.6, ls="--", label="truth", zorder=2)
    for r in results:
        for tk in r.tracks if r.ran else []:
            if tk in recon:
                continue
            xy = _track_enu(tk, origin)
            k = stride(len(xy))
            ax.plot(xy[k, 0], xy[k, 1], color=COLOURS["other"], lw=0.8, ls=":", label=f"{r.name}: {tk.name}")
    for tk in recon:
        xy = _track_enu(tk, origin)
        k = stride(len(xy))
        ax.plot(xy[k, 0], xy[k, 1], color=COLOURS["reconstructed"], lw=1.6, label=tk.name, zorder=3)
        drawn.append((np.asarray(tk.t, dtype=float), xy, "reconstructed"))
    for rid in table.receivers():
        fx = table.fixes_of(rid)
        t = fx["t_s"].to_numpy(dtype=float)
        xy = _enu(fx["lat_deg"].to_numpy(), fx["lon_deg"].to_numpy(), fx["height_m"].to_numpy(), origin)
        k = stride(len(xy))
        ax.plot(xy[k, 0], xy[k, 1], color=COLOURS["reported"], lw=0.9, label=f"reported GNSS {rid}", zorder=4)
        _during_incidents(ax, rid, t, xy, incidents)
        drawn.append((t, xy, rid))
    _onsets_and_ends(ax, drawn, incidents)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.legend(loc="best")
    caption = (
        f"Local east/north metres from the first fix ({origin[0]:.6f}, {origin[1]:.6f}). Reported GNSS red "
        "(thick and coloured inside each incident), reconstructed track green (INS with the spoofed GNSS "
        "left out), truth blue dashed when known; triangles mark onsets, squares ends."
    )
    return Plot("track", "Track: reported, reconstructed and true", caption, _svg(fig, "track"), "track")


def _during_incidents(ax: Axes, rid: str, t: FloatArray, xy: FloatArray, incidents: Sequence[Incident]) -> None:
    """A receiver's track inside each incident, thick in the incident's colour: a legend entry each, or
    beyond MAX_LABELLED one entry for them all (one line per colour, broken between them)."""
    labelled = len(incidents) <= MAX_LABELLED
    parts: dict[str, list[FloatArray]] = defaultdict(list)
    for i, inc in enumerate(incidents):
        sel = (t >= inc.onset_s) & (t <= inc.end_s)
        if sel.sum() < 2:
            continue
        colour, part = incident_colour(i, inc), xy[sel][stride(int(sel.sum()))]
        if labelled:
            what = f"incident {i + 1}" if inc.is_spoofing else f"anomaly {i + 1}"
            ax.plot(part[:, 0], part[:, 1], color=colour, lw=2.6, alpha=0.85, label=f"{rid} during {what}", zorder=5)
        else:
            parts[colour] += [part[:, :2], np.full((1, 2), np.nan)]
    what = "incidents" if incidents and incidents[0].is_spoofing else "anomalies"
    for k, (colour, pieces) in enumerate(parts.items()):
        line = np.concatenate(pieces)
        name = f"{rid} during the {len(incidents)} {what}" if k == 0 else "_nolegend_"
        ax.plot(line[:, 0], line[:, 1], color=colour, lw=2.6, alpha=0.85, label=name, zorder=5)


def _onsets_and_ends(
    ax: Axes, drawn: Sequence[tuple[FloatArray, FloatArray, str]], incidents: Sequence[Incident]
) -> None:
    """A triangle at each incident's onset and a square at its end on every drawn track, with its number
    and time when there are at most MAX_LABELLED incidents."""
    labelled = len(incidents) <= MAX_LABELLED
    points: dict[tuple[str, str], list[tuple[float, float]]] = defaultdict(list)
    for i, inc in enumerate(incidents):
        for t, xy, _ in drawn:
            for when, marker, word in ((inc.onset_s, "^", "onset"), (inc.end_s, "s", "end")):
                p = _at(t, xy, when)
                if p is None or (word == "end" and inc.ongoing_at_end):
                    continue
                points[(incident_colour(i, inc), marker)].append(p)
                if labelled:
                    tag = f"{i + 1} {word} {when:.0f} s"
                    ax.annotate(tag, p, xytext=(5, 5), textcoords="offset points", fontsize=7.5)
    for (colour, marker), ps in points.items():
        x, y = zip(*ps, strict=True)
        ax.plot(x, y, marker=marker, ms=8, color=colour, mec="black", mew=0.7, ls="none", zorder=6)


def _track_enu(tk: Track, origin: tuple[float, float, float]) -> FloatArray:
    return _enu(np.asarray(tk.lat_deg), np.asarray(tk.lon_deg), np.asarray(tk.height_m), origin)


def departure(table: EpochTable, results: Sequence[DetectorResult], verdict: Verdict) -> Plot | None:
    """Horizontal distance of each receiver's fixes from the reconstructed track, over the whole log."""
    recon = reconstructed_tracks(results, verdict)
    origin = _origin(table)
    if not recon or origin is None:
        return None
    tk = recon[0]
    ref = _track_enu(tk, origin)
    fig, (ax,) = _figure(1, 2.6)
    for rid in table.receivers():
        fx = table.fixes_of(rid)
        t = fx["t_s"].to_numpy(dtype=float)
        xy = _enu(fx["lat_deg"].to_numpy(), fx["lon_deg"].to_numpy(), fx["height_m"].to_numpy(), origin)
        ok = (t >= tk.t[0]) & (t <= tk.t[-1])
        gap = np.hypot(xy[ok, 0] - np.interp(t[ok], tk.t, ref[:, 0]), xy[ok, 1] - np.interp(t[ok], tk.t, ref[:, 1]))
        td, gd = minmax(t[ok], gap)
        ax.plot(td, gd, label=rid)
    _shade_incidents(ax, verdict.incidents, label_them=True)
    ax.set_ylabel("m")
    ax.set_xlabel(_time_label(table))
    ax.legend(loc="upper left")
    caption = f"Horizontal distance between the reported fixes and '{tk.name}'; incidents shaded."
    return Plot("departure", "How far GNSS went from the reconstructed track", caption, _svg(fig, "departure"), "track")


# -------------------------------------------------------------------------------------- detector evidence


def _sigma_pairs(res: DetectorResult) -> list[tuple[Series, Series]]:
    by_name = {s.name: s for s in res.series}
    return [
        (s, by_name[s.name + SIGMA_SUFFIX])
        for s in res.series
        if s.name + SIGMA_SUFFIX in by_name and np.shape(s.values) == np.shape(by_name[s.name + SIGMA_SUFFIX].values)
    ]


def detector_plots(res: DetectorResult, table: EpochTable) -> list[Plot]:
    """Every series of one result: one plot per unit (statistic with threshold and alarms), one per
    sigma-banded series; then one per curve."""
    if not res.ran:
        return []
    plots: list[Plot] = []
    pairs = _sigma_pairs(res)
    banded = {s.name for pair in pairs for s in pair}
    groups: dict[str, list[Series]] = {}
    for s in res.series:
        if s.name not in banded and len(s.t) and _finite(s.values):
            groups.setdefault(s.unit, []).append(s)
    what = (label(res.evidence) if res.evidence else "analysis product") + (", advisory" if res.advisory else "")
    for unit, series in groups.items():
        fig, (ax,) = _figure(1, 2.5)
        _shade_alarms(ax, res)
        for s in series:
            v, names = _components(s)
            td, vd = minmax(np.asarray(s.t, dtype=float), v)
            lines = ax.plot(td, vd, label=names if len(names) > 1 or len(series) > 1 else None)
            if s.threshold is not None and math.isfinite(s.threshold):
                ax.axhline(s.threshold, color=lines[0].get_color(), ls="--", lw=1.1, label=f"threshold {s.threshold:g}")
        if _log_scale([np.asarray(s.values) for s in series]):
            ax.set_yscale("log")
        ax.set_ylabel(unit or "value")
        ax.set_xlabel(_time_label(table))
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper left", ncols=3)
        key = f"{res.name}:{unit}"
        listed = ", ".join(s.name for s in series)
        title = f"{res.name} ({what}): {listed}" + (f" [{unit}]" if unit else "")
        caption = (
            "Alarms shaded"
            + (" grey (advisory, not counted)" if res.advisory else " red")
            + (", estimated onsets dotted; threshold dashed." if res.alarms else "; no alarm.")
        )
        plots.append(Plot(key, title, caption, _svg(fig, key), "evidence"))
    for s, sigma in pairs:
        plots.append(_banded(res, s, sigma, table, what))
    for c in res.curves:
        if len(c.x) and _finite(c.y):
            plots.append(_curve(res, c, what))
    return plots


def _banded(res: DetectorResult, s: Series, sigma: Series, table: EpochTable, what: str) -> Plot:
    v, names = _components(s)
    sd, _ = _components(sigma)
    fig, axes = _figure(v.shape[1], 1.6)
    t = np.asarray(s.t, dtype=float)
    for k, ax in enumerate(axes):
        # a band is a filled polygon (never simplified by the renderer): fewer, wider buckets, drawn at
        # each bucket's largest sigma so the band is never narrower than it was
        tb, sig = minmax(t, sd[:, k], BAND_POINTS)
        if len(t) > BAND_POINTS:  # decimated: (min, max) pairs
            sig = np.fmax(sig[0::2], sig[1::2]).repeat(2)
        ax.fill_between(tb, -3 * sig, 3 * sig, color="#adb5bd", alpha=0.25, lw=0, label="+-3 sigma")
        ax.fill_between(tb, -sig, sig, color="#74c0fc", alpha=0.35, lw=0, label="+-1 sigma")
        ax.plot(*minmax(t, v[:, k]), color="#1c1c1c", lw=0.8, label=names[k])
        _shade_alarms(ax, res)
        ax.set_ylabel(f"{names[k].split()[-1]} ({s.unit})" if s.unit else names[k])
        if k == 0:
            ax.legend(loc="upper left", ncols=3)
    axes[-1].set_xlabel(_time_label(table))
    key = f"{res.name}:{s.name}"
    caption = (
        f"{s.name} with the filter's own 1-sigma ({sigma.name}) and 3-sigma bands: a channel the spoofer moves "
        "walks out of its band."
    )
    return Plot(key, f"{res.name} ({what}): {s.name}", caption, _svg(fig, key), "evidence")


def _curve(res: DetectorResult, c: Curve, what: str) -> Plot:
    fig, (ax,) = _figure(1, 2.4, sharex=False)
    x = np.asarray(c.x, dtype=float)
    y = np.asarray(c.y, dtype=float)
    order = np.argsort(x, kind="stable")
    xd, yd = minmax(x[order], y[order])
    ax.plot(xd, yd, color="#5f3dc4")
    ax.set_xlabel(c.x_label)
    ax.set_ylabel(c.unit or c.name)
    key = f"{res.name}:curve:{c.name}"
    caption = f"{c.name} over {c.x_label}, as {res.name} computed it over the whole log."
    return Plot(key, f"{res.name} ({what}): {c.name}", caption, _svg(fig, key), "curves")


# ------------------------------------------------------------------------------------- receiver quality


def _outside(t: FloatArray, incidents: Sequence[Incident]) -> NDArray[np.bool_]:
    keep = np.ones(len(t), dtype=bool)
    for inc in incidents:
        keep &= ~((t >= inc.onset_s) & (t <= inc.end_s))
    return keep if keep.sum() >= 10 else np.ones(len(t), dtype=bool)


def _baseline(ax: Axes, t: FloatArray, v: FloatArray, incidents: Sequence[Incident]) -> None:
    """The log's own baseline: median and 2.5-97.5 percentiles outside every incident."""
    base = v[_outside(t, incidents) & np.isfinite(v)]
    if len(base) < 5:
        return
    lo, mid, hi = np.percentile(base, [2.5, 50, 97.5])
    ax.axhspan(lo, hi, color="#51cf66", alpha=0.12, lw=0)
    ax.axhline(mid, color="#2b8a3e", ls="--", lw=0.9, label="baseline (median, 95% band outside incidents)")


def _shade_interference(ax: Axes, verdict: Verdict, rid: str) -> bool:
    """The jamming / interference events of this receiver (or of every receiver), hatched; whether any."""
    events = [e for e in verdict.events_of(Kind.JAMMING) if not e.receivers or rid in e.receivers]
    for e in events:
        ax.axvspan(
            min(e.onset_s, e.start_s), e.end_s, facecolor="none", edgecolor=INTERFERENCE_COLOUR, hatch="///", lw=0
        )
    return bool(events)


def receiver_quality(table: EpochTable, verdict: Verdict) -> list[Plot]:
    plots = []
    obs = table.observations
    for rid in table.receivers():
        fx = table.fixes_of(rid)
        cols = quality_columns(fx)
        raw = obs[obs["receiver_id"].astype(str) == rid] if len(obs) else obs
        cn0 = raw["cn0_dbhz"].to_numpy(dtype=float) if len(raw) else np.array([])
        has_raw = len(raw) > 0
        rows = len(cols) + (1 if has_raw else 0) + (1 if np.isfinite(cn0).any() else 0)
        if not rows:
            continue
        fig, axes = _figure(rows, 1.35)
        t = fx["t_s"].to_numpy(dtype=float)
        i = 0
        jammed = False
        for name, text in cols:
            ax = axes[i]
            v = fx[name].to_numpy(dtype=float)
            td, vd = minmax(t, v)
            ax.plot(td, vd, color="#1c7ed6", drawstyle="steps-post")
            _baseline(ax, t, v, verdict.incidents)
            _shade_incidents(ax, verdict.incidents)
            jammed = _shade_interference(ax, verdict, rid)
            ax.set_ylabel(text, rotation=0, ha="right", va="center")
            i += 1
        if has_raw:
            per_epoch = raw.groupby("t_s", sort=True)
            te = np.asarray(list(per_epoch.groups), dtype=float)
            n = per_epoch.size().to_numpy(dtype=float)
            ax = axes[i]
            ax.plot(*minmax(te, n), color="#1c7ed6", drawstyle="steps-post")
            _baseline(ax, te, n, verdict.incidents)
            _shade_incidents(ax, verdict.incidents)
            jammed = _shade_interference(ax, verdict, rid)
            ax.set_ylabel("satellites tracked (raw)", rotation=0, ha="right", va="center")
            i += 1
            if np.isfinite(cn0).any():
                stats = per_epoch["cn0_dbhz"].agg(["mean", "min", "max"]).to_numpy(dtype=float)
                ax = axes[i]
                td, sd = minmax(te, stats)
                ax.fill_between(td, sd[:, 1], sd[:, 2], color="#74c0fc", alpha=0.3, lw=0, label="min-max")
                ax.plot(td, sd[:, 0], color="#1c7ed6", label="mean")
                _baseline(ax, te, stats[:, 0], verdict.incidents)
                _shade_incidents(ax, verdict.incidents)
                jammed = _shade_interference(ax, verdict, rid)
                ax.set_ylabel("C/N0 of tracked satellites (dB-Hz)", rotation=0, ha="right", va="center")
        axes[0].legend(loc="upper left") if axes[0].get_legend_handles_labels()[0] else None
        axes[-1].set_xlabel(_time_label(table))
        key = f"receiver:{rid}"
        caption = (
            "Everything this receiver says about itself that the log holds, against the log's own baseline "
            "(green: median and 95% band outside the incidents); incidents shaded"
            + ("; jamming / interference hatched orange." if jammed else ".")
        )
        plots.append(Plot(key, f"Receiver quality: {rid}", caption, _svg(fig, key), "receiver"))
    return plots


def odometry(table: EpochTable, verdict: Verdict) -> list[Plot]:
    """Wheel odometry speed against the GNSS-reported speed: a spoofer moves the fixes, not the wheels."""
    od = table.odometry
    if not len(od):
        return []
    fig, (ax,) = _figure(1, 2.6)
    for oid in dict.fromkeys(od["odometry_id"].astype(str)):
        rows = od[od["odometry_id"].astype(str) == oid]
        t = rows["t_s"].to_numpy(dtype=float)
        v = np.hypot(rows["vx_mps"].to_numpy(dtype=float), rows["vy_mps"].to_numpy(dtype=float))
        ax.plot(*minmax(t, v), color="#2b8a3e", label=f"wheel odometry {oid}")
    for rid in table.receivers():
        fx = table.fixes_of(rid)
        t = fx["t_s"].to_numpy(dtype=float)
        v = np.hypot(fx["vel_e_mps"].to_numpy(dtype=float), fx["vel_n_mps"].to_numpy(dtype=float))
        source = "reported velocity"
        if not np.isfinite(v).any() and len(t) > 2:
            origin = _origin(table)
            assert origin is not None
            xy = _enu(fx["lat_deg"].to_numpy(), fx["lon_deg"].to_numpy(), fx["height_m"].to_numpy(), origin)
            v = np.r_[np.nan, np.hypot(*np.diff(xy[:, :2], axis=0).T) / np.maximum(np.diff(t), 1e-9)]
            source = "from position differences"
        ax.plot(*minmax(t, v), color=COLOURS["reported"], lw=0.8, alpha=0.8, label=f"GNSS {rid} ({source})")
    _shade_incidents(ax, verdict.incidents, label_them=True)
    ax.set_ylabel("horizontal speed (m/s)")
    ax.set_xlabel(_time_label(table))
    ax.legend(loc="upper left")
    caption = "Speed over ground from the wheels against the speed GNSS reports; incidents shaded."
    return [Plot("odometry", "Wheel odometry against GNSS", caption, _svg(fig, "odometry"), "receiver")]
