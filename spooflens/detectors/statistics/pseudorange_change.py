"""Seed 002's statistics: pseudorange changes at a receiver of known position, predicted by a Kalman
filter or a recurrent network, and the spoofing they reveal compensated.

Per satellite s and epoch k (Mosavi et al. 2014, eqs. 2-9, with SEEDS.md's errata applied):

    z_s(k) = [rho_s(k) - rho_s(k-1)] - [r_s(k) - r_s(k-1)]                      (eqs. 4-5)

with r the modelled pseudorange of a receiver at the reference position without its clock (range with
Earth rotation, satellite clock, troposphere, broadcast ionosphere: `spooflens.gnss.grid.predicted`),
so the satellite's own motion, clock and the slow atmosphere are gone and z is the receiver clock change
c[B(k) - B(k-1)] (common to all satellites, 10^1-10^3 m/s and the odd 1 ms jump: the paper's eq. 4 drops
it, which is wrong) plus noise and whatever a spoofer added. The common part is removed by the
cross-satellite median of each epoch (`common_mode`: robust while fewer than half the satellites are
spoofed; a delay on every satellite alike moves only the clock, which is what it is). A clock-model
variant (`clock_model_residual`: the common part predicted from earlier epochs instead) is kept for the
benchmark's comparison. Millisecond clock resets are removed first.

The noise of z depends on elevation, var = sigma^2 (1 + 1/sin^2 el), and on each satellite's multipath:
sigma read off the log robustly, then each satellite's own factor (robust over its samples, at least 0.5).

Predictors (each satellite's arc separately, `z` in units of its own sigma):
- Kalman filter, constant acceleration (eqs. 6-7): x = [z, z', z''], F = [[1, 1, 1/2], [0, 1, 1],
  [0, 0, 1]] (one epoch), H = [1, 0, 0], R = 1, Q = q x the white-jerk matrix with q = 1e-4 (z is nearly
  white: the filter tracks only slow multipath and atmosphere residue), P0 = diag(1, 0.1, 0.01).
- echo-state network (the paper gives no architecture): a leaky tanh reservoir of 64 units (spectral
  radius 0.9, leak 0.5, input scale 0.5, seeded weights) fed z(k), a ridge-regression readout predicting
  z(k+1), trained in one least-squares solve on the log's own clean epochs (teacher forcing, 10-epoch
  washout per arc). A differenced white noise is not white (lag-1 correlation -1/2): its next value is
  partly predictable from the past, which the reservoir can learn and the constant-acceleration filter
  cannot.

Residual v = z - prediction (eq. 8), normalised by its predicted variance S, tested against chi-square(1).
Carrier confirmation (not in the paper, whose data had carrier phase): a spoofer or meaconer delays the
whole signal, so the carrier moves with the code; code multipath moves the code alone (on the real GSI
pair the one change beyond 5 sigma is a 3.5 m code jump of a satellite at 12 deg the carrier did not
share). Where the carrier was tracked, an alarm needs it to have moved at least half as far the same
way, unless code and carrier disagree by more than `CODE_ONLY_LIMIT_M` (30 m; more than C/A-code
multipath reaches), which no real signal does. Where no carrier was tracked (phones often log none), a
code change undone at the next epoch (a one-epoch spike: a tracking glitch, as the real Android log of
2016-08-22 shows on G12 by 44 m) is not confirmed either: a spoofer holds the delay it imposes.
An alarmed satellite's predictor coasts (the spoofed value is not learnt: the filter skips its update, the
network is fed its own prediction) for at most `max_coast` epochs, then restarts at the new level.

Compensation (eq. 9 corrected: the printed delta rho - alpha z with alpha = 1 would return the true
range change exactly): while a satellite is alarmed, delta rho_comp = delta rho - alpha v, and the
pseudorange is rebuilt cumulatively from the last clean sample: rho_comp(k) = rho(k) - sum of alpha v
over its alarmed epochs so far. That sum is the spoofing offset the detector estimates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spooflens.detectors.references import Reference
from spooflens.detectors.statistics.scales import robust_scale
from spooflens.gnss.ephemeris import C_MPS, Klobuchar
from spooflens.gnss.grid import ObservationGrid, epoch_change, predicted

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
MS_M = C_MPS * 1e-3  # a 1 ms receiver clock reset, in metres
MIN_PER_SATELLITE = 20  # samples for a satellite's own noise level
CODE_ONLY_LIMIT_M = 30.0  # a code change the carrier does not share, up to this size, is taken for multipath


@dataclass(frozen=True)
class PseudorangeChanges:
    t: FloatArray  # (E,)
    sv_id: NDArray[np.str_]  # (S,)
    z: FloatArray  # (E, S) m, receiver clock change included (millisecond resets removed)
    common: FloatArray  # (E,) cross-satellite median of z: the receiver clock change
    z_median: FloatArray  # (E, S) z - common
    sigma_m: FloatArray  # (E, S) noise scale of each cell of z_median
    arc_start: BoolArray  # (E, S) first z of an arc (the satellite was not seen the epoch before)
    clock_resets: NDArray[np.int64]  # (E,) millisecond resets removed at each epoch
    delta_rho: FloatArray  # (E, S) the measured pseudorange change
    carrier_z: FloatArray  # (E, S) the same change measured on the carrier (median removed), NaN without

    def confirmed(self, code_only_limit_m: float = CODE_ONLY_LIMIT_M) -> BoolArray:
        """Cells whose code change the carrier confirms (module notes): no carrier to ask, the carrier moved
        at least half as far the same way, or code and carrier disagree by more than multipath can."""
        zc, zp = self.z_median, self.carrier_z
        carrier_agrees = ~np.isfinite(zp) | (zp * zc >= 0.5 * zc**2) | (np.abs(zc - zp) > code_only_limit_m)
        return np.asarray(carrier_agrees & ~self.code_spikes(), dtype=bool)

    def code_spikes(self) -> BoolArray:
        """Cells without carrier whose code change the next epoch undoes (or that undo the previous one's):
        a one-epoch jump and its return leave the pseudorange where it was."""
        zc, zp = self.z_median, self.carrier_z
        nxt = np.full_like(zc, np.nan)
        nxt[:-1] = zc[1:]
        with np.errstate(invalid="ignore"):
            start = np.isfinite(nxt) & (np.abs(zc + nxt) < 0.5 * np.abs(zc))
        spike = start.copy()
        spike[1:] |= start[:-1]  # the return
        return np.asarray(spike & ~np.isfinite(zp), dtype=bool)


def elevation_factor(elevation_rad: FloatArray) -> FloatArray:
    """sqrt(1 + 1/sin^2 el): how the code noise grows towards the horizon (RTKLIB's model)."""
    s = np.sin(np.clip(elevation_rad, 0.05, None))
    return np.asarray(np.sqrt(1.0 + 1.0 / s**2), dtype=float)


def _row_median(x: FloatArray, min_count: int = 3) -> FloatArray:
    ok = np.isfinite(x).sum(axis=1) >= min_count
    out = np.full(len(x), np.nan)
    if ok.any():
        out[ok] = np.nanmedian(x[ok], axis=1)
    return out


def pseudorange_changes(
    grid: ObservationGrid, ref: Reference, iono: Klobuchar | None, mask_deg: float = 10.0, max_gap_s: float = 120.0
) -> PseudorangeChanges:
    """z for every satellite and epoch of one receiver against a reference (module notes)."""
    E, S = grid.pseudorange_m.shape
    now = predicted(grid, ref.pos, iono)
    before = predicted(grid, ref.pos_prev[1:], iono, np.arange(E - 1))
    d_pred = np.full((E, S), np.nan)
    d_pred[1:] = now.code_m[1:] - before.code_m
    d_rho = epoch_change(grid.pseudorange_m)
    ok = grid.usable & ref.valid[:, None] & (now.elevation_rad >= np.radians(mask_deg))
    ok[1:] &= ok[:-1]  # both ends of the difference
    ok[0] = False
    dt = np.full(E, np.inf)
    dt[1:] = np.diff(grid.t_s)
    ok &= (dt <= max_gap_s)[:, None]
    z = np.where(ok, d_rho - d_pred, np.nan)
    common = _row_median(z)
    # millisecond resets: the common change jumps by a whole number of c x 1 ms against its usual value
    typical = np.nanmedian(common) if np.isfinite(common).any() else 0.0
    whole = np.round((common - typical) / MS_M)
    whole = np.where(np.isfinite(whole) & (np.abs(common - typical - whole * MS_M) < 0.05 * MS_M), whole, 0.0)
    resets = whole.astype(np.int64)
    z = z - (resets * MS_M)[:, None]
    common = common - resets * MS_M
    zm = z - common[:, None]
    factor = elevation_factor(now.elevation_rad)
    sigma = robust_scale(zm / factor, 1e-3)
    # each satellite's own level on top of the elevation model: multipath makes some noisier than their
    # elevation says (a robust scale per satellite over the log; one epoch's step does not move it)
    for j in range(S):
        col = zm[:, j] / (sigma * factor[:, j])
        if np.isfinite(col).sum() >= MIN_PER_SATELLITE:
            factor[:, j] *= max(robust_scale(col, 0.5), 0.5)
    arc_start = np.zeros((E, S), dtype=bool)
    arc_start[1:] = ok[1:] & ~ok[:-1]
    arc_start[0] = ok[0]
    d_pred_carrier = np.full((E, S), np.nan)
    d_pred_carrier[1:] = now.carrier_m[1:] - before.carrier_m
    zp = np.where(ok, epoch_change(grid.carrier_m) - d_pred_carrier, np.nan)
    zp = zp - _row_median(zp)[:, None]
    return PseudorangeChanges(grid.t_s, grid.sv_id, z, common, zm, sigma * factor, arc_start, resets, d_rho, zp)


def _clock_filter(m: FloatArray, r: float, q: float, gate: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Local linear trend Kalman filter on the common change m(k) (receiver clock change per epoch and its
    rate): predictions, their variances and the innovations. An epoch whose innovation exceeds `gate`
    sigmas is not learnt from (a common delay step is not the clock)."""
    F = np.array([[1.0, 1.0], [0.0, 1.0]])
    Q = q * np.array([[1 / 3, 1 / 2], [1 / 2, 1.0]])
    E = len(m)
    pred, var, innov = np.full(E, np.nan), np.full(E, np.nan), np.full(E, np.nan)
    x: FloatArray | None = None
    P = np.diag([r, r])
    for k in range(E):
        if not np.isfinite(m[k]):
            continue
        if x is None:
            x = np.array([m[k], 0.0])
            P = np.diag([r, 1e6 * r])
            continue
        x = F @ x
        P = F @ P @ F.T + Q
        S = P[0, 0] + r
        pred[k], var[k], innov[k] = x[0], S, m[k] - x[0]
        if innov[k] ** 2 > gate**2 * S and np.isfinite(pred[k - 1] if k else np.nan):
            continue
        K = P[:, 0] / S
        x = x + K * innov[k]
        P = P - np.outer(K, P[0, :])
    return pred, var, innov


def clock_model_residual(ch: PseudorangeChanges, gate: float = 5.0) -> tuple[FloatArray, FloatArray]:
    """The clock-model variant: z minus the common clock change predicted from the earlier epochs by a
    local-linear-trend Kalman filter on the cross-satellite medians. Its measurement noise is the median's
    (1.25 sigma / sqrt(n) of the satellites' noise); its process noise is the one of a grid (1e-4 to 1e2
    times that) that maximises the innovations' likelihood (each term capped, so attack epochs do not
    decide it). Returns (residual (E, S), predicted common change (E,))."""
    m = ch.common
    n = np.maximum(np.isfinite(ch.z).sum(axis=1), 1)
    noise = np.nanmedian(ch.sigma_m, axis=1) if np.isfinite(ch.sigma_m).any() else np.ones(len(m))
    r = float(np.nanmedian((1.25 * noise) ** 2 / n)) if np.isfinite(noise).any() else 1.0
    best: tuple[float, FloatArray] | None = None
    for ratio in 10.0 ** np.arange(-4, 3):
        pred, var, innov = _clock_filter(m, r, ratio * r, gate)
        ok = np.isfinite(innov)
        if not ok.any():
            continue
        cost = float(np.sum(np.log(var[ok]) + np.minimum(innov[ok] ** 2 / var[ok], 25.0)))
        if best is None or cost < best[0]:
            best = (cost, pred)
    pred = best[1] if best is not None else np.full(len(m), np.nan)
    return ch.z - pred[:, None], pred


# --- predictors ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Prediction:
    """One predictor's run over every arc: residuals, their predicted variances and what it alarmed."""

    name: str
    v: FloatArray  # (E, S) residual z - prediction, m
    S: FloatArray  # (E, S) predicted variance of v, m^2
    statistic: FloatArray  # (E, S) v^2 / S
    alarm: BoolArray  # (E, S)
    threshold: float


@dataclass(frozen=True)
class KalmanOptions:
    q: float = 1e-4  # white-jerk spectral density, in units of the cell's noise variance per epoch^5
    p0: tuple[float, float, float] = (1.0, 0.1, 0.01)
    max_coast: int = 5  # epochs an alarmed satellite coasts before its filter restarts at the new level


_F = np.array([[1.0, 1.0, 0.5], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]])
_Q_JERK = np.array([[1 / 20, 1 / 8, 1 / 6], [1 / 8, 1 / 3, 1 / 2], [1 / 6, 1 / 2, 1.0]])


def kalman_predictor(ch: PseudorangeChanges, threshold: float, opts: KalmanOptions | None = None) -> Prediction:
    """Constant-acceleration Kalman filter on each satellite's normalised z (vectorised over satellites)."""
    opts = opts or KalmanOptions()
    u = ch.z_median / ch.sigma_m
    E, S = u.shape
    x = np.zeros((S, 3))
    P = np.tile(np.diag(opts.p0), (S, 1, 1))
    coast = np.zeros(S, dtype=np.int64)
    v = np.full((E, S), np.nan)
    var = np.full((E, S), np.nan)
    alarm = np.zeros((E, S), dtype=bool)
    Q = opts.q * _Q_JERK
    P0 = np.diag(opts.p0)
    confirmed = ch.confirmed()
    for k in range(E):
        obs = np.isfinite(u[k])
        restart = obs & ch.arc_start[k]
        x[restart] = 0.0
        P[restart] = P0
        coast[restart] = 0
        x = x @ _F.T
        P = _F @ P @ _F.T + Q
        if not obs.any():
            continue
        innov = u[k] - x[:, 0]
        s = P[:, 0, 0] + 1.0
        stat = innov**2 / s
        hit = obs & (stat > threshold) & confirmed[k]
        v[k, obs] = innov[obs]
        var[k, obs] = s[obs]
        alarm[k] = hit
        coast = np.where(hit, coast + 1, 0)
        update = obs & ~hit
        too_long = hit & (coast > opts.max_coast)
        if update.any():
            K = P[update][:, :, 0] / s[update][:, None]
            x[update] += K * innov[update][:, None]
            P[update] -= K[:, :, None] * P[update][:, 0, :][:, None, :]
        if too_long.any():  # a lasting change is the new normal: start again from it
            x[too_long] = np.c_[u[k, too_long], np.zeros((int(too_long.sum()), 2))]
            P[too_long] = P0
            coast[too_long] = 0
    scale = ch.sigma_m
    return Prediction(
        "kalman", v * scale, var * scale**2, np.where(np.isfinite(v), v**2 / var, np.nan), alarm, threshold
    )


@dataclass(frozen=True)
class EsnOptions:
    units: int = 64
    spectral_radius: float = 0.9
    leak: float = 0.5
    input_scale: float = 0.5
    ridge: float = 1e-2
    washout: int = 10  # epochs of each arc before its reservoir state is trusted
    seed: int = 0
    max_coast: int = 5
    min_training: int = 50  # clean samples needed to train


@dataclass(frozen=True)
class EchoStateNetwork:
    W_in: FloatArray  # (N, 2): bias, input
    W: FloatArray  # (N, N)
    W_out: FloatArray  # (N + 2,): bias, input, state
    leak: float
    residual_var: float  # of the training residuals, normalised units

    def step(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """Reservoir states (S, N) after feeding inputs u (S,)."""
        pre = self.W_in[:, 0] + u[:, None] * self.W_in[:, 1] + x @ self.W.T
        return np.asarray((1.0 - self.leak) * x + self.leak * np.tanh(pre), dtype=float)

    def predict(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """Next input predicted from states x (S, N) and the inputs u (S,) that produced them."""
        return np.asarray(self.W_out[0] + self.W_out[1] * u + x @ self.W_out[2:], dtype=float)


def _reservoir(opts: EsnOptions) -> tuple[FloatArray, FloatArray]:
    rng = np.random.default_rng(opts.seed)
    W_in = rng.uniform(-opts.input_scale, opts.input_scale, (opts.units, 2))
    W = rng.uniform(-1.0, 1.0, (opts.units, opts.units))
    W *= opts.spectral_radius / np.max(np.abs(np.linalg.eigvals(W)))
    return W_in, W


def train_esn(
    u: FloatArray, arc_start: BoolArray, clean: BoolArray, opts: EsnOptions | None = None
) -> EchoStateNetwork:
    """Fit the readout by ridge regression on the clean cells (teacher forcing: the reservoir is fed the
    measured values), every satellite's arcs at once. ValueError when too few clean samples."""
    opts = opts or EsnOptions()
    W_in, W = _reservoir(opts)
    net = EchoStateNetwork(W_in, W, np.zeros(opts.units + 2), opts.leak, 1.0)
    E, S = u.shape
    x = np.zeros((S, opts.units))
    age = np.zeros(S, dtype=np.int64)
    feats, targets = [], []
    prev_u = np.zeros(S)
    prev_x = np.zeros((S, opts.units))
    for k in range(E):
        obs = np.isfinite(u[k])
        restart = obs & arc_start[k]
        x[restart] = 0.0
        age[restart] = 0
        age[~obs] = 0
        usable = obs & (age > opts.washout) & clean[k] & (k > 0)
        if usable.any():
            feats.append(np.c_[np.ones(int(usable.sum())), prev_u[usable], prev_x[usable]])
            targets.append(u[k, usable])
        feed = np.where(obs, u[k], 0.0)
        x = np.where(obs[:, None], net.step(x, feed), 0.0)
        prev_u, prev_x = feed, x.copy()
        age[obs] += 1
    if not feats or sum(len(t) for t in targets) < opts.min_training:
        n = sum(len(t) for t in targets) if targets else 0
        raise ValueError(f"{n} clean samples to train the recurrent network ({opts.min_training} needed)")
    A, y = np.concatenate(feats), np.concatenate(targets)
    W_out = np.linalg.solve(A.T @ A + opts.ridge * np.eye(A.shape[1]), A.T @ y)
    resid = y - A @ W_out
    return EchoStateNetwork(W_in, W, W_out, opts.leak, float(np.mean(resid**2)))


def esn_predictor(
    ch: PseudorangeChanges, net: EchoStateNetwork, threshold: float, opts: EsnOptions | None = None
) -> Prediction:
    """Run the trained network over every arc; an alarmed satellite is fed the network's own prediction."""
    opts = opts or EsnOptions()
    u = ch.z_median / ch.sigma_m
    E, S = u.shape
    x = np.zeros((S, opts.units))
    age = np.zeros(S, dtype=np.int64)
    coast = np.zeros(S, dtype=np.int64)
    prev_in = np.zeros(S)
    v = np.full((E, S), np.nan)
    alarm = np.zeros((E, S), dtype=bool)
    confirmed = ch.confirmed()
    for k in range(E):
        obs = np.isfinite(u[k])
        restart = obs & ch.arc_start[k]
        x[restart] = 0.0
        prev_in[restart] = 0.0
        age[restart | ~obs] = 0
        pred = net.predict(x, prev_in)
        innov = u[k] - pred
        judged = obs & (age > opts.washout)
        hit = judged & (innov**2 / net.residual_var > threshold) & confirmed[k]
        v[k, judged] = innov[judged]
        alarm[k] = hit
        coast = np.where(hit, coast + 1, 0)
        too_long = hit & (coast > opts.max_coast)
        feed = np.where(hit & ~too_long, pred, np.where(obs, u[k], 0.0))
        coast[too_long] = 0
        x = np.where(obs[:, None], net.step(x, feed), 0.0)
        prev_in = feed
        age[obs] += 1
    var = np.where(np.isfinite(v), net.residual_var, np.nan)
    scale = ch.sigma_m
    return Prediction("rnn", v * scale, var * scale**2, np.where(np.isfinite(v), v**2 / var, np.nan), alarm, threshold)


def compensation(pred: Prediction, arc_start: BoolArray, alpha: float) -> FloatArray:
    """Estimated spoofing offset of each satellite (m), summed over its alarmed epochs since its arc began:
    subtract it from the pseudorange to compensate (eq. 9 corrected; module notes)."""
    step = np.where(pred.alarm, alpha * np.nan_to_num(pred.v), 0.0)
    total = np.cumsum(step, axis=0)
    # restart the sum at every arc: what was summed before the arc began is subtracted back out
    before = np.zeros_like(total)
    for s in range(step.shape[1]):
        starts = np.flatnonzero(arc_start[:, s]).tolist()
        for a, b in zip(starts, [*starts[1:], len(step)][: len(starts)], strict=True):
            before[a:b, s] = total[a, s] - step[a, s]
    return np.asarray(total - before, dtype=float)
