"""Body-frame conventions and initial alignment from the log itself.

In depth: docs/methods/navigation.md."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.errors import AnalysisError
from spooflens.geodesy import geodetic_to_enu, normal_gravity
from spooflens.navigation.rotations import (
    quat_conjugate,
    quat_multiply,
    quat_rotate,
    quat_to_matrix,
    rotvec_to_matrix,
    skew,
)
from spooflens.navigation.strapdown import Axes, Preintegrated, axes_of, rates

FloatArray = NDArray[np.float64]

# body axes of each declared convention expressed in FLU: rows map FLU <- declared
TO_FLU = {
    "FLU": np.eye(3),
    "FRD": np.diag([1.0, -1.0, -1.0]),
    "RFU": np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
    # Android SensorEvent axes: x right, y toward the top of the screen, z out of the screen; a phone
    # lying flat with its top forward is RFU, so the same rows (forward = the top of the screen)
    "ANDROID": np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
}


def flu_axes(values: FloatArray | Sequence[FloatArray], body_frame: str) -> Axes:
    """FLU x, y, z columns from (N, 3) rows or three columns in the declared body frame.

    Axis by axis, not a matrix product: the conventions are signed permutations, so an FLU log's
    columns are used as they are (a day of 100 Hz IMU is 0.2 GB a vector) and others are negated
    copies; a (N, 3) @ (3, 3) product also costs more than the whole preintegration."""
    try:
        M = TO_FLU[body_frame]
    except KeyError:
        raise AnalysisError(f"unknown IMU body frame {body_frame!r}; known: {sorted(TO_FLU)}") from None
    cols = axes_of(values)
    out = []
    for i in range(3):
        terms = [(M[i, j], cols[j]) for j in range(3) if M[i, j] != 0.0]
        if len(terms) == 1 and terms[0][0] == 1.0:
            out.append(terms[0][1])
        else:
            out.append(sum((m * c for m, c in terms), start=np.zeros(len(cols[0]))))
    return out[0], out[1], out[2]


@dataclass(frozen=True)
class Alignment:
    t0: float
    C0: FloatArray  # C_b^n (FLU body) at t0
    v0: FloatArray  # ENU velocity at t0
    lat0: float  # rad
    lon0: float
    h0: float
    method: str  # how the attitude and heading were found
    residual_m: float  # RMS position misfit of the alignment window
    window_s: float


def _kabsch(a: FloatArray, b: FloatArray) -> FloatArray:
    """Rotation R minimising sum |b_i - R a_i|^2."""
    u, _, vt = np.linalg.svd(b.T @ a)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def _imu_orientation(imu: pd.DataFrame, t: float, near: int = 4096) -> FloatArray | None:
    """The log's orientation at the sample nearest `t` that has one. Looked for among the `near` samples
    on each side first (the columns of a whole day-long stream are half a gigabyte); the whole stream
    only when none there is nearer than the window's edges."""
    ts = imu["t_s"].to_numpy(dtype=float)
    k = int(np.searchsorted(ts, t))
    for lo, hi in ((max(0, k - near), min(len(ts), k + near)), (0, len(ts))):
        q = imu[["qw", "qx", "qy", "qz"]].iloc[lo:hi].to_numpy(dtype=float)
        ok = np.flatnonzero(np.isfinite(q).all(axis=1))
        if len(ok):
            best = ok[int(np.argmin(np.abs(ts[lo:hi][ok] - t)))]
            edge = min(t - ts[lo - 1] if lo > 0 else np.inf, ts[hi] - t if hi < len(ts) else np.inf)
            if abs(ts[lo + best] - t) <= edge:
                return quat_to_matrix(q[best])
    return None


def align_from_orientation(
    pre: Preintegrated, imu: pd.DataFrame, fixes: pd.DataFrame, first: int, max_tilt_error_deg: float = 10.0
) -> Alignment | None:
    """Initial state from the attitude the log carries (a ROS Imu orientation, PX4 vehicle_attitude),
    when it agrees with gravity: the mean specific force over the first two seconds, turned into the
    local level by it, must point up within `max_tilt_error_deg`. Velocity from the receiver's, else
    from the first fixes' positions. Costs nothing, where velocity matching needs manoeuvres."""
    tf = fixes["t_s"].to_numpy(dtype=float)
    t0 = float(tf[first])
    C = _imu_orientation(imu, t0)
    if C is None:
        return None
    k0 = int(np.clip(np.searchsorted(pre.t, t0), 0, len(pre.t) - 1))
    k1 = int(np.searchsorted(pre.t, t0 + 2.0))
    f_up = C @ np.array([np.mean(a[k0 : max(k1, k0 + 1)]) for a in pre.f_axes])
    tilt = np.degrees(np.arccos(np.clip(f_up[2] / max(np.linalg.norm(f_up), 1e-9), -1.0, 1.0)))
    if not tilt <= max_tilt_error_deg:
        return None
    lat0, lon0, h0 = (float(fixes[c].iloc[first]) for c in ("lat_deg", "lon_deg", "height_m"))
    v = fixes[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy(dtype=float)[first]
    source = "the receiver's velocity"
    if not np.isfinite(v[:2]).all():
        p = geodetic_to_enu(fixes["lat_deg"], fixes["lon_deg"], fixes["height_m"], lat0, lon0, h0)
        later = np.flatnonzero((tf > t0 + 0.5) & (tf <= t0 + 3.0))
        j = int(later[-1]) if len(later) else min(first + 1, len(tf) - 1)
        v = (p[j] - p[first]) / max(tf[j] - t0, 1e-3) if j > first else np.zeros(3)
        source = "the first fixes' positions"
    v = np.where(np.isfinite(v), v, 0.0)
    method = f"attitude from the log's orientation (tilt against gravity {tilt:.1f} deg), velocity from {source}"
    return Alignment(t0, C, np.asarray(v, dtype=float), np.radians(lat0), np.radians(lon0), h0, method, 0.0, 0.0)


def align(
    pre: Preintegrated,
    imu: pd.DataFrame,
    fixes: pd.DataFrame,
    t_start: float,
    min_window_s: float = 20.0,
    max_window_s: float = 180.0,
    min_excitation_m: float = 10.0,
    max_yaw_sigma: float = np.radians(2.0),
    accel_bias_sigma: float = 0.1,
    gyro_bias_sigma: float = 2e-3,
) -> Alignment:
    """Initial state at the first fix at or after `t_start` (fixes: one receiver, schema columns): from the
    log's own attitude when it has one that agrees with gravity, else by velocity matching."""
    tf = fixes["t_s"].to_numpy(dtype=float)
    first = int(np.searchsorted(tf, max(t_start, pre.t[0])))
    if first >= len(tf) - 3:
        raise AnalysisError("too few GNSS fixes inside the IMU's time span to align the INS")
    from_log = align_from_orientation(pre, imu, fixes, first)
    if from_log is not None:
        return from_log
    lat0, lon0, h0 = (float(fixes[c].iloc[first]) for c in ("lat_deg", "lon_deg", "height_m"))
    p = geodetic_to_enu(fixes["lat_deg"], fixes["lon_deg"], fixes["height_m"], lat0, lon0, h0)
    g = float(normal_gravity(np.radians(lat0), h0))
    s = int(np.clip(np.searchsorted(pre.t, tf[first]), 0, len(pre.t) - 1))
    q_s, G_s, H_s = pre.integrals(s)
    qs_inv = quat_conjugate(q_s)
    window = min_window_s
    while True:
        sel = (tf >= tf[first]) & (tf <= tf[first] + window) & (tf <= pre.t[-1])
        idx = np.flatnonzero(sel)
        if len(idx) < 4:
            raise AnalysisError("too few GNSS fixes inside the IMU's time span to align the INS")
        k = np.clip(np.searchsorted(pre.t, tf[idx]), 0, len(pre.t) - 1)
        tau = pre.t[k] - pre.t[s]
        dH = quat_rotate(qs_inv, pre.integrals(k)[2] - H_s - G_s * tau[:, None])
        P = p[idx] - p[first]
        earth = _earth_terms(np.radians(lat0), h0, g, tau, P, tf[idx] - tf[first])
        grav = np.outer(0.5 * tau**2, [0.0, 0.0, -g]) + earth
        # p0 and v0 enter linearly: project them out (onto the complement of [1, tau]), then the
        # rotation is a single Kabsch problem on the projected vector pairs
        design = np.c_[np.ones_like(tau), tau]
        proj = np.eye(len(tau)) - design @ np.linalg.pinv(design)
        if not (np.isfinite(dH).all() and np.isfinite(P - grav).all()):
            raise AnalysisError("the IMU or GNSS values in the alignment window are not finite: cannot align")
        try:
            C0 = _kabsch(proj @ dH, proj @ (P - grav))
        except np.linalg.LinAlgError as err:
            raise AnalysisError(f"alignment failed on this log's IMU and GNSS ({err})") from None
        resid = P - grav - dH @ C0.T
        coef, *_ = np.linalg.lstsq(design, resid, rcond=None)
        v0 = coef[1]
        misfit = resid - design @ coef
        # excitation: horizontal motion the INS sees that a constant velocity does not explain
        excitation = float(np.sqrt(np.mean(np.sum((proj @ (dH @ C0.T))[:, :2] ** 2, axis=1))))
        yaw_sigma = float("inf")
        if excitation >= min_excitation_m:
            C0, v0, misfit, yaw_sigma = _refine_yaw_with_bias(
                C0, pre, s, k, tau, dH, P - grav, accel_bias_sigma, gyro_bias_sigma
            )
        if yaw_sigma <= max_yaw_sigma or window >= max_window_s or idx[-1] >= len(tf) - 1:
            break
        window = min(1.5 * window, max_window_s)
    method = (
        f"velocity matching over {window:.0f} s (horizontal excitation {excitation:.1f} m, "
        f"yaw sigma {np.degrees(yaw_sigma):.1f} deg)"
    )
    if excitation < min_excitation_m or yaw_sigma > np.radians(15.0):
        C0 = _heading_fallback(C0, imu, fixes, tf[first], p, first)
        method = "levelled from gravity; too little horizontal acceleration for yaw, " + (
            "yaw from the IMU orientation"
            if _imu_orientation(imu, tf[first]) is not None
            else "yaw from the course over ground"
        )
    rms = float(np.sqrt(np.mean(np.sum(misfit**2, axis=1))))
    return Alignment(float(tf[first]), C0, v0, np.radians(lat0), np.radians(lon0), h0, method, rms, window)


def _refine_yaw_with_bias(
    C0: FloatArray,
    pre: Preintegrated,
    s: int,
    k: NDArray[np.int64],
    tau: FloatArray,
    dH: FloatArray,
    target: FloatArray,
    accel_bias_sigma: float = 0.1,
    gyro_bias_sigma: float = 2e-3,
    noise_sigma: float = 3.0,
) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """Attitude again, with constant accelerometer and gyro biases in the model.

    Over a 40-80 s window a consumer accelerometer bias (0.05 m/s^2) moves the position by tens of
    metres, and a gyro bias (0.03 deg/s) tilts gravity into the horizontal and moves it by hundreds:
    both pull the Kabsch attitude. In the initial body frame an accelerometer bias b_a adds B_i b_a
    (B = double integral of the body rotation R(u) since the start) and a gyro bias b_g adds
    D_i b_g (D = double integral of [F(s) x] J(s), J = integral of R, F the specific force), so
        target_i = p0 + v0 tau_i + C0 (dH_i - B_i b_a - D_i b_g),
    linear in p0, v0, b_a, b_g (biases with weak priors) for a given C0. Yaw is searched on a 1 deg
    grid, then all three angles are polished by parabolic line searches. Also returns the yaw's
    standard deviation from the curvature of the misfit (Delta chi^2 = 1).
    """
    span = slice(s, k[-1] + 1)
    q = pre.integrals(span)[0]  # its first row is the attitude at s
    rot = quat_to_matrix(quat_multiply(quat_conjugate(q[0])[None, :], q))
    dt = np.diff(pre.t[span])

    def cumint(x: FloatArray) -> FloatArray:
        return np.concatenate([np.zeros((1, *x.shape[1:])), np.cumsum(x[:-1] * dt[:, None, None], axis=0)])

    B = cumint(cumint(rot))[k - s]
    F = np.einsum("nij,nj->ni", rot, pre.f(span))
    D = cumint(cumint(np.einsum("nij,njk->nik", skew(F), cumint(rot))))[k - s]
    n = len(tau)
    base = np.zeros((n, 3, 6))
    base[:, :, :3] = np.eye(3)
    base[:, :, 3:] = tau[:, None, None] * np.eye(3)
    prior_rows = np.zeros((6, 12))
    prior_rows[:3, 6:9] = np.eye(3) * (noise_sigma / accel_bias_sigma)
    prior_rows[3:, 9:] = np.eye(3) * (noise_sigma / gyro_bias_sigma)
    y_prior = np.zeros(6)

    def fit(C: FloatArray) -> tuple[float, FloatArray, FloatArray]:
        design = np.concatenate(
            [base, -np.einsum("ij,njk->nik", C, B), -np.einsum("ij,njk->nik", C, D)], axis=2
        ).reshape(3 * n, 12)
        y = (target - dH @ C.T).reshape(3 * n)
        A = np.vstack([design, prior_rows])
        coef, *_ = np.linalg.lstsq(A, np.r_[y, y_prior], rcond=None)
        r = A @ coef - np.r_[y, y_prior]
        return float(r @ r), coef, (y - design @ coef).reshape(n, 3)

    def costs(C: FloatArray, turns: list[FloatArray]) -> FloatArray:
        return _turned_costs(C, base, B, D, dH, target, prior_rows, np.stack(turns))

    yaws = np.radians(np.arange(-180.0, 180.0, 1.0))
    best = int(np.argmin(costs(C0, [_rotate_yaw(np.eye(3), yaw) for yaw in yaws])))
    C = _rotate_yaw(C0, yaws[best])
    step = np.radians(0.5)
    for _ in range(3):
        for axis in np.eye(3):
            c_minus, c0, c_plus = costs(C, [rotvec_to_matrix(axis * d) for d in (-step, 0.0, step)])
            curvature = c_plus - 2 * c0 + c_minus
            if curvature > 0:
                d = float(np.clip(0.5 * step * (c_minus - c_plus) / curvature, -step, step))
                C = rotvec_to_matrix(axis * d) @ C
        step /= 3.0
    cost, coef, misfit = fit(C)
    # yaw uncertainty with roll and pitch free: a constant specific force leaves the rotation about
    # its own direction unobservable, which a yaw-only curvature would not show
    h = np.radians(1.0)
    axes = np.eye(3) * h

    pairs = [(i, j) for i in range(3) for j in range(i, 3)]
    signs = ((1, 1), (1, -1), (-1, 1), (-1, -1))  # the four corners of each second difference
    corners = costs(C, [rotvec_to_matrix(a * axes[i] + b * axes[j]) for i, j in pairs for a, b in signs])
    hess = np.empty((3, 3))
    for (i, j), (pp, pm, mp, mm) in zip(pairs, corners.reshape(len(pairs), 4), strict=True):
        hess[i, j] = hess[j, i] = (pp - pm - mp + mm) / (4 * h * h)
    noise_var = cost / max(3 * n - 12, 1)
    try:
        cov = 2 * noise_var * np.linalg.inv(hess)
        yaw_sigma = float(np.sqrt(cov[2, 2])) if cov[2, 2] > 0 else float("inf")
    except np.linalg.LinAlgError:
        yaw_sigma = float("inf")
    return C, coef[3:6], misfit, yaw_sigma


def _earth_terms(lat: float, h: float, g: float, tau: FloatArray, P: FloatArray, fix_tau: FloatArray) -> FloatArray:
    """Position change from the local-level frame's rotation and Coriolis over the window (`tau`: the IMU
    samples' times, `fix_tau`: the fixes' own, which the velocity is taken over).

    The specific force seen in the initial body frame is, to first order, gravity rotating with the
    local-level frame at omega_in: -(omega_in x [0, 0, g]) tau^3 / 6; Coriolis adds
    -double integral of (2 omega_ie + omega_en) x v, with v from the GNSS positions. At aircraft speeds
    and 40 s windows each is tens of metres, the size of the heading signal itself.
    """
    # over the fixes' times: two fixes closer than an IMU period share its sample (a 25 Hz IMU beside a
    # receiver whose 5 Hz fixes jitter by 20 ms: the real log171 copter's IMU logged at half its rate), which
    # made the velocity between them infinite and the alignment refused
    with np.errstate(divide="ignore", invalid="ignore"):  # repeated stamps (damaged logs): NaN, refused later
        v = np.gradient(P, fix_tau, axis=0) if len(fix_tau) > 2 else np.zeros_like(P)
    w_ie, w_en, _, _ = rates(lat, h, np.mean(v, axis=0))
    rotation = -np.outer(tau**3 / 6.0, np.cross(w_ie + w_en, [0.0, 0.0, g]))
    cor = np.cross(2 * w_ie + w_en, v)
    first = np.vstack([np.zeros(3), np.cumsum(0.5 * (cor[1:] + cor[:-1]) * np.diff(tau)[:, None], axis=0)])
    second = np.vstack([np.zeros(3), np.cumsum(0.5 * (first[1:] + first[:-1]) * np.diff(tau)[:, None], axis=0)])
    return rotation - second


def _yaw_of(C: FloatArray, axis: FloatArray) -> float:
    d = C @ axis
    return float(np.arctan2(d[1], d[0]))


def _turned_costs(
    C: FloatArray,
    base: FloatArray,
    B: FloatArray,
    D: FloatArray,
    dH: FloatArray,
    target: FloatArray,
    prior_rows: FloatArray,
    turns: FloatArray,
) -> FloatArray:
    """The bias model's least-squares misfit with the attitude `R C`, for every rotation R of `turns`.

    R turns every epoch's residual in the navigation frame without changing its length, so turning the
    targets by R^T instead leaves one design, that of C (the biases are in the body frame and keep their
    priors; p0 and v0 turn with the targets): one factorisation for all of them.
    """
    n = len(target)
    design = np.concatenate([base, -np.einsum("ij,njk->nik", C, B), -np.einsum("ij,njk->nik", C, D)], axis=2)
    A = np.vstack([design.reshape(3 * n, 12), prior_rows])
    turned = np.einsum("mji,nj->nim", turns, target)  # R^T target_i for every R: (n, 3, len(turns))
    y = (turned - (dH @ C.T)[:, :, None]).reshape(3 * n, len(turns))
    y = np.vstack([y, np.zeros((len(prior_rows), len(turns)))])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = A @ coef - y
    out: FloatArray = np.einsum("ij,ij->j", r, r)
    return out


def _rotate_yaw(C: FloatArray, dyaw: float) -> FloatArray:
    c, s = np.cos(dyaw), np.sin(dyaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ C


def _heading_fallback(
    C_level: FloatArray, imu: pd.DataFrame, fixes: pd.DataFrame, t0: float, p: FloatArray, first: int
) -> FloatArray:
    """Keep roll/pitch of C_level; take yaw from the IMU orientation or the course over ground."""
    C_imu = _imu_orientation(imu, t0)
    forward = np.array([1.0, 0.0, 0.0])
    if C_imu is not None:
        target = _yaw_of(C_imu, forward)
    else:
        tf = fixes["t_s"].to_numpy(dtype=float)
        later = np.flatnonzero((tf > t0) & (np.linalg.norm(p[:, :2] - p[first, :2], axis=1) > 5.0))
        if not len(later):
            return C_level
        d = p[later[0]] - p[first]
        target = float(np.arctan2(d[1], d[0]))
    return _rotate_yaw(C_level, target - _yaw_of(C_level, forward))


def heading_from_course(
    al: Alignment, fixes: pd.DataFrame, forward_b: FloatArray, window_s: float = 60.0, min_speed: float = 0.5
) -> Alignment | None:
    """The alignment with its yaw replaced by the course over ground, for a vehicle that moves along its
    forward axis `forward_b` (body frame; a wheeled vehicle, whose mount the odometry gives): the first
    fixes within `window_s` of the start that move faster than `min_speed`. None if it never moves."""
    tf = fixes["t_s"].to_numpy(dtype=float)
    sel = np.flatnonzero((tf >= al.t0) & (tf <= al.t0 + window_s))
    if len(sel) < 3:
        return None
    p = geodetic_to_enu(
        fixes["lat_deg"].to_numpy()[sel],
        fixes["lon_deg"].to_numpy()[sel],
        fixes["height_m"].to_numpy()[sel],
        np.degrees(al.lat0),
        np.degrees(al.lon0),
        al.h0,
    )
    v = fixes[["vel_e_mps", "vel_n_mps"]].to_numpy(dtype=float)[sel]
    if not np.isfinite(v).all(axis=1).any():
        dt = np.gradient(tf[sel])
        v = np.gradient(p[:, :2], axis=0) / np.maximum(dt, 1e-3)[:, None]
    speed = np.hypot(v[:, 0], v[:, 1])
    moving = np.flatnonzero(np.isfinite(speed) & (speed > min_speed))
    if len(moving) < 3:
        return None
    k = moving[: max(3, len(moving) // 4)]
    course = float(np.arctan2(np.mean(v[k, 1]), np.mean(v[k, 0])))
    C = _rotate_yaw(al.C0, course - _yaw_of(al.C0, forward_b))
    delta = np.degrees(np.angle(np.exp(1j * (course - _yaw_of(al.C0, forward_b)))))
    method = al.method + f"; yaw from the course over ground along the odometry's forward axis ({delta:+.0f} deg)"
    return replace(al, C0=C, method=method)
