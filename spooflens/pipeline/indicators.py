"""A receiver's own indicators around an alarm, against their level before it: what the natural
explanations (`spooflens.pipeline.explanations`) read.

Per receiver the fixes (fix type, satellites used, DOP, reported accuracy, mean C/N0, noise, AGC,
jamming state and indicator, spoofing flag, time against the log's clock), its monitor reports where it
logged them apart from its fixes (noise, AGC, jamming state and indicator) and its sky (each satellite's
C/N0 and whether the receiver used it: the `satellites` frame, else the raw observations) as arrays.
A window's level is read through a 3-epoch running median (one odd epoch moves nothing); its baseline
is the minute before it, or the minute after it when fewer than 5 fixes lie before (an alarm at the
log's start). C/N0 changes are read per satellite against that satellite's own baseline, so losing the
weak satellites does not raise the mean.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.detectors.receiver_time import time_resolution_s
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import small_move_en_m
from spooflens.schema import FixType, SpoofingFlag

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

BASELINE_S = 60.0
GUARD_S = 2.0
MIN_BASELINE_FIXES = 5
MIN_COMMON_SATELLITES = 3
FIX_COLUMNS = (
    "lat_deg",
    "lon_deg",
    "vel_e_mps",
    "vel_n_mps",
    "h_acc_m",
    "vel_acc_mps",
    "sats_used",
    "hdop",
    "vdop",
    "noise_per_ms",
    "agc",
    "jamming_state",
    "jamming_indicator",
    "cn0_mean_dbhz",
    "time_offset_s",
)
# the front end's monitor: read from the receiver's own reports (`receiver_status`) when it logged any, which
# go on where a jammer costs the fix (ArduPilot UBX1), else from its fixes (the interference detector's rule)
MONITOR_COLUMNS = ("noise_per_ms", "agc", "jamming_state", "jamming_indicator")


@dataclass(frozen=True)
class Sky:
    """One receiver's satellites as matrices: epochs down, satellites across (NaN: not tracked/unknown)."""

    t: FloatArray
    sv: tuple[str, ...]
    cn0: FloatArray
    used: FloatArray  # 1 used in the fix, 0 left out, NaN unknown

    @cached_property
    def typical_cn0(self) -> FloatArray:
        """Each satellite's median C/N0 over the whole log: the level its sky usually gives it."""
        if not self.cn0.size:
            return np.zeros(self.cn0.shape[1:])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a satellite never tracked
            return np.nanmedian(self.cn0, axis=0)

    @cached_property
    def usual_cn0(self) -> float:
        """The sky's usual strength: the median over satellites of their typical C/N0 (NaN with none)."""
        return _finite_median(self.typical_cn0)

    @classmethod
    def of(cls, table: EpochTable, rid: str) -> Sky:
        rows = table.satellites[table.satellites["receiver_id"] == rid]
        if not len(rows) or not rows["cn0_dbhz"].notna().any():
            obs = table.observations
            rows = obs[obs["receiver_id"] == rid].assign(used=np.nan)
        rows = rows[np.isfinite(rows["cn0_dbhz"].to_numpy(float))]
        if "used" not in rows:
            rows = rows.assign(used=np.nan)
        if not len(rows):
            return cls(np.zeros(0), (), np.zeros((0, 0)), np.zeros((0, 0)))
        cn0 = rows.pivot_table(index="t_s", columns="sv_id", values="cn0_dbhz", aggfunc="max")
        used = rows.pivot_table(index="t_s", columns="sv_id", values="used", aggfunc="max", dropna=False)
        used = used.reindex(index=cn0.index, columns=cn0.columns)
        return cls(
            cn0.index.to_numpy(float), tuple(str(s) for s in cn0.columns), cn0.to_numpy(float), used.to_numpy(float)
        )


@dataclass(frozen=True)
class Monitor:
    """One receiver's monitor reports (`receiver_status`) as arrays, on their own times."""

    t: FloatArray
    columns: dict[str, FloatArray]

    @classmethod
    def of(cls, table: EpochTable, rid: str) -> Monitor | None:
        rows = table.receiver_status[table.receiver_status["receiver_id"].astype(str) == rid].sort_values("t_s")
        if not len(rows):
            return None
        return cls(rows["t_s"].to_numpy(float), {c: rows[c].to_numpy(float) for c in MONITOR_COLUMNS if c in rows})


@dataclass(frozen=True)
class Receiver:
    """One receiver's fixes as arrays, its sky and its monitor reports."""

    receiver_id: str
    t: FloatArray
    columns: dict[str, FloatArray]
    fix_type: NDArray[np.int64]
    spoofing_flag: NDArray[np.int64]
    sky: Sky
    monitor: Monitor | None = None

    @classmethod
    def of(cls, table: EpochTable, rid: str) -> Receiver:
        fx = table.fixes_of(rid).sort_values("t_s")
        columns = {c: fx[c].to_numpy(float) for c in FIX_COLUMNS if c in fx}
        return cls(
            rid,
            fx["t_s"].to_numpy(float),
            columns,
            fx["fix_type"].to_numpy(np.int64),
            fx["spoofing_flag"].to_numpy(np.int64),
            Sky.of(table, rid),
            Monitor.of(table, rid),
        )

    def col(self, name: str) -> FloatArray:
        return self.columns.get(name, np.full(len(self.t), np.nan))

    @property
    def period_s(self) -> float:
        return float(np.median(np.diff(self.t))) if len(self.t) > 2 else 1.0

    @cached_property
    def time_resolution_s(self) -> float:
        """How far the receiver's time offset moves with no move of its time: the resolution of a coarse time
        read on a cycle of its own (`receiver_time.coarse_time`), else 0."""
        x = self.col("time_offset_s")
        ok = np.isfinite(x)
        return time_resolution_s(self.t[ok], x[ok]) if ok.sum() >= 3 else 0.0


def _between(t: FloatArray, a: float, b: float) -> slice:
    return slice(int(np.searchsorted(t, a, "left")), int(np.searchsorted(t, b, "right")))


def running_median(x: FloatArray, n: int = 3) -> FloatArray:
    return pd.Series(x).rolling(n, center=True, min_periods=1).median().to_numpy(float)


def _finite_median(x: FloatArray) -> float:
    x = x[np.isfinite(x)]
    return float(np.median(x)) if len(x) else float("nan")


@dataclass(frozen=True)
class Window:
    """A receiver's indicators over [start_s, end_s] and over its baseline."""

    rx: Receiver
    start_s: float
    end_s: float
    now: slice  # fixes in the window
    base: slice | None  # fixes of the baseline (None: too few on either side)
    base_where: str  # "before" | "after" | ""
    sky_now: slice
    sky_base: slice | None
    monitor_now: slice | None = None  # the monitor reports in the window and its baseline (`Receiver.monitor`)
    monitor_base: slice | None = None

    @classmethod
    def of(cls, rx: Receiver, start_s: float, end_s: float, lead_s: float = 0.0) -> Window:
        """The window [start_s - lead_s, end_s] against the minute before it; when fewer than 5 fixes lie
        there, [start_s - 2 s, end_s] against the minute before that (a log that begins just before its
        alarm), else the minute after the window."""
        choices = (
            (start_s - lead_s, (start_s - lead_s - BASELINE_S, start_s - lead_s - GUARD_S), "before"),
            (start_s - GUARD_S, (start_s - BASELINE_S, start_s - GUARD_S), "before"),
            (start_s - lead_s, (end_s + GUARD_S, end_s + BASELINE_S), "after"),
        )
        lo, base, where = start_s - lead_s, None, ""
        bounds: tuple[float, float] | None = None
        for w0, (b0, b1), side in choices:
            span = _between(rx.t, b0, b1)
            if span.stop - span.start >= MIN_BASELINE_FIXES:
                lo, base, where, bounds = w0, span, side, (b0, b1)
                break
        sky_base = _between(rx.sky.t, *bounds) if bounds is not None else None
        mon = rx.monitor
        monitor_now = _between(mon.t, lo, end_s) if mon is not None else None
        monitor_base = _between(mon.t, *bounds) if mon is not None and bounds is not None else None
        return cls(
            rx,
            lo,
            end_s,
            _between(rx.t, lo, end_s),
            base,
            where,
            _between(rx.sky.t, lo, end_s),
            sky_base,
            monitor_now,
            monitor_base,
        )

    @property
    def fixes(self) -> int:
        return self.now.stop - self.now.start

    def values(self, name: str) -> tuple[FloatArray, FloatArray | None]:
        """The indicator's values in the window and in its baseline (None: no baseline); a monitor's from
        the receiver's own reports when it logged any."""
        mon = self.rx.monitor
        if mon is not None and name in MONITOR_COLUMNS and self.monitor_now is not None:
            x = mon.columns.get(name, np.full(len(mon.t), np.nan))
            return x[self.monitor_now], (x[self.monitor_base] if self.monitor_base is not None else None)
        x = self.rx.col(name)
        return x[self.now], (x[self.base] if self.base is not None else None)

    def level(self, name: str) -> float:
        """The indicator's baseline level (NaN without a baseline or values)."""
        base = self.values(name)[1]
        return _finite_median(base) if base is not None else float("nan")

    def worst(self, name: str, direction: int) -> float:
        """The indicator's largest (direction +1) or smallest (-1) running-median level in the window."""
        x = running_median(self.values(name)[0])
        x = x[np.isfinite(x)]
        if not len(x):
            return float("nan")
        return float(x.max() if direction > 0 else x.min())

    def satellite_cn0_change(self, above_typical: bool = False) -> FloatArray:
        """Per epoch of the window, the median over satellites of each one's C/N0 against its own baseline
        (running median; NaN where fewer than 3 satellites have both). `above_typical`: against the higher of
        its baseline and its typical level in the log (`Sky.typical_cn0`): a sky coming back to its usual
        strength after a stretch of obstruction rises against the minute before, and no higher."""
        sky = self.rx.sky
        if self.sky_base is None or not len(sky.t):
            return np.zeros(0)
        base = sky.cn0[self.sky_base]
        if not np.isfinite(base).any():
            return np.zeros(0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # satellites not tracked in the baseline
            own = np.nanmedian(base, axis=0)
            if above_typical:
                own = np.where(np.isfinite(own), np.fmax(own, sky.typical_cn0), own)
            delta = sky.cn0[self.sky_now] - own
            enough = np.isfinite(delta).sum(axis=1) >= MIN_COMMON_SATELLITES
            per_epoch = np.where(enough, np.nanmedian(np.where(enough[:, None], delta, 0.0), axis=1), np.nan)
        return running_median(per_epoch)

    def cn0_change_db(self) -> tuple[float, float, str]:
        """(largest drop, largest rise) of the C/N0 in dB, and what it was read from: per satellite where the
        receiver reports its sky, else the mean C/N0 of its fixes. The drop is against the baseline; the rise
        against the higher of the baseline and the log's typical level (a sky recovering from obstruction
        rises to its usual strength, a spoofer's signal above it)."""
        per_sat = self.satellite_cn0_change()
        if np.isfinite(per_sat).any():
            rise = self.satellite_cn0_change(above_typical=True)
            return float(-np.nanmin(per_sat)), float(np.nanmax(rise)), "each satellite's C/N0"
        base = self.level("cn0_mean_dbhz")
        if not np.isfinite(base):
            return float("nan"), float("nan"), ""
        typical = _finite_median(self.rx.col("cn0_mean_dbhz"))
        above = max(base, typical) if np.isfinite(typical) else base
        return base - self.worst("cn0_mean_dbhz", -1), self.worst("cn0_mean_dbhz", +1) - above, "mean C/N0"

    def equal_cn0(self, within_db: float, min_satellites: int, min_epochs: int) -> tuple[float, float] | None:
        """(spread, level) where `min_satellites` or more satellites sat within `within_db` of each other (5-epoch
        median of the standard deviation) for `min_epochs` epochs, else None."""
        cn0 = self.rx.sky.cn0[self.sky_now]
        if not len(cn0):
            return None
        n = np.isfinite(cn0).sum(axis=1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # epochs without a satellite
            spread = np.where(n >= min_satellites, np.nanstd(cn0, axis=1), np.nan)
            level = np.nanmedian(cn0, axis=1)
        spread = running_median(spread, 5)
        tight = np.isfinite(spread) & (spread <= within_db)
        if tight.sum() < min_epochs:
            return None
        return float(np.nanmin(spread[tight])), float(np.nanmedian(level[tight]))

    def cn0_level_now(self) -> float:
        """The window's median satellite C/N0, else the median of its fixes' mean C/N0 (NaN unknown)."""
        sky = self.rx.sky.cn0[self.sky_now]
        if np.isfinite(sky).any():
            return _finite_median(sky.ravel())
        return _finite_median(self.rx.col("cn0_mean_dbhz")[self.now])

    def cn0_usual_level(self) -> float:
        """The receiver's usual C/N0 over the whole log (`Sky.usual_cn0`), else the median of its fixes' mean C/N0."""
        usual = self.rx.sky.usual_cn0
        return usual if np.isfinite(usual) else _finite_median(self.rx.col("cn0_mean_dbhz"))

    def cn0_level_before(self) -> float:
        """The baseline's median satellite C/N0, else the median of its fixes' mean C/N0 (NaN unknown or
        without a baseline)."""
        if self.base is None or self.sky_base is None:
            return float("nan")
        sky = self.rx.sky.cn0[self.sky_base]
        if np.isfinite(sky).any():
            return _finite_median(sky.ravel())
        return _finite_median(self.rx.col("cn0_mean_dbhz")[self.base])

    def spoofing_flag_raised(self) -> bool:
        return bool((self.rx.spoofing_flag[self.now] == SpoofingFlag.INDICATED).any())

    def longest_gap_s(self) -> float:
        """The longest time without a valid fix inside the window (and from its last fix before it)."""
        lo = max(self.now.start - 1, 0)
        t = self.rx.t[lo : self.now.stop]
        valid = self.rx.fix_type[lo : self.now.stop] >= FixType.FIX_2D
        t = t[valid]
        return float(np.diff(t).max()) if len(t) > 1 else 0.0

    def fix_types(self) -> NDArray[np.int64]:
        return self.rx.fix_type[self.now]

    def largest_jump_m(self) -> float:
        """The largest move of the fix between two epochs beyond what its reported velocity (else the median
        move) explains, horizontally."""
        lo = max(self.now.start - 1, 0)
        lat, lon = self.rx.col("lat_deg")[lo : self.now.stop], self.rx.col("lon_deg")[lo : self.now.stop]
        if len(lat) < 2:
            return 0.0
        t = self.rx.t[lo : self.now.stop]
        east, north = small_move_en_m(np.diff(lat), np.diff(lon), np.nanmean(lat))
        ve, vn = self.rx.col("vel_e_mps")[lo : self.now.stop], self.rx.col("vel_n_mps")[lo : self.now.stop]
        dt = np.diff(t)
        pe, pn = 0.5 * (ve[1:] + ve[:-1]) * dt, 0.5 * (vn[1:] + vn[:-1]) * dt
        step = np.hypot(east, north)
        fallback = float(np.nanmedian(step)) if np.isfinite(step).any() else 0.0
        with np.errstate(invalid="ignore"):
            beyond = np.where(np.isfinite(pe) & np.isfinite(pn), np.hypot(east - pe, north - pn), step - fallback)
        return float(np.nanmax(beyond)) if np.isfinite(beyond).any() else 0.0
