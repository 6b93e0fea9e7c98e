"""Forward-backward smoothing of the loosely coupled filter: the best estimate of where the vehicle
was at every epoch given ALL the data (before and after), and its covariance.

Rauch-Tung-Striebel for a closed-loop error-state filter (kernels.rts_closed_loop). Between epochs the
smoothed position correction is interpolated linearly onto the filter's block-rate track for plotting.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spooflens.errors import AnalysisError
from spooflens.geodesy import radii
from spooflens.navigation import kernels
from spooflens.navigation.loosely_coupled import SMOOTHER_NEEDS, NavSolution

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SmoothedSolution:
    t: FloatArray  # (M,) GNSS epochs
    state: FloatArray  # (M, 22) smoothed nominal state (layout of NavSolution.state)
    delta: FloatArray  # (M, 24) smoothed error of the filtered state
    var: FloatArray  # (M, 24) smoothed variances (the diagonal of the smoothed covariance); (M, 0) not asked
    track_t: FloatArray  # (K,) block-rate times
    track_llh: FloatArray  # (K, 3) smoothed lat, lon (rad), h
    gm: FloatArray  # (M, 9) smoothed sensor errors (Gauss-Markov states)


def smooth(sol: NavSolution, variances: bool = True) -> SmoothedSolution:
    """The smoothed solution; without `variances` the smoothed error and track alone (equal to rounding,
    a fifth of the backward pass's arithmetic: all a drawn track needs)."""
    M = len(sol.t)
    if len(sol.Phi) != M or len(sol.Qd) != M or (sol.P_upd_every > 1 and len(sol.H) != M):
        raise ValueError(
            "smooth needs the solution's Phi and Qd (and H when it kept a part of the updated covariances): "
            f"run the filter with record={SMOOTHER_NEEDS!r}"
        )
    try:
        delta, var = kernels.rts_closed_loop(
            sol.P_upd,
            sol.P_upd_every,
            sol.Phi.head,
            sol.Phi.tail,
            sol.Qd.head,
            sol.Qd.tail,
            sol.H,
            sol.R,
            sol.used,
            sol.dx,
            variances,
        )
    except np.linalg.LinAlgError as err:  # non-finite covariances (`check_smoothable` finds them first)
        raise _cannot_invert(sol, str(err)) from None
    state = kernels.correct_all(sol.state, delta)
    return SmoothedSolution(sol.t, state, delta, var, sol.track_t, _smoothed_track(sol, delta), sol.gm + delta[:, 15:])


def check_smoothable(sol: NavSolution) -> None:
    """Raise the smoother's error now if the filter kept a covariance that is not finite (an IMU whose
    times or values are damage): what makes the smoother fail, found before it is begun in the background."""
    if not np.isfinite(sol.P_upd).all():
        raise _cannot_invert(sol, "not finite")


def _cannot_invert(sol: NavSolution, why: str) -> AnalysisError:
    return AnalysisError(
        f"INS {sol.imu_id}: the smoother met a covariance it cannot invert ({why}); the IMU's times or "
        "values do not carry a navigation"
    )


# block-rate track rows corrected at a time: a day of 1 Hz GNSS has 0.86 M blocks, and the correction's
# dozen temporaries over all of them (0.1 GB) were the day-long voyage's memory peak
TRACK_CHUNK = 65_536


def _smoothed_track(sol: NavSolution, delta: FloatArray) -> FloatArray:
    """Block-rate track with the smoothed position correction interpolated between epochs."""
    out = np.empty((len(sol.track_t), 3))
    for lo in range(0, len(out), TRACK_CHUNK):
        rows = slice(lo, lo + TRACK_CHUNK)
        out[rows] = _corrected(sol, delta, sol.track_epoch[rows], sol.track_t[rows], sol.track_llh[rows])
    return out


def _corrected(
    sol: NavSolution, delta: FloatArray, e: NDArray[np.int64], track_t: FloatArray, track_llh: FloatArray
) -> FloatArray:
    """Rows of the block-rate track (their epochs `e`, times and positions) with the smoothed correction."""
    M = len(sol.t)
    # correction known at the start of each inter-epoch segment (after epoch e) and at its end (epoch e+1,
    # relative to the nominal propagated from e: the filter's update there plus the smoothed error)
    # (the position errors only, states 6..8: the block-rate track is long, 0.2 GB a column set a day)
    pos = delta[:, 6:9]
    start = np.where(e[:, None] >= 0, pos[np.clip(e, 0, M - 1)], 0.0)
    nxt = np.clip(e + 1, 0, M - 1)
    end = np.where((e + 1 < M)[:, None], sol.dx[nxt, 6:9] + pos[nxt], start)
    t0 = np.where(e >= 0, sol.t[np.clip(e, 0, M - 1)], sol.track_t[0])
    t1 = np.where(e + 1 < M, sol.t[nxt], sol.track_t[-1])
    w = np.clip((track_t - t0) / np.maximum(t1 - t0, 1e-9), 0.0, 1.0)[:, None]
    d = (1 - w) * start + w * end
    lat, lon, h = track_llh.T
    rm, rn = radii(lat)
    return np.c_[lat - d[:, 1] / (rm + h), lon - d[:, 0] / ((rn + h) * np.cos(lat)), h - d[:, 2]]
