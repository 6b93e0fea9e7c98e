"""The log's own noise: measurement and IMU noise learned from the log, never from what the receiver
says about itself.

Receivers report accuracies that are wrong (5-10x larger than the fixes' real scatter in clean flight)
and that a capture inflates exactly while the innovation grows, so the filter's measurement noise
cannot come from them. Instead the parameters of the sensors' error model are chosen by maximum
likelihood of the filter's own innovations on the quiet part of the log:

- receiver position error = white (sigma_w, horizontal and vertical) + first-order Gauss-Markov
  (sigma_b, horizontal and vertical, time constant tau);
- receiver velocity error likewise, when the log has GNSS velocity;
- wheel odometry (when present): white + Gauss-Markov (scale, skid) per vehicle axis;
- the IMU preset's noise densities scaled by one factor (the preset is the prior, the log decides).

The likelihood is the sum over epochs of nu^T S^-1 nu + log det S (the innovations' Gaussian negative
log-likelihood, twice), over a window of the log (the first `max_epochs` epochs, at least
`min_window_s` long) after the filter has settled, leaving out time ranges suspected of an attack
(`exclude`: the caller passes the incidents of a first detection pass, so the noise is kept fixed
through a suspected attack rather than learned from it) and the windows whose first-pass innovations
are the worst (`trim`), so an attack inside the window cannot inflate the noise it is judged against.
The search is coordinate-wise on a log scale (factors 3 then sqrt 3, two sweeps), each candidate one
run of the compiled filter.

With a vehicle's baseline (`NoisePrior`, from `spooflens.baseline.use.noise_prior`) the search starts
from the values the vehicle's clean logs learned and may not go above their allowance, nor feed a
Gauss-Markov error faster than it (its sigma^2 / tau: a wander held at its size would otherwise be made
quicker instead): a log attacked from its first fix to its last cannot teach the filter that the attack
is the receiver's noise.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np
from numpy.typing import NDArray

from spooflens.navigation.alignment import Alignment
from spooflens.navigation.imu_models import ImuGrade
from spooflens.navigation.loosely_coupled import (
    FILTER_SETTLE_S,
    FilterInputs,
    FilterOptions,
    GnssNoise,
    NavSolution,
    OdometryAiding,
    run_prepared,
)
from spooflens.navigation.strapdown import NavState
from spooflens.threads import in_parallel, thread_count

FloatArray = NDArray[np.float64]


PRIOR = "prior"  # how the source of a noise that was not learned begins


@dataclass(frozen=True)
class LearnOptions:
    max_epochs: int = 1500
    min_window_s: float = 300.0
    settle_s: float = FILTER_SETTLE_S
    trim_window_s: float = 20.0
    trim_fraction: float = 0.15  # the worst windows of the first pass are left out of the likelihood
    sweeps: int = 2
    max_sweeps: int = 6  # when a noise is still rising at the top of the two sweeps' reach (`_beyond_reach`)
    steps: tuple[float, ...] = (3.0, np.sqrt(3.0))
    max_block_s: float = 1.0  # tuning runs propagate in blocks up to the next fix (faster, same answer)
    min_gain: float = 2.0  # 2 NLL a sweep must gain to be worth another
    wander_grid_m: tuple[float, ...] = (0.5, 1.0, 2.0, 4.0, 8.0)
    min_scored_epochs: int = 50  # with fewer clean epochs than this, the prior stands (nothing to learn from)
    min_scored_s: float = 30.0

    def enough(self, t_fix: FloatArray) -> bool:
        """Whether fixes at these times leave the learning enough to learn from once the filter has
        settled (before anything suspected is left out): else the prior stands."""
        epochs, seconds = self.scored(t_fix)
        return epochs >= self.min_scored_epochs and seconds >= self.min_scored_s

    def scored(self, t_fix: FloatArray) -> tuple[int, float]:
        """(epochs, seconds) of fixes at these times after the filter's first `settle_s`."""
        t = np.asarray(t_fix, dtype=float)
        after = t[t >= t[0] + self.settle_s] if len(t) else t
        return len(after), float(after[-1] - after[0]) if len(after) >= 2 else 0.0


@dataclass(frozen=True)
class NoisePrior:
    """What a vehicle's clean logs say about the noise: where the search starts (parameter name ->
    value, the names of `learn_noise`'s search) and how high each parameter may go."""

    start: dict[str, float]
    upper: dict[str, float]
    source: str  # e.g. "baseline vehicle.baseline.json (4 logs)"
    # a Gauss-Markov error's size -> (its time constant, the largest size^2 / time constant): the rate its
    # driving noise feeds it, capped as the sizes are
    rates: dict[str, tuple[str, float]] = field(default_factory=dict)
    # how low each noise may go: the quietest clean log's (a log trusted more than the vehicle ever earned
    # would make a clean log's ordinary excursions alarms)
    lower: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class LearnedNoise:
    noise: GnssNoise
    odometry: OdometryAiding | None
    grade: ImuGrade  # the preset scaled by imu_scale
    imu_scale: float
    evaluations: int
    neg_log_likelihood: float
    window_s: tuple[float, float]
    excluded_s: tuple[tuple[float, float], ...]
    imu_id: str = ""  # the IMU and receiver the filter ran on
    receiver_id: str = ""
    prior: str = ""  # the baseline the search started from and stayed under, if any
    at_upper: tuple[str, ...] = ()  # parameters the log would have raised beyond the baseline's allowance

    @property
    def is_prior(self) -> bool:
        """Nothing was learned: too little clean data, the prior stands."""
        return self.noise.source.startswith(PRIOR)

    @property
    def learned(self) -> bool:
        """False when the log left too little clean data and the prior stands."""
        return not self.is_prior

    def describe(self) -> str:
        return self._describe() + (f"; {self.baseline_note()}" if self.prior else "")

    def baseline_note(self) -> str:
        """What came from the baseline, and where the log pushed against it."""
        text = f"started from the {self.prior}"
        if self.at_upper:
            text += f"; held at the allowance: {', '.join(self.at_upper)} (the log asked for more noise)"
        return text

    def _describe(self) -> str:
        n = self.noise
        if not self.learned:
            whence = "from the baseline" if self.prior else "from the fixes' scatter"
            text = (
                f"noise NOT learned: {n.source.removeprefix(PRIOR).strip(' ()')}; prior used: position white "
                f"{n.white_pos_m[0]:.2g}/{n.white_pos_m[1]:.2g} m (h/v, {whence}) + Gauss-Markov "
                f"{n.gm_pos_m[0]:.2g}/{n.gm_pos_m[1]:.2g} m, tau {n.tau_pos_s:.0f} s"
                + (" (from the baseline)" if self.prior else " (defaults)")
            )
            if n.has_velocity:
                text += (
                    f"; velocity white {n.white_vel_mps[0]:.2g}/{n.white_vel_mps[1]:.2g} m/s "
                    f"({'from the baseline' if self.prior else 'from the scatter'}) + Gauss-Markov "
                    f"{n.gm_vel_mps[0]:.2g}/{n.gm_vel_mps[1]:.2g} m/s, tau {n.tau_vel_s:.0f} s"
                    + (" (from the baseline)" if self.prior else " (defaults)")
                )
            if self.odometry is not None:
                o = self.odometry
                text += (
                    f"; odometry white {'/'.join(f'{x:.2g}' for x in o.sigma_mps)} m/s + Gauss-Markov "
                    f"{'/'.join(f'{x:.2g}' for x in o.gm_mps)} m/s (defaults)"
                )
            imu = f"{self.imu_scale:.2g} x preset {self.grade.name} (from the baseline)" if self.prior else ""
            return text + (f"; IMU noise {imu}" if imu else f"; IMU noise the preset {self.grade.name} as it is")
        text = (
            f"noise learned from the log ({self.evaluations} filter runs on {self.window_s[0]:.0f}-"
            f"{self.window_s[1]:.0f} s): position white {n.white_pos_m[0]:.2g}/{n.white_pos_m[1]:.2g} m "
            f"(h/v) + Gauss-Markov {n.gm_pos_m[0]:.2g}/{n.gm_pos_m[1]:.2g} m, tau {n.tau_pos_s:.0f} s"
        )
        if n.has_velocity:
            text += (
                f"; velocity white {n.white_vel_mps[0]:.2g}/{n.white_vel_mps[1]:.2g} m/s + Gauss-Markov "
                f"{n.gm_vel_mps[0]:.2g}/{n.gm_vel_mps[1]:.2g} m/s, tau {n.tau_vel_s:.0f} s"
            )
        if self.odometry is not None:
            o = self.odometry
            text += f"; odometry white {'/'.join(f'{s:.2g}' for s in o.sigma_mps)} m/s"
        return text + f"; IMU noise {self.imu_scale:.2g} x preset {self.grade.name}"


def scaled_grade(grade: ImuGrade, scale: float) -> ImuGrade:
    """The grade with every noise density (white and bias random walk) multiplied by sqrt(scale)."""
    r = float(np.sqrt(scale))
    return replace(
        grade,
        name=grade.name if scale == 1.0 else f"{grade.name} x{scale:.2g}",
        gyro_arw=grade.gyro_arw * r,
        accel_vrw=grade.accel_vrw * r,
        gyro_bias_rw=grade.gyro_bias_rw * r,
        accel_bias_rw=grade.accel_bias_rw * r,
    )


def _robust_std(x: FloatArray) -> float:
    x = x[np.isfinite(x)]
    if len(x) < 5:
        return float("nan")
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def _mean_of_finite(values: Sequence[float]) -> float:
    finite = [v for v in values if np.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


def initial_noise(inputs: FilterInputs, exclude: Sequence[tuple[float, float]] = ()) -> GnssNoise:
    """A starting point from the fixes alone (away from suspected stretches): white noise from the scatter
    of second differences (the vehicle's motion is smooth over three epochs; exact repeats, a frozen
    receiver or a hover spoofer, left out), a wander of 2 m."""
    from spooflens.geodesy import geodetic_to_enu

    fx = inputs.fixes
    t = fx["t_s"].to_numpy(dtype=float)
    keep = np.ones(len(t), dtype=bool)
    for a, b in exclude:
        keep &= ~((t >= a) & (t <= b))
    if keep.sum() >= 10:
        fx = fx[keep].reset_index(drop=True)
    p = geodetic_to_enu(
        fx["lat_deg"],
        fx["lon_deg"],
        fx["height_m"],
        *(float(fx[c].iloc[0]) for c in ("lat_deg", "lon_deg", "height_m")),
    )
    d2 = np.diff(p, 2, axis=0)
    d2 = np.where(np.abs(d2) > 1e-6, d2, np.nan)
    wh = _mean_of_finite([_robust_std(d2[:, 0]), _robust_std(d2[:, 1])]) / np.sqrt(6.0)
    wv = _robust_std(d2[:, 2]) / np.sqrt(6.0)
    # the wander's size is found by the search; never started from the receiver's reported accuracy,
    # which is 5-10 times the real scatter in some receivers and a fifth of it in others
    wander = 2.0
    v = fx[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy(dtype=float)
    has_vel = bool(np.isfinite(v[:, :2]).all(axis=1).any())
    dv = np.diff(v, 2, axis=0)
    dv = np.where(np.abs(dv) > 1e-9, dv, np.nan)
    vh = _mean_of_finite([_robust_std(dv[:, 0]), _robust_std(dv[:, 1])]) / np.sqrt(6.0) if has_vel else 0.0
    vv = _robust_std(dv[:, 2]) / np.sqrt(6.0) if has_vel and np.isfinite(v[:, 2]).any() else vh

    def ok(x: float, floor: float) -> float:
        return float(max(x, floor)) if np.isfinite(x) else floor

    return GnssNoise(
        white_pos_m=(ok(wh, 0.02), ok(wv, 0.04)),
        gm_pos_m=(max(wander, 0.5), max(2 * wander, 1.0)),
        tau_pos_s=100.0,
        white_vel_mps=(ok(vh, 0.01), ok(vv, 0.02)) if has_vel else (0.0, 0.0),
        gm_vel_mps=(0.05, 0.1) if has_vel else (0.0, 0.0),
        tau_vel_s=10.0,
        source="initial guess",
    )


def estimate_mount(inputs: FilterInputs, odometry_id: str, min_correlation: float = 0.2) -> FloatArray | None:
    """Rotation vehicle <- IMU body from the sensors alone (no heading needed): up is the mean specific
    force; in the plane across it, the specific force follows the wheels' longitudinal acceleration
    d(v_x)/dt along the vehicle's forward axis and the turn's centripetal acceleration v_x w_z along its
    left axis, so with f = f1 + i f2 in a basis of that plane and z = a + i v_x w_z,
    f = z exp(i psi) gives the forward axis' angle psi by least squares. None when the motion does not
    determine it (correlation below `min_correlation`)."""
    od = inputs.table.odometry[inputs.table.odometry["odometry_id"] == odometry_id]
    pre = inputs.pre
    if len(od) < 20:
        return None
    to = od["t_s"].to_numpy(dtype=float)
    grid = np.arange(max(pre.t[0], to[0]), min(pre.t[-1], to[-1]), 0.1)
    if len(grid) < 50:
        return None

    def smooth(x: FloatArray) -> FloatArray:
        kernel = np.ones(10) / 10.0  # 1 s: the wheels' and the IMU's clocks and rates differ
        return np.convolve(x, kernel, mode="same")

    f = np.stack([smooth(np.interp(grid, pre.t, a)) for a in pre.f_axes], axis=1)
    vx = smooth(np.interp(grid, to, od["vx_mps"].to_numpy(dtype=float)))
    wz = smooth(np.interp(grid, to, od["wz_radps"].to_numpy(dtype=float)))
    up = np.array([np.mean(a) for a in pre.f_axes])
    if np.linalg.norm(up) < 1e-6:
        return None
    up = up / np.linalg.norm(up)
    e1 = np.cross([0.0, 0.0, 1.0], up) if abs(up[2]) < 0.9 else np.cross([1.0, 0.0, 0.0], up)
    e1 = e1 / np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    fh = f - f.mean(axis=0)
    z = np.gradient(vx, grid) + 1j * vx * wz
    y = fh @ e1 + 1j * (fh @ e2)
    c = np.sum(np.conj(z) * y)
    norm = np.sqrt(np.sum(np.abs(z) ** 2) * np.sum(np.abs(y) ** 2))
    if norm <= 0 or abs(c) / norm < min_correlation:
        return None
    psi = float(np.angle(c))
    forward = np.cos(psi) * e1 + np.sin(psi) * e2
    return np.vstack([forward, np.cross(up, forward), up])


@dataclass
class _Objective:
    inputs: FilterInputs
    start: tuple[NavState, Alignment | None]
    base: FilterOptions
    score_mask: NDArray[np.bool_] | None = None
    evaluations: int = 0

    def run(self, opts: FilterOptions) -> NavSolution:
        self.evaluations += 1
        return run_prepared(self.inputs, opts, self.start)

    def __call__(self, opts: FilterOptions) -> float:
        self.evaluations += 1
        return self._score(opts)

    def many(self, candidates: Sequence[FilterOptions]) -> list[float]:
        """The score of each candidate, the runs side by side."""
        self.evaluations += len(candidates)
        return in_parallel([partial(self._score, o) for o in candidates])

    def first_better(self, candidates: Sequence[FilterOptions], best: float) -> tuple[int, float] | None:
        """(index, score) of the first candidate, in order, that scores below `best`; None if none does.
        With two threads the candidates run side by side; with one, the runs stop at the first better."""
        values = self.many(candidates) if thread_count() >= 2 else (self(o) for o in candidates)
        return next(((i, value) for i, value in enumerate(values) if value < best), None)

    def _score(self, opts: FilterOptions) -> float:
        return score(run_prepared(self.inputs, opts, self.start), self.score_mask)


def score(sol: NavSolution, mask: NDArray[np.bool_] | None = None) -> float:
    """Twice the negative log-likelihood of the innovations of the scored epochs (constants dropped)."""
    sel = np.isfinite(sol.nis) & (sol.dof > 0)
    if mask is not None:
        sel &= mask
    if not sel.any():
        return float("inf")
    logdet = sol.logdet_S[sel]  # the filter's own, NaN where S was not positive definite
    if np.isnan(logdet).any():
        return float("inf")
    return float(np.sum(sol.nis[sel]) + np.sum(logdet))


def _scored_epochs(
    sol: NavSolution, window: tuple[float, float], exclude: Sequence[tuple[float, float]], opts: LearnOptions
) -> NDArray[np.bool_]:
    t = sol.t
    mask = (t >= window[0] + opts.settle_s) & (t <= window[1])
    for a, b in exclude:
        mask &= ~((t >= a) & (t <= b))
    # leave out the windows whose first-pass innovations are the worst (an attack inside the window)
    edges = np.arange(window[0], window[1] + opts.trim_window_s, opts.trim_window_s)
    worst: list[tuple[float, float, float]] = []
    for a, b in itertools.pairwise(edges):
        w = mask & (t >= a) & (t < b)
        per_dof = sol.nis[w] / np.maximum(sol.dof[w], 1)
        if w.sum() >= 3 and np.isfinite(per_dof).any():  # a window with no update has nothing to rank
            worst.append((float(np.nanmean(per_dof)), a, b))
    worst.sort(reverse=True)
    for _, a, b in worst[: int(opts.trim_fraction * len(worst))]:
        mask &= ~((t >= a) & (t < b))
    return mask


def _up_to_last_scored(
    inputs: FilterInputs, t: FloatArray, mask: NDArray[np.bool_]
) -> tuple[FilterInputs, NDArray[np.bool_]]:
    """The inputs and the score mask up to the last scored epoch. The filter is causal: nothing after that
    epoch changes a score, so the candidate runs stop there (a second pass, whose suspected stretch runs
    to the window's end, scores only the epochs before it: a sample flight's second learning is half as
    long)."""
    t_last = float(t[np.flatnonzero(mask)[-1]])
    return inputs.between(-np.inf, t_last), mask[: int(np.searchsorted(t, t_last, side="right"))]


def coordinate_search(
    objective: _Objective,
    make: Callable[[dict[str, float]], FilterOptions],
    params: dict[str, float],
    names: Sequence[str],
    opts: LearnOptions,
    best: float | None = None,
    prior: NoisePrior | None = None,
) -> tuple[float, dict[str, float]]:
    """Coordinate descent on a log scale over `names` (factors `opts.steps`, `opts.sweeps` sweeps).

    Each step's two candidates (up and down) are run side by side (`threads.in_parallel`) and judged in
    that order, the first that improves taken: the path and the answer are those of trying them one
    after the other; only the second run is wasted when the first already improved. `best`: the score of
    `params` when known (not run again). `prior`: a baseline's caps and floors, which `params` respects
    (`_capped`)."""
    if best is None:
        best = objective(make(params))
    upper, rates, lower = (prior.upper, prior.rates, prior.lower) if prior is not None else ({}, {}, {})
    start = dict(params)
    reach = float(np.prod(opts.steps)) ** opts.sweeps
    sweep = 0
    while True:
        sweep += 1
        before = best
        for name in names:
            lo, hi = BOUNDS.get(name, (1e-4, 1e4))
            hi = min(hi, upper.get(name, hi))
            lo = min(max(lo, lower.get(name, lo)), hi)
            for s, (tau, r) in rates.items():  # the wanders' driving noise under its cap
                if name == s and tau in params:
                    hi = min(hi, float(np.sqrt(r * params[tau])))
                elif name == tau and s in params:
                    lo = max(lo, params[s] ** 2 / r)
            for step in opts.steps:
                trials = []
                for factor in (step, 1.0 / step):
                    trial = dict(params)
                    trial[name] = float(np.clip(params[name] * factor, lo, hi))
                    if trial[name] != params[name]:
                        trials.append(trial)
                better = objective.first_better([make(trial) for trial in trials], best)
                if better is not None:
                    best, params = better[1], trials[better[0]]
        if before - best < opts.min_gain:  # a sweep that bought almost nothing: converged
            break
        if sweep >= opts.sweeps and not (sweep < opts.max_sweeps and _beyond_reach(params, start, reach, names)):
            break
    return best, params


# the noises' sizes (not their time constants): raising one makes the filter trust its sensor less
NOISE_SIZES = frozenset({"w_h", "w_v", "b_h", "b_v", "wv_h", "wv_v", "bv_h", "bv_v", "imu", "o_f", "o_l", "o_b"})


def _beyond_reach(params: dict[str, float], start: dict[str, float], reach: float, names: Sequence[str]) -> bool:
    """Whether a noise the sweeps raised at every step sits at the top of their reach while they still
    gain: the log is noisier than they reach, and the filter overconfident (a copter's 50 Hz IMU samples of
    a vibrating airframe, log171: its IMU scale stopped at 27 with clean coasts 6-9 times the filter's
    uncertainty within seconds). The search then goes on over every parameter. A noise only lowered to the
    bottom of the reach does not extend it: there the INS is trusted less than the log warrants, which
    makes the tests less sensitive, never more prone to false alarms (the simulated vehicles' tactical
    IMUs against the consumer preset)."""
    return any(n in NOISE_SIZES and params[n] >= start[n] * reach * (1.0 - 1e-9) for n in names)


BOUNDS = {"tau_p": (2.0, 5000.0), "tau_v": (0.5, 1000.0), "tau_o": (1.0, 3000.0), "imu": (1e-3, 1e3)}


def learn_noise(
    inputs: FilterInputs,
    grade: ImuGrade,
    start: tuple[NavState, Alignment | None],
    odometry_id: str | None = None,
    exclude: Sequence[tuple[float, float]] = (),
    opts: LearnOptions | None = None,
    prior: NoisePrior | None = None,
) -> LearnedNoise:
    """Maximum-likelihood sensor noise for this log (see the module docstring).

    GNSS and IMU noise first; then, when the log has wheel odometry and its motion determines the
    IMU-to-vehicle rotation (`estimate_mount`), the odometry's noise (with the IMU's again) on top."""
    opts = opts or LearnOptions()
    tf = inputs.fixes["t_s"].to_numpy(dtype=float)
    t0 = max(float(start[0].t), float(tf[0]))
    k_end = min(len(tf) - 1, int(np.searchsorted(tf, t0)) + opts.max_epochs)
    t_end = max(float(tf[k_end]), t0 + opts.min_window_s)
    window = (t0, min(t_end, float(tf[-1])))
    sub = inputs.between(-np.inf, window[1])
    noise = initial_noise(sub, exclude)  # the first run and what it leaves out are the same with a prior
    has_vel = noise.has_velocity
    base = FilterOptions(grade=grade, noise=noise, max_block_s=opts.max_block_s, record=False, compare=False)
    objective = _Objective(sub, start, base)
    first = objective.run(base)
    objective.score_mask = _scored_epochs(first, window, exclude, opts)
    odometry: OdometryAiding | None = None
    scored_t = first.t[objective.score_mask]
    if len(scored_t) < opts.min_scored_epochs or float(scored_t[-1] - scored_t[0]) < opts.min_scored_s:
        # too little clean data (a short log, or one suspected almost throughout): the prior stands
        mount = estimate_mount(sub, odometry_id) if odometry_id is not None else None
        if mount is not None and odometry_id is not None:
            odometry = OdometryAiding(mount, (0.1, 0.1, 0.1), odometry_id, (0.05, 0.05, 0.05), 30.0, "prior")
        span = float(scored_t[-1] - scored_t[0]) if len(scored_t) else 0.0
        why = (
            f"{PRIOR} (too little clean data to learn from: {len(scored_t)} clean fixes over {span:.0f} s after "
            f"the filter's first {opts.settle_s:.0f} s, at least {opts.min_scored_epochs} over "
            f"{opts.min_scored_s:.0f} s needed)"
        )
        imu = min(prior.start.get("imu", 1.0), prior.upper.get("imu", np.inf)) if prior is not None else 1.0
        return LearnedNoise(
            replace(_from_prior(noise, prior) if prior is not None else noise, source=why),
            odometry,
            scaled_grade(grade, imu) if prior is not None else grade,
            imu,
            objective.evaluations,
            float("nan"),
            window,
            tuple(exclude),
            inputs.imu_id,
            inputs.receiver_id,
            prior.source if prior is not None else "",
        )

    objective.inputs, objective.score_mask = _up_to_last_scored(sub, first.t, objective.score_mask)
    params = noise_parameters(noise, 1.0, has_vel)

    def options(p: dict[str, float]) -> FilterOptions:
        n = GnssNoise(
            white_pos_m=(p["w_h"], p["w_v"]),
            gm_pos_m=(p["b_h"], p["b_v"]),
            tau_pos_s=p["tau_p"],
            white_vel_mps=(p.get("wv_h", 0.1), p.get("wv_v", 0.1)),
            gm_vel_mps=(p.get("bv_h", 0.0), p.get("bv_v", 0.0)),
            tau_vel_s=p.get("tau_v", 10.0),
            source="learned",
        )
        odo = None
        if odometry is not None:
            odo = replace(
                odometry,
                sigma_mps=(p["o_f"], p["o_l"], p["o_l"]),
                gm_mps=(p["o_b"], p["o_b"], p["o_b"]),
                tau_s=p["tau_o"],
            )
        return FilterOptions(
            grade=scaled_grade(grade, p["imu"]),
            noise=n,
            odometry=odo,
            max_block_s=opts.max_block_s,
            record=False,
            compare=False,
        )

    # the likelihood is flat along large slow wanders: start the search from the best of a coarse grid (and,
    # with a baseline, of the values its clean logs learned), every candidate under the baseline's caps
    grid = [_capped({**params, "b_h": b, "b_v": 2.0 * b}, prior) for b in opts.wander_grid_m]
    if prior is not None:
        grid.append(_capped(noise_parameters(_from_prior(noise, prior), prior.start.get("imu", 1.0), has_vel), prior))
    values = objective.many([options(g) for g in grid])
    params = grid[int(np.argmin(values))]
    best, params = coordinate_search(objective, options, params, list(params), opts, min(values), prior)
    if odometry_id is not None:
        R_vb = estimate_mount(sub, odometry_id)
        if R_vb is not None:
            odometry = OdometryAiding(R_vb, (0.1, 0.1, 0.1), odometry_id, (0.05, 0.05, 0.05), 30.0, "learned")
            params |= {"o_f": 0.1, "o_l": 0.1, "o_b": 0.05, "tau_o": 30.0}
            best, params = coordinate_search(
                objective, options, params, ["o_f", "o_l", "o_b", "tau_o", "imu"], opts, prior=prior
            )
    final = replace(options(params), max_block_s=FilterOptions().max_block_s, record=True, compare=True)
    assert final.noise is not None
    return LearnedNoise(
        replace(final.noise, source="learned from the log"),
        final.odometry,
        final.grade,
        params["imu"],
        objective.evaluations,
        best,
        window,
        tuple(exclude),
        inputs.imu_id,
        inputs.receiver_id,
        prior.source if prior is not None else "",
        _at_caps(params, prior.upper, prior.rates) if prior is not None else (),
    )


def _at_caps(params: dict[str, float], upper: dict[str, float], rates: dict[str, tuple[str, float]]) -> tuple[str, ...]:
    """The parameters the search left at a baseline's cap (the log asked for more noise)."""
    held = [f"{k} {params[k]:.3g}" for k in sorted(upper) if k in params and params[k] >= 0.999 * upper[k]]
    held += [
        f"{s} {params[s]:.3g} at {tau} {params[tau]:.3g} s (its driving noise)"
        for s, (tau, r) in sorted(rates.items())
        if s in params and tau in params and params[s] ** 2 / params[tau] >= 0.998 * r
    ]
    return tuple(held)


def noise_parameters(noise: GnssNoise, imu: float, has_vel: bool) -> dict[str, float]:
    """The search's parameters of a noise model, by the names a baseline records them under."""
    params = {
        "imu": imu,
        "w_h": noise.white_pos_m[0],
        "w_v": noise.white_pos_m[1],
        "b_h": noise.gm_pos_m[0],
        "b_v": noise.gm_pos_m[1],
        "tau_p": noise.tau_pos_s,
    }
    if has_vel:
        params |= {
            "wv_h": noise.white_vel_mps[0],
            "wv_v": noise.white_vel_mps[1],
            "bv_h": noise.gm_vel_mps[0],
            "bv_v": noise.gm_vel_mps[1],
            "tau_v": noise.tau_vel_s,
        }
    return params


def _capped(params: dict[str, float], prior: NoisePrior | None) -> dict[str, float]:
    """The parameters under a baseline's caps and above its floors (as they are without one); a wander fed
    faster than its cap allows made slower (its time constant raised, up to its bound), then smaller."""
    if prior is None:
        return dict(params)
    out = {k: min(max(v, prior.lower.get(k, v)), prior.upper.get(k, np.inf)) for k, v in params.items()}
    for s, (tau, r) in prior.rates.items():
        if s in out and tau in out and out[s] ** 2 > r * out[tau]:
            out[tau] = min(out[s] ** 2 / r, BOUNDS[tau][1])
            out[s] = min(out[s], float(np.sqrt(r * out[tau])))
    return out


def _from_prior(noise: GnssNoise, prior: NoisePrior) -> GnssNoise:
    """The initial guess with the baseline's values in place (each under its cap)."""
    has_vel = noise.has_velocity
    start = _capped({**noise_parameters(noise, 1.0, has_vel), **prior.start}, prior)

    def value(name: str, default: float) -> float:
        return float(start.get(name, default))

    return replace(
        noise,
        white_pos_m=(value("w_h", noise.white_pos_m[0]), value("w_v", noise.white_pos_m[1])),
        gm_pos_m=(value("b_h", noise.gm_pos_m[0]), value("b_v", noise.gm_pos_m[1])),
        tau_pos_s=value("tau_p", noise.tau_pos_s),
        white_vel_mps=(value("wv_h", noise.white_vel_mps[0]), value("wv_v", noise.white_vel_mps[1]))
        if has_vel
        else noise.white_vel_mps,
        gm_vel_mps=(value("bv_h", noise.gm_vel_mps[0]), value("bv_v", noise.gm_vel_mps[1]))
        if has_vel
        else noise.gm_vel_mps,
        tau_vel_s=value("tau_v", noise.tau_vel_s),
        source="baseline",
    )
