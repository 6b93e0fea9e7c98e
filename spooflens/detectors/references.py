"""What the raw-observation detectors compare a receiver's signals with: where the receiver was, known
independently of its GNSS.

- a **known station** (`Evidence.KNOWN_STATION`; which receivers are stations: `spooflens.gnss.stations`):
  zero velocity, the same position at every epoch.
- the **INS over a window** (`Evidence.INERTIAL`): the GNSS/INS solution is corrected by the receiver's
  own (possibly spoofed) fixes, so at each observation epoch k the INS is restarted from the filter's
  state at least `window_s` earlier and propagated by the IMU alone to epochs k-1 and k. An attack is
  then seen against a clean reference for its first `window_s`; later restarts have seen the spoofed
  fixes. The antenna lever arm is not known and not applied.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spooflens.geodesy import ecef_to_geodetic, enu_rotation, geodetic_to_ecef
from spooflens.gnss.grid import ObservationGrid
from spooflens.gnss.stations import Station
from spooflens.navigation.loosely_coupled import FILTER_SETTLE_S
from spooflens.navigation.product import navigation_of
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.registry import AnalysisContext

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Reference:
    """Where the receiver was at each epoch of an observation grid, independently of its GNSS.

    `pos_prev[k]` is the position at epoch k-1 as seen by the same reference run as `pos[k]` (a free INS
    restarted before k-1), so pos[k] - pos_prev[k] carries that run's drift over one epoch only.
    """

    kind: str  # "station" or "ins"
    description: str
    evidence: Evidence
    pos_prev: FloatArray  # (E, 3) ECEF, NaN where unknown
    pos: FloatArray  # (E, 3)
    vel: FloatArray  # (E, 3) ECEF velocity at epoch k
    # (E,) when the GNSS last touched the reference used at epoch k (the INS restart state's time; -inf for
    # a station): after an alarm, references restarted later have seen the spoofed fixes
    informed_s: FloatArray | None = None
    # (E,) horizontal velocity change over the free run, m/s: a heading error turns it into a velocity error,
    # so the reference's error grows with it in turns and accelerations; None for a station
    dynamics_mps: FloatArray | None = None

    def contaminated(self, k: int, since_s: float) -> bool:
        """Whether epoch k's reference was informed by the GNSS at or after `since_s`."""
        return self.informed_s is not None and bool(self.informed_s[k] >= since_s)

    @property
    def valid(self) -> NDArray[np.bool_]:
        return np.asarray(np.isfinite(self.pos).all(axis=1), dtype=bool)


def station_reference(grid: ObservationGrid, station: Station) -> Reference:
    E = grid.n_epochs
    pos = np.tile(station.ecef_m, (E, 1))
    lat, lon, h = ecef_to_geodetic(station.ecef_m)
    return Reference(
        "station",
        f"known station {float(lat):.6f}, {float(lon):.6f}, {float(h):.1f} m ({station.source})",
        Evidence.KNOWN_STATION,
        pos.copy(),
        pos,
        np.zeros((E, 3)),
    )


def ins_reference(
    ctx: AnalysisContext,
    grid: ObservationGrid,
    window_s: float,
    settle_s: float = FILTER_SETTLE_S,
    block_s: float = 1.0,
) -> Reference:
    """The free INS restarted at least `window_s` before each epoch (module notes); computed once per
    analysis and receiver (both raw-observation detectors use it)."""
    key = f"ins_reference/{grid.receiver_id}/{window_s:g}/{settle_s:g}/{block_s:g}/{grid.n_epochs}"
    ref: Reference = ctx.cached(key, lambda: _ins_reference(ctx, grid, window_s, settle_s, block_s))
    return ref


def _ins_reference(
    ctx: AnalysisContext, grid: ObservationGrid, window_s: float, settle_s: float, block_s: float
) -> Reference:
    """Restarts only from states after the filter has settled: `settle_s` after its start and not before the
    alignment's window ends (until then the heading is not known to its stated accuracy and a free run
    from it drifts by metres per second in the first turn)."""
    from spooflens.navigation.strapdown import NavState, propagate

    nav = navigation_of(ctx)
    sol = nav.solution
    pre = nav.inputs.pre  # the filter's own preintegration of this IMU (not a second one: 1 GB a day)
    states = np.asarray(sol.state, dtype=float)
    t_state = states[:, -1]  # the IMU sample time each post-update state refers to
    settled = float(sol.t[0]) + settle_s
    if sol.alignment is not None:
        settled = max(settled, sol.alignment.t0 + sol.alignment.window_s)
    E = grid.n_epochs
    out_prev = np.full((E, 3), np.nan)
    out_pos = np.full((E, 3), np.nan)
    out_vel_enu = np.full((E, 3), np.nan)
    llh_prev = np.full((E, 3), np.nan)
    llh = np.full((E, 3), np.nan)
    informed = np.full(E, np.nan)
    dynamics = np.full(E, np.nan)

    def to_sample(t: float) -> int:
        return int(np.clip(np.searchsorted(pre.t, t, side="right") - 1, 0, len(pre.t) - 1))

    def run(s: NavState, i: int, j: int) -> NavState:
        while i < j:
            k = min(j, max(i + 1, to_sample(pre.t[i] + block_s)))
            s = propagate(s, *pre.increment(i, k))
            i = k
        return s

    for e in range(1, E):
        t_prev, t_now = grid.t_s[e - 1], grid.t_s[e]
        latest = min(t_now - window_s, t_prev)
        j = int(np.searchsorted(t_state, latest + 1e-9, side="right") - 1)
        if j < 0 or t_state[j] < settled or t_now > pre.t[-1] + 1.0:
            continue
        s = NavState.from_vector(states[j])
        informed[e] = sol.t[j]
        v_restart = s.v[:2].copy()
        i = to_sample(s.t)
        for target_t, out in ((t_prev, llh_prev), (t_now, llh)):
            k = to_sample(target_t)
            s = run(s, i, k)
            i = k
            lead = target_t - pre.t[k]  # the epoch is a little after the last IMU sample
            out[e] = _extrapolated(s, lead)
        out_vel_enu[e] = s.v
        dynamics[e] = float(np.linalg.norm(s.v[:2] - v_restart))
    ok = np.isfinite(llh).all(axis=1)
    out_prev[ok] = geodetic_to_ecef(np.degrees(llh_prev[ok, 0]), np.degrees(llh_prev[ok, 1]), llh_prev[ok, 2])
    out_pos[ok] = geodetic_to_ecef(np.degrees(llh[ok, 0]), np.degrees(llh[ok, 1]), llh[ok, 2])
    R = enu_rotation(np.degrees(llh[ok, 0]), np.degrees(llh[ok, 1]))
    vel = np.full((E, 3), np.nan)
    vel[ok] = np.einsum("eji,ej->ei", R, out_vel_enu[ok])  # ENU -> ECEF: R^T v
    return Reference(
        "ins",
        f"INS {sol.imu_id} propagated alone from the GNSS/INS state {window_s:g} s before each epoch "
        f"(from {settled:.0f} s, once the filter settled)",
        Evidence.INERTIAL,
        out_prev,
        out_pos,
        vel,
        informed,
        dynamics,
    )


def _extrapolated(s, lead: float) -> FloatArray:
    """(lat, lon, h) of the state moved along its velocity for `lead` seconds."""
    from spooflens.geodesy import radii

    rm, rn = radii(s.lat)
    return np.array(
        [
            s.lat + s.v[1] * lead / (rm + s.h),
            s.lon + s.v[0] * lead / ((rn + s.h) * math.cos(s.lat)),
            s.h + s.v[2] * lead,
        ]
    )
