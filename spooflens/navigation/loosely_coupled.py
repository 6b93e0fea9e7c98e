"""Loosely coupled GNSS/INS: a closed-loop error-state Kalman filter over a whole log.

Between GNSS epochs the INS propagates in blocks (`strapdown.propagate`, at most `max_block_s` long)
and the error covariance with Phi, Qd of the 15-state model. At each GNSS epoch the measurement
z = INS - GNSS (position in ENU metres, velocity) updates the error state, the estimate is fed back
into the INS (closed loop) and the error state is reset to zero. Everything a detector or the smoother
needs is stored per epoch: z, the innovation (equal to z, the prior error being zero), S, NIS, R,
Phi and Qd from the previous epoch, P before and after the update, and the applied correction.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.epoch_table import EpochTable
from spooflens.errors import AnalysisError
from spooflens.estimation.statespace import BlockDiagonal, LinearGaussianModel
from spooflens.navigation import kernels
from spooflens.navigation.alignment import Alignment, align, flu_axes
from spooflens.navigation.error_model import (
    MEASUREMENT_NAMES,
    STATE_NAMES,
)
from spooflens.navigation.imu_models import ImuGrade, grade
from spooflens.navigation.strapdown import NavState, Preintegrated, preintegrate

FloatArray = NDArray[np.float64]
DEFAULT_SIGMA_POS = (3.7, 3.7, 6.0)  # seed 000's R when a log reports no accuracy
DEFAULT_SIGMA_VEL = 0.1
# the filter's first seconds, while its covariance converges from the initial state: no test alarms in them
FILTER_SETTLE_S = 20.0
GM_FLOOR = 1e-4  # a Gauss-Markov state switched off keeps this much variance (smoother stays invertible)


@dataclass(frozen=True)
class GnssNoise:
    """The receiver's measurement errors: white noise plus a first-order Gauss-Markov process per axis,
    (horizontal, vertical) 1-sigma values. `source` says where the numbers came from."""

    white_pos_m: tuple[float, float]
    gm_pos_m: tuple[float, float] = (0.0, 0.0)
    tau_pos_s: float = 100.0
    white_vel_mps: tuple[float, float] = (DEFAULT_SIGMA_VEL, DEFAULT_SIGMA_VEL)
    gm_vel_mps: tuple[float, float] = (0.0, 0.0)
    tau_vel_s: float = 10.0
    source: str = ""

    @property
    def has_velocity(self) -> bool:
        """False when the log's velocity was found unusable (no white noise learned for it: (0, 0))."""
        return self.white_vel_mps != (0.0, 0.0)

    def gm_arrays(self, odometry: OdometryAiding | None = None) -> tuple[FloatArray, FloatArray]:
        """(tau, sigma) of the nine Gauss-Markov states, in the kernel's order (pos ENU, vel ENU, odometry)."""
        odo_tau = odometry.tau_s if odometry is not None else 30.0
        odo_sigma = odometry.gm_mps if odometry is not None else (0.0, 0.0, 0.0)
        tau = np.r_[np.full(3, self.tau_pos_s), np.full(3, self.tau_vel_s), np.full(3, odo_tau)]
        (ph, pv), (vh, vv) = self.gm_pos_m, self.gm_vel_mps
        sigma = np.maximum(np.array([ph, ph, pv, vh, vh, vv, *odo_sigma], dtype=float), GM_FLOOR)
        return tau, sigma


@dataclass(frozen=True)
class OdometryAiding:
    """Wheel odometry as a body-velocity measurement: the IMU-to-vehicle rotation and the noise of the
    forward, lateral and vertical rows (lateral and vertical are the non-holonomic constraint)."""

    R_vb: FloatArray  # vehicle <- IMU body (FLU)
    sigma_mps: tuple[float, float, float] = (0.1, 0.1, 0.1)  # white, forward / lateral / vertical
    odometry_id: str = ""
    gm_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)  # Gauss-Markov part (scale, skid)
    tau_s: float = 30.0
    source: str = ""


@dataclass(frozen=True)
class FilterOptions:
    grade: ImuGrade = field(default_factory=lambda: grade("consumer_mems"))
    max_block_s: float = 0.1
    use_velocity: bool = True
    min_sigma_pos_m: float = 0.3  # floor on reported accuracies: receivers are optimistic
    min_sigma_vel_mps: float = 0.03
    sigma_pos_m: tuple[float, float, float] | None = None  # overrides the log's accuracies
    sigma_vel_mps: float | None = None
    noise: GnssNoise | None = None  # learned noise model; None: reported accuracies, white, as before
    odometry: OdometryAiding | None = None
    exclude_after_s: float | None = None  # ignore GNSS from this time on (coast on the INS) ...
    exclude_until_s: float | None = None  # ... up to this time (None: to the end of the log)
    exclude_velocity_too: bool = True
    # more stretches to leave GNSS out of (incidents already confirmed), (start, end or None)
    exclude_windows: tuple[tuple[float, float | None], ...] = ()
    initial: NavState | None = None  # skip alignment (simulation benchmarks start from truth)
    # continue from another run's epoch: its covariance (24 x 24) and sensor-error estimates (9)
    initial_covariance: FloatArray | None = None
    initial_gm: FloatArray | None = None
    # the per-epoch matrices to keep: True all (RECORDED), False none (noise learning needs only S, a
    # coast only S_all), or those named (a run only smoothed needs SMOOTHER_NEEDS)
    record: bool | tuple[str, ...] = True
    # the updated covariance of every n-th epoch only (when recorded): the smoother and continued runs
    # make the others again from the last kept (0.15 GB per hour of 10 Hz GNSS with 10)
    P_upd_every: int = 1
    compare: bool = True  # keep S_all (what coasting compares GNSS with)
    t_start: float | None = None


RECORDED = ("Phi", "Qd", "H", "P_pred", "P_upd")
SMOOTHER_NEEDS = ("Phi", "Qd", "H", "P_upd")  # H: to make the updated covariances a thinned run left out
# an analysis's solution: the smoother, the detectors' model (Phi, Qd, H) and coasts (P_upd); the
# predicted covariances only at the first epoch, the model's prior (the smoother makes the rest)
ANALYSIS_NEEDS = ("Phi", "Qd", "H", "P_upd")


def _recorded_names(record: bool | tuple[str, ...]) -> tuple[str, ...]:
    return RECORDED if record is True else () if record is False else record


def _kept(record: bool | tuple[str, ...]) -> NDArray[np.bool_]:
    names = _recorded_names(record)
    unknown = set(names) - set(RECORDED)
    if unknown:
        raise ValueError(f"FilterOptions.record names {sorted(unknown)!r}; it can keep {RECORDED!r}")
    return np.array([name in names for name in RECORDED], dtype=np.bool_)


def quadratic_forms(nu: FloatArray, S: FloatArray) -> FloatArray:
    """nu_k^T S_k^-1 nu_k for a stack of innovations and covariances; NaN where either is not finite.
    A singular covariance (a degenerate epoch of a long log) is solved by least squares, not refused."""
    out = np.full(len(nu), np.nan)
    ok = np.isfinite(nu).all(axis=1) & np.isfinite(S).all(axis=(1, 2))
    if not ok.any():
        return out
    e, C = nu[ok], S[ok]
    try:
        weighted = np.linalg.solve(C, e[..., None])[..., 0]
    except np.linalg.LinAlgError:
        weighted = (np.linalg.pinv(C, hermitian=True) @ e[..., None])[..., 0]
    out[ok] = np.einsum("ni,ni->n", e, weighted)
    return out


def nis_by_pattern(
    nu: FloatArray, S: FloatArray, present: NDArray[np.bool_], rows: tuple[int, ...]
) -> tuple[FloatArray, NDArray[np.int64]]:
    """NIS of the measurement `rows` present at each epoch (`present`: epochs x len(rows)), over the
    rows present there, and its degrees of freedom; the epochs are grouped by which rows they have."""
    idx = np.array(rows)
    dof = present.sum(axis=1).astype(np.int64)
    nis = np.full(len(nu), np.nan)
    for pattern in np.unique(present[dof > 0], axis=0):
        k = np.flatnonzero((present == pattern).all(axis=1))
        r = idx[pattern]
        nis[k] = quadratic_forms(nu[np.ix_(k, r)], S[np.ix_(k, r, r)])  # those rows only, not all 9 x 9
    return nis, dof


@dataclass
class NavSolution:
    """The filter's record. Arrays are per GNSS epoch (M) unless named as per block. Measurement rows
    (9): GNSS position ENU, GNSS velocity ENU, odometry body velocity; states (24): 15 INS errors and
    nine Gauss-Markov sensor errors (`error_model.STATE_NAMES`)."""

    imu_id: str
    receiver_id: str
    grade: ImuGrade
    alignment: Alignment | None
    t: FloatArray  # (M,)
    z: FloatArray  # (M, 9) INS - measurement, NaN where not measured
    nu: FloatArray  # (M, 9) innovation: z minus the predicted receiver error
    used: NDArray[np.bool_]  # (M, 9)
    S: FloatArray  # (M, 9, 9) innovation covariance of the used rows (zero elsewhere)
    S_all: FloatArray  # (M, 9, 9) the same for every measured row, used or not (GNSS left out: coasting)
    # H, Phi, Qd, P_pred and P_upd not named in options.record hold one epoch only (not kept), and S_all
    # too without options.compare.
    R: FloatArray  # (M, 9, 9)
    H: FloatArray  # (M, 9, 24); without odometry one matrix seen at every epoch (read-only, stride 0)
    nis: FloatArray  # (M,)
    dof: NDArray[np.int64]  # (M,)
    logdet_S: FloatArray  # (M,) log det S of the used rows; NaN where S is not positive definite, or none used
    Phi: BlockDiagonal  # (M, 24, 24) from the previous epoch (identity at the first): 15 x 15 block, diagonal
    Qd: BlockDiagonal  # (M, 24, 24), the same shape
    P_pred: FloatArray  # (M, 24, 24) when recorded; else the first epoch only
    P_upd: FloatArray  # (M, 24, 24); with P_upd_every > 1, epochs 0, P_upd_every, 2 P_upd_every, ... only
    dx: FloatArray  # (M, 24) update (INS part applied to the nominal state, receiver part kept)
    gm: FloatArray  # (M, 9) estimated sensor errors (receiver, odometry) after the update
    state: FloatArray  # (M, 22) after the update, columns STATE_COLUMNS (C_b^n row-major)
    track_t: FloatArray  # (K,) block ends
    track_llh: FloatArray  # (K, 3) lat, lon (rad), h
    track_v: FloatArray  # (K, 3)
    track_epoch: NDArray[np.int64]  # (K,) index of the last epoch at or before each block end
    options: FilterOptions = field(default_factory=FilterOptions)
    P_upd_every: int = 1
    state_names: tuple[str, ...] = STATE_NAMES
    measurement_names: tuple[str, ...] = MEASUREMENT_NAMES

    @property
    def innovation(self) -> FloatArray:
        return self.nu

    def error_model(self) -> LinearGaussianModel:
        """The filter's linearised error model as a LinearGaussianModel, for the model-based detectors.

        The closed-loop filter corrects its nominal trajectory at every update, so its measurements z_k are
        relative to a moving linearisation point. Adding back the INS corrections already applied, propagated
        through the model (u_k = Phi_k (u_{k-1} + dx_{k-1}), u_0 = 0, INS part only: the receiver's
        Gauss-Markov error states are estimated, never fed back), gives open-loop-equivalent measurements
        y_k = z_k + H_k u_k that follow ONE linear model: eps_k = Phi_k eps_{k-1} + w_k, y_k = H_k eps_k + e_k.
        A plain Kalman filter on it, started at zero with P_pred[0], reproduces the closed-loop filter's
        innovations and covariances exactly (tests/navigation/test_filter.py).
        """
        M, n = self.dx.shape
        applied = self.dx.copy()
        applied[:, 15:] = 0.0
        u = np.zeros((M, n))  # the Gauss-Markov part stays zero: nothing is applied there
        head = self.Phi.head
        h = head.shape[1]
        for k in range(1, M):
            u[k, :h] = head[k] @ (u[k - 1, :h] + applied[k - 1, :h])
        y = self.z + np.einsum("kij,kj->ki", self.H, u)
        y = np.where(self.used, y, np.nan)
        return LinearGaussianModel(
            # the solution's own arrays, not copies (166 MB each per hour of 10 Hz GNSS): nothing writes them
            t=self.t,
            A=self.Phi,
            Q=self.Qd,
            C=self.H,
            R=self.R,
            y=y,
            x0=np.zeros(n),
            P0=self.P_pred[0].copy(),
            state_names=STATE_NAMES,
            measurement_names=MEASUREMENT_NAMES,
        )


_FILTER_COLUMNS = (
    "vel_e_mps",
    "vel_n_mps",
    "vel_u_mps",
    "lat_deg",
    "lon_deg",
    "height_m",
    "h_acc_m",
    "v_acc_m",
    "vel_acc_mps",
)


def _measurement_sigmas(fixes: Mapping[str, FloatArray], n: int, opts: FilterOptions) -> FloatArray:
    """(n, 9) 1-sigma of each measurement row: the learned noise when given, else reported accuracies
    (`fixes`: column name -> values)."""
    out = np.zeros((n, 9))
    if opts.sigma_pos_m is not None:
        sp = np.tile(opts.sigma_pos_m, (n, 1))
    elif opts.noise is not None:
        (h, v) = opts.noise.white_pos_m
        sp = np.tile([h, h, v], (n, 1))
    else:
        reported = np.c_[fixes["h_acc_m"], fixes["h_acc_m"], fixes["v_acc_m"]]
        sp = np.where(np.isfinite(reported) & (reported > 0), reported, np.tile(DEFAULT_SIGMA_POS, (n, 1)))
        sp = np.maximum(sp, opts.min_sigma_pos_m)
    if opts.sigma_vel_mps is not None:
        sv = np.full((n, 3), opts.sigma_vel_mps)
    elif opts.noise is not None:
        (h, v) = opts.noise.white_vel_mps
        sv = np.tile([h, h, v], (n, 1))
    else:
        a = fixes["vel_acc_mps"]
        a = np.maximum(np.where(np.isfinite(a) & (a > 0), a, DEFAULT_SIGMA_VEL), opts.min_sigma_vel_mps)
        sv = np.repeat(a[:, None], 3, axis=1)
    out[:, 0:3], out[:, 3:6] = sp, sv
    out[:, 6:9] = opts.odometry.sigma_mps if opts.odometry is not None else 1.0
    return out


def odometry_at(table: EpochTable, odometry_id: str, t: FloatArray, max_gap_s: float = 0.3) -> FloatArray:
    """(M, 3) vehicle-frame velocity of an odometry stream at times t (linear interpolation between
    samples at most `max_gap_s` apart; NaN elsewhere)."""
    od = table.odometry[table.odometry["odometry_id"] == odometry_id]
    out = np.full((len(t), 3), np.nan)
    if len(od) < 2:
        return out
    to = od["t_s"].to_numpy(dtype=float)
    v = od[["vx_mps", "vy_mps", "vz_mps"]].to_numpy(dtype=float)
    k = np.clip(np.searchsorted(to, t), 1, len(to) - 1)
    t0, t1 = to[k - 1], to[k]
    ok = (t >= t0 - 1e-9) & (t <= t1 + 1e-9) & (t1 - t0 <= max_gap_s)
    w = np.clip((t - t0) / np.maximum(t1 - t0, 1e-9), 0.0, 1.0)[:, None]
    out[ok] = ((1 - w) * v[k - 1] + w * v[k])[ok]
    return out


STATE_COLUMNS = (
    "lat",
    "lon",
    "h",
    "ve",
    "vn",
    "vu",
    "c00",
    "c01",
    "c02",
    "c10",
    "c11",
    "c12",
    "c20",
    "c21",
    "c22",
    "bgx",
    "bgy",
    "bgz",
    "bax",
    "bay",
    "baz",
    "t",
)


def select_streams(table: EpochTable, imu_id: str | None, receiver_id: str | None) -> tuple[str, str, str]:
    imus, rxs = table.imus(), table.receivers()
    if not imus or not rxs:
        raise AnalysisError(
            f"{table.source}: the INS filter needs an IMU and a GNSS receiver (IMUs {imus}, receivers {rxs})"
        )
    imu_id = imu_id or imus[0]
    receiver_id = receiver_id or rxs[0]
    if imu_id not in imus or receiver_id not in rxs:
        raise AnalysisError(f"{table.source}: no IMU {imu_id!r} or receiver {receiver_id!r} (have {imus}, {rxs})")
    info = table.stream("imu", imu_id)
    return imu_id, receiver_id, (info.body_frame if info and info.body_frame else "FLU")


@dataclass(frozen=True)
class FilterInputs:
    """What every run of the filter over one IMU and receiver shares: the preintegrated IMU, the fixes,
    the odometry at the fix times and the initial state (computed once, reused by every pass)."""

    table: EpochTable
    imu_id: str
    receiver_id: str
    pre: Preintegrated
    imu: pd.DataFrame
    fixes: pd.DataFrame
    odometry_ids: tuple[str, ...]
    _odometry_at: dict[str, FloatArray] = field(default_factory=dict, init=False, repr=False, compare=False)

    @cached_property
    def fix_columns(self) -> dict[str, FloatArray]:
        """The fixes' columns the filter reads, as arrays: taken out of the frame once (noise learning runs
        the filter some 90 times over the same inputs; the frame's column lookups were a tenth of a run)."""
        return {c: self.fixes[c].to_numpy(dtype=float) for c in ("t_s", *_FILTER_COLUMNS)}

    def odometry_at_fixes(self, odometry_id: str) -> FloatArray:
        """`odometry_at` the fix times (made once per odometry stream, as `fix_columns`)."""
        if odometry_id not in self._odometry_at:
            self._odometry_at[odometry_id] = odometry_at(self.table, odometry_id, self.fix_columns["t_s"])
        return self._odometry_at[odometry_id]

    @property
    def odometry_id(self) -> str | None:
        """The odometry the navigation uses: the log's first, if it has any."""
        return self.odometry_ids[0] if self.odometry_ids else None

    def between(self, t_after: float, t_end: float | None = None) -> FilterInputs:
        """The inputs from t_after (fixes strictly after it) to t_end: a filter run continued from another
        run's epoch at t_after (`FilterOptions.initial*`) covers only this span."""
        pre = self.pre
        end = np.inf if t_end is None else t_end
        k0 = max(int(np.searchsorted(pre.t, t_after, side="right")) - 1, 0)
        # from the integrals' checkpoint at or before it: views, not integrals made again to the log's end
        # (a continued run starts at its initial state's time, however early its samples begin)
        k0 -= k0 % pre.every
        k1 = int(np.searchsorted(pre.t, end + 1.0))
        cut = pre.between(k0, k1)
        t = self.fixes["t_s"].to_numpy(dtype=float)
        fixes = self.fixes[(t > t_after) & (t <= end)].reset_index(drop=True)
        return replace(self, pre=cut, fixes=fixes)


def prepare(table: EpochTable, imu_id: str | None = None, receiver_id: str | None = None) -> FilterInputs:
    imu_id, receiver_id, body = select_streams(table, imu_id, receiver_id)
    imu = table.imu_of(imu_id)
    fixes = table.fixes_of(receiver_id)
    if len(imu) < 10:
        raise AnalysisError(f"{table.source} [{imu_id}]: only {len(imu)} IMU samples")
    t_imu = imu["t_s"].to_numpy(dtype=float)
    f_b = flu_axes([imu[c].to_numpy(dtype=float) for c in ("ax_mps2", "ay_mps2", "az_mps2")], body)
    w_b = flu_axes([imu[c].to_numpy(dtype=float) for c in ("wx_radps", "wy_radps", "wz_radps")], body)
    odometry_ids = tuple(dict.fromkeys(table.odometry["odometry_id"].astype(str)))
    return FilterInputs(table, imu_id, receiver_id, preintegrate(t_imu, f_b, w_b), imu, fixes, odometry_ids)


def initial_state(inputs: FilterInputs, opts: FilterOptions) -> tuple[NavState, Alignment | None]:
    if opts.initial is not None:
        return opts.initial.copy(), None
    t0 = opts.t_start if opts.t_start is not None else float(inputs.pre.t[0])
    alignment = align(inputs.pre, inputs.imu, inputs.fixes, t0)
    s = NavState(alignment.t0, alignment.lat0, alignment.lon0, alignment.h0, alignment.v0.copy(), alignment.C0.copy())
    return s, alignment


def run_prepared(
    inputs: FilterInputs, opts: FilterOptions, start: tuple[NavState, Alignment | None] | None = None
) -> NavSolution:
    """One pass of the filter over prepared inputs (`start` reuses an alignment already made)."""
    s, alignment = start if start is not None else initial_state(inputs, opts)
    odo = None
    if opts.odometry is not None:
        odo = inputs.odometry_at_fixes(opts.odometry.odometry_id)
    return _run(inputs.pre, inputs.fix_columns, s.copy(), opts, inputs.imu_id, inputs.receiver_id, alignment, odo)


def run_filter(
    table: EpochTable, imu_id: str | None = None, receiver_id: str | None = None, options: FilterOptions | None = None
) -> NavSolution:
    """The closed-loop filter over one IMU and one receiver of `table`."""
    opts = options or FilterOptions()
    return run_prepared(prepare(table, imu_id, receiver_id), opts)


def _run(
    pre: Preintegrated,
    fixes: Mapping[str, FloatArray],
    s: NavState,
    opts: FilterOptions,
    imu_id: str,
    receiver_id: str,
    alignment: Alignment | None,
    odometry: FloatArray | None = None,
) -> NavSolution:
    tf = fixes["t_s"]
    keep = (tf >= s.t - 1e-9) & (tf <= pre.t[-1] + 1e-9)
    tf = tf[keep]
    needed = 1 if opts.initial is not None else 2  # a continued run may cover one epoch
    if len(tf) < needed:
        few = "no GNSS fix" if needed == 1 else "fewer than two GNSS fixes"
        raise AnalysisError(f"{few} of {receiver_id} inside the IMU's time span")
    # the columns the filter reads, not the frame (noise learning runs this ~90 times; a wide frame's
    # boolean selection was 12% of it)
    cols = {c: fixes[c][keep] for c in _FILTER_COLUMNS}
    sigma = _measurement_sigmas(cols, len(tf), opts)
    vel = np.column_stack([cols["vel_e_mps"], cols["vel_n_mps"], cols["vel_u_mps"]])
    if not opts.use_velocity or (opts.noise is not None and not opts.noise.has_velocity):
        vel = np.full_like(vel, np.nan)  # a velocity with no noise learned (e.g. an axis missing) is not used
    llh = np.column_stack([cols["lat_deg"], cols["lon_deg"], cols["height_m"]])
    odo = np.full((len(tf), 3), np.nan) if odometry is None else np.asarray(odometry, dtype=float)[keep]
    odometry_measured = bool(np.isfinite(odo).any())
    R_vb = opts.odometry.R_vb if opts.odometry is not None else np.eye(3)
    use = np.ones((len(tf), 9), dtype=np.bool_)
    use[:, 6:9] = opts.odometry is not None
    windows = list(opts.exclude_windows)
    if opts.exclude_after_s is not None:
        windows.append((opts.exclude_after_s, opts.exclude_until_s))
    for a, b in windows:
        late = (tf >= a) & (tf <= (np.inf if b is None else b))
        use[late, :3] = False
        if opts.exclude_velocity_too:
            use[late, 3:6] = False
    noise = opts.noise or GnssNoise(white_pos_m=(1.0, 1.0))
    gm_tau, gm_sigma = noise.gm_arrays(opts.odometry)
    qc = np.r_[opts.grade.qc_diagonal(), np.zeros(len(gm_sigma))]
    P0 = np.diag(np.r_[opts.grade.p0_diagonal(), gm_sigma**2])
    if opts.initial_covariance is not None:
        P0 = np.array(opts.initial_covariance, dtype=float)
    g0 = np.zeros(len(gm_sigma)) if opts.initial_gm is None else np.array(opts.initial_gm, dtype=float)
    (
        z,
        nu,
        S,
        S_all,
        R,
        H,
        nis,
        dof,
        logdet_S,
        Phi,
        Phi_gm,
        Qd,
        Qd_gm,
        P_pred,
        P_upd,
        dx,
        gm,
        states,
        track,
        track_epoch,
    ) = kernels.filter_loop(
        pre.kernel_args(),
        s.to_vector(),
        P0,
        qc,
        float(opts.max_block_s),
        tf,
        np.c_[np.radians(llh[:, 0]), np.radians(llh[:, 1]), llh[:, 2]],
        vel,
        odo,
        np.ascontiguousarray(R_vb, dtype=float),
        sigma,
        use,
        gm_tau,
        gm_sigma,
        g0,
        _kept(opts.record),
        opts.compare,
        max(1, int(opts.P_upd_every)),
        odometry_measured,
    )
    if not odometry_measured and "H" in _recorded_names(opts.record):
        # one matrix for every epoch, seen as (M, 9, 24) without its copies (0.15 GB a day of 1 Hz GNSS)
        H = np.broadcast_to(H[0], (len(tf), *H.shape[1:]))
    return NavSolution(
        imu_id,
        receiver_id,
        opts.grade,
        alignment,
        tf,
        z,
        nu,
        use & np.isfinite(z),
        S,
        S_all,
        R,
        H,
        nis,
        dof,
        logdet_S,
        BlockDiagonal(Phi, Phi_gm),
        BlockDiagonal(Qd, Qd_gm),
        P_pred,
        P_upd,
        dx,
        gm,
        states,
        track[:, 0],
        track[:, 1:4],
        track[:, 4:7],
        track_epoch,
        opts,
        max(1, int(opts.P_upd_every)),
    )
