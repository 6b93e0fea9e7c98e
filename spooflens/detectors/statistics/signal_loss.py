"""Signal loss: stretches where a receiver's satellites get weaker together, against each satellite's own
recent past, and what the loss looked like.

The rest of its description: docs/interference.md ("Notes from the code")."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.detectors.base import trailing_median

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class SkyMatrix:
    """One receiver's satellites as a matrix: epochs down, satellites across."""

    t: FloatArray  # (T,) epochs at which the receiver reported its sky
    sv: tuple[str, ...]  # (S,)
    cn0: FloatArray  # (T, S) dB-Hz, NaN where the satellite was not tracked
    elevation: FloatArray  # (T, S) deg, NaN unknown
    carrier_hz: FloatArray  # (S,) the signal's carrier, NaN unknown (a sky view's L1-band report)

    @classmethod
    def from_rows(cls, rows: pd.DataFrame) -> SkyMatrix:
        """From rows of t_s, sv_id, cn0_dbhz and optionally elevation_deg and carrier_freq_hz; of several
        signals of one satellite and epoch the strongest."""
        rows = rows.sort_values("t_s")
        cn0 = rows.pivot_table(index="t_s", columns="sv_id", values="cn0_dbhz", aggfunc="max", dropna=False)
        t = np.unique(rows["t_s"].to_numpy(float))
        cn0 = cn0.reindex(index=t)
        svs = tuple(str(s) for s in cn0.columns)
        if "elevation_deg" in rows and rows["elevation_deg"].notna().any():
            el = rows.pivot_table(index="t_s", columns="sv_id", values="elevation_deg", aggfunc="mean")
            elevation = el.reindex(index=t, columns=cn0.columns).to_numpy(float)
        else:
            elevation = np.full(cn0.shape, np.nan)
        carrier = np.full(len(svs), np.nan)
        if "carrier_freq_hz" in rows and rows["carrier_freq_hz"].notna().any():
            strongest = rows.sort_values("cn0_dbhz").groupby("sv_id")["carrier_freq_hz"].last()
            carrier = strongest.reindex(cn0.columns).to_numpy(float)
        return cls(t, svs, cn0.to_numpy(float), elevation, carrier)


@dataclass(frozen=True)
class LossOptions:
    span_s: float = 60.0  # reference window (at least `span_epochs` epochs)
    span_epochs: int = 10
    gap_s: float = 3.0  # the reference ends this long before the epoch
    min_drop_db: float = 6.0  # a loss: the level reaches this
    hold_db: float = 3.0  # ... and lasts while it stays at this
    quiet_db: float = 2.0  # below this the satellites are back at their reference
    min_expected: int = 4  # expected satellites needed to judge an epoch
    merge_gap_s: float = 5.0
    after_s: float = 30.0  # how the satellites came back: the C/N0 this long after the loss
    max_events: int = 50


@dataclass(frozen=True)
class LossEvent:
    """One stretch of signal loss and what each expected satellite did in it."""

    start_s: float  # first epoch at `min_drop_db`
    end_s: float  # last epoch at `min_drop_db`
    onset_interval_s: tuple[float, float]  # (last quiet epoch before, first epoch of the loss)
    end_interval_s: tuple[float, float]  # (last epoch of the loss, first quiet epoch after; the log's end if none)
    ongoing_at_end: bool
    peak_level_db: float  # largest level in it (inf: every expected satellite lost)
    reference_db: FloatArray  # (S,) each satellite's frozen reference C/N0, NaN for the not expected
    drop_db: FloatArray  # (S,) each satellite's median drop over the loss, NaN if lost or not expected
    lost: BoolArray  # (S,) expected, and tracked at fewer than half of the loss's epochs
    elevation_deg: FloatArray  # (S,) mean elevation over the reference and the loss, NaN unknown
    after_db: float  # median C/N0 change against the reference `after_s` after the loss (NaN: none)
    spread_before_db: float  # standard deviation of the satellites' reference C/N0 (the sky's spread)
    spread_after_db: float  # ... of their median C/N0 `after_s` after the loss (NaN: none): near 0, one source

    @property
    def expected(self) -> BoolArray:
        return np.isfinite(self.reference_db)

    @property
    def tracked(self) -> BoolArray:
        return self.expected & ~self.lost


def _windows(t: FloatArray, opts: LossOptions) -> tuple[float, float]:
    """The reference window's span and gap for this sky's epoch period."""
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    return max(opts.span_s, opts.span_epochs * dt), max(opts.gap_s, 1.01 * dt)


def _reference(t: FloatArray, cn0: FloatArray, excluded: BoolArray, span: float, gap: float) -> FloatArray:
    """Each satellite's trailing reference C/N0 per epoch, NaN where it was not expected (tracked at no
    more than half the reference window's epochs); `excluded` epochs (earlier losses) left out."""
    kept = ~excluded[:, None]
    reference = trailing_median(t, np.where(kept, cn0, np.nan), span, gap)
    tracked = np.where(kept, np.isfinite(cn0).astype(float), np.nan)
    expected = trailing_median(t, tracked, span, gap) > 0.5
    return np.where(expected, reference, np.nan)


def _level(reference: FloatArray, cn0: FloatArray, min_expected: int) -> FloatArray:
    """Per epoch the median fall below the reference over the expected satellites (lost: +inf); NaN where
    fewer than `min_expected` are expected. `reference` is (S,) or (T, S)."""
    ref = np.broadcast_to(reference, cn0.shape)
    expected = np.isfinite(ref)
    drop = np.where(expected, np.where(np.isfinite(cn0), ref - cn0, np.inf), np.nan)
    n = expected.sum(axis=1)
    out = np.full(len(cn0), np.nan)
    ok = n >= min_expected
    if ok.any():
        out[ok] = np.nanmedian(drop[ok], axis=1)
    return out


def _extent(t: FloatArray, level: FloatArray, k: int, opts: LossOptions) -> tuple[int, int]:
    """First and last epoch of the loss around epoch k: back while the level holds, forward while it
    holds or recovers for no longer than `merge_gap_s`."""
    holds = np.nan_to_num(level, nan=0.0, posinf=np.inf) >= opts.hold_db
    first = k
    while first > 0 and holds[first - 1]:
        first -= 1
    last = k
    j = k + 1
    while j < len(t):
        if holds[j]:
            last = j
        elif t[j] - t[last] > opts.merge_gap_s:
            break
        j += 1
    return first, last


def signal_losses(sky: SkyMatrix, opts: LossOptions | None = None) -> tuple[list[LossEvent], FloatArray]:
    """Every loss in the sky, in time order, and the per-epoch level against the running reference (for
    drawing; NaN where too few satellites were expected)."""
    opts = opts or LossOptions()
    t, cn0 = sky.t, sky.cn0
    events: list[LossEvent] = []
    if len(t) < 3:
        return events, np.full(len(t), np.nan)
    excluded = np.zeros(len(t), dtype=bool)  # the references leave out earlier losses
    running = np.full(len(t), np.nan)
    span, gap = _windows(t, opts)
    begin = 0
    while begin < len(t) and len(events) < opts.max_events:
        # the references from `begin` on look back span + gap at most: computed from there only
        lo = int(np.searchsorted(t, t[begin] - span - gap - 1.0))
        reference = _reference(t[lo:], cn0[lo:], excluded[lo:], span, gap)
        level = _level(reference, cn0[lo:], opts.min_expected)
        running[begin:] = level[begin - lo :]
        above = np.flatnonzero(np.nan_to_num(level[begin - lo :], nan=0.0) >= opts.min_drop_db)
        if not len(above):
            break
        k = begin + int(above[0])
        frozen = reference[k - lo]
        level0 = _level(frozen, cn0, opts.min_expected)
        first, last = _extent(t, level0, k, opts)
        core = np.flatnonzero(np.nan_to_num(level0[first : last + 1], nan=0.0) >= opts.min_drop_db) + first
        start_i, end_i = int(core[0]), int(core[-1])
        events.append(_event(sky, frozen, level0, start_i, end_i, opts))
        excluded[first : last + 1] = True
        begin = last + 1
    return events, running


def _event(
    sky: SkyMatrix, reference: FloatArray, level: FloatArray, start_i: int, end_i: int, opts: LossOptions
) -> LossEvent:
    t, cn0 = sky.t, sky.cn0
    quiet = np.nan_to_num(level, nan=np.inf) < opts.quiet_db
    # the onset: where the level left its floor, the last epoch before the loss at or under the median
    # level of the minute before its last quiet epoch (noise puts half the floor's epochs there)
    score = np.nan_to_num(level, nan=0.0, posinf=1e6)
    before = np.flatnonzero(quiet[:start_i])
    last_quiet = int(before[-1]) if len(before) else 0
    window = (t >= t[last_quiet] - opts.span_s) & (np.arange(len(t)) <= last_quiet)
    floor_level = float(np.median(score[window]))
    at_floor = np.flatnonzero(score[: last_quiet + 1] <= floor_level)
    onset_lo = float(t[at_floor[-1]]) if len(at_floor) else float(t[0])
    after = np.flatnonzero(quiet[end_i + 1 :])
    ongoing = not len(after)
    end_hi = float(t[-1]) if ongoing else float(t[end_i + 1 + after[0]])
    inside = cn0[start_i : end_i + 1]
    expected = np.isfinite(reference)
    tracked_frac = np.isfinite(inside).mean(axis=0)
    lost = expected & (tracked_frac < 0.5)
    with warnings.catch_warnings():  # a satellite lost throughout has an all-NaN column: NaN, silently
        warnings.simplefilter("ignore", RuntimeWarning)
        drop = np.where(expected & ~lost, np.nanmedian(reference - inside, axis=0), np.nan)
        lo = max(0, int(np.searchsorted(t, t[start_i] - opts.span_s)))
        elevation = np.nanmean(sky.elevation[lo : end_i + 1], axis=0)
        later = (t > end_hi) & (t <= end_hi + opts.after_s)
        change = cn0[later] - reference if later.any() else np.full((0, len(reference)), np.nan)
        after_db = float(np.nanmedian(change)) if np.isfinite(change).any() else float("nan")
        back = np.nanmedian(cn0[later], axis=0) if later.any() else np.full(len(reference), np.nan)
        spread_after = float(np.nanstd(back)) if np.isfinite(back).sum() >= 4 else float("nan")
        spread_before = float(np.nanstd(reference)) if expected.sum() >= 4 else float("nan")
    core = level[start_i : end_i + 1]
    return LossEvent(
        float(t[start_i]),
        float(t[end_i]),
        (onset_lo, float(t[start_i])),
        (float(t[end_i]), end_hi),
        ongoing,
        float(np.nanmax(core)) if np.isfinite(core).any() or np.isinf(core).any() else float("nan"),
        reference,
        drop,
        lost,
        elevation,
        after_db,
        spread_before,
        spread_after,
    )
