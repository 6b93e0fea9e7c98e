"""Loosely coupled GNSS/INS: a closed-loop error-state Kalman filter over a whole log.

Between GNSS epochs the INS propagates in blocks (`strapdown.propagate`, at most `max_block_s` long)
and the error covariance with Phi, Qd of the 15-state model. At each GNSS epoch the measurement
z = INS - GNSS (position in ENU metres, velocity) updates the error state, the estimate is fed back
into the INS (closed loop) and the error state is reset to zero. Everything a detector or the smoother
needs is stored per epoch: z, the innovation (equal to z, the prior error being zero), S, NIS, R,
Phi and Qd from the previous epoch, P before and after the update, and the applied correction.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.epoch_table import EpochTable
from spooflens.errors import AnalysisError
from spooflens.navigation import kernels
from spooflens.navigation.alignment import Alignment, align, to_flu
from spooflens.navigation.error_model import (
    MEASUREMENT_NAMES,
    STATE_NAMES,
)
from spooflens.navigation.imu_models import ImuGrade, grade
from spooflens.navigation.strapdown import NavState, Preintegrated, preintegrate

FloatArray = NDArray[np.float64]
DEFAULT_SIGMA_POS = (3.7, 3.7, 6.0)  # seed 000's R when a log reports no accuracy
DEFAULT_SIGMA_VEL = 0.1


@dataclass(frozen=True)
class FilterOptions:
    grade: ImuGrade = field(default_factory=lambda: grade("consumer_mems"))
    max_block_s: float = 0.1
    use_velocity: bool = True
    min_sigma_pos_m: float = 0.3  # floor on reported accuracies: receivers are optimistic
    min_sigma_vel_mps: float = 0.03
    sigma_pos_m: tuple[float, float, float] | None = None  # overrides the log's accuracies
    sigma_vel_mps: float | None = None
    exclude_after_s: float | None = None  # ignore GNSS from this time on (coast on the INS) ...
    exclude_until_s: float | None = None  # ... up to this time (None: to the end of the log)
    exclude_velocity_too: bool = True
    initial: NavState | None = None  # skip alignment (simulation benchmarks start from truth)
    t_start: float | None = None


@dataclass
class NavSolution:
    """The filter's record. Arrays are per GNSS epoch (M) unless named as per block."""

    imu_id: str
    receiver_id: str
    grade: ImuGrade
    alignment: Alignment | None
    t: FloatArray  # (M,)
    z: FloatArray  # (M, 6) INS - GNSS, NaN where not measured
    used: NDArray[np.bool_]  # (M, 6)
    S: FloatArray  # (M, 6, 6) innovation covariance of the used rows (zero elsewhere)
    R: FloatArray  # (M, 6, 6)
    nis: FloatArray  # (M,)
    dof: NDArray[np.int64]  # (M,)
    Phi: FloatArray  # (M, 15, 15) from the previous epoch (identity at the first)
    Qd: FloatArray  # (M, 15, 15)
    P_pred: FloatArray  # (M, 15, 15)
    P_upd: FloatArray  # (M, 15, 15)
    dx: FloatArray  # (M, 15) applied correction
    state: FloatArray  # (M, 22) after the update, columns STATE_COLUMNS (C_b^n row-major)
    track_t: FloatArray  # (K,) block ends
    track_llh: FloatArray  # (K, 3) lat, lon (rad), h
    track_v: FloatArray  # (K, 3)
    track_epoch: NDArray[np.int64]  # (K,) index of the last epoch at or before each block end
    state_names: tuple[str, ...] = STATE_NAMES
    measurement_names: tuple[str, ...] = MEASUREMENT_NAMES

    @property
    def innovation(self) -> FloatArray:
        return self.z

    def error_model(self):
        from spooflens.navigation.solution_model import error_model

        return error_model(self)


def _fix_arrays(fixes: pd.DataFrame, opts: FilterOptions) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Per-fix measurement sigmas (position ENU, velocity) and values."""
    n = len(fixes)
    if opts.sigma_pos_m is not None:
        sp = np.tile(opts.sigma_pos_m, (n, 1))
    else:
        h = fixes["h_acc_m"].to_numpy(dtype=float)
        v = fixes["v_acc_m"].to_numpy(dtype=float)
        sp = np.c_[h, h, v]
        default = np.tile(DEFAULT_SIGMA_POS, (n, 1))
        sp = np.where(np.isfinite(sp) & (sp > 0), sp, default)
    sp = np.maximum(sp, opts.min_sigma_pos_m)
    vel = fixes[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy(dtype=float)
    if opts.sigma_vel_mps is not None:
        sv = np.full(n, opts.sigma_vel_mps)
    else:
        sv = fixes["vel_acc_mps"].to_numpy(dtype=float)
        sv = np.where(np.isfinite(sv) & (sv > 0), sv, DEFAULT_SIGMA_VEL)
    sv = np.maximum(sv, opts.min_sigma_vel_mps)
    return sp, sv, vel, fixes[["lat_deg", "lon_deg", "height_m"]].to_numpy(dtype=float)


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


def run_filter(
    table: EpochTable, imu_id: str | None = None, receiver_id: str | None = None, options: FilterOptions | None = None
) -> NavSolution:
    """The closed-loop filter over one IMU and one receiver of `table`."""
    opts = options or FilterOptions()
    imu_id, receiver_id, body = select_streams(table, imu_id, receiver_id)
    imu = table.imu_of(imu_id)
    fixes = table.fixes_of(receiver_id)
    if len(imu) < 10:
        raise AnalysisError(f"{table.source} [{imu_id}]: only {len(imu)} IMU samples")
    t_imu = imu["t_s"].to_numpy(dtype=float)
    f_b = to_flu(imu[["ax_mps2", "ay_mps2", "az_mps2"]].to_numpy(dtype=float), body)
    w_b = to_flu(imu[["wx_radps", "wy_radps", "wz_radps"]].to_numpy(dtype=float), body)
    pre = preintegrate(t_imu, f_b, w_b)
    if opts.initial is not None:
        s, alignment = opts.initial.copy(), None
    else:
        alignment = align(pre, imu, fixes, opts.t_start if opts.t_start is not None else t_imu[0])
        s = NavState(
            alignment.t0, alignment.lat0, alignment.lon0, alignment.h0, alignment.v0.copy(), alignment.C0.copy()
        )
    return _run(pre, fixes, s, opts, imu_id, receiver_id, alignment)


def _run(
    pre: Preintegrated,
    fixes: pd.DataFrame,
    s: NavState,
    opts: FilterOptions,
    imu_id: str,
    receiver_id: str,
    alignment: Alignment | None,
) -> NavSolution:
    tf = fixes["t_s"].to_numpy(dtype=float)
    keep = (tf >= s.t - 1e-9) & (tf <= pre.t[-1] + 1e-9)
    fixes = fixes[keep].reset_index(drop=True)
    tf = tf[keep]
    if len(tf) < 2:
        raise AnalysisError(f"fewer than two GNSS fixes of {receiver_id} inside the IMU's time span")
    sp, sv, vel, llh = _fix_arrays(fixes, opts)
    has_vel = np.isfinite(vel).all(axis=1) & opts.use_velocity
    vel = np.where(has_vel[:, None], vel, np.nan)
    use = np.zeros((len(tf), 6), dtype=np.bool_)
    use[:, :3] = True
    use[:, 3:] = has_vel[:, None]
    if opts.exclude_after_s is not None:
        late = (tf >= opts.exclude_after_s) & (tf <= (np.inf if opts.exclude_until_s is None else opts.exclude_until_s))
        use[late, :3] = False
        if opts.exclude_velocity_too:
            use[late, 3:] = False
    (z, S, R, nis, dof, Phi, Qd, P_pred, P_upd, dx, states, track, track_epoch) = kernels.filter_loop(
        pre.t,
        pre.Qb,
        pre.G,
        pre.H,
        pre.f,
        s.to_vector(),
        np.diag(opts.grade.p0_diagonal()),
        opts.grade.qc_diagonal(),
        float(opts.max_block_s),
        tf,
        np.c_[np.radians(llh[:, 0]), np.radians(llh[:, 1]), llh[:, 2]],
        vel,
        sp,
        sv,
        use,
    )
    return NavSolution(
        imu_id,
        receiver_id,
        opts.grade,
        alignment,
        tf,
        z,
        use,
        S,
        R,
        nis,
        dof,
        Phi,
        Qd,
        P_pred,
        P_upd,
        dx,
        states,
        track[:, 0],
        track[:, 1:4],
        track[:, 4:7],
        track_epoch,
    )
