"""What the raw-observation detectors compare a receiver's signals with: where the receiver was, known
independently of its GNSS.

- a **known station** (`Evidence.KNOWN_STATION`): a position given with `--station`, or a RINEX header's
  APPROX POSITION for a receiver that stayed put. A station that starts to move during the log is evidence,
  not a reason to stop looking, so whether it stayed put is judged on the fixes of its first
  `STATIC_WINDOW_S` (over 30 s spans, 90% of them slower than 0.5 m/s), and the header must lie within
  100 m of its first fixes (a moving receiver's header is only where it started; a rough one would bias
  the differences). Zero velocity, the same position at every epoch.
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

from spooflens.epoch_table import EpochTable
from spooflens.errors import SpooflensError
from spooflens.geodesy import ecef_to_geodetic, enu_rotation, geodetic_to_ecef, geodetic_to_enu
from spooflens.gnss.grid import ObservationGrid
from spooflens.navigation.loosely_coupled import FILTER_SETTLE_S
from spooflens.navigation.product import navigation_of
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.registry import AnalysisContext

FloatArray = NDArray[np.float64]
APPROX_POSITION_KEY = "rinex.approx_position_xyz_m"  # readers.rinex.APPROX_POSITION_KEY
STATIC_WINDOW_S = 300.0  # whether a station stayed put is judged on its first minutes (module notes)
STATION_OPTION = "station"  # AnalyzeOptions.extra key: list of (receiver id or None, lat deg, lon deg, h m)
STATIC_SPAN_S = 30.0
STATIC_SPEED_MPS = 0.5
STATIC_FRACTION = 0.9
HEADER_AGREEMENT_M = 100.0


@dataclass(frozen=True)
class Station:
    receiver_id: str
    ecef_m: FloatArray  # (3,)
    source: str  # where the position came from, for the report


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


def parse_station(text: str) -> tuple[str | None, float, float, float]:
    """`[RECEIVER=]LAT,LON,H` (degrees, degrees, metres above the ellipsoid) -> (receiver or None, lat, lon, h)."""
    rid, sep, rest = text.rpartition("=")
    parts = [p.strip() for p in rest.split(",")]
    try:
        lat, lon, h = (float(p) for p in parts)
    except ValueError:
        raise ValueError(
            f"{text!r}: expected LAT,LON,H in degrees, degrees, metres (optionally RECEIVER=...)"
        ) from None
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 360.0 and -1000.0 < h < 1e5):
        raise ValueError(f"{text!r}: latitude, longitude or height out of range")
    return (rid.strip() or None) if sep else None, lat, lon, h


def _is_static(table: EpochTable, receiver_id: str) -> tuple[bool, str]:
    """Whether the receiver's fixes of its first STATIC_WINDOW_S stay put (see the module notes), with the
    measured figure."""
    fx = table.fixes_of(receiver_id)
    t = fx["t_s"].to_numpy(float)
    fx = fx[t <= t[0] + STATIC_WINDOW_S] if len(t) else fx
    if len(fx) < 3:
        return False, f"{len(fx)} fixes"
    t = fx["t_s"].to_numpy(float)
    lat0, lon0, h0 = (float(fx[c].iloc[0]) for c in ("lat_deg", "lon_deg", "height_m"))
    p = geodetic_to_enu(fx["lat_deg"], fx["lon_deg"], fx["height_m"], lat0, lon0, h0)
    j = np.searchsorted(t, t - STATIC_SPAN_S, side="right") - 1
    ok = (j >= 0) & (t - t[np.maximum(j, 0)] > 0.5 * STATIC_SPAN_S)
    if not ok.any():
        span = t[-1] - t[0]
        ok_all = span > 0
        speed = np.array([np.linalg.norm(p[-1, :2] - p[0, :2]) / span]) if ok_all else np.array([np.inf])
    else:
        k = np.flatnonzero(ok)
        speed = np.linalg.norm(p[k, :2] - p[j[k], :2], axis=1) / (t[k] - t[j[k]])
    moving = float(np.mean(speed > STATIC_SPEED_MPS))
    return moving <= 1.0 - STATIC_FRACTION, (
        f"{100 * moving:.0f}% of 30 s spans of its first {STATIC_WINDOW_S / 60:g} min faster than "
        f"{STATIC_SPEED_MPS} m/s"
    )


def surveyed_station(table: EpochTable, receiver_id: str) -> tuple[Station | None, str]:
    """The receiver's RINEX header position as a known station when it is one (module notes), else why not."""
    text = table.metadata.get(f"{APPROX_POSITION_KEY}.{receiver_id}")
    if not text:
        return None, "no station position (give one with --station LAT,LON,H)"
    xyz = np.array([float(v) for v in text.split()])
    if not 6.2e6 < np.linalg.norm(xyz) < 6.5e6:
        return None, f"RINEX header position {text} is not on the Earth's surface"
    static, figure = _is_static(table, receiver_id)
    if not static:
        return None, f"the receiver moves ({figure}): its RINEX header position is not a station"
    fx = table.fixes_of(receiver_id).iloc[:10]
    first = geodetic_to_ecef(fx["lat_deg"], fx["lon_deg"], fx["height_m"])
    gap = float(np.linalg.norm(np.median(first, axis=0) - xyz))
    if gap > HEADER_AGREEMENT_M:
        return None, (
            f"its first fixes lie {gap:.0f} m from the RINEX header position (more than "
            f"{HEADER_AGREEMENT_M:.0f} m: a rough header, or an attack from the start of the log): not used"
        )
    return Station(receiver_id, xyz, f"RINEX header APPROX POSITION (static receiver, {figure})"), ""


def stations(table: EpochTable, extra: dict[str, object]) -> tuple[dict[str, Station], dict[str, str]]:
    """Known stations per receiver with observations, and for the others why none is used."""
    receivers = list(dict.fromkeys(table.observations["receiver_id"].astype(str)))
    found: dict[str, Station] = {}
    why: dict[str, str] = {}
    given = extra.get(STATION_OPTION) or []
    for rid, lat, lon, h in given:  # type: ignore[attr-defined]
        target = rid or (receivers[0] if receivers else None)
        if target is None:
            continue
        if target not in receivers:
            raise SpooflensError(f"--station names receiver {target!r}, but the log's receivers are {receivers}")
        found[target] = Station(target, geodetic_to_ecef(lat, lon, h), f"--station {lat:.7f},{lon:.7f},{h:.2f}")
    for rid in receivers:
        if rid in found:
            continue
        station, reason = surveyed_station(table, rid)
        if station is None:
            why[rid] = reason
        else:
            found[rid] = station
    return found, why


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
