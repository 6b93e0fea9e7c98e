"""What every detector returns: statistic series, alarm intervals and anything worth drawing."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.pipeline.evidence import Evidence

FloatArray = NDArray[np.float64]
# a Series named X + SIGMA_SUFFIX is X's 1-sigma band (the report draws X inside its 1- and 3-sigma bands)
SIGMA_SUFFIX = "_sigma"


@dataclass(frozen=True)
class Alarm:
    """One alarm interval. Times in seconds since the log start."""

    start_s: float
    end_s: float
    peak_statistic: float
    peak_s: float
    onset_s: float | None = None  # the detector's estimate of when the attack began
    onset_interval_s: tuple[float, float] | None = None  # credible/confidence interval for the onset
    receiver_id: str | None = None  # the receiver the alarm is about (None: not receiver-specific)
    satellites: tuple[str, ...] = ()  # satellites found inconsistent, for raw-measurement detectors
    systems: tuple[str, ...] = ()  # GNSS hit (e.g. "GPS", "Galileo"), for detectors that say which
    bands: tuple[str, ...] = ()  # signal bands hit (e.g. "L1", "E1")
    end_interval_s: tuple[float, float] | None = None  # between the last alarmed epoch and the first quiet one
    # how far the named satellite's range was off over this alarm (its median, m), where the detector
    # measures it (RAIM): a reflection makes tens of metres, a counterfeit kilometres (`pipeline.explanations`)
    range_error_m: float | None = None


@dataclass(frozen=True)
class Series:
    """A statistic over time, with its decision threshold when it has one."""

    name: str
    t: FloatArray
    values: FloatArray  # (N,) or (N, k) for k named components
    unit: str = ""
    threshold: float | None = None
    components: tuple[str, ...] = ()


@dataclass(frozen=True)
class Curve:
    """A statistic over something other than time, e.g. l_N(m) over candidate onset times m."""

    name: str
    x: FloatArray
    y: FloatArray
    x_label: str  # e.g. "candidate onset (s)"
    unit: str = ""


@dataclass(frozen=True)
class Bars:
    """One set of bars of a histogram: counts of values, or a fitted distribution's expected counts."""

    label: str  # e.g. "clean windows", "Rayleigh fit, sigma 2.10 m"
    counts: FloatArray  # (B,) one value per bin of the histogram's edges
    fitted: bool = False  # expected counts of a fitted distribution, not data


@dataclass(frozen=True)
class Histogram:
    """A statistic's distribution: bin edges and one or more sets of bars over them (e.g. the baseline
    distance in clean and in flagged windows, each with its fitted density as expected counts per bin)."""

    name: str
    edges: FloatArray  # (B + 1,)
    bars: tuple[Bars, ...]
    x_label: str  # e.g. "baseline distance (m)"
    unit: str = ""


@dataclass(frozen=True)
class Track:
    """A trajectory a detector reconstructed (e.g. the INS solution with spoofed GNSS excluded)."""

    name: str
    t: FloatArray
    lat_deg: FloatArray
    lon_deg: FloatArray
    height_m: FloatArray


@dataclass(frozen=True)
class Finding:
    """Something a detector established that is worth a line of its own in the verdict, e.g. a satellite
    excluded by RAIM at most epochs, or the receiver's own spoofing flag raised."""

    text: str
    start_s: float
    end_s: float
    satellites: tuple[str, ...] = ()
    receiver_id: str | None = None
    # how far the named satellites' ranges were off (the largest, m), where the detector measures it: a
    # reflection makes tens of metres, no multipath makes kilometres (`spooflens.pipeline.explanations`)
    range_error_m: float | None = None


@dataclass(frozen=True)
class Unmet:
    """A precondition of a detector's model that a log does not meet (`spooflens.pipeline.preconditions`):
    what the log has and what the model needs, in words a user understands ("IMU at 0.7 Hz" / "strapdown
    needs >= 20 Hz"), with the measured values. `stops`: the detector does not run; otherwise it runs on
    what there is and this says what it could not do."""

    name: str
    found: str
    requires: str
    values: dict[str, float | int | str] = field(default_factory=dict)
    stops: bool = True

    @property
    def text(self) -> str:
        return f"{self.found}: {self.requires}"

    def as_dict(self) -> dict[str, object]:
        return {"name": self.name, "found": self.found, "requires": self.requires, "values": dict(self.values)}


@dataclass
class DetectorResult:
    """What one detector (or, with `evidence` None, an analysis product such as the navigation solution)
    returned. Only results with an evidence class count in the verdict."""

    name: str
    ran: bool
    reason: str = ""  # why it did not run, or what it assumed
    alarms: list[Alarm] = field(default_factory=list)
    series: list[Series] = field(default_factory=list)
    curves: list[Curve] = field(default_factory=list)
    tracks: list[Track] = field(default_factory=list)
    extras: dict[str, object] = field(default_factory=dict)  # JSON-able facts for the summary
    advisory: bool = False  # reported and drawn, but not used for the verdict (an uncalibrated rule)
    evidence: Evidence | None = None  # the class of reference this detector compares GNSS with
    findings: list[Finding] = field(default_factory=list)
    histograms: list[Histogram] = field(default_factory=list)
    precondition: Unmet | None = None  # the precondition that kept it from running
    limitations: list[Unmet] = field(default_factory=list)  # preconditions that limited what it could do

    @property
    def is_detector(self) -> bool:
        return self.evidence is not None

    @classmethod
    def skipped(
        cls, name: str, reason: str, evidence: Evidence | None = None, precondition: Unmet | None = None
    ) -> DetectorResult:
        return cls(name=name, ran=False, reason=reason, evidence=evidence, precondition=precondition)


def alarm_intervals(
    t: FloatArray, statistic: FloatArray, alarm: NDArray[np.bool_], merge_gap_s: float = 0.0
) -> list[Alarm]:
    """Contiguous runs of `alarm` as intervals; runs closer than `merge_gap_s` are merged.

    An interval ends at the last alarmed epoch; the peak is the largest statistic inside it.
    """
    t = np.asarray(t, dtype=float)
    a = np.asarray(alarm, dtype=bool)
    if not a.any():
        return []
    edges = np.diff(np.concatenate([[0], a.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1) - 1
    runs: list[tuple[int, int]] = []
    for first, last in zip(starts.tolist(), stops.tolist(), strict=True):
        if runs and t[first] - t[runs[-1][1]] <= merge_gap_s:
            runs[-1] = (runs[-1][0], last)
        else:
            runs.append((first, last))
    out = []
    for s, e in runs:
        seg = np.asarray(statistic[s : e + 1], dtype=float)
        k = s + int(np.nanargmax(seg)) if np.isfinite(seg).any() else s
        out.append(Alarm(float(t[s]), float(t[e]), float(statistic[k]), float(t[k])))
    return out


def nearest(t: NDArray[np.float64], samples: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Index of the sample nearest each time (`samples` sorted, not empty; the earlier one on a tie) and
    how far it is (s)."""
    k = np.clip(np.searchsorted(samples, t), 0, len(samples) - 1)
    before = np.maximum(k - 1, 0)
    near = np.where(np.abs(samples[before] - t) < np.abs(samples[k] - t), before, k)
    return near, np.abs(samples[near] - t)


def onsets_after_quiet(
    t: FloatArray, quiet: NDArray[np.bool_], raised: NDArray[np.bool_], alarms: list[Alarm], receiver_id: str
) -> list[Alarm]:
    """Each alarm with its onset: the last quiet epoch before it. Where no epoch before it was quiet (a log
    that starts disturbed, or one whose own baseline the attack set: half of a short log spoofed), the last
    epoch before it where its alarm condition did not hold, not the log's first epoch, which would date the
    attack to the start of the log against the log's own evidence."""
    out = []
    for a in alarms:
        before = np.flatnonzero((t < a.start_s) & quiet)
        if not len(before):
            before = np.flatnonzero((t < a.start_s) & ~raised)
        onset = float(t[before[-1]]) if len(before) else float(t[0])
        out.append(Alarm(a.start_s, a.end_s, a.peak_statistic, a.peak_s, onset_s=onset, receiver_id=receiver_id))
    return out


def rise_start(t: FloatArray, score: FloatArray, start_s: float, quiet_level: float) -> tuple[int, int]:
    """Where the rise of `score` that led to an alarm at `start_s` began, and the last quiet epoch before
    the alarm (below `quiet_level`; 0 if none): from that epoch back down the rise while the statistic
    keeps falling, so an onset is where the statistic left its floor, not where it crossed a level."""
    before = np.flatnonzero((t < start_s) & (score < quiet_level))
    last_quiet = int(before[-1]) if len(before) else 0
    k = last_quiet
    while k > 0 and score[k - 1] <= score[k]:
        k -= 1
    return k, last_quiet


def center_scale(x: FloatArray, floor: float, relative_floor: float) -> tuple[float, float]:
    """Median and robust scale (1.4826 MAD, at least `floor` and `relative_floor` times |median|) of the
    finite values of x."""
    x = x[np.isfinite(x)]
    med = float(np.median(x))
    return med, max(1.4826 * float(np.median(np.abs(x - med))), floor, relative_floor * abs(med))


def robust_z(
    x: FloatArray, direction: int, floor: float, relative_floor: float, reference: NDArray[np.bool_] | None = None
) -> FloatArray:
    """Directional robust z-score of a series against its median over the `reference` epochs (all by
    default; NaN where x is NaN): +1 a rise counts, -1 a drop, 0 any change."""
    ok = np.isfinite(x) & (True if reference is None else reference)
    if ok.sum() < 5:
        ok = np.isfinite(x)
        if ok.sum() < 5:
            return np.full(len(x), np.nan)
    med, scale = center_scale(x[ok], floor, relative_floor)
    z = (x - med) / scale
    return np.abs(z) if direction == 0 else direction * z


def trailing_max(t: FloatArray, z: FloatArray, window_s: float) -> FloatArray:
    """max of z over the trailing [t - window_s, t] (NaN-aware), for indicators of one event that change
    seconds apart: raised when the later one moves, never before the first did."""
    index = pd.to_timedelta(t, unit="s")
    rolled = pd.Series(z, index=index).rolling(pd.Timedelta(seconds=window_s), closed="both", min_periods=1)
    return rolled.max().to_numpy(dtype=float)


def trailing_median(t: FloatArray, x: FloatArray, span_s: float, gap_s: float) -> FloatArray:
    """Per column of x (N, k), the median over the samples in [t - gap - span, t - gap]: a baseline the last
    `gap_s` cannot move (NaN where fewer than 3 samples are in the window, and before any)."""
    idx = pd.to_timedelta(t, unit="s")
    out = np.full(x.shape, np.nan)
    for j in range(x.shape[1]):
        med = pd.Series(x[:, j], index=idx).rolling(pd.Timedelta(seconds=span_s), min_periods=3).median()
        m = med.to_numpy(dtype=float)
        ok = np.isfinite(m)
        if ok.sum() >= 2:
            out[:, j] = np.interp(t - gap_s, t[ok], m[ok], left=np.nan)
    return out
