"""Per-satellite evidence: a counterfeit satellite among real ones (below the horizon, a C/N0 step of one
satellite, one C/N0 for all, a strong satellite the receiver refuses). Declared in `ANALYSIS`
(docs/detectors.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.detectors.base import Alarm, DetectorResult, Finding, Series, nearest
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import geodetic_to_ecef
from spooflens.gnss.geometry import azimuth_elevation
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo

HORIZON = "satellite_horizon"
SIGNALS = "satellite_signals"
EARTH_RADIUS_M = 6_371_000.0
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class SatelliteSignalOptions:
    horizon_margin_deg: float = 3.0
    min_epochs: int = 3
    step_db: float = 10.0
    hold_s: float = 10.0
    min_history_s: float = 30.0
    above_median_db: float = 3.0
    refused_fraction: float = 0.8
    refused_min_s: float = 30.0
    refused_min_elevation_deg: float = 15.0
    min_used: int = 4
    residual_m: float = 100.0
    uniform_cn0_db: float = 1.5
    min_satellites: int = 6
    # a writer's placeholder holds every satellite's C/N0 (PX4 drivers without it write 1); a simulator
    # feeding a real receiver left 4 of its 7 at 51 dB-Hz and moved the others
    placeholder_varying_fraction: float = 0.2
    fix_gap_s: float = 2.0


@dataclass(frozen=True)
class SkyView:
    """One receiver's satellites, one row per satellite and epoch."""

    receiver_id: str
    rows: pd.DataFrame  # t_s, sv_id, cn0_dbhz, elevation_deg, used, residual_m, healthy
    elevation_source: str  # "receiver" or "orbits" or ""
    height_m: float


def _fix_positions(table: EpochTable, rid: str) -> pd.DataFrame:
    f = table.fixes
    f = f[f["receiver_id"].astype(str) == rid]
    return f[np.isfinite(f[["lat_deg", "lon_deg", "height_m"]].to_numpy(float)).all(axis=1)]


def _orbit_elevations(obs: pd.DataFrame, fixes: pd.DataFrame, gap_s: float) -> NDArray[np.float64]:
    """Elevation (deg) of each observation row from its satellite state and the receiver's fix at that time."""
    out = np.full(len(obs), np.nan)
    sv = obs[["sv_x_m", "sv_y_m", "sv_z_m"]].to_numpy(float)
    ok = np.isfinite(sv).all(axis=1)
    if not ok.any() or not len(fixes):
        return out
    near, gap = nearest(obs["t_s"].to_numpy(float), fixes["t_s"].to_numpy(float))
    ok &= gap <= gap_s
    rx = geodetic_to_ecef(
        fixes["lat_deg"].to_numpy(float)[near],
        fixes["lon_deg"].to_numpy(float)[near],
        fixes["height_m"].to_numpy(float)[near],
    )
    _, el = azimuth_elevation(sv[ok], rx[ok])
    out[ok] = np.degrees(el)
    return out


def sky_views(table: EpochTable, opts: SatelliteSignalOptions) -> list[SkyView]:
    """Every receiver's sky: its own satellite reports when it logged them, else its raw observations."""
    views: list[SkyView] = []
    sats, obs = table.satellites, table.observations
    reported = set(sats["receiver_id"].astype(str)) if len(sats) else set()
    for rid in sorted(reported):
        rows = sats[sats["receiver_id"].astype(str) == rid].reset_index(drop=True)
        fixes = _fix_positions(table, rid)
        with_fix = _near_fix(rows["t_s"].to_numpy(float), fixes["t_s"].to_numpy(float), opts.fix_gap_s)
        rows = rows.assign(elevation_deg=np.where(with_fix, rows["elevation_deg"], np.nan))
        views.append(SkyView(rid, rows, "receiver", _height(fixes)))
    if len(obs):
        for rid, rows in obs.groupby(obs["receiver_id"].astype(str), sort=True):
            if rid in reported:
                continue
            rows = rows.reset_index(drop=True)
            fixes = _fix_positions(table, str(rid))
            el = _orbit_elevations(rows, fixes, opts.fix_gap_s)
            view = pd.DataFrame(
                {
                    "t_s": rows["t_s"].to_numpy(float),
                    "sv_id": rows["sv_id"].astype(str).to_numpy(),
                    "cn0_dbhz": rows["cn0_dbhz"].to_numpy(float),
                    "elevation_deg": el,
                    "used": np.nan,
                    "residual_m": np.nan,
                    "healthy": np.nan,
                }
            )
            views.append(SkyView(str(rid), view, "orbits" if np.isfinite(el).any() else "", _height(fixes)))
    return views


def _near_fix(t: NDArray[np.float64], tf: NDArray[np.float64], gap_s: float) -> BoolArray:
    if not len(tf):
        return np.ones(len(t), dtype=bool)  # no fixes at all: the receiver's elevations are all we have
    return nearest(t, tf)[1] <= gap_s


def _height(fixes: pd.DataFrame) -> float:
    return float(np.nanmedian(fixes["height_m"].to_numpy(float))) if len(fixes) else 0.0


def horizon_dip_deg(height_m: float) -> float:
    """How far below the horizontal the geometric horizon lies at this height (deg)."""
    h = max(height_m, 0.0)
    return math.degrees(math.acos(EARTH_RADIUS_M / (EARTH_RADIUS_M + h)))


def _runs(t: NDArray[np.float64], flag: BoolArray, min_len: int) -> list[tuple[int, int]]:
    """Index ranges [first, last] of runs of `flag` at least `min_len` long."""
    if not flag.any():
        return []
    edges = np.diff(np.concatenate([[0], flag.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    return [(int(s), int(e)) for s, e in zip(starts, stops, strict=True) if e - s + 1 >= min_len]


def _alarm(start: float, end: float, peak: float, rid: str, sv: str | None) -> Alarm:
    """An alarm whose onset is its start, about one satellite (or, with `sv` None, the whole sky)."""
    sats = (sv,) if sv is not None else ()
    return Alarm(float(start), float(end), float(peak), float(start), float(start), receiver_id=rid, satellites=sats)


def _per_satellite(rows: pd.DataFrame) -> dict[str, pd.DataFrame]:
    return {str(sv): g.sort_values("t_s") for sv, g in rows.groupby("sv_id", sort=True)}


def below_horizon(view: SkyView, opts: SatelliteSignalOptions) -> tuple[list[Alarm], list[Finding], Series | None]:
    rows = view.rows
    limit = -(horizon_dip_deg(view.height_m) + opts.horizon_margin_deg)
    tracked = np.isfinite(rows["cn0_dbhz"].to_numpy(float)) | rows["cn0_dbhz"].isna().all()
    el = rows["elevation_deg"].to_numpy(float)
    if not np.isfinite(el).any():
        return [], [], None
    low = tracked & np.isfinite(el) & (el < limit)
    rows = rows.assign(low=low)
    alarms, findings = [], []
    for sv, g in _per_satellite(rows).items():
        t = g["t_s"].to_numpy(float)
        for s, e in _runs(t, g["low"].to_numpy(bool), opts.min_epochs):
            seg = g.iloc[s : e + 1]
            worst = float(seg["elevation_deg"].min())
            alarms.append(_alarm(t[s], t[e], -worst, view.receiver_id, sv))
            cn0 = seg["cn0_dbhz"].to_numpy(float)
            power = f" at {np.nanmedian(cn0):.0f} dB-Hz" if np.isfinite(cn0).any() else ""
            findings.append(
                Finding(
                    f"{view.receiver_id}: {sv} tracked {abs(worst):.0f} deg below the horizon{power} for "
                    f"{t[e] - t[s]:.0f} s (elevation from the {view.elevation_source})",
                    float(t[s]),
                    float(t[e]),
                    (sv,),
                    view.receiver_id,
                )
            )
    epoch_min = rows.groupby("t_s")["elevation_deg"].min()
    series = Series(
        f"{view.receiver_id}/lowest_elevation", epoch_min.index.to_numpy(float), epoch_min.to_numpy(float), "deg", limit
    )
    return alarms, findings, series


def _relative_cn0(rows: pd.DataFrame) -> pd.Series:
    """Each satellite's C/N0 minus the median of its epoch's satellites."""
    med = rows.groupby("t_s")["cn0_dbhz"].transform("median")
    return rows["cn0_dbhz"] - med


def cn0_steps(view: SkyView, opts: SatelliteSignalOptions) -> tuple[list[Alarm], list[Finding], Series | None]:
    rows = view.rows[np.isfinite(view.rows["cn0_dbhz"].to_numpy(float))]
    if rows.empty or rows["t_s"].nunique() < 3:
        return [], [], None
    rows = rows.assign(rel=_relative_cn0(rows))
    parts = []
    for sv, g in _per_satellite(rows).items():
        if len(g) < 3:
            continue
        t = g["t_s"].to_numpy(float)
        s = pd.Series(g["rel"].to_numpy(float), index=pd.to_datetime(t, unit="s"))
        trailing = s.rolling(f"{opts.hold_s}s").median().to_numpy()  # (t - hold, t]
        before_short = np.concatenate([[np.nan], trailing[:-1]])  # up to the previous epoch
        history = np.concatenate([[np.nan], s.expanding().median().to_numpy()[:-1]])
        j = np.searchsorted(t, t + opts.hold_s, side="left") - 1  # the window [t, t + hold)
        after = trailing[j]
        old = (t - t[0]) >= opts.min_history_s
        full = t[j] - t >= 0.5 * opts.hold_s
        change = np.where(full, after - before_short, np.nan)
        jump = np.where(old, np.minimum(change, after - history), np.nan)
        # the highest level the satellite held for a window before: a car's satellite shadowed by trees for
        # most of a minute comes back to its own level, above its median but never above itself
        held = np.where(t - t[0] >= 0.5 * opts.hold_s, trailing, -np.inf)
        held_before = np.concatenate([[-np.inf], np.maximum.accumulate(held)[:-1]])
        parts.append(
            pd.DataFrame(
                {"t": t, "sv": sv, "rel": g["rel"].to_numpy(float), "before": before_short}
                | {"change": change, "jump": jump, "after": after, "until": t[j], "above_held": after - held_before}
            )
        )
    if not parts:
        return [], [], None
    steps = pd.concat(parts, ignore_index=True)
    # one satellite alone: no other satellite fell at the same time, and fewer than half rose with it (the
    # antenna turned or the vehicle moved: several satellites change, some down)
    half = 0.5 * opts.step_db
    change = steps["change"]
    per_epoch = pd.DataFrame({"down": change <= -half, "up": change >= half, "n": change.notna()})
    n_down, n_up, n = per_epoch.groupby(steps["t"]).transform("sum").T.to_numpy()
    isolated = (n_down == 0) & (n_up - 1 <= 0.5 * (n - 1))
    steps["hit"] = isolated & (steps["jump"] >= opts.step_db) & (steps["after"] >= opts.above_median_db)
    alarms, findings = [], []
    for sv, g in steps.groupby("sv", sort=True):
        t, hit = g["t"].to_numpy(float), g["hit"].to_numpy(bool)
        jump, after, until, rel, before, above_held = (
            g[c].to_numpy(float) for c in ("jump", "after", "until", "rel", "before", "above_held")
        )
        for a, b in _runs(t, hit, 1):
            if not np.any(above_held[a : b + 1] >= opts.step_db):
                continue  # back to a level it held before: no rise of its own
            k = a + int(np.nanargmax(jump[a : b + 1]))
            # the window's median crosses before the step: the step is the first epoch half-way up
            up = np.flatnonzero((t >= t[a]) & (t <= until[a]) & (rel >= before[a] + half))
            onset = float(t[up[0]] if len(up) else t[a])
            alarm = _alarm(onset, until[b], jump[k], view.receiver_id, str(sv))
            alarms.append(replace(alarm, peak_s=float(t[k])))
            findings.append(
                Finding(
                    f"{view.receiver_id}: {sv}'s C/N0 rose {jump[k]:.0f} dB against the other satellites at "
                    f"{onset:.1f} s, alone, and stayed {after[k]:.0f} dB above their median",
                    onset,
                    float(until[b]),
                    (str(sv),),
                    view.receiver_id,
                )
            )
    per_epoch = steps.groupby("t")["jump"].max()
    series = Series(
        f"{view.receiver_id}/cn0_step", per_epoch.index.to_numpy(float), per_epoch.to_numpy(float), "dB", opts.step_db
    )
    return alarms, findings, series


def refused(view: SkyView, opts: SatelliteSignalOptions) -> tuple[list[Alarm], list[Finding]]:
    rows = view.rows
    used = rows["used"].to_numpy(float)
    if not np.isfinite(used).any():
        return [], []
    rows = rows.assign(system=rows["sv_id"].astype(str).str[0], used_b=used == 1)
    used_cn0 = rows["cn0_dbhz"].where(rows["used_b"]).groupby(rows["t_s"]).transform("median")
    n_used_sys = rows.groupby(["t_s", "system"])["used_b"].transform("sum")
    strong = (
        (rows["healthy"].fillna(1.0) == 1.0)
        & (rows["elevation_deg"] >= opts.refused_min_elevation_deg)
        & (rows["cn0_dbhz"] >= used_cn0)
        & (n_used_sys - rows["used_b"] >= opts.min_used)
    ).to_numpy(bool)
    rows = rows.assign(strong=strong, left_out=strong & (used == 0))
    alarms, findings = [], []
    for sv, g in _per_satellite(rows).items():
        t = g["t_s"].to_numpy(float)
        st, out = g["strong"].to_numpy(bool), g["left_out"].to_numpy(bool)
        if st.sum() >= opts.min_epochs and out.sum() >= opts.refused_fraction * st.sum():
            span = float(t[out].max() - t[out].min()) if out.any() else 0.0
            if span >= opts.refused_min_s:
                for a, b in _runs(t, out, opts.min_epochs):
                    alarms.append(_alarm(t[a], t[b], float(out.mean()), view.receiver_id, sv))
                seg = g[out]
                findings.append(
                    Finding(
                        f"{view.receiver_id}: the receiver left {sv} out of its solution at "
                        f"{100 * out.sum() / st.sum():.0f}% of the epochs it was healthy, "
                        f"{seg['elevation_deg'].median():.0f} deg high and strong "
                        f"({seg['cn0_dbhz'].median():.0f} dB-Hz)",
                        float(t[out].min()),
                        float(t[out].max()),
                        (sv,),
                        view.receiver_id,
                    )
                )
        res = g["residual_m"].to_numpy(float)
        big = np.isfinite(res) & (np.abs(res) >= opts.residual_m)
        for a, b in _runs(t, big, opts.min_epochs):
            worst = float(np.nanmax(np.abs(res[a : b + 1])))
            alarms.append(_alarm(t[a], t[b], worst, view.receiver_id, sv))
            findings.append(
                Finding(
                    f"{view.receiver_id}: the receiver used {sv} with a pseudorange residual up to {worst:.0f} m",
                    float(t[a]),
                    float(t[b]),
                    (sv,),
                    view.receiver_id,
                    worst,
                )
            )
    return alarms, findings


def uniform_cn0(view: SkyView, opts: SatelliteSignalOptions) -> tuple[list[Alarm], list[Finding], Series | None]:
    """Epochs where `min_satellites` or more satellites all arrive at nearly one C/N0: real satellites
    at different elevations and ranges spread over several dB (2.5 dB standard deviation at the least
    in the real logs at hand), the channels of one transmitter do not."""
    rows = view.rows[np.isfinite(view.rows["cn0_dbhz"].to_numpy(float))]
    varies = rows.groupby("sv_id")["cn0_dbhz"].nunique() > 1
    if not len(varies) or varies.mean() <= opts.placeholder_varying_fraction:
        return [], [], None  # C/N0 that never moves is a writer's placeholder, not a measurement
    by_t = rows.groupby("t_s")["cn0_dbhz"]
    n = by_t.count()
    spread = by_t.std()[n >= opts.min_satellites]
    if len(spread) < 3:
        return [], [], None
    t = spread.index.to_numpy(float)
    smooth = pd.Series(spread.to_numpy(float), index=pd.to_datetime(t, unit="s")).rolling("5s").median().to_numpy()
    flat = smooth <= opts.uniform_cn0_db
    alarms, findings = [], []
    for a, b in _runs(t, flat, 1):
        if t[b] - t[a] < opts.hold_s:
            continue
        low = float(np.min(smooth[a : b + 1]))
        alarms.append(_alarm(t[a], t[b], -low, view.receiver_id, None))
        findings.append(
            Finding(
                f"{view.receiver_id}: {int(n.loc[t[a]])} satellites at one C/N0 (spread {low:.1f} dB) from "
                f"{t[a]:.1f} s to {t[b]:.1f} s: one transmitter's signals, not the sky's",
                float(t[a]),
                float(t[b]),
                (),
                view.receiver_id,
            )
        )
    series = Series(f"{view.receiver_id}/cn0_spread", t, smooth, "dB", opts.uniform_cn0_db)
    return alarms, findings, series


def satellites_heard_text(rows: pd.DataFrame) -> str:
    """How many satellites the receiver gave a C/N0, and how many more it only listed (a receiver's GSV slots
    filled with placeholders: PRNs 33-51 at elevation 0 or below, never a C/N0)."""
    listed = int(rows["sv_id"].nunique())
    heard = int(rows.loc[np.isfinite(rows["cn0_dbhz"].to_numpy(float)), "sv_id"].nunique())
    if heard in (0, listed):
        return f"{listed} satellites"
    return f"{heard} satellites with a C/N0 ({listed - heard} more listed without one)"


def run_satellite_signals(ctx: AnalysisContext, opts: SatelliteSignalOptions | None = None) -> list[DetectorResult]:
    opts = opts or SatelliteSignalOptions()
    views = sky_views(ctx.table, opts)
    sources = {v.elevation_source for v in views if v.elevation_source}
    horizon_class = Evidence.RAW_MEASUREMENT if sources == {"orbits"} else Evidence.RECEIVER
    horizon = DetectorResult(HORIZON, ran=False, evidence=horizon_class)
    signals = DetectorResult(SIGNALS, ran=False, evidence=Evidence.RECEIVER)
    h_notes, s_notes = [], []
    for view in views:
        epochs = int(view.rows["t_s"].nunique())
        if epochs < opts.min_epochs:  # every test here holds for that many epochs before it alarms
            short = f"{view.receiver_id}: its sky at {epochs} epoch(s), {opts.min_epochs} needed"
            h_notes.append(short)
            s_notes.append(short)
            continue
        h_alarms, h_findings, h_series = below_horizon(view, opts)
        if h_series is not None:
            horizon.ran = True
            horizon.alarms += h_alarms
            horizon.findings += h_findings
            horizon.series.append(h_series)
            h_notes.append(
                f"{view.receiver_id}: elevation from the {view.elevation_source}, horizon dip "
                f"{horizon_dip_deg(view.height_m):.1f} deg at {view.height_m:.0f} m"
            )
        c_alarms, c_findings, c_series = cn0_steps(view, opts)
        u_alarms, u_findings, u_series = uniform_cn0(view, opts)
        r_alarms, r_findings = refused(view, opts)
        if c_series is not None or np.isfinite(view.rows["used"].to_numpy(float)).any():
            signals.ran = True
            signals.alarms += c_alarms + u_alarms + r_alarms
            signals.findings += c_findings + u_findings + r_findings
            signals.series += [x for x in (c_series, u_series) if x is not None]
            s_notes.append(f"{view.receiver_id}: {satellites_heard_text(view.rows)}")
    horizon.reason = "; ".join(h_notes) or "no satellite elevations (no satellite reports, or orbits and fixes)"
    signals.reason = "; ".join(s_notes) or "no per-satellite C/N0 or use flags"
    for r in (horizon, signals):
        r.alarms.sort(key=lambda a: a.start_s)
    return [horizon, signals]


_O = SatelliteSignalOptions()
_SKY = (
    "Each receiver's sky is read from what it reports per satellite (u-blox NAV-SAT, NMEA GSV, PX4 "
    "satellite_info, GnssLogger Status: C/N0, elevation, used, health; the `satellites` frame), else from its raw "
    "observations (C/N0, and elevation from the broadcast orbits and the receiver's fixes). A spoofer that fakes "
    "one or a few satellites leaves marks on those satellites alone, which means over all satellites hide."
)
ANALYSIS = AnalysisSpec(
    SIGNALS,
    "per-satellite evidence: a counterfeit satellite among real ones (horizon, C/N0 step, refused by the receiver)",
    ("satellite_view",),
    run_satellite_signals,
    (
        DetectorInfo(
            HORIZON,
            Evidence.RAW_MEASUREMENT,
            "satellites tracked below the receiver's horizon",
            method=f"{_SKY} A satellite tracked more than {_O.horizon_margin_deg:g} deg below the geometric horizon "
            f"(its dip at the receiver's height counted) for {_O.min_epochs} consecutive epochs: no real "
            "satellite's signal comes through the Earth, nor is the real sky seen from a position the spoofer "
            'invented elsewhere. Names the satellite ("G31 tracked 25 deg below the horizon at 46 dB-Hz for '
            '79 s"). Evidence: raw-measurement consistency with elevations from the broadcast orbits, receiver '
            "self-report with the receiver's own.",
            p_false_alarm="geometric: no false alarm from a real satellite's signal",
            threshold=f"{_O.horizon_margin_deg:g} deg below the horizon for {_O.min_epochs} epochs",
        ),
        DetectorInfo(
            SIGNALS,
            Evidence.RECEIVER,
            "one satellite's C/N0 stepping above the others, one C/N0 for all, or a strong satellite refused",
            method=f"{_SKY} Three signatures, each of satellites alone. A C/N0 step: one satellite's C/N0 relative "
            "to the epoch's median satellite (which removes what moves them all: antenna gain, attenuation, AGC) "
            f"rising {_O.step_db:g} dB within {_O.hold_s:g} s against both its last {_O.hold_s:g} s and its whole "
            f"history (once it has {_O.min_history_s:g} s of it), and ending {_O.above_median_db:g} dB above the "
            "median, while no other satellite falls and fewer than half rise (a turned antenna or a manoeuvre "
            "moves several, some down; a rising satellite climbs slowly; one leaving an obstruction returns to its "
            f"history), and above the highest level it held for {_O.hold_s:g} s before (a car's satellite shadowed "
            "for most of a minute comes back to its own level, above its median, never above itself). One C/N0 "
            f"for all: {_O.min_satellites} or more satellites within {_O.uniform_cn0_db:g} dB "
            f"(standard deviation, 5-s median) for {_O.hold_s:g} s, the channels of one transmitter (the real logs "
            "at hand never go below 2.5 dB). Refused by the receiver: a healthy satellite with a known orbit at "
            f"least {_O.refused_min_elevation_deg:g} deg high and as strong as the median used one that the "
            f"receiver leaves out of its solution at {100 * _O.refused_fraction:.0f}% of such epochs over "
            f"{_O.refused_min_s:g} s while it uses {_O.min_used} others of the same system (its own integrity "
            f"monitor refused it); a used satellite with a {_O.residual_m:g} m residual for {_O.min_epochs} epochs.",
            p_false_alarm="rule thresholds (not a calibrated rate)",
            threshold=f"a {_O.step_db:g} dB step of one satellite; {_O.min_satellites} satellites within "
            f"{_O.uniform_cn0_db:g} dB for {_O.hold_s:g} s; refused at {100 * _O.refused_fraction:.0f}% over "
            f"{_O.refused_min_s:g} s",
        ),
    ),
)
