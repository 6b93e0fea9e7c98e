"""Truth trajectories for aircraft-, ship- and ground-vehicle-like motion, at the IMU rate.

A trajectory is a list of manoeuvre segments (duration, longitudinal acceleration, turn rate, climb
rate), blended smoothly so accelerations have no steps. Speed, course and vertical speed integrate
from the segments; attitude follows the motion (yaw = course, pitch = flight-path angle, roll = the
coordinated-turn bank angle for aircraft, zero for surface vehicles; a multirotor instead tilts its
thrust axis along the acceleration it needs and stays level in a vertical climb); position integrates the
velocity with the trapezoid rule on the ellipsoid, the same rule the mechanization uses, so the
sampled truth is consistent with the IMU derived from it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spooflens.constants import STANDARD_GRAVITY
from spooflens.geodesy import geodetic_to_ecef, radii
from spooflens.navigation.rotations import euler_to_matrix

FloatArray = NDArray[np.float64]
G0 = STANDARD_GRAVITY


@dataclass(frozen=True)
class Segment:
    duration_s: float
    accel_mps2: float = 0.0  # along-track acceleration
    turn_rate_dps: float = 0.0  # course rate, deg/s, positive = counter-clockwise (left)
    climb_mps: float = 0.0  # target vertical speed during the segment


@dataclass(frozen=True)
class Profile:
    lat_deg: float
    lon_deg: float
    height_m: float
    speed_mps: float
    course_deg: float  # ENU, from east, counter-clockwise
    segments: tuple[Segment, ...]
    banked_turns: bool  # aircraft roll into turns; ships and cars do not
    blend_s: float = 2.0  # manoeuvre changes are smoothed over this long
    thrust_tilt: bool = False  # a multirotor: body up along the thrust (no nose-up to the flight path)

    @property
    def duration_s(self) -> float:
        return float(sum(s.duration_s for s in self.segments))


@dataclass(frozen=True)
class Truth:
    t: FloatArray  # (N,) s since start
    lat: FloatArray  # rad
    lon: FloatArray  # rad
    h: FloatArray  # m
    v_enu: FloatArray  # (N, 3)
    C: FloatArray  # (N, 3, 3) C_b^n, FLU body
    roll: FloatArray
    pitch: FloatArray
    yaw: FloatArray

    def ecef(self, lever_arm_b: FloatArray | None = None) -> FloatArray:
        """Truth ECEF position (N, 3) of the IMU, or of a point at `lever_arm_b` (FLU metres) on the body."""
        lat, lon, h = np.degrees(self.lat), np.degrees(self.lon), self.h
        if lever_arm_b is not None:
            lat, lon, h = self.offset_geodetic(lever_arm_b)
        return geodetic_to_ecef(lat, lon, h)

    def ecef_velocity(self) -> FloatArray:
        """Truth ECEF velocity (N, 3) from the ENU velocity."""
        sl, cl, sp, cp = np.sin(self.lon), np.cos(self.lon), np.sin(self.lat), np.cos(self.lat)
        e, n, u = self.v_enu.T
        return np.stack(
            [-sl * e - sp * cl * n + cp * cl * u, cl * e - sp * sl * n + cp * sl * u, cp * n + sp * u], axis=-1
        )

    def offset_geodetic(self, lever_arm_b: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Geodetic position (deg, deg, m) of a body-fixed point (FLU metres from the IMU)."""
        d = self.C @ np.asarray(lever_arm_b, dtype=float)
        rm, rn = radii(self.lat)
        lat = self.lat + d[:, 1] / (rm + self.h)
        lon = self.lon + d[:, 0] / ((rn + self.h) * np.cos(self.lat))
        return np.degrees(lat), np.degrees(lon), self.h + d[:, 2]


def _blended(t: FloatArray, profile: Profile, attr: str) -> FloatArray:
    """Piecewise-constant segment values smoothed by a raised-cosine over `blend_s`."""
    edges = np.cumsum([0.0] + [s.duration_s for s in profile.segments])
    values = np.array([getattr(s, attr) for s in profile.segments])
    out = np.full_like(t, values[0])
    for k in range(1, len(values)):
        step = values[k] - values[k - 1]
        x = np.clip((t - edges[k]) / profile.blend_s + 0.5, 0.0, 1.0)
        out += step * (0.5 - 0.5 * np.cos(np.pi * x))
    return out


def _cumtrapz(y: FloatArray, t: FloatArray) -> FloatArray:
    """Cumulative trapezoid integral of a 1-D series, starting at 0."""
    return np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))])


def generate(profile: Profile, rate_hz: float) -> Truth:
    t = np.arange(0.0, profile.duration_s + 0.5 / rate_hz, 1.0 / rate_hz)
    speed = profile.speed_mps + _cumtrapz(_blended(t, profile, "accel_mps2"), t)
    speed = np.maximum(speed, 0.0)
    turn = np.radians(_blended(t, profile, "turn_rate_dps"))
    course = np.radians(profile.course_deg) + _cumtrapz(turn, t)
    climb = _blended(t, profile, "climb_mps")
    horizontal = np.sqrt(np.maximum(speed**2 - climb**2, 0.0))
    v = np.stack([horizontal * np.cos(course), horizontal * np.sin(course), climb], axis=-1)
    if profile.thrust_tilt:
        # the thrust carries gravity plus the manoeuvre's acceleration: forward acceleration pitches the
        # nose down, a left turn's centripetal acceleration rolls left (negative roll for a FLU body)
        lift = G0 + np.gradient(climb, t)
        pitch = -np.arctan2(_blended(t, profile, "accel_mps2") * (speed > 0), lift)
        roll = -np.arctan2(horizontal * turn, lift)
    else:
        pitch = np.arctan2(climb, np.maximum(horizontal, 1e-9))
        roll = np.arctan2(-speed * turn, G0) if profile.banked_turns else np.zeros_like(t)
    # a left (positive) turn banks left wing down, which is negative roll for a FLU body
    yaw = course
    C = euler_to_matrix(roll, pitch, yaw)
    lat = np.empty_like(t)
    lon = np.empty_like(t)
    h = profile.height_m + _cumtrapz(v[:, 2], t)
    lat[0], lon[0] = np.radians(profile.lat_deg), np.radians(profile.lon_deg)
    dt = np.diff(t)
    vm = 0.5 * (v[1:] + v[:-1])
    hm = 0.5 * (h[1:] + h[:-1])
    # latitude needs the radius at the midpoint latitude: a short fixed-point iteration, vectorised
    lat_inc = np.zeros_like(dt)
    lat_mid = np.full_like(dt, lat[0])
    for _ in range(3):
        rm, _ = radii(lat_mid)
        lat_inc = vm[:, 1] * dt / (rm + hm)
        lat_all = lat[0] + np.concatenate([[0.0], np.cumsum(lat_inc)])
        lat_mid = 0.5 * (lat_all[1:] + lat_all[:-1])
    lat = lat_all
    _, rn = radii(lat_mid)
    lon = lon[0] + np.concatenate([[0.0], np.cumsum(vm[:, 0] * dt / ((rn + hm) * np.cos(lat_mid)))])
    return Truth(t, lat, lon, h, v, C, roll, pitch, yaw)


# --- named profiles -------------------------------------------------------------------------------


def _seg(*rows: tuple[float, ...]) -> tuple[Segment, ...]:
    return tuple(Segment(*r) for r in rows)


PROFILES: dict[str, Profile] = {
    # Seed 000's case: an aircraft for 15 s (GNSS 1 Hz, INS 160 Hz); gentle climbing turn at 100 m/s.
    "seed000": Profile(
        38.08,
        46.29,
        1500.0,
        100.0,
        45.0,
        _seg((5.0, 0.5, 0.0, 2.0), (10.0, 0.0, 3.0, 2.0)),
        banked_turns=True,
        blend_s=1.0,
    ),
    # Aircraft: climb out, two coordinated turns, cruise, descent (10 min).
    "aircraft": Profile(
        48.35,
        11.78,
        500.0,
        70.0,
        80.0,
        _seg(
            (60.0, 0.3, 0.0, 8.0),
            (60.0, 0.0, 3.0, 5.0),
            (120.0, 0.0, 0.0, 0.0),
            (45.0, 0.0, -4.0, 0.0),
            (135.0, 0.1, 0.0, 0.0),
            (60.0, -0.1, 2.0, -4.0),
            (120.0, 0.0, 0.0, 0.0),
        ),
        banked_turns=True,
        blend_s=4.0,
    ),
    # Ship: 6 m/s with slow course changes for an hour.
    "ship": Profile(
        59.40,
        24.70,
        15.0,
        6.0,
        30.0,
        _seg(
            (900.0, 0.0, 0.0, 0.0),
            (300.0, 0.0, 0.1, 0.0),
            (900.0, 0.0, 0.0, 0.0),
            (600.0, 0.0, -0.05, 0.0),
            (900.0, 0.0, 0.0, 0.0),
        ),
        banked_turns=False,
        blend_s=30.0,
    ),
    # Multirotor: climb out, hover, cruise with turns at 8 m/s, hover, cruise back (10 min).
    "multirotor": Profile(
        47.3977,
        8.5456,
        450.0,
        0.0,
        20.0,
        _seg(
            (20.0, 0.0, 0.0, 2.0),
            (60.0, 0.0, 0.0, 0.0),
            (8.0, 1.0, 0.0, 0.0),
            (90.0, 0.0, 0.0, 0.0),
            (12.0, 0.0, 15.0, 0.0),
            (120.0, 0.0, 0.0, 0.0),
            (8.0, -1.0, 0.0, 0.0),
            (60.0, 0.0, 0.0, 0.0),
            (8.0, 1.0, 12.0, 0.0),
            (150.0, 0.0, 0.0, 0.0),
            (8.0, -1.0, 0.0, -1.0),
            (56.0, 0.0, 0.0, 0.0),
        ),
        banked_turns=False,
        blend_s=2.0,
        thrust_tilt=True,
    ),
    # Ground vehicle: accelerate, turn, brake, stop, go again (5 min).
    "ground": Profile(
        42.3765,
        -71.1468,
        10.0,
        0.0,
        130.0,
        _seg(
            (10.0, 1.5, 0.0, 0.0),
            (30.0, 0.0, 0.0, 0.0),
            (9.0, 0.0, 10.0, 0.0),
            (40.0, 0.0, 0.0, 0.0),
            (10.0, -1.5, 0.0, 0.0),
            (10.0, 0.0, 0.0, 0.0),
            (12.0, 1.2, 0.0, 0.0),
            (9.0, 0.0, -10.0, 0.0),
            (60.0, 0.0, 0.0, 0.0),
            (18.0, 0.0, 5.0, 0.0),
            (92.0, 0.0, 0.0, 0.0),
        ),
        banked_turns=False,
        blend_s=2.0,
    ),
}
