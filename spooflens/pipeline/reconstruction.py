"""Where the vehicle really was during each incident, and how long each incident really lasted.

Detectors on the closed-loop filter alarm when an attack starts; afterwards the filter follows the
spoofed fixes and the alarms stop, although the attack goes on. So, for every incident with inertial
evidence, the filter is run again with that receiver's GNSS left out from the onset on: the INS (and
wheel odometry when the log has it) coasts, and every later fix is compared with this reference
within its growing uncertainty (`CoastingCheck`):

- the incident is *confirmed* when GNSS departs from the coasted reference beyond that uncertainty
  (position and velocity NIS over chi-square(dof) at P_FA `p_disagree` per epoch) for at least
  `min_disagree_s` within `confirm_window_s` of the onset. A receiver glitch (a jump of an SBAS
  solution, a short wander) does not leave the reference's uncertainty for long and is not confirmed:
  its inertial evidence does not count, and the incident keeps only its other evidence classes;
- it *ends* at the first fix after the departure from which GNSS agrees with the reference again for
  `agree_s` seconds (back within the reference's 3 sigma or `min_departure_m`, not merely under the
  clean envelope), with an interval from the last disagreeing fix to that one, or at the end of the
  log when GNSS never agrees again.

The reconstructed track is the INS solution with the GNSS left out over the whole incident (its
velocity kept when the GNSS-only check showed the receiver's velocity stayed honest: a position-only
drag), smoothed, so GNSS after a finished attack ties the gap down.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import partial

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.baseline.use import coast_envelope_limit
from spooflens.detectors.base import DetectorResult, Track
from spooflens.detectors.gnss_consistency import NAME as GNSS_CONSISTENCY
from spooflens.errors import SpooflensError
from spooflens.estimation.quantiles import chi2_isf, norm_isf
from spooflens.navigation.error_model import PHI
from spooflens.navigation.loosely_coupled import (
    SMOOTHER_NEEDS,
    FilterOptions,
    NavSolution,
    nis_by_pattern,
    run_prepared,
)
from spooflens.navigation.product import NAVIGATION, Navigation, navigation_of
from spooflens.navigation.smoother import smooth
from spooflens.navigation.strapdown import NavState
from spooflens.pipeline.evidence import CORROBORATION_S, NOT_SPOOFING, Evidence
from spooflens.pipeline.explanations import ExplanationOptions, Shock, inertial_shocks
from spooflens.pipeline.registry import AnalysisContext, navigation_parts
from spooflens.pipeline.verdict import Incident, Verdict, incident_of

FloatArray = NDArray[np.float64]
GNSS_ROWS = (0, 1, 2, 3, 4, 5)
# said of a check judged without this log's own clean departures (a log too short for a clean coast)
NO_CLEAN_COASTS = (
    "no clean stretch of this log was long enough to measure its own departures from a coasted reference "
    "(a short log): judged against the filter's own uncertainty and the physical floors alone"
)
# said of an inertial alarm that nothing of this log or its vehicle calibrated (`CoastingOptions.calibrating_s`)
UNCALIBRATED = (
    "the INS reference was never calibrated on this log: its noise was not learned (too little clean data) and "
    "no clean stretch before the alarm was long enough to coast it and measure how far it departs by "
    "itself (a vibrating IMU's coast departs tens of times further than the IMU preset says); a vehicle baseline "
    "(`--baseline`) would calibrate it"
)
# The check compares horizontal position and velocity: receivers' heights wander by tens of metres
# (an SBAS solution converging), and the vertical channel of a coasting INS diverges.
HORIZONTAL_ROWS = (0, 1, 3, 4)


@dataclass(frozen=True)
class CoastingOptions:
    p_disagree: float = 1e-3
    margin: float = 2.0  # a departure must exceed the log's own clean envelope by this factor
    # ... to this with no clean coast (and no vehicle baseline) to measure that envelope (`Envelope.margin`):
    # a short log's reference drifts as far as its unlearned noise lets it, which the filter's own
    # uncertainty understates (the real husky bag cut to 60 s: a clean stretch departed 2.7 times the
    # filter's uncertainty, a 2 m/s ramp 9.6 times)
    uncalibrated_margin: float = 5.0
    # ... and where few clean coasts measured it, the bound of a next clean coast (`clean_coast_bound`)
    coast_spread: float = 0.9
    coast_spread_weight: float = 4.0
    p_next_coast: float = 0.01
    min_disagree_s: float = 2.0
    min_disagree_epochs: int = 3
    # after the incident's last alarm (and before the next incident), within the clean envelope's reach: a
    # slow pull (0.5 m/s) is 10 m off only after 20 s
    confirm_window_s: float = 60.0
    agree_s: float = 10.0
    min_agree_epochs: int = 5
    margin_s: float = 1.0  # GNSS is left out from this long before the onset estimate
    resolution: float = 3.0  # agreement counts while the reference's sigma is below the departure / this
    placebo_horizon_s: tuple[float, float] = (60.0, 60.0)  # half the log, within these bounds
    placebo_trim: float = 0.1  # the largest tenth of the clean coasts is left out (another attack, if any)
    placebo_runs: int = 24
    settle_s: float = 30.0
    # where no placebo coast is clean before an incident, coasts from the reference's convergence on, every
    # `calibration_step_s`, each up to the incident, measure its departures; one counts when clean this long
    # (the real log171 copter cut to 45 s: its INS departed 10-50 times the preset's uncertainty within 10 s
    # of every start, and an alarm 0.2 s after convergence was confirmed at 40 times with nothing to measure
    # that against; the husky bag's coasts stayed below 1.7, a 5 m/s ramp on it 100 and more)
    calibrating_s: float = 5.0
    calibration_step_s: float = 5.0
    converge_s: float = 20.0  # a reference younger than this cannot confirm anything (still converging)
    # a GNSS outage longer than this leaves the INS to re-converge for `converge_s` once fixes are back
    outage_s: float = 10.0
    # GNSS must also have moved this far from the reference: real receivers wander and jump by metres
    # (an SBAS solution converging, a correction switching), which no spoofing verdict should rest on
    min_departure_m: float = 10.0
    # or its velocity this far from the reference's within `young_s` of the coast's start: a velocity pull
    # is metres off only after many seconds, while its velocity is off from the first pulled fix, when the
    # coast is still sharp; later, an unobservable heading (a hover) makes the coasted velocity drift
    min_departure_mps: float = 0.3
    young_s: float = 10.0
    # a coasting check first coasts this long past its deadline (then on to the end only when needed)
    first_look_s: float = 30.0
    # coasts tried from later bursts of alarms inside one incident, when its first coast confirms nothing
    max_later_coasts: int = 4


@dataclass(frozen=True)
class Envelope:
    """How far GNSS departs from the coasted reference in this log's clean stretches, per horizon since
    the coasting began: the largest NIS-over-threshold ratio of `runs` coasts started there (never
    below 1). A real receiver's jumps and a real IMU's drift make it larger than the model says."""

    horizon_s: FloatArray
    kappa: FloatArray
    runs: int
    from_baseline: bool = False  # capped by the vehicle's baseline (`capped`): its clean logs calibrate it
    # the log standard deviation of the clean coasts' peaks above the model (a peak floored at 1 says nothing of
    # it): how far apart this log's own clean coasts fall; None with fewer than two above it
    peak_log_sd: float | None = None
    # how many independent coasts the `runs` are worth (None: each is one); nested calibration coasts,
    # all run up to the same incident, share most of their span
    independent: float | None = None

    @property
    def samples(self) -> float:
        """The number of clean coasts the bound of a next one rests on (`independent`, else `runs`)."""
        return float(self.runs) if self.independent is None else self.independent

    def margin(self, opts: CoastingOptions) -> float:
        """How far a departure must exceed this envelope: `opts.margin`, or where few clean coasts measured it
        the bound a next clean coast stays below (`clean_coast_bound`), whichever is larger;
        `opts.uncalibrated_margin` over the model with none; a vehicle baseline's envelope needs no widening."""
        if self.from_baseline:
            return opts.margin
        if not self.runs:
            return opts.uncalibrated_margin
        return max(opts.margin, clean_coast_bound(self.samples, opts, self.peak_log_sd))

    def at(self, h: FloatArray) -> FloatArray:
        """The envelope at horizons `h`. Beyond the longest horizon a clean coast measured, nothing says how
        much faster than its own uncertainty the INS drifts on this log: the ratio goes on growing as the
        square of the horizon (the drift one power of time ahead of the uncertainty, as an unmodelled tilt or
        heading error makes it). A short log's calibration coasts measure seconds (the real log171 copter
        cut to 75 s: one clean coast of 8 s at 3.7 times its uncertainty, then a coast through its next
        manoeuvres at 65 times by 19 s)."""
        if not len(self.horizon_s):
            return np.ones_like(h)
        inside = np.interp(h, self.horizon_s, self.kappa, left=self.kappa[0], right=self.kappa[-1])
        last = float(self.horizon_s[-1])
        if last <= 0:
            return inside
        return np.where(h > last, self.kappa[-1] * (np.asarray(h, dtype=float) / last) ** 2, inside)


def clean_coast_bound(n: float, opts: CoastingOptions, peak_log_sd: float | None = None) -> float:
    """How far above the largest of `n` clean coasts' peaks the next clean coast stays, but for a share
    `p_next_coast` of them: the peaks as log-normal, the largest of n near their mean plus the expected
    largest of n standard normals (Blom's approximation), and the next one's bound from the mean over the
    spread widened by the mean's own uncertainty. The spread: `coast_spread` (the real husky bag's clean
    coasts: a log standard deviation of 0.9, so that the largest of one or two says little about the next),
    weighing as `coast_spread_weight` coasts against the log's own `peak_log_sd` over n - 1 (a conjugate
    prior on the variance), and never wider than it. With the prior alone it is 19 times with one coast,
    3.4 with five, and from about 14 on below `opts.margin`."""
    spread2 = opts.coast_spread**2
    if peak_log_sd is not None and n >= 2:
        w = opts.coast_spread_weight
        # never wider than the prior: it is the widest a real INS showed, and "clean" coasts spread wider
        # than that hold something else (an attack filling the log made a car's two coasts 10 times apart)
        spread2 = min(spread2, (w * spread2 + (n - 1) * peak_log_sd**2) / (w + n - 1))
    expected_largest = norm_isf(1.0 - (n - 0.375) / (n + 0.25))
    z = norm_isf(opts.p_next_coast) * float(np.sqrt(1.0 + 1.0 / n))
    return float(np.exp(float(np.sqrt(spread2)) * (z - expected_largest)))


@dataclass(frozen=True)
class CoastingCheck:
    excluded_from_s: float
    t: FloatArray
    ratio: FloatArray  # GNSS against the coasted reference: NIS / chi-square threshold
    kappa: FloatArray  # the clean envelope at each epoch's horizon
    offset_m: FloatArray  # horizontal distance GNSS - reference
    confirmed: bool
    departure_s: float | None  # start of the first sustained disagreement
    end_s: float | None  # first fix of sustained agreement after it (None: never, to the end of the log)
    end_interval_s: tuple[float, float] | None
    inconclusive_from_s: float | None = None  # the reference became too uncertain to see an end from here
    offset_en_m: FloatArray | None = None  # (M, 2) GNSS - reference, east and north
    lost_s: float | None = None  # an IMU shock the coast met: nothing was judged from here

    @property
    def peak_over_envelope(self) -> float | None:
        """The largest ratio over the clean envelope along the coast (None: nothing compared)."""
        over = self.ratio / self.kappa
        return float(np.nanmax(over)) if np.isfinite(over).any() else None


def _offset_peak(check: CoastingCheck) -> float | None:
    """The largest horizontal GNSS - reference distance from the departure to the end (the log's end if
    GNSS never came back); None without a departure."""
    if check.departure_s is None:
        return None
    end = check.end_s if check.end_s is not None else np.inf
    inside = (check.t >= check.departure_s) & (check.t <= end) & np.isfinite(check.offset_m)
    return float(np.max(check.offset_m[inside])) if inside.any() else None


def _runs(flags: NDArray[np.bool_]) -> list[tuple[int, int]]:
    edges = np.diff(np.r_[0, flags.astype(np.int8), 0])
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1, strict=True))


def coasting_nis(sol: NavSolution, rows: tuple[int, ...] = GNSS_ROWS) -> tuple[FloatArray, NDArray[np.int64]]:
    """NIS of the measured GNSS rows against the filter's prediction, whether the rows were used or not."""
    return nis_by_pattern(sol.nu, sol.S_all, np.isfinite(sol.z[:, np.array(rows)]), rows)


def continued(
    nav: Navigation, sol: NavSolution, t_from: float, opts: FilterOptions, t_end: float | None = None
) -> NavSolution:
    """`opts` run from `sol`'s last epoch at or before `t_from` (its state, covariance and sensor errors
    after that update: the fixes up to it are in them) to `t_end`, or from the log's start when `t_from`
    comes before `sol`'s first epoch. A smoothed or compared estimate after that epoch is the one a run
    over the whole log with the same options gives."""
    return _continued(nav, sol, t_from, opts, t_end)[0]


def _continued(
    nav: Navigation, sol: NavSolution, t_from: float, opts: FilterOptions, t_end: float | None
) -> tuple[NavSolution, FloatArray | None]:
    """`continued`, and the covariance it started from (None when it ran from the log's start)."""
    k = int(np.searchsorted(sol.t, t_from, side="right")) - 1
    if k < 0:
        return run_prepared(nav.inputs.between(-np.inf, t_end), opts, nav.start), None
    x, P, g = _updated_at(nav, sol, k)
    opts = replace(opts, initial=NavState.from_vector(x), initial_covariance=P, initial_gm=g)
    return run_prepared(nav.inputs.between(float(sol.t[k]), t_end), opts), P


def _updated_at(nav: Navigation, sol: NavSolution, k: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """`sol`'s state, covariance and sensor errors after epoch k's update; when `sol` kept the covariance
    of a part of its epochs, refiltered with its own options from the last kept one."""
    k0 = k - k % sol.P_upd_every
    x, P, g = sol.state[k0], sol.P_upd[k0 // sol.P_upd_every], sol.gm[k0]
    if k0 == k:
        return x, P, g
    opts = replace(
        sol.options,
        initial=NavState.from_vector(x),
        initial_covariance=P,
        initial_gm=g,
        record=("P_upd",),
        P_upd_every=1,
    )
    head = run_prepared(nav.inputs.between(float(sol.t[k0]), float(sol.t[k])), opts)
    return head.state[-1], head.P_upd[-1], head.gm[-1]


def coast(
    nav: Navigation, t_from: float, t_end: float | None = None, base: NavSolution | None = None
) -> NavSolution | None:
    """The INS (and odometry) continued from a solution's last epoch at or before `t_from` (the main one,
    or `base`: one that left the incidents already confirmed out) with every later GNSS fix left out
    (each still compared with it), up to `t_end`; None when no fix lies there to compare it with (a
    GNSS outage: a jammed receiver reports nothing)."""
    sol = base if base is not None else nav.solution
    k = int(np.searchsorted(sol.t, t_from, side="right")) - 1
    tf = nav.inputs.fixes["t_s"].to_numpy(dtype=float)
    after = -np.inf if k < 0 else float(sol.t[k])
    compared = int(np.count_nonzero((tf > after) & (tf <= (np.inf if t_end is None else t_end))))
    if compared < (2 if k < 0 else 1):  # what a run from the start, or a continued one, needs
        return None
    # a coast is only compared with GNSS (t, z, nu, S_all): the per-epoch matrices are not kept
    opts = replace(
        sol.options,
        exclude_after_s=t_from,
        exclude_until_s=None,
        exclude_velocity_too=True,
        record=False,
        compare=True,
    )
    out, P0 = _continued(nav, sol, t_from, opts, t_end)
    # the attitude error's third (vertical) axis: the heading
    return out if P0 is None else with_heading_curvature(out, float(P0[PHI, PHI][2, 2]))


def with_heading_curvature(sol: NavSolution, heading_var: float) -> NavSolution:
    """A coast's innovation covariance with the second-order term of its heading error. A heading error d
    turns the coast's manoeuvres (its displacement from straight, steady motion M, its velocity change dV)
    by d: to first order across them, which the filter's linear covariance holds, and by d^2 / 2 along
    them, which it does not. That term is small where the coast flies straight and grows with the turn:
    a simulated aircraft's coast began 14 degrees off in heading (1.85 sigma) and entered a 1.1 g turn, and
    the linear covariance, thin along the turn's displacement, made its error 7 times the clean envelope.
    Added: the mean square of d^2 / 2, 3/4 of the heading variance squared, times M M^T (position) and
    dV dV^T (velocity)."""
    if len(sol.t) < 2 or not np.isfinite(heading_var) or heading_var <= 0:
        return sol
    dv = sol.state[:, 3:5] - sol.state[0, 3:5]
    dt = np.diff(sol.t)[:, None]
    m = np.concatenate([np.zeros((1, 2)), np.cumsum(0.5 * (dv[1:] + dv[:-1]) * dt, axis=0)])
    c = 0.75 * heading_var**2
    S = sol.S_all.copy()
    S[:, 0:2, 0:2] += c * m[:, :, None] * m[:, None, :]
    S[:, 3:5, 3:5] += c * dv[:, :, None] * dv[:, None, :]
    return replace(sol, S_all=S)


def _ratio(sol: NavSolution, p: float, window_s: float = 1.0) -> FloatArray:
    """NIS over its chi-square threshold, as a centred running median over `window_s`: a single fix's
    NIS is mostly receiver noise, so a slow pull (ratio near the margin) would break into short runs."""
    nis, dof = coasting_nis(sol, HORIZONTAL_ROWS)
    threshold = np.where(dof > 0, chi2_isf(p, np.maximum(dof, 1)), np.nan)
    ratio = pd.Series(nis / threshold)
    dt = np.diff(sol.t)
    n = round(window_s / float(np.median(dt))) if len(dt) and np.median(dt) > 0 else 1
    n = max(1, n) | 1
    return np.asarray(ratio.rolling(n, center=True, min_periods=1).median().where(ratio.notna()), dtype=float)


@dataclass(frozen=True)
class Placebo:
    """Coasts started all over the log: what GNSS-minus-reference looks like where (most likely) nobody
    attacked. A coast counts for an incident only up to where it reaches a suspected stretch."""

    starts: FloatArray
    grid: FloatArray  # horizon, s
    curves: FloatArray  # (runs, len(grid)) running maximum of the NIS-over-threshold ratio
    # every coast runs up to the same time (`calibration_coasts`): they share most of their span, and the
    # peaks of coasts that integrate the same seconds are not independent draws of the INS's clean departure
    nested: bool = False

    def envelope(
        self,
        own: tuple[float, float],
        confirmed: list[tuple[float, float]],
        margin_s: float,
        trim: float = 0.1,
        min_runs: int = 4,
        later: Sequence[tuple[float, float]] = (),
        min_clean_s: float = 0.0,
    ) -> Envelope:
        """The largest clean departure per horizon over the coasts (and the part of each) before this
        incident, away from the incidents already confirmed and from the `later` ones not judged yet;
        with fewer than `min_runs` of those, the coasts anywhere away from them, leaving out the largest
        `trim`. Beyond the longest clean horizon the last value holds. A coast counts when clean for more
        than `min_clean_s`.

        A later incident may be the attack: a coast that runs into it measures the attack, not the log's
        clean behaviour (a simulated meaconer 300 m off made the envelope 800 times the model's, and the
        attack then stayed "within" it). An earlier incident that was not confirmed was judged the log's
        own behaviour (a receiver glitch), so coasts through it count."""
        if not len(self.starts):
            return Envelope(np.array([]), np.array([]), 0)
        usable = self._clean(own, margin_s)
        for span in (*confirmed, *later):
            usable = np.minimum(usable, self._clean(span, margin_s))
        # the stretch before the incident is the baseline a later attack or its end cannot spoil
        earlier = np.minimum(usable, np.clip(own[0] - self.starts, 0.0, None))
        if (earlier > min_clean_s).sum() >= min_runs:
            usable = earlier
        usable = np.where(usable > min_clean_s, usable, 0.0)
        runs = np.flatnonzero(usable > 0)
        if not len(runs):
            return Envelope(np.array([]), np.array([]), 0)
        # a coast that starts inside a suspected stretch has no clean part, not even its first epoch
        valid = (self.grid[None, :] <= usable[:, None]) & (usable[:, None] > 0)
        peaks = np.where(valid, self.curves, -np.inf).max(axis=1)
        drop = runs[np.argsort(peaks[runs])[::-1][: int(trim * len(runs))]]
        counted = np.zeros(len(self.starts), dtype=bool)
        counted[runs] = True
        counted[drop] = False
        if not counted.any():
            return Envelope(np.array([]), np.array([]), 0)
        # each curve is a running maximum: a coast cut short where it reached a suspected stretch would have
        # departed at least as far at every longer horizon. Dropping it there left the long horizons to the
        # few coasts that ran their full length (on the husky bag with an attack from 157 s, two quiet ones:
        # a clean wander of 2x the model at 50 s was then a departure, where the same log's coast from 30 s
        # had shown 6x by 10 s)
        held = np.where(valid, self.curves, peaks[:, None])
        kappa = np.where(counted[:, None], held, -np.inf).max(axis=0)
        # a coast that stayed within the model peaks at the floor (1): it says the coast stayed within, not how
        # far below, so floored peaks tell nothing of the spread (the real husky bag cut at 191.5 s for 180 s:
        # three clean coasts all within the model made a spread of 0, a bound of 3.8, and a glrt alarm at
        # 4.6 times near the stretch's end was SPOOFING)
        above = np.log(peaks[counted][peaks[counted] > 1.0])
        spread = float(np.std(above, ddof=1)) if len(above) >= 2 else None
        independent = _independent(self.starts[counted], usable[counted]) if self.nested else None
        return Envelope(
            self.grid, np.maximum(kappa, 1.0), int(counted.sum()), peak_log_sd=spread, independent=independent
        )

    def _clean(self, span: tuple[float, float], margin_s: float) -> FloatArray:
        """How long each coast runs before it reaches `span` (its full horizon if it never does, 0 if it
        starts inside it)."""
        H = float(self.grid[-1])
        a, b = span[0] - margin_s, span[1] + margin_s
        inside = (self.starts >= a) & (self.starts <= b)
        before = self.starts < a
        return np.where(inside, 0.0, np.where(before, np.minimum(H, a - self.starts), H))


def _independent(starts: FloatArray, horizons: FloatArray) -> float:
    """How many independent coasts overlapping ones are worth: the time they cover together over their mean
    horizon, between 1 and their number. Calibration coasts every 5 s, each run up to the same incident,
    cover 40 s with a mean horizon of 22 s: under 2, not 8 (counted as 8, they made a bound of 2.5 times
    their envelope, and the real log171 copter cut at 146.8 s for 75 s was SPOOFING at 4.4 times through its
    manoeuvres just before its crash, where the same log cut a few seconds earlier or later raised nothing)."""
    order = np.argsort(starts)
    a, b = starts[order], (starts + horizons)[order]
    covered, reach = 0.0, -np.inf
    for lo, hi in zip(a, b, strict=True):
        if hi > reach:
            covered += hi - max(lo, reach)
            reach = hi
    mean = float(np.mean(horizons))
    return float(np.clip(covered / mean, 1.0, len(starts))) if mean > 0 else 1.0


def shocks_of(nav: Navigation) -> list[Shock]:
    """The shocks every IMU of the navigation's table read (`spooflens.pipeline.explanations`)."""
    return inertial_shocks(nav.inputs.table, ExplanationOptions())


def reference_lost_at(shocks: Sequence[Shock], t_from: float) -> float:
    """Where a coast from `t_from` loses its reference: the start of the first shock not over by then (inf:
    none). An INS integrating a tumble or an impact has lost its attitude, and what GNSS says against it
    from there is the crash's, not the sky's: no coast is judged beyond, clean or not."""
    return min((sh.start_s for sh in shocks if sh.end_s >= t_from), default=np.inf)


def placebo_coasts(nav: Navigation, opts: CoastingOptions, shocks: Sequence[Shock] = ()) -> Placebo:
    t = nav.solution.t
    H = float(np.clip(0.5 * (t[-1] - t[0]), *opts.placebo_horizon_s))
    starts = np.arange(t[0] + opts.settle_s, t[-1] - H, min(H / 2.0, 30.0))
    if len(starts) > opts.placebo_runs:
        starts = starts[np.linspace(0, len(starts) - 1, opts.placebo_runs).round().astype(int)]
    return _coasted(nav, opts, shocks, starts, starts + H, np.arange(0.0, H + 1.0, 1.0))


def _coasted(
    nav: Navigation,
    opts: CoastingOptions,
    shocks: Sequence[Shock],
    starts: FloatArray,
    ends: FloatArray,
    grid: FloatArray,
    nested: bool = False,
) -> Placebo:
    """The coasts from `starts` to `ends`, each as the running maximum of its ratio on `grid`."""
    kept, curves = [], []
    for s, e in zip(starts, ends, strict=True):
        sol = coast(nav, float(s), float(e))
        if sol is None:  # no fix in the horizon: a clean coast needs GNSS to be compared with
            continue
        r = _ratio(sol, opts.p_disagree)
        fine = np.isfinite(r) & (sol.t < reference_lost_at(shocks, float(s)))
        if fine.sum() < 3:
            continue
        running = np.maximum.accumulate(np.where(fine, r, 0.0))
        kept.append(float(s))
        curves.append(np.interp(grid, sol.t - s, running))
    return Placebo(np.array(kept), grid, np.array(curves).reshape(len(curves), len(grid)), nested)


def calibration_coasts(nav: Navigation, opts: CoastingOptions, until_s: float, shocks: Sequence[Shock] = ()) -> Placebo:
    """Coasts every `calibration_step_s` over the placebo horizon before `until_s` (an incident's coast start),
    from the reference's convergence on, each run up to `until_s`: what this log's INS departs by itself where
    no placebo coast is clean before that incident (a short log, or an alarm soon after the start). Bounded
    by that horizon, a late incident in a long log costs a dozen short coasts, not one per 5 s of the log."""
    horizon = opts.placebo_horizon_s[1]
    first = max(float(nav.solution.t[0]) + opts.converge_s, until_s - opts.margin_s - horizon)
    starts = np.arange(first, until_s - opts.margin_s - opts.calibrating_s, opts.calibration_step_s)
    grid = np.arange(0.0, max(min(until_s - first, horizon), 0.0) + 1.0, 1.0)
    return _coasted(nav, opts, shocks, starts, np.minimum(starts + horizon, until_s), grid, nested=True)


def clean_envelope(nav: Navigation, left_out: list[tuple[float, float]]) -> Envelope:
    """How far GNSS departs from INS coasts started all over a log, the stretches `left_out` (its
    incidents) avoided: what a vehicle's clean log says about its INS and receiver (a baseline's)."""
    opts = CoastingOptions()
    end = float(nav.solution.t[-1]) + 1e9  # no incident of its own: every coast is before it
    return placebo_coasts(nav, opts, shocks_of(nav)).envelope((end, end), left_out, opts.margin_s, opts.placebo_trim)


def capped(envelope: Envelope, limit: FloatArray | None) -> Envelope:
    """The envelope at most `limit` per second of horizon (a baseline's allowance: a log attacked
    throughout has no clean coasts of its own to tell its envelope)."""
    if limit is None or not len(limit):
        return envelope
    grid = np.arange(len(limit), dtype=float)
    if not envelope.runs:
        return Envelope(grid, np.maximum(limit, 1.0), 0, from_baseline=True)
    allowed = np.interp(envelope.horizon_s, grid, limit)
    kappa = np.maximum(np.minimum(envelope.kappa, allowed), 1.0)
    return replace(envelope, kappa=kappa, from_baseline=True)


def coasting_check(
    nav: Navigation,
    onset_s: float,
    envelope: Envelope,
    deadline_s: float | None = None,
    opts: CoastingOptions | None = None,
    base: NavSolution | None = None,
    shocks: Sequence[Shock] = (),
) -> CoastingCheck:
    """Coast from `onset_s` and judge GNSS against the reference: confirmed when a sustained departure
    begins by `deadline_s` (default `confirm_window_s` after the onset); then when it ends. Nothing is
    judged from the first of `shocks` the coast meets on (`reference_lost_at`)."""
    opts = opts or CoastingOptions()
    t_ex = onset_s - opts.margin_s
    lost = reference_lost_at(shocks, t_ex)
    deadline = deadline_s if deadline_s is not None else onset_s + opts.confirm_window_s
    # first a coast just past the deadline: most anomalies are not confirmed, and a coast to the end of a
    # day-long log for each of them made the check quadratic in the log's length (21 anomalies of a 24 h
    # voyage: 185 s). Only a departure, or a disagreement still running where that coast ends, needs the
    # coast to the end; the decision is the one the long coast gives (the same filter over the same span)
    # (no fix in the first look, a GNSS outage: straight to the coast to the end)
    sol = coast(nav, t_ex, deadline + opts.first_look_s, base=base)
    last = (base if base is not None else nav.solution).t[-1]
    if sol is not None:
        t, ratio, kappa, offset, disagree, departure, open_at_end = _departure(
            sol, t_ex, deadline, envelope, opts, lost
        )
    if sol is None or departure is not None or (open_at_end and t[-1] < last):
        sol = coast(nav, t_ex, base=base)
        if sol is None:  # no fix from here to the end: nothing GNSS said can depart from the reference
            none = np.array([])
            return CoastingCheck(t_ex, none, none, none, none, False, None, None, None, None, np.zeros((0, 2)))
        t, ratio, kappa, offset, disagree, departure, _ = _departure(sol, t_ex, deadline, envelope, opts, lost)
    met = lost if lost <= t[-1] else None
    if departure is None:
        return CoastingCheck(t_ex, t, ratio, kappa, offset, False, None, None, None, None, sol.nu[:, :2], met)
    end = end_interval = None
    # the reference can tell agreement only while its own uncertainty is well below the departure seen so
    # far beyond that uncertainty; a consumer INS coasting for minutes cannot
    sigma_ref = np.sqrt(np.maximum(sol.S_all[:, 0, 0], sol.S_all[:, 1, 1]))
    # the departure seen so far beyond what the reference's own drift explains
    beyond = np.clip(np.nan_to_num(offset) - 3.0 * sigma_ref, 0.0, None)
    peak = np.maximum.accumulate(np.where(np.arange(len(t)) >= departure, beyond, 0.0))
    # judged against the departure reached up to `agree_s` later: a growing one keeps ahead of the drift
    ahead = peak[np.minimum(np.searchsorted(t, t + opts.agree_s), len(t) - 1)]
    conclusive = (sigma_ref < ahead / opts.resolution) & (t < lost)
    # GNSS agrees again when it is back where the reference is (within its uncertainty, or the metres a
    # receiver wanders), not merely under a clean envelope that a consumer INS's coasts made wide
    back = np.nan_to_num(offset, nan=np.inf) <= np.maximum(opts.min_departure_m, 3.0 * sigma_ref)
    agree = ~disagree & np.isfinite(ratio) & conclusive & back
    lost_at = next((i for i in range(departure, len(t)) if not conclusive[i]), None)
    for a, b in _runs(agree):
        if a <= departure:
            continue
        if lost_at is not None and a > lost_at:
            break
        if b - a + 1 >= opts.min_agree_epochs and t[b] - t[a] >= opts.agree_s:
            end = float(t[a])
            last_bad = np.flatnonzero(disagree[:a])
            end_interval = (float(t[last_bad[-1]]) if len(last_bad) else float(t[a]), end)
            break
    inconclusive_from = float(t[lost_at]) if end is None and lost_at is not None else None
    return CoastingCheck(
        t_ex,
        t,
        ratio,
        kappa,
        offset,
        True,
        float(t[departure]),
        end,
        end_interval,
        inconclusive_from,
        sol.nu[:, :2],
        met,
    )


def _departure(
    sol: NavSolution, t_ex: float, deadline: float, envelope: Envelope, opts: CoastingOptions, lost: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, NDArray[np.bool_], int | None, bool]:
    """(t, ratio, kappa, offset, disagree, departure epoch or None, whether a disagreement that began by
    the deadline is still running at the coast's last epoch) of a coast from t_ex that lost its reference
    at `lost`."""
    t = sol.t
    ratio = _ratio(sol, opts.p_disagree)
    kappa = envelope.at(t - t_ex)
    offset = np.hypot(sol.nu[:, 0], sol.nu[:, 1])
    velocity_off = np.hypot(sol.nu[:, 3], sol.nu[:, 4])
    young = t - t_ex <= opts.young_s
    away = (np.nan_to_num(offset) > opts.min_departure_m) | (
        young & (np.nan_to_num(velocity_off) > opts.min_departure_mps)
    )
    margin = envelope.margin(opts)
    disagree = (np.nan_to_num(ratio) > margin * kappa) & away & (t < lost)
    departure, open_at_end = None, False
    for a, b in _runs(disagree):
        if t[a] > deadline:
            break
        if b - a + 1 >= opts.min_disagree_epochs and t[b] - t[a] >= opts.min_disagree_s:
            departure = int(a)
            break
        open_at_end = b == len(t) - 1
    return t, ratio, kappa, offset, disagree, departure, open_at_end


def _reconstructed_track(nav: Navigation, t_from: float, t_to: float | None, velocity_honest: bool) -> Track:
    """The smoothed trajectory with GNSS (positions, and velocity unless it stayed honest) left out over
    the incident, `continued` from the main solution's last epoch before it: a smoothed estimate depends
    only on its filtered state and the data after it, so the track over the incident is a whole-log run's
    at a fraction of the memory (the per-epoch matrices the smoother keeps are 0.5 GB per hour of 10 Hz
    GNSS)."""
    opts = nav.options(  # only smoothed: no comparison with GNSS kept (S_all)
        exclude_after_s=t_from,
        exclude_until_s=t_to,
        exclude_velocity_too=not velocity_honest,
        record=SMOOTHER_NEEDS,
        compare=False,
    )
    sm = smooth(continued(nav, nav.solution, t_from, opts), variances=False)
    name = (
        "reconstructed (INS + GNSS velocity, GNSS positions excluded)"
        if velocity_honest
        else "reconstructed (INS alone, GNSS excluded)"
    )
    if nav.solution.options.odometry is not None:
        name = name.replace("INS", "INS + odometry", 1)
    return Track(name, sm.track_t, np.degrees(sm.track_llh[:, 0]), np.degrees(sm.track_llh[:, 1]), sm.track_llh[:, 2])


def reconstruct(ctx: AnalysisContext, results: Sequence[DetectorResult], verdict: Verdict) -> Verdict:
    """Confirm, extend and reconstruct every incident that has inertial evidence: the verdict anew, with the
    tracks reconstructed with GNSS left out and each coast's facts (nothing in `results` is changed).

    Where the navigation ran between the IMU's gaps (`navigation_parts`), each incident is judged on the
    stretch its coast starts in, never coasted across a gap: GNSS that had not agreed again by the end of
    that stretch is said to, and the incident ends there (the log goes on, unnavigated); an incident
    outside every stretch stays as the alarms made it."""
    navigated = any(r.name == NAVIGATION and r.ran for r in results)
    if not navigated or not any(Evidence.INERTIAL in i.evidence for i in verdict.incidents):
        return verdict
    parts = navigation_parts(ctx)
    if parts[0] is ctx:
        return _on_navigation(ctx, results, verdict, None)
    tf = ctx.table.fixes["t_s"].to_numpy(dtype=float)
    log_end = float(np.nanmax(tf)) if len(tf) else -np.inf
    rest, judged = list(verdict.incidents), []
    for part in parts:
        a, b = part.span_s or (np.nan, np.nan)
        mine = tuple(i for i in rest if a <= _coast_start(i) <= b)
        rest = [i for i in rest if i not in mine]
        if any(Evidence.INERTIAL in i.evidence for i in mine):
            judged.append(_on_navigation(part, results, replace(verdict, incidents=mine), log_end))
        else:
            rest += mine
    incidents = sorted([*rest, *(i for v in judged for i in v.incidents)], key=lambda i: i.start_s)
    return replace(
        verdict,
        spoofed=any(i.is_spoofing for i in incidents),
        incidents=tuple(incidents),
        reconstructed=tuple(tr for v in judged for tr in v.reconstructed),
        coasting_checks=tuple(c for v in judged for c in v.coasting_checks),
    )


def _on_navigation(
    ctx: AnalysisContext, results: Sequence[DetectorResult], verdict: Verdict, log_end_s: float | None
) -> Verdict:
    """`reconstruct` on the navigation of `ctx`: the whole log's, or one stretch between the IMU's gaps of a
    log whose fixes go on to `log_end_s`."""
    try:
        nav = navigation_of(ctx)
    except SpooflensError:
        return verdict
    t_last = float(nav.solution.t[-1])
    # the IMU stopped before the log's fixes did: nothing after this stretch was coasted
    stopped = log_end_s is not None and t_last < log_end_s
    opts = CoastingOptions()
    incidents: list[Incident] = []
    checks: list[tuple[Incident, CoastingCheck]] = []
    cleared: set[int] = set()  # ids of the incidents in `checks` whose coast cleared them (`_cleared`)
    shocks = shocks_of(nav)
    placebo = placebo_coasts(nav, opts, shocks)
    cap = coast_envelope_limit(ctx.options.baseline, nav.inputs.receiver_id, nav.inputs.imu_id)
    limit = cap[0] if cap is not None else None
    envelopes = []
    base: NavSolution | None = None  # the filter with the incidents confirmed so far left out
    current_check: CoastingCheck | None = None  # the coast that confirmed the last incident
    ordered = sorted(verdict.incidents, key=lambda i: i.start_s)
    for n, inc in enumerate(ordered):
        current = incidents[-1] if incidents and incidents[-1].is_spoofing else None
        interference_only = bool(inc.evidence) and all(e in NOT_SPOOFING for e in inc.evidence)
        # a log off its vehicle's baseline stays an incident apart (`APART`): absorbed into an earlier
        # incident it begins inside, it would end where that one ends, not with the log
        if current is not None and inc.start_s <= current.end_s and not (interference_only or inc.kept_apart):
            # inside a confirmed incident the filter state has followed the spoofed fixes, so no coast can
            # start there; its alarms belong to the incident, and inside the stretch where the reference
            # could no longer tell, they are how the receiver's return to the real sky shows
            incidents[-1] = _absorb(current, inc, current_check, opts.min_departure_m)
            continue
        if Evidence.INERTIAL not in inc.evidence:
            incidents.append(inc)
            continue
        confirmed_spans = [_span(i, opts) for i in incidents if i.is_spoofing]
        unjudged = [_span(i, opts) for i in ordered[n + 1 :]]

        envelope_of = partial(_envelope, nav, shocks, placebo, confirmed_spans, unjudged, limit, opts)
        envelope = envelope_of(inc)
        # a departure from where the next inertial incident's coast begins is that incident's, not this one's
        later = [_coast_start(i) - opts.margin_s for i in ordered[n + 1 :] if Evidence.INERTIAL in i.evidence]
        check, young = _judge(nav, inc, envelope, later, opts, base, shocks)
        if not check.confirmed or young:
            # alarms of an unrelated glitch before the attack merge into its incident and start its coast
            # too early (a consumer INS coasted for a minute cannot see a 300 m jump); coast again from
            # each later burst of inertial alarms, the first confirmed departure splitting the incident; the
            # alarms before it are then judged the log's own, so the clean coasts through them count
            split = next(
                (
                    (before, after, later_check, after_envelope)
                    for before, after in later_onsets(results, inc)[: opts.max_later_coasts]
                    for after_envelope in (envelope_of(after),)
                    for later_check, later_young in (_judge(nav, after, after_envelope, later, opts, base, shocks),)
                    if later_check.confirmed and not later_young
                ),
                None,
            )
            if split is None:
                checks.append((inc, check))
                envelopes.append(envelope)
                if _cleared(inc, check, young):
                    cleared.add(id(inc))
                else:
                    incidents.append(_not_confirmed(inc, check, young, envelope, opts))
                continue
            before, inc, later_check, after_envelope = split
            checks += [(before, check), (inc, later_check)]
            envelopes += [envelope, after_envelope]
            if _cleared(before, check, young):
                cleared.add(id(before))
            else:
                incidents.append(_not_confirmed(before, check, young, envelope, opts))
            check, envelope = later_check, after_envelope
        else:
            checks.append((inc, check))
            envelopes.append(envelope)
        current_check = check
        # the coasting comparison says when GNSS agreed again; alarms after that are the closed-loop
        # filter's recovery from the spoofed track, not more attack
        end = check.end_s if check.end_s is not None else t_last
        sel = (check.t >= check.excluded_from_s) & (check.t <= end)
        offsets = check.offset_m[sel]
        if check.end_s is not None:
            interval, method = check.end_interval_s, "GNSS agreed again with the coasted INS reference"
        elif check.inconclusive_from_s is not None:
            interval = (check.inconclusive_from_s, t_last)
            method = (
                f"GNSS still departed from the coasted INS reference at {check.inconclusive_from_s:.1f} s, when the "
                "reference became too uncertain to tell an end: the end lies in the interval"
            )
        else:
            interval, method = (t_last, t_last), "GNSS never agreed again with the coasted INS reference"
        if check.end_s is None and stopped:
            method += f" before the IMU stopped at {t_last:.1f} s; nothing after was navigated with this stretch"
        if not envelope.runs:
            method += f"; {NO_CLEAN_COASTS}"
        onset, onset_interval = _onset_before(results, inc, check.departure_s)
        # the departure itself is the inertial evidence: whatever else alarmed while it lasted agrees
        departure_span = (Evidence.INERTIAL, _coast_start(inc), end)
        incidents.append(
            replace(
                inc,
                onset_s=onset,
                onset_interval_s=onset_interval,
                end_s=end,
                end_interval_s=interval,
                ongoing_at_end=check.end_s is None and not stopped,
                end_method=method,
                offset_peak_m=float(np.nanmax(offsets)) if len(offsets) else None,
                offset_end_m=float(offsets[-1]) if len(offsets) else None,
            ).with_spans((*inc.spans, departure_span))
        )
        # later coasts start from a filter that left this incident out, not from one that followed the
        # spoofed fixes and then had to recover from their jump back; made only when a later inertial
        # incident will coast (one inside this incident is absorbed, none follows one lasting to the end)
        if any(Evidence.INERTIAL in i.evidence and i.start_s > end for i in ordered[n + 1 :]):
            windows = tuple(
                (_coast_start(i) - opts.margin_s, None if i.ongoing_at_end else i.end_s)
                for i in incidents
                if i.is_spoofing
            )
            # what later coasts start from: the states and covariances after each update (no other matrices)
            base = run_prepared(nav.inputs, nav.options(exclude_windows=windows, record=("P_upd",)), nav.start)
    incidents = _merge_overlapping(incidents)
    tracks = []
    for inc in (i for i in incidents if i.is_spoofing):
        onset = inc.onset_interval_s[0] if inc.onset_interval_s else inc.onset_s
        t_to = None if inc.ongoing_at_end else inc.end_s
        velocity_honest = any(
            r.name == GNSS_CONSISTENCY and any(onset <= a.end_s and a.start_s <= inc.end_s for a in r.alarms)
            for r in results
        )
        tracks.append(_reconstructed_track(nav, onset - opts.margin_s, t_to, velocity_honest))
    coasting_checks = tuple(
        {
            "incident_onset_s": inc.onset_s,
            "incident_start_s": inc.start_s,
            "incident_end_s": inc.end_s,
            "confirmed": c.confirmed,
            "departure_s": c.departure_s,
            "end_s": c.end_s,
            "clean_coasts": e.runs,
            "independent_coasts": e.samples if e.runs else None,
            "clean_envelope_max_ratio": float(e.kappa.max()) if e.runs else None,
            "peak_ratio_over_envelope": c.peak_over_envelope,
            # how far GNSS went from the coasted INS between its departure and its return
            "offset_peak_m": _offset_peak(c),
            # an inertial alarm the coast cleared is no incident: this record is where it shows
            "cleared": id(inc) in cleared,
        }
        for (inc, c), e in zip(checks, envelopes, strict=True)
    )
    return replace(
        verdict,
        spoofed=any(i.is_spoofing for i in incidents),
        incidents=tuple(incidents),
        reconstructed=tuple(tracks),
        coasting_checks=coasting_checks,
    )


def _jumps_back(
    check: CoastingCheck | None,
    inc: Incident,
    min_jump_m: float,
    window_s: float = 10.0,
    settle_s: float = 3.0,
    share: float = 0.25,
) -> bool:
    """Whether GNSS jumped back toward the coasted reference across the transient `inc` by a good part of
    its distance from it: a receiver returning to the real sky drops the spoofer's offset within seconds,
    while the reference's own drift is smooth (extrapolated linearly from the `window_s` before) and a
    glitch on a continuing attack moves GNSS by metres. The jump's part toward the reference must reach
    `share` of the distance before it and `min_jump_m` (the departure a confirmation needs): a jump away
    from the reference is no return but more of a departure (a spoofer's new step, or a new attack)."""
    if check is None or check.offset_en_m is None:
        return False
    t, d = check.t, check.offset_en_m
    pre = (t >= inc.start_s - window_s) & (t < inc.start_s) & np.isfinite(d).all(axis=1)
    post = (t >= inc.start_s + settle_s) & (t <= inc.start_s + settle_s + window_s) & np.isfinite(d).all(axis=1)
    if pre.sum() < 3 or not post.any():
        return False
    coef = np.polyfit(t[pre], d[pre], 1)  # (2, 2): slope, intercept per axis
    drift = np.outer(t[post], coef[0]) + coef[1]
    jump = np.median(d[post] - drift, axis=0)
    distance = float(np.median(np.hypot(d[pre, 0], d[pre, 1])))
    away = np.median(d[pre], axis=0)  # where GNSS lay from the reference before the transient
    norm = float(np.hypot(*away))
    if norm == 0.0:
        return False
    toward = -float(jump @ away) / norm
    return toward >= max(share * distance, min_jump_m)


def _absorb(current: Incident, inc: Incident, check: CoastingCheck | None, min_jump_m: float) -> Incident:
    """`inc` (alarms inside a confirmed incident) merged into it; when it starts where the reference could
    no longer tell whether GNSS agreed, and GNSS comes back toward the reference across it, it marks the
    end: a spoofer switching off makes the receiver lose and re-acquire the real sky, which the detectors
    see as a new transient."""
    merged = replace(
        current,
        detectors=tuple(sorted({*current.detectors, *inc.detectors})),
        receivers=tuple(sorted({*current.receivers, *inc.receivers})),
        satellites=tuple(sorted({*current.satellites, *inc.satellites})),
    ).with_spans((*current.spans, *inc.spans))
    window = current.end_interval_s
    # the return shows in evidence that does not depend on the filter that followed the spoofed fixes
    independent_of_filter = any(e != Evidence.INERTIAL for e in inc.evidence)
    if (
        current.ongoing_at_end
        and independent_of_filter
        and window is not None
        and window[0] < window[1]
        and window[0] <= inc.start_s
        and _jumps_back(check, inc, min_jump_m)
    ):
        before = inc.onset_s if inc.onset_s < inc.start_s else inc.start_s - 2.0
        return replace(
            merged,
            end_s=inc.start_s,
            end_interval_s=(max(window[0], before), inc.start_s),
            ongoing_at_end=False,
            end_method=f"the reference could no longer tell after {window[0]:.1f} s; the transient at "
            f"{inc.start_s:.1f} s ({', '.join(inc.detectors)}) is the receiver returning to the real signals",
        )
    return merged


def _merge_overlapping(incidents: list[Incident]) -> list[Incident]:
    """Incidents whose extended spans overlap are one incident."""
    out: list[Incident] = []
    for inc in sorted(incidents, key=lambda i: i.start_s):
        if out and inc.start_s <= out[-1].end_s and out[-1].is_spoofing and inc.is_spoofing:
            prev = out[-1]
            out[-1] = replace(
                prev,
                end_s=max(prev.end_s, inc.end_s),
                end_interval_s=inc.end_interval_s if inc.end_s >= prev.end_s else prev.end_interval_s,
                ongoing_at_end=prev.ongoing_at_end or inc.ongoing_at_end,
                detectors=tuple(sorted({*prev.detectors, *inc.detectors})),
                receivers=tuple(sorted({*prev.receivers, *inc.receivers})),
                satellites=tuple(sorted({*prev.satellites, *inc.satellites})),
            ).with_spans((*prev.spans, *inc.spans))
        else:
            out.append(inc)
    return out


def _coast_start(inc: Incident) -> float:
    return min(inc.onset_s, inc.onset_interval_s[0] if inc.onset_interval_s else inc.onset_s, inc.start_s)


def _envelope(
    nav: Navigation,
    shocks: Sequence[Shock],
    placebo: Placebo,
    confirmed: list[tuple[float, float]],
    unjudged: list[tuple[float, float]],
    limit: FloatArray | None,
    opts: CoastingOptions,
    inc: Incident,
) -> Envelope:
    """The clean envelope `inc` is judged against (`Placebo.envelope`, capped by a baseline's `limit`); with no
    clean placebo coast and no baseline, the envelope of the calibration coasts before it (`calibration_coasts`)."""
    span = _span(inc, opts)
    envelope = placebo.envelope(span, confirmed, opts.margin_s, opts.placebo_trim, later=unjudged)
    if not envelope.runs and limit is None:
        early = calibration_coasts(nav, opts, _coast_start(inc), shocks)
        envelope = early.envelope(span, confirmed, opts.margin_s, opts.placebo_trim, min_clean_s=opts.calibrating_s)
    return capped(envelope, limit)


def _judge(
    nav: Navigation,
    inc: Incident,
    envelope: Envelope,
    later: list[float],
    opts: CoastingOptions,
    base: NavSolution | None,
    shocks: Sequence[Shock],
) -> tuple[CoastingCheck, str]:
    """The coasting check of `inc` from its coast start, and why the reference could not tell yet where the
    coast leaves GNSS out (`margin_s` before that: still converging from the log's start or re-converging
    after a GNSS outage; "" when it could); `later`: where the next inertial incidents' coasts begin (a
    departure from there is theirs)."""
    start = _coast_start(inc)
    # beyond its longest clean horizon an envelope holds its last value; a short log's calibration coasts
    # (`calibration_coasts`) measure a few seconds, which must not shorten the confirmation window
    reach = start + max(float(envelope.horizon_s[-1]) if envelope.runs else 0.0, opts.confirm_window_s)
    deadline = min([inc.end_s + opts.confirm_window_s, reach, *later])
    check = coasting_check(nav, start, envelope, deadline, opts, base, shocks)
    t_first = float(nav.solution.t[0])
    if check.excluded_from_s < t_first + opts.converge_s:
        return check, f"the INS reference had run only {start - t_first:.0f} s and was still converging"
    if not envelope.runs and not envelope.from_baseline and not nav.learned.learned:
        return check, UNCALIBRATED
    back = aided_again_s(base if base is not None else nav.solution, check.excluded_from_s, opts.outage_s)
    # the INS unaided for longer than an outage where the coast begins, or back for less than its convergence
    t_ex = check.excluded_from_s
    if back is not None and t_ex - back[0] > opts.outage_s and t_ex < back[1] + opts.converge_s:
        # the INS coasted through a GNSS outage (a tunnel, a jammer that cost the fix): what the returning
        # fixes say against it is its drift over the outage until the filter has re-converged, not a departure
        return check, (
            f"GNSS came back at {back[1]:.1f} s after {back[1] - back[0]:.0f} s without a fix and the INS reference "
            f"was still re-converging from its drift over the outage"
        )
    return check, ""


def aided_again_s(sol: NavSolution, t_ex: float, outage_s: float) -> tuple[float, float] | None:
    """(last fix before, first fix after) of the last GNSS outage longer than `outage_s` up to the first fix
    after `t_ex` (a coast that begins inside the outage began where the INS was last aided): a gap between
    the receiver's fixes, not a stretch the analysis left out (whose fixes are there); None if none."""
    k = int(np.searchsorted(sol.t, t_ex, side="right")) + 1
    t = sol.t[:k][np.isfinite(sol.z[:k, :3]).any(axis=1)]
    gaps = np.flatnonzero(np.diff(t) > outage_s)
    return (float(t[gaps[-1]]), float(t[gaps[-1] + 1])) if len(gaps) else None


def _cleared(inc: Incident, check: CoastingCheck, young: str) -> bool:
    """Whether `inc` is an inertial alarm alone whose coast stayed within this log's clean departures all the
    way (never above the envelope, nor cut short by a shock, from a reference that could tell): the
    filter's own test alarmed where GNSS agreed with the coasted INS, which is no anomaly of GNSS. It stays
    in the coasting checks (`cleared`), not among the anomalies."""
    if young or check.lost_s is not None or set(inc.evidence) != {Evidence.INERTIAL}:
        return False
    peak = check.peak_over_envelope
    return peak is not None and peak <= 1.0


def _not_confirmed(
    inc: Incident, check: CoastingCheck, young: str, envelope: Envelope, opts: CoastingOptions
) -> Incident:
    """`inc` with its inertial evidence dropped: the coast did not confirm it (`young`: why the reference
    could not tell yet, if that was why)."""
    peak = check.peak_over_envelope or 0.0
    if young:
        why = f"inertial alarm not confirmed: {young}"
    elif peak > 1.0 and envelope.runs:
        # above what the clean coasts showed: say how far, and why that confirmed nothing
        margin = envelope.margin(opts)
        coasts = f"{envelope.runs} clean coast(s)"
        if envelope.independent is not None and envelope.independent < envelope.runs:
            coasts += f", nested: worth {envelope.independent:.1f} independent ones,"
        why = (
            f"inertial alarm not confirmed: GNSS departed up to {peak:.1f} times this log's own clean departures, "
            + (
                f"within the {margin:.1f} times that {coasts} allow (the next clean coast of a "
                "real INS may depart that far)"
                if peak <= margin
                else f"beyond the {margin:.1f} times that {coasts} allow only briefly, by less "
                f"than {opts.min_departure_m:g} m or after the confirmation window"
            )
        )
    else:
        why = (
            "inertial alarm not confirmed: GNSS stayed within the coasted INS reference's uncertainty and this "
            "log's own clean departures (a receiver glitch, not a sustained departure)"
        )
    if check.lost_s is not None:
        why += f"; judged up to {check.lost_s:.1f} s, where the IMU read a shock and the INS lost its attitude"
    if not envelope.runs and young != UNCALIBRATED:
        why += f"; {NO_CLEAN_COASTS}"
    return replace(
        inc,
        end_method=why,
        offset_peak_m=float(np.nanmax(check.offset_m)) if len(check.offset_m) else None,
    ).with_spans(tuple(sp for sp in inc.spans if sp[0] != Evidence.INERTIAL))


def later_onsets(results: Sequence[DetectorResult], inc: Incident) -> list[tuple[Incident, Incident]]:
    """Each way to split `inc` where a burst of alarms begins more than `CORROBORATION_S` after the alarm
    before it and holds inertial evidence: (the alarms before, the alarms from there on) as incidents, in
    time order. The incident's alarms are recovered from `results` (an incident holds every counted alarm
    that starts inside it)."""
    alarms = sorted(
        (
            (a, r)
            for r in results
            if r.is_detector and r.ran and not r.advisory and r.name in inc.detectors
            for a in r.alarms
            if inc.start_s <= a.start_s <= inc.end_s
        ),
        key=lambda x: x[0].start_s,
    )
    starts = np.array([a.start_s for a, _ in alarms])
    out = []
    for k in np.flatnonzero(np.diff(starts) > CORROBORATION_S) + 1:
        before, after = alarms[:k], alarms[k:]
        if any(r.evidence == Evidence.INERTIAL for _, r in after):
            out.append((incident_of(before), incident_of(after)))
    return out


def _span(inc: Incident, opts: CoastingOptions) -> tuple[float, float]:
    return (_coast_start(inc) - opts.margin_s, inc.end_s + opts.agree_s)


def _onset_before(
    results: Sequence[DetectorResult], inc: Incident, departure_s: float | None
) -> tuple[float, tuple[float, float] | None]:
    """The incident's onset: of the counted detectors' onset estimates in it that precede the confirmed
    departure, the latest (an estimate with an interval first). Alarms merged into an incident from a
    glitch just before the attack carry earlier onsets that the departure does not support."""
    if departure_s is None:
        return inc.onset_s, inc.onset_interval_s
    found = [
        (a.onset_s, a.onset_interval_s)
        for r in results
        if r.is_detector and r.ran and not r.advisory and r.name in inc.detectors
        for a in r.alarms
        if a.onset_s is not None
        and a.onset_s <= departure_s + 1.0
        and a.end_s >= inc.start_s
        and a.start_s <= inc.end_s
    ]
    with_interval = [f for f in found if f[1] is not None]
    pool = with_interval or found
    if not pool:
        return inc.onset_s, inc.onset_interval_s
    onset = float(max(pool, key=lambda f: f[0])[0])
    # the interval: what every estimate within the corroboration window before it says (its own model's
    # interval alone excludes the truth when the errors are not white or the attack is neither a ramp nor
    # a step; the detectors that agree bracket it), and at the latest the confirmed departure, which the
    # attack must precede (a slow receiver error drifting the same way can pull every estimate early)
    near = [f for f in found if f[0] >= onset - CORROBORATION_S]
    lows = [f[1][0] if f[1] is not None else f[0] for f in near]
    highs = [f[1][1] if f[1] is not None else f[0] for f in near]
    return onset, (float(min(lows)), float(max(*highs, onset, departure_s)))
