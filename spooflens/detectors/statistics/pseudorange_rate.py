"""Seed 001's statistics: pseudorange-rate consistency with an independent velocity reference.

Per satellite s and epoch k (Chang et al. 2022, eqs. 7-18, with SEEDS.md's errata applied):

- measured rate: the carrier-phase difference lambda (phi_k - phi_{k-1}) / dt (eq. 8; the paper's
  dt = 1 s made it m/s), screened for cycle slips; where the carrier slipped, the trapezoid of the
  Doppler rates (-lambda D) over the interval; logs with Doppler or logged rates only use those
  (instantaneous, at epoch k).
- predicted rate (eq. 17, errata: the line of sight points receiver -> satellite and the reference
  velocity is ENU, so it enters ECEF through G^T; the satellite's clock drift from the broadcast
  clock, eq. 10): for carrier intervals the change of the modelled carrier range (satellite motion,
  Earth rotation, satellite clock, troposphere, ionosphere advance) between the reference positions
  at k-1 and k, over dt; for instantaneous rates `spooflens.gnss.geometry.expected_range_rate` with
  the reference velocity.
- the receiver clock drift df_r is unknown (the paper's eq. 17 leaves it in): per epoch, weighted
  least squares of y_s = measured - predicted = -u_s . dv + df_r (u_s the ENU line of sight, one drift
  per satellite system) gives dv = v_signals - v_reference, whose east/north/up components are the
  statistic the paper plots (and the common repeater term of eq. 13 goes into df_r).

Cycle-slip screening: the change of code minus carrier separates a slip (the carrier alone jumps)
from a change of the signal's delay (code and carrier move together: what a spoofer or meaconer does).
With Doppler, a carrier change that disagrees with the Doppler trapezoid is a slip when the code did
not follow it (or the jump is too small for the code to tell) and a delay step when it did; without
Doppler, a code-minus-carrier change beyond `slip_sigmas` of its robust scale is a slip (slips smaller
than that go unseen; their rate error is then tested like any other).

Decision rules, both reported:
- per sample: each component of dv against a threshold; the paper's thresholds are a normal fit to the
  first 200 s of clean data at P_FA 0.01 (`paper_threshold`);
- windowed t-test (eqs. 21-26): T = mean / (S / sqrt(K)) over the last K samples of one component,
  H1 when |T| >= t_{1-alpha/2}(K-1); K from the noncentral t so that a bias A is seen with probability
  P_D (the paper's step 4 with its inequality corrected: the achievable P'_D must reach P_D).

The pseudorange (position) model the paper compares with: the same least squares on code residuals
against the reference position gives dp = p_signals - p_reference (`position_error`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spooflens.detectors.references import Reference
from spooflens.detectors.statistics.scales import robust_scale
from spooflens.estimation.quantiles import chi2_isf, norm_isf, t_isf
from spooflens.gnss.ephemeris import Klobuchar
from spooflens.gnss.grid import ObservationGrid, epoch_change, predicted, predicted_rate

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class RateOptions:
    source: str = "auto"  # "carrier", "doppler" or "auto" (carrier when most cells have it)
    slip_sigmas: float = 5.0  # code-minus-carrier change beyond this many robust sigmas: a slip
    doppler_slip_m: float = 0.1  # carrier change this far from the Doppler trapezoid: slip or delay step
    min_step_m: float = 3.0  # a delay change smaller than this is left to the rate statistic, not named a step
    max_interval_s: float = 60.0  # carrier differences across longer gaps are not used
    elevation_mask_deg: float = 10.0


@dataclass(frozen=True)
class RateResiduals:
    """y = measured - predicted pseudorange rate (receiver clock drift left in), per epoch and satellite."""

    t: FloatArray  # (E,)
    source: str  # "carrier" (interval means) or "doppler" (instantaneous)
    y: FloatArray  # (E, S) m/s, NaN where unusable
    los_enu: FloatArray  # (E, S, 3) receiver -> satellite
    elevation_rad: FloatArray  # (E, S)
    slip: BoolArray  # (E, S) carrier slipped (replaced by Doppler, or dropped)
    delay_step: BoolArray  # (E, S) code and carrier jumped together (a change of the signal's delay)
    step_m: FloatArray  # (E, S) size of that jump (carrier change minus what was expected), m
    # (E, S) measured by the Doppler where the carrier is the source (it slipped): noisier than an intact carrier
    from_doppler: BoolArray | None = None
    doppler_noise_mps: float = 0.0  # the Doppler's scatter about intact carriers' rates, robust, m/s


def row_median(x: FloatArray, mask: BoolArray | None = None) -> FloatArray:
    """Median of each row (epoch) over its finite cells (optionally only `mask`ed ones), as a column;
    NaN for rows with none."""
    v = np.where(np.isfinite(x) if mask is None else mask & np.isfinite(x), x, np.nan)
    out = np.full((len(v), 1), np.nan)
    ok = np.isfinite(v).any(axis=1)
    if ok.any():
        out[ok, 0] = np.nanmedian(v[ok], axis=1)
    return out


def _choose_source(grid: ObservationGrid, requested: str) -> str:
    if requested != "auto":
        return requested
    usable = grid.usable
    n = max(int(usable.sum()), 1)
    carrier = int((usable & np.isfinite(grid.carrier_m)).sum())
    rate = int((usable & np.isfinite(grid.rate_mps)).sum())
    if carrier >= 0.5 * n:
        return "carrier"
    if rate >= 0.5 * n:
        return "doppler"
    return "carrier" if carrier >= rate else "doppler"


def rate_residuals(
    grid: ObservationGrid, ref: Reference, iono: Klobuchar | None, opts: RateOptions | None = None
) -> RateResiduals:
    """Measured minus predicted pseudorange rates of one receiver against a reference (module notes)."""
    opts = opts or RateOptions()
    source = _choose_source(grid, opts.source)
    E, S = grid.pseudorange_m.shape
    now = predicted(grid, ref.pos, iono)
    dt = np.full(E, np.nan)
    dt[1:] = np.diff(grid.t_s)
    slip = np.zeros((E, S), dtype=bool)
    delay_step = np.zeros((E, S), dtype=bool)
    step_m = np.full((E, S), np.nan)
    if source == "carrier":
        before = predicted(grid, ref.pos_prev[1:], iono, np.arange(E - 1))  # epoch k-1 seen from run k
        pred_change = np.full((E, S), np.nan)
        pred_change[1:] = now.carrier_m[1:] - before.carrier_m
        pred_code_change = np.full((E, S), np.nan)
        pred_code_change[1:] = now.code_m[1:] - before.code_m
        d_carrier = epoch_change(grid.carrier_m)
        d_code = epoch_change(grid.pseudorange_m)
        # code minus carrier: unchanged by motion, clock and delay changes; a slip moves the carrier alone
        d_cmc = (d_code - pred_code_change) - (d_carrier - pred_change)
        cmc_scale = robust_scale(d_cmc - row_median(d_cmc), 0.05)
        code_follows = np.abs(d_cmc - row_median(d_cmc)) <= opts.slip_sigmas * cmc_scale
        mean_rate = np.full((E, S), np.nan)
        mean_rate[1:] = 0.5 * (grid.rate_mps[1:] + grid.rate_mps[:-1])
        doppler_change = mean_rate * dt[:, None]
        has_doppler = np.isfinite(doppler_change)
        jump = d_carrier - doppler_change
        # the receiver clock moves code, carrier and Doppler alike, so compare after its common part
        jump_c = jump - row_median(jump, has_doppler)
        off_doppler = has_doppler & (np.abs(jump_c) > opts.doppler_slip_m)
        big = np.abs(jump_c) > max(opts.slip_sigmas * cmc_scale, opts.min_step_m)
        delay_step = off_doppler & code_follows & big
        slip = (off_doppler & ~(code_follows & big)) | (~has_doppler & np.isfinite(d_cmc) & ~code_follows)
        if grid.carrier_arc_start is not None:
            # the receiver's own word (a half-cycle slip, 0.095 m on L1, passes the Doppler screen): no rate
            # across it; a delay step stays one (code and carrier jumping together is the signal's delay, and a
            # takeover also makes a receiver lose lock)
            slip |= grid.carrier_arc_start & np.isfinite(d_carrier) & ~delay_step
        intact = np.isfinite(d_carrier) & ~slip
        measured = np.where(intact, d_carrier, doppler_change) / dt[:, None]
        from_doppler = ~intact & has_doppler
        # the Doppler trapezoid's own error, read where the carrier is intact: a Doppler standing in for a
        # slipped carrier is that much noisier than the carrier rates the unit-weight scale is learned from
        intact_jump = np.where(intact & has_doppler, jump_c, np.nan) / dt[:, None]
        doppler_noise = robust_scale(intact_jump[np.isfinite(intact_jump)], 1e-6) if from_doppler.any() else 0.0
        # a delay step's size, for the report: the carrier change beyond what the Doppler (else the
        # reference) expected, receiver clock removed
        expected = np.where(has_doppler, doppler_change, pred_change)
        step = d_carrier - expected
        step_m = np.where(delay_step, step - row_median(step), np.nan)
        y = measured - pred_change / dt[:, None]
        y[~(dt <= opts.max_interval_s)] = np.nan
        if not has_doppler.any():
            # without Doppler a large code-and-carrier jump is still a delay change, not a slip
            dev = d_carrier - pred_change
            dev = dev - row_median(dev)
            delay_step = code_follows & (np.abs(dev) > max(opts.slip_sigmas * cmc_scale, opts.min_step_m))
            step_m = np.where(delay_step, dev, np.nan)
    else:
        y = grid.rate_mps - predicted_rate(grid, ref.pos, ref.vel)
        from_doppler, doppler_noise = np.zeros((E, S), dtype=bool), 0.0
    usable = grid.usable & ref.valid[:, None] & (now.elevation_rad >= np.radians(opts.elevation_mask_deg))
    y = np.where(usable & np.isfinite(y), y, np.nan)
    return RateResiduals(
        grid.t_s,
        source,
        y,
        now.los_enu,
        now.elevation_rad,
        slip & usable,
        delay_step & usable,
        step_m,
        from_doppler & usable & np.isfinite(y),
        doppler_noise,
    )


@dataclass(frozen=True)
class EpochFit:
    """Per-epoch weighted least squares of residuals y_s = -u_s . d + clock_sys(s) + noise."""

    d_enu: FloatArray  # (E, 3) the fitted offset (velocity or position error), NaN where unsolvable
    clock: FloatArray  # (E, n_systems)
    cov_unit: FloatArray  # (E, 3, 3) covariance of d_enu for unit-weight variance 1
    residual: FloatArray  # (E, S) y - fit, NaN where unused
    standardised: FloatArray  # (E, S) residual sqrt(w) / sqrt(1 - leverage), unit-weight scale
    used: BoolArray  # (E, S)
    dof: NDArray[np.int64]  # (E,) used - unknowns
    weighted_sq: FloatArray  # (E,) sum of w r^2: chi-square(dof) times the unit-weight variance


def elevation_weight(elevation_rad: FloatArray) -> FloatArray:
    """Relative weight 1 / (1 + 1/sin^2 el): RTKLIB's elevation model, normalised to 1/2 at zenith."""
    s = np.sin(np.clip(elevation_rad, 0.05, None))
    return 1.0 / (1.0 + 1.0 / s**2)


def fit_epochs(
    y: FloatArray, los_enu: FloatArray, systems: NDArray[np.str_], weight: FloatArray, use: BoolArray | None = None
) -> EpochFit:
    """Solve every epoch at once (batched normal equations); an epoch needs one redundant satellite."""
    use = np.isfinite(y) & (weight > 0) if use is None else use & np.isfinite(y) & (weight > 0)
    sys_list = sorted(set(systems.tolist()))
    SYS = np.stack([systems == s for s in sys_list], axis=-1).astype(float)  # (S, n_sys)
    E, S = y.shape
    n_x = 3 + len(sys_list)
    H = np.concatenate([-np.nan_to_num(los_enu), np.broadcast_to(SYS, (E, S, len(sys_list)))], axis=-1)
    w = np.where(use, weight, 0.0)
    H = np.where(use[..., None], H, 0.0)
    N = np.einsum("esi,es,esj->eij", H, w, H)
    seen = np.einsum("es,sk->ek", use.astype(float), SYS) > 0
    idx = np.arange(3, n_x)
    N[:, idx, idx] += np.where(seen, 0.0, 1.0)  # a system without satellites this epoch: pin its clock
    b = np.einsum("esi,es,es->ei", H, w, np.nan_to_num(y))
    dof = use.sum(axis=1) - 3 - seen.sum(axis=1)
    ok = (dof >= 1) & (np.abs(np.linalg.det(N)) > 1e-12)
    x = np.full((E, n_x), np.nan)
    cov = np.full((E, n_x, n_x), np.nan)
    if ok.any():
        Ninv = np.linalg.inv(N[ok])
        cov[ok] = Ninv
        x[ok] = np.einsum("eij,ej->ei", Ninv, b[ok])
    fit = np.einsum("esi,ei->es", H, np.nan_to_num(x))
    residual = np.where(use & ok[:, None], y - fit, np.nan)
    leverage = np.einsum("esi,eij,esj->es", H, np.nan_to_num(cov), H) * w
    standardised = residual * np.sqrt(w) / np.sqrt(np.clip(1.0 - leverage, 1e-6, None))
    weighted_sq = np.where(ok, np.nansum(w * np.nan_to_num(residual) ** 2, axis=1), np.nan)
    return EpochFit(
        x[:, :3], x[:, 3:], cov[:, :3, :3], residual, standardised, use & ok[:, None], np.where(ok, dof, 0), weighted_sq
    )


@dataclass(frozen=True)
class VelocityErrorFit:
    """dv = v_signals - v_reference per epoch, with the satellites the residual test set aside."""

    fit: EpochFit  # all usable satellites (the paper's statistic)
    sigma_unit: float  # unit-weight scale of the rate residuals, robust over the log (m/s)
    excluded: BoolArray  # (E, S) set aside: delay steps first, then the residual test's choices
    residual_chi2: FloatArray  # (E,) before exclusion
    consistent: BoolArray  # (E,) the satellites left pass the residual test (or are too few to test)

    def named(self) -> list[NDArray[np.int64]]:
        """Per epoch, the satellite columns to name when the epoch is alarmed: the ones set aside when that
        left the others consistent, else every satellite used (the signals agree with each other on a
        wrong velocity, or the faulty ones cannot be told apart)."""
        return [
            np.flatnonzero(self.excluded[e] if (self.consistent[e] and self.excluded[e].any()) else self.fit.used[e])
            for e in range(len(self.consistent))
        ]


def fit_velocity_error(
    res: RateResiduals, systems: NDArray[np.str_], p_exclude: float = 1e-4, max_exclusions: int = 4
) -> VelocityErrorFit:
    """The per-epoch velocity error and, where the satellites disagree among themselves, the ones to name.

    Satellites whose code and carrier jumped together are set aside first (their delay changed: the
    strongest evidence there is). Then a residual (RAIM-style) test on the rates: while the normalised
    residual sum exceeds chi-square(dof) at `p_exclude`, the satellite with the largest standardised
    residual is set aside (at most `max_exclusions`, keeping one redundant satellite).
    """
    w = elevation_weight(res.elevation_rad)
    full = fit_epochs(res.y, res.los_enu, systems, w)
    sigma = robust_scale(full.standardised, 1e-6)
    if res.from_doppler is not None and res.from_doppler.any() and res.doppler_noise_mps > 0:
        # a Doppler standing in for a slipped carrier: its variance is the cell's plus the Doppler's own (a
        # clean static receiver's one 0.11 m/s Doppler on a weak satellite, weighed as a 2 mm/s carrier, was
        # a known-station alarm)
        w = np.where(res.from_doppler, w / (1.0 + w * (res.doppler_noise_mps / sigma) ** 2), w)
        full = fit_epochs(res.y, res.los_enu, systems, w)
        sigma = robust_scale(full.standardised, 1e-6)
    chi2 = np.where(full.dof > 0, full.weighted_sq / sigma**2, np.nan)

    def failing(fit: EpochFit) -> BoolArray:
        c = np.nan_to_num(fit.weighted_sq) / sigma**2
        return (fit.dof >= 1) & (c > chi2_isf(p_exclude, np.maximum(fit.dof, 1)))

    excluded = res.delay_step & full.used
    use = full.used & ~excluded
    fit = fit_epochs(res.y, res.los_enu, systems, w, use) if excluded.any() else full
    for _ in range(max_exclusions):
        bad = failing(fit) & (fit.dof >= 2)
        if not bad.any():
            break
        worst = np.nanargmax(np.where(np.isfinite(fit.standardised), np.abs(fit.standardised), -1.0), axis=1)
        rows = np.flatnonzero(bad)
        use[rows, worst[rows]] = False
        excluded[rows, worst[rows]] = True
        fit = fit_epochs(res.y, res.los_enu, systems, w, use)
    return VelocityErrorFit(full, sigma, excluded, chi2, ~failing(fit))


def normalised_components(
    d: FloatArray, cov_unit: FloatArray, sigma_unit: float, dynamics: FloatArray | None = None, cap: float = 4.0
) -> tuple[FloatArray, FloatArray, float]:
    """Each ENU component of d over its scale, and the scale's parameters.

    scale_i(k)^2 = sigma_unit^2 cov_ii(k) + sigma_ref_i^2 + [i horizontal] (b dynamics(k))^2: the
    least-squares geometry, the reference's own error (the free INS drift over its window) and, for an
    INS reference, a heading error b (rad) times the horizontal velocity change over the free run (a
    turn or an acceleration). sigma_ref and b maximise a Gaussian likelihood of d whose terms are capped
    at `cap` sigmas, so a minority of attacked epochs does not inflate them. Returns (normalised (E, 3),
    sigma_ref (3,), b).
    """
    geometric = sigma_unit**2 * np.diagonal(cov_unit, axis1=1, axis2=2)
    ok = np.isfinite(d).all(axis=1) & np.isfinite(geometric).all(axis=1)
    dyn = np.zeros(len(d)) if dynamics is None else np.nan_to_num(np.asarray(dynamics, float))
    sigma_ref = np.zeros(3)
    b = 0.0
    if ok.sum() >= 8:
        x, g, D = d[ok], geometric[ok], dyn[ok]
        start = np.array([max(robust_scale(x[:, i]), 1e-6) for i in range(3)])

        def variance(params: FloatArray) -> FloatArray:
            s_ref, bb = np.exp(params[:3]), (np.exp(params[3]) if dynamics is not None else 0.0)
            extra = np.zeros_like(g)
            extra[:, :2] = (bb * D[:, None]) ** 2
            return np.asarray(g + s_ref**2 + extra, dtype=float)

        def cost(params: FloatArray) -> float:
            var = variance(params)
            return float(np.sum(np.log(var) + np.minimum(x**2 / var, cap**2)))

        from scipy import optimize  # only for logs with raw observations and an IMU

        p0 = np.r_[np.log(start), np.log(1e-3)]
        best = optimize.minimize(
            cost, p0, method="Nelder-Mead", options={"xatol": 1e-3, "fatol": 1e-3, "maxiter": 2000}
        )
        sigma_ref = np.exp(best.x[:3])
        b = float(np.exp(best.x[3])) if dynamics is not None else 0.0
    extra = np.zeros((len(d), 3))
    extra[:, :2] = (b * dyn[:, None]) ** 2
    z = d / np.sqrt(geometric + sigma_ref**2 + extra)
    return z, sigma_ref, b


# --- the paper's decision rules -----------------------------------------------------------------------


def paper_threshold(x: FloatArray, p_false_alarm: float = 0.01) -> tuple[float, float]:
    """Normal fit (mean, sd) of clean samples and the two-sided per-sample band half-width z sd: alarm when
    |x - mean| > z sd. Returns (mean, half-width)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    mu, sd = float(np.mean(x)), float(np.std(x, ddof=1))
    return mu, norm_isf(p_false_alarm / 2.0) * sd


def t_statistic(x: FloatArray, K: int) -> FloatArray:
    """T(k) = mean / (S / sqrt(K)) over samples k-K+1..k (eq. 23's T, S the sample standard deviation);
    NaN until K finite samples are in the window."""
    x = np.asarray(x, float)
    ok = np.isfinite(x)
    xv = np.where(ok, x, 0.0)
    c1 = np.concatenate([[0.0], np.cumsum(xv)])
    c2 = np.concatenate([[0.0], np.cumsum(xv * xv)])
    cn = np.concatenate([[0], np.cumsum(ok)])
    out = np.full(len(x), np.nan)
    if len(x) < K:
        return out
    s1 = c1[K:] - c1[:-K]
    s2 = c2[K:] - c2[:-K]
    n = cn[K:] - cn[:-K]
    full = n == K
    mean = s1 / K
    var = np.maximum(s2 - K * mean**2, 0.0) / (K - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = mean / np.sqrt(var / K)
    out[K - 1 :] = np.where(full, t, np.nan)
    return out


def t_threshold(p_false_alarm: float, K: int) -> float:
    """gamma_1 = t_{1-alpha/2}(K-1) (eq. 25)."""
    return t_isf(p_false_alarm / 2.0, K - 1)


def detection_probability(bias: float, sigma: float, K: int, p_false_alarm: float) -> float:
    """P'_D of the two-sided t-test over K samples for a bias `bias` in noise `sigma` (noncentral t,
    delta = bias sqrt(K) / sigma)."""
    from scipy import stats  # the noncentral t: only here

    g = t_threshold(p_false_alarm, K)
    nc = bias * np.sqrt(K) / sigma
    return float(stats.nct.sf(g, K - 1, nc) + stats.nct.cdf(-g, K - 1, nc))


def window_for_bias(
    bias: float, sigma: float, p_false_alarm: float = 0.01, p_detect: float = 0.9, k_max: int = 600
) -> tuple[int, float]:
    """The smallest window K with achievable P'_D >= P_D (the paper's step 4, inequality corrected),
    and that P'_D; K = k_max (and its P'_D) when no window up to k_max reaches it."""
    pd = 0.0
    for K in range(2, k_max + 1):
        pd = detection_probability(bias, sigma, K, p_false_alarm)
        if pd >= p_detect:
            return K, pd
    return k_max, pd


# --- the pseudorange (position) model -----------------------------------------------------------------


def position_error(grid: ObservationGrid, ref: Reference, iono: Klobuchar | None, mask_deg: float = 10.0) -> EpochFit:
    """dp = p_signals - p_reference per epoch: least squares of code residuals against the reference
    position (the paper's pseudorange model), receiver clock per system estimated."""
    pr = predicted(grid, ref.pos, iono)
    y = grid.pseudorange_m - pr.code_m
    ok = grid.usable & ref.valid[:, None] & (pr.elevation_rad >= np.radians(mask_deg))
    y = np.where(ok, y, np.nan)
    return fit_epochs(y, pr.los_enu, grid.systems, elevation_weight(pr.elevation_rad))
