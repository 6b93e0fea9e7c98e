"""Compiled (numba) kernels of the low-rate navigation loop: one block of mechanization, the error
model F, its discretisation, and the whole closed-loop filter.

They are the single implementation: `strapdown.propagate`, `error_model.error_dynamics` and
`error_model.discretise` are thin wrappers over them, so the tests that check the mechanization and
F against each other exercise exactly the code the filter runs. The equations are documented in
strapdown.py and error_model.py; here they are written out for speed (per block ~10 us instead of
~300 us of numpy dispatch on 3-vectors, which is what the one-hour benchmark needs).

Nominal state vector x (22): lat, lon, h, v_e, v_n, v_u, C_b^n (9, row-major), b_g (3), b_a (3), t.
"""

from __future__ import annotations

import math

import numpy as np

from spooflens.compile.jit import njit
from spooflens.constants import WGS84_A_M as A_M
from spooflens.constants import WGS84_E2 as E2
from spooflens.constants import WGS84_F as F_FLAT
from spooflens.constants import WGS84_GAMMA_E as _GE
from spooflens.constants import WGS84_K_SOMIGLIANA as _K
from spooflens.constants import WGS84_M_GEO as _M
from spooflens.constants import WGS84_OMEGA_IE as OMEGA_IE
from spooflens.estimation.kalman_update import masked_update_into, update_into, update_scratch
from spooflens.estimation.sparse_products import add_block_diagonal, block_congruence

NX = 22
CACHE = True


@njit(cache=CACHE)
def gravity(lat: float, h: float) -> float:
    s2 = math.sin(lat) ** 2
    g0 = _GE * (1 + _K * s2) / math.sqrt(1 - E2 * s2)
    return g0 * (1 - 2 / A_M * (1 + F_FLAT + _M - 2 * F_FLAT * s2) * h + 3 / A_M**2 * h * h)


@njit(cache=CACHE)
def local_radii(lat: float) -> tuple[float, float]:
    s2 = math.sin(lat) ** 2
    w = math.sqrt(1 - E2 * s2)
    return A_M * (1 - E2) / w**3, A_M / w


# The 3-vector and 3 x 3 helpers work on scalars or into given arrays: the filter's loop makes no array
# per block or epoch (small arrays made afresh were a quarter of a noise-learning run). Each kernel the loop
# calls has an `_into` form writing into arrays the caller made once; where Python wrappers and the tests
# need an array-returning form, it is over the `_into` one. The helpers the loop calls at every block and
# epoch are inlined into it (`inline="always"`, `kalman_update.update_into` too): a noise-learning run 0.91
# of its time. A call of a compiled function counts a reference up and down for every array it is handed
# (an IMU stream is ten, the update's working arrays eight): 15 % of a run before, 13 % after (numba still
# counts where an inlined helper binds its arrays); the rest of the gain is the calls themselves.


@njit(cache=CACHE, inline="always")
def _cross_s(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> tuple[float, float, float]:
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=CACHE, inline="always")
def _mm3_into(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """out = a b for 3 x 3 matrices (out neither a nor b), written out: a BLAS call costs more than the
    27 products."""
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]


@njit(cache=CACHE, inline="always")
def _mv3_s(a: np.ndarray, v0: float, v1: float, v2: float) -> tuple[float, float, float]:
    """a v for a 3 x 3 matrix (written out, as `_mm3_into`)."""
    return (
        a[0, 0] * v0 + a[0, 1] * v1 + a[0, 2] * v2,
        a[1, 0] * v0 + a[1, 1] * v1 + a[1, 2] * v2,
        a[2, 0] * v0 + a[2, 1] * v1 + a[2, 2] * v2,
    )


@njit(cache=CACHE, inline="always")
def _rotvec_into(x: float, y: float, z: float, out: np.ndarray) -> None:
    """out = exp([v x]), the rotation by the rotation vector v = (x, y, z)."""
    a2 = x * x + y * y + z * z
    if a2 < 1e-18:
        s, c = 1.0, 0.5
    else:
        a = math.sqrt(a2)
        s, c = math.sin(a) / a, (1.0 - math.cos(a)) / a2
    out[0, 0] = 1 - c * (y * y + z * z)
    out[0, 1] = c * x * y - s * z
    out[0, 2] = c * x * z + s * y
    out[1, 0] = c * x * y + s * z
    out[1, 1] = 1 - c * (x * x + z * z)
    out[1, 2] = c * y * z - s * x
    out[2, 0] = c * x * z - s * y
    out[2, 1] = c * y * z + s * x
    out[2, 2] = 1 - c * (x * x + y * y)


@njit(cache=CACHE, inline="always")
def _quat_into(w: float, x: float, y: float, z: float, out: np.ndarray) -> None:
    """out = the rotation matrix of the unit quaternion (w, x, y, z)."""
    out[0, 0] = 1 - 2 * (y * y + z * z)
    out[0, 1] = 2 * (x * y - w * z)
    out[0, 2] = 2 * (x * z + w * y)
    out[1, 0] = 2 * (x * y + w * z)
    out[1, 1] = 1 - 2 * (x * x + z * z)
    out[1, 2] = 2 * (y * z - w * x)
    out[2, 0] = 2 * (x * z - w * y)
    out[2, 1] = 2 * (y * z + w * x)
    out[2, 2] = 1 - 2 * (x * x + y * y)


@njit(cache=CACHE, inline="always")
def _rotate(qw: float, qx: float, qy: float, qz: float, v0: float, v1: float, v2: float) -> tuple[float, float, float]:
    """v turned by the unit quaternion q: v + w t + u x t with t = 2 u x v (`rotations.quat_rotate`)."""
    s0, s1, s2 = 2.0 * (qy * v2 - qz * v1), 2.0 * (qz * v0 - qx * v2), 2.0 * (qx * v1 - qy * v0)
    return v0 + qw * s0 + (qy * s2 - qz * s1), v1 + qw * s1 + (qz * s0 - qx * s2), v2 + qw * s2 + (qx * s1 - qy * s0)


@njit(cache=CACHE, inline="always")
def _advance(
    qw: float,
    qx: float,
    qy: float,
    qz: float,
    g0: float,
    g1: float,
    g2: float,
    h0: float,
    h1: float,
    h2: float,
    dt: float,
    fx: float,
    fy: float,
    fz: float,
    wx: float,
    wy: float,
    wz: float,
) -> tuple[float, float, float, float, float, float, float, float, float, float]:
    """The integrals at sample k+1 from those at k and sample k (dt = t[k+1] - t[k]): the rotation
    exp(theta), theta = w dt; the sculling-corrected increment f dt + theta x f dt / 2 and its integral
    f dt dt / 2 + theta x f dt dt / 6, both turned into the first body frame by the attitude at k.
    The one statement of the step, so integrals made again from a checkpoint equal the first pass's
    bit for bit."""
    t0, t1, t2 = wx * dt, wy * dt, wz * dt
    f0, f1, f2 = fx * dt, fy * dt, fz * dt
    c0, c1, c2 = t1 * f2 - t2 * f1, t2 * f0 - t0 * f2, t0 * f1 - t1 * f0
    v0, v1, v2 = _rotate(qw, qx, qy, qz, f0 + 0.5 * c0, f1 + 0.5 * c1, f2 + 0.5 * c2)
    p0, p1, p2 = _rotate(
        qw, qx, qy, qz, 0.5 * f0 * dt + c0 * dt / 6.0, 0.5 * f1 * dt + c1 * dt / 6.0, 0.5 * f2 * dt + c2 * dt / 6.0
    )
    h0, h1, h2 = h0 + (g0 * dt + p0), h1 + (g1 * dt + p1), h2 + (g2 * dt + p2)
    g0, g1, g2 = g0 + v0, g1 + v1, g2 + v2
    a = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    half = 0.5 * a
    sinc = 0.5 - a * a / 48.0 if a < 1e-6 else math.sin(half) / a  # a series keeps tiny angles exact
    dw, dx, dy, dz = math.cos(half), t0 * sinc, t1 * sinc, t2 * sinc
    qw, qx, qy, qz = (
        qw * dw - qx * dx - qy * dy - qz * dz,
        qw * dx + qx * dw + qy * dz - qz * dy,
        qw * dy - qx * dz + qy * dw + qz * dx,
        qw * dz + qx * dy - qy * dx + qz * dw,
    )
    norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    return qw / norm, qx / norm, qy / norm, qz / norm, g0, g1, g2, h0, h1, h2


@njit(cache=CACHE)
def preintegrate_rows(
    t: np.ndarray,
    fx: np.ndarray,
    fy: np.ndarray,
    fz: np.ndarray,
    wx: np.ndarray,
    wy: np.ndarray,
    wz: np.ndarray,
    every: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Qb, G, H) of `strapdown.preintegrate` at samples 0, every, 2 every, ...: the body attitude
    relative to the first sample (unit quaternions), the cumulative velocity increment and its integral
    in the first body frame (`_advance`). One loop with no whole-stream temporaries (the vectorised form
    held a dozen arrays of the stream: 1.4 GB more than its result on a day of 100 Hz)."""
    N = t.shape[0]
    M = (N + every - 1) // every
    Qb = np.empty((M, 4))
    G = np.empty((M, 3))
    H = np.empty((M, 3))
    qw, qx, qy, qz, g0, g1, g2, h0, h1, h2 = 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    for k in range(N):
        if k % every == 0:
            c = k // every
            Qb[c, 0], Qb[c, 1], Qb[c, 2], Qb[c, 3] = qw, qx, qy, qz
            G[c, 0], G[c, 1], G[c, 2] = g0, g1, g2
            H[c, 0], H[c, 1], H[c, 2] = h0, h1, h2
        if k < N - 1:
            qw, qx, qy, qz, g0, g1, g2, h0, h1, h2 = _advance(
                qw, qx, qy, qz, g0, g1, g2, h0, h1, h2, t[k + 1] - t[k], fx[k], fy[k], fz[k], wx[k], wy[k], wz[k]
            )
    return Qb, G, H


# An IMU stream as the kernels take it (`strapdown.Preintegrated.kernel_args`): (t, fx, fy, fz, wx, wy,
# wz, Qb, G, H, every), the sample times and FLU columns, and the integrals at every `every`-th sample.
Stream = tuple[
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    int,
]


@njit(cache=CACHE, inline="always")
def _advance_to(stream: Stream, x: np.ndarray, k: int, i: int) -> None:
    """x (qw, qx, qy, qz, G (3), H (3)): the integrals at sample k, advanced in place to sample i >= k."""
    t, fx, fy, fz, wx, wy, wz = stream[0], stream[1], stream[2], stream[3], stream[4], stream[5], stream[6]
    qw, qx, qy, qz, g0, g1, g2, h0, h1, h2 = x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7], x[8], x[9]
    while k < i:
        qw, qx, qy, qz, g0, g1, g2, h0, h1, h2 = _advance(
            qw, qx, qy, qz, g0, g1, g2, h0, h1, h2, t[k + 1] - t[k], fx[k], fy[k], fz[k], wx[k], wy[k], wz[k]
        )
        k += 1
    x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7], x[8], x[9] = qw, qx, qy, qz, g0, g1, g2, h0, h1, h2


@njit(cache=CACHE)
def integrals_at(stream: Stream, i: int) -> np.ndarray:
    """(qw, qx, qy, qz, G (3), H (3)) at sample i: the checkpoint at or before it, advanced."""
    x = np.empty(10)
    _integrals_at_into(stream, i, x)
    return x


@njit(cache=CACHE, inline="always")
def _checkpoint_into(stream: Stream, c: int, x: np.ndarray) -> None:
    """x = the integrals at checkpoint c (sample c * every)."""
    Qb, G, H = stream[7], stream[8], stream[9]
    for r in range(4):
        x[r] = Qb[c, r]
    for r in range(3):
        x[4 + r] = G[c, r]
        x[7 + r] = H[c, r]


@njit(cache=CACHE, inline="always")
def _integrals_at_into(stream: Stream, i: int, x: np.ndarray) -> None:
    every = stream[10]
    _checkpoint_into(stream, i // every, x)
    _advance_to(stream, x, i - i % every, i)


@njit(cache=CACHE)
def integrals_rows(stream: Stream, rows: np.ndarray) -> np.ndarray:
    """(len(rows), 10) integrals (`integrals_at`) at each row; increasing rows advance from the last."""
    every = stream[10]
    out = np.empty((rows.shape[0], 10))
    for r in range(rows.shape[0]):
        i = rows[r]
        if r > 0 and rows[r - 1] <= i and i - rows[r - 1] <= i % every:
            x = out[r - 1].copy()
            _advance_to(stream, x, rows[r - 1], i)
        else:
            x = integrals_at(stream, i)
        out[r] = x
    return out


@njit(cache=CACHE, inline="always")
def integrals_from(stream: Stream, a: np.ndarray, i: int, j: int, b: np.ndarray) -> None:
    """The integrals at sample j into `b`, given those at sample i (`a`): advanced from i when that is
    nearer than j's checkpoint (a filter's consecutive blocks share their ends), else from the checkpoint."""
    every = stream[10]
    if i <= j and j - i <= j % every:
        for r in range(10):
            b[r] = a[r]
    else:
        _checkpoint_into(stream, j // every, b)
        i = j - j % every
    _advance_to(stream, b, i, j)  # one copy of the step where this is inlined


@njit(cache=CACHE, inline="always")
def increment_between(a: np.ndarray, b: np.ndarray, T: float, dC: np.ndarray, dv: np.ndarray, dp: np.ndarray) -> None:
    """(dC_b, dv_b, dp_b) into the arrays given, from the integrals at one sample (`a`) to those at a
    later one (`b`), T apart, in the body frame at the first (see strapdown.py)."""
    wi, xi, yi, zi = a[0], a[1], a[2], a[3]
    wj, xj, yj, zj = b[0], b[1], b[2], b[3]
    _quat_into(
        wi * wj + xi * xj + yi * yj + zi * zj,
        wi * xj - xi * wj - yi * zj + zi * yj,
        wi * yj + xi * zj - yi * wj - zi * xj,
        wi * zj - xi * yj + yi * xj - zi * wj,
        dC,
    )
    # R_i^T (b - a) with R_i the rotation of quaternion a: written out, R_i's columns are the rows of the product
    r00, r01, r02 = 1 - 2 * (yi * yi + zi * zi), 2 * (xi * yi - wi * zi), 2 * (xi * zi + wi * yi)
    r10, r11, r12 = 2 * (xi * yi + wi * zi), 1 - 2 * (xi * xi + zi * zi), 2 * (yi * zi - wi * xi)
    r20, r21, r22 = 2 * (xi * zi - wi * yi), 2 * (yi * zi + wi * xi), 1 - 2 * (xi * xi + yi * yi)
    g0, g1, g2 = b[4] - a[4], b[5] - a[5], b[6] - a[6]
    dv[0] = r00 * g0 + r10 * g1 + r20 * g2
    dv[1] = r01 * g0 + r11 * g1 + r21 * g2
    dv[2] = r02 * g0 + r12 * g1 + r22 * g2
    h0, h1, h2 = b[7] - a[7] - a[4] * T, b[8] - a[8] - a[5] * T, b[9] - a[9] - a[6] * T
    dp[0] = r00 * h0 + r10 * h1 + r20 * h2
    dp[1] = r01 * h0 + r11 * h1 + r21 * h2
    dp[2] = r02 * h0 + r12 * h1 + r22 * h2


@njit(cache=CACHE, inline="always")
def step_to(
    stream: Stream, a: np.ndarray, i: int, j: int, b: np.ndarray, dC: np.ndarray, dv: np.ndarray, dp: np.ndarray
) -> float:
    """From sample i, whose integrals are `a`, to sample j: the integrals at j into `b` and the increment
    in the body frame at t[i] into dC, dv, dp (see strapdown.py); returns T. The filter makes no array
    per block (a block made seven, most of a tuning run's allocations)."""
    integrals_from(stream, a, i, j, b)
    T = stream[0][j] - stream[0][i]
    increment_between(a, b, T, dC, dv, dp)
    return T


@njit(cache=CACHE)
def increment(stream: Stream, i: int, j: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(dC_b, dv_b, dp_b, T) from sample i to j in the body frame at t[i] (see strapdown.py)."""
    dC, dv, dp = np.empty((3, 3)), np.empty(3), np.empty(3)
    T = step_to(stream, integrals_at(stream, i), i, j, np.empty(10), dC, dv, dp)
    return dC, dv, dp, T


@njit(cache=CACHE, inline="always")
def _rates(lat: float, h: float, v0: float, v1: float) -> tuple[float, float, float, float, float, float, float, float]:
    """omega_ie^n (east, north, up), omega_en^n (east, north, up), R_M + h, R_N + h."""
    rm, rn = local_radii(lat)
    rmh, rnh = rm + h, rn + h
    return (
        0.0,
        OMEGA_IE * math.cos(lat),
        OMEGA_IE * math.sin(lat),
        -v1 / rmh,
        v0 / rnh,
        v0 * math.tan(lat) / rnh,
        rmh,
        rnh,
    )


@njit(cache=CACHE)
def propagate(x: np.ndarray, dC: np.ndarray, dv_b: np.ndarray, dp_b: np.ndarray, T: float) -> np.ndarray:
    """One low-rate block of the mechanization (equations in strapdown.py): the new state."""
    out = np.empty_like(x)
    propagate_into(x, dC, dv_b, dp_b, T, out, np.empty((6, 3, 3)))
    return out


@njit(cache=CACHE, inline="always")
def propagate_into(
    x: np.ndarray, dC: np.ndarray, dv_b: np.ndarray, dp_b: np.ndarray, T: float, out: np.ndarray, m: np.ndarray
) -> None:
    """`propagate` into `out` (not x), on scalars, with `m` (6 x 3 x 3) the room for its 3 x 3 matrices."""
    for i in range(x.shape[0]):
        out[i] = x[i]
    if T <= 0.0:
        return
    lat, h = x[0], x[2]
    v0, v1, v2 = x[3], x[4], x[5]
    C = m[0]
    for i in range(3):
        for j in range(3):
            C[i, j] = x[6 + 3 * i + j]
    ba0, ba1, ba2 = x[18], x[19], x[20]
    bgT0, bgT1, bgT2 = x[15] * T, x[16] * T, x[17] * T
    d0, d1, d2 = _mv3_s(dC, ba0, ba1, ba2)
    baT0, baT1, baT2 = d0 * T, d1 * T, d2 * T
    c0, c1, c2 = _cross_s(bgT0, bgT1, bgT2, dv_b[0], dv_b[1], dv_b[2])
    dv0 = dv_b[0] - 0.5 * (ba0 * T + baT0) - 0.5 * c0
    dv1 = dv_b[1] - 0.5 * (ba1 * T + baT1) - 0.5 * c1
    dv2 = dv_b[2] - 0.5 * (ba2 * T + baT2) - 0.5 * c2
    c0, c1, c2 = _cross_s(bgT0, bgT1, bgT2, dp_b[0], dp_b[1], dp_b[2])
    dp0 = dp_b[0] - (2.0 * ba0 * T + baT0) * (T / 6.0) - c0 / 3.0
    dp1 = dp_b[1] - (2.0 * ba1 * T + baT1) * (T / 6.0) - c1 / 3.0
    dp2 = dp_b[2] - (2.0 * ba2 * T + baT2) * (T / 6.0) - c2 / 3.0
    half, product, dCc = m[1], m[2], m[3]
    _rotvec_into(-0.5 * bgT0, -0.5 * bgT1, -0.5 * bgT2, half)
    _mm3_into(half, dC, product)
    _mm3_into(product, half, dCc)
    ie0, ie1, ie2, en0, en1, en2, rmh, rnh = _rates(lat, h, v0, v1)
    Cdv0, Cdv1, Cdv2 = _mv3_s(C, dv0, dv1, dv2)
    c0, c1, c2 = _cross_s(2.0 * ie0 + en0, 2.0 * ie1 + en1, 2.0 * ie2 + en2, v0, v1, v2)
    a0, a1, a2 = -c0, -c1, -c2 - gravity(lat, h)
    vm0 = v0 + 0.5 * (Cdv0 + a0 * T)
    vm1 = v1 + 0.5 * (Cdv1 + a1 * T)
    vm2 = v2 + 0.5 * (Cdv2 + a2 * T)
    lat_mid = lat + 0.5 * T * vm1 / rmh
    h_mid = h + 0.5 * T * vm2
    ie0, ie1, ie2, en0, en1, en2, rmh, rnh = _rates(lat_mid, h_mid, vm0, vm1)
    z0, z1, z2 = (ie0 + en0) * T, (ie1 + en1) * T, (ie2 + en2) * T
    c0, c1, c2 = _cross_s(2.0 * ie0 + en0, 2.0 * ie1 + en1, 2.0 * ie2 + en2, vm0, vm1, vm2)
    a0, a1, a2 = -c0, -c1, -c2 - gravity(lat_mid, h_mid)
    c0, c1, c2 = _cross_s(z0, z1, z2, Cdv0, Cdv1, Cdv2)
    out[3] = v0 + Cdv0 - 0.5 * c0 + a0 * T
    out[4] = v1 + Cdv1 - 0.5 * c1 + a1 * T
    out[5] = v2 + Cdv2 - 0.5 * c2 + a2 * T
    Cdp0, Cdp1, Cdp2 = _mv3_s(C, dp0, dp1, dp2)
    c0, c1, c2 = _cross_s(z0, z1, z2, Cdp0, Cdp1, Cdp2)
    dpn0 = v0 * T + Cdp0 - c0 / 3.0 + (0.5 * T * T) * a0
    dpn1 = v1 * T + Cdp1 - c1 / 3.0 + (0.5 * T * T) * a1
    dpn2 = v2 * T + Cdp2 - c2 / 3.0 + (0.5 * T * T) * a2
    turn, C_new, CtC = m[1], m[4], m[5]
    _rotvec_into(-z0, -z1, -z2, turn)
    _mm3_into(turn, C, product)
    _mm3_into(product, dCc, C_new)
    _mm3_into(C_new.T, C_new, CtC)
    for i in range(3):  # keep C orthonormal: C (3 I - C^T C) / 2
        for j in range(3):
            CtC[i, j] = 1.5 * (1.0 if i == j else 0.0) - 0.5 * CtC[i, j]
    _mm3_into(C_new, CtC, product)
    out[0] = lat + dpn1 / rmh
    out[1] = x[1] + dpn0 / (rnh * math.cos(lat_mid))
    out[2] = h + dpn2
    for i in range(3):
        for j in range(3):
            out[6 + 3 * i + j] = product[i, j]
    out[21] = x[21] + T


@njit(cache=CACHE)
def error_dynamics(x: np.ndarray, f_b: np.ndarray) -> np.ndarray:
    """F (15 x 15) of the error model (equations in error_model.py)."""
    F = np.zeros((15, 15))
    error_dynamics_into(x, f_b[0], f_b[1], f_b[2], F)
    return F


@njit(cache=CACHE, inline="always")
def error_dynamics_into(x: np.ndarray, f0: float, f1: float, f2: float, F: np.ndarray) -> None:
    """`error_dynamics` of force (f0, f1, f2) into F, whose other entries must be zero: every call writes
    the same entries, so a filter zeroes its F once."""
    lat, h = x[0], x[2]
    ve, vn, vu = x[3], x[4], x[5]
    rm, rn = local_radii(lat)
    rmh, rnh = rm + h, rn + h
    sin_l, cos_l = math.sin(lat), math.cos(lat)
    tan_l, sec2 = sin_l / cos_l, 1.0 / (cos_l * cos_l)
    wie_n, wie_u = OMEGA_IE * cos_l, OMEGA_IE * sin_l
    wen_e, wen_n, wen_u = -vn / rmh, ve / rnh, ve * tan_l / rnh
    wx, wy, wz = wen_e, wie_n + wen_n, wie_u + wen_u
    F[0, 1], F[0, 2], F[1, 0], F[1, 2], F[2, 0], F[2, 1] = wz, -wy, -wz, wx, wy, -wx
    F[0, 4] = -1.0 / rmh
    F[1, 3] = 1.0 / rnh
    F[2, 3] = tan_l / rnh
    a1, a2 = -OMEGA_IE * sin_l / rmh, OMEGA_IE * cos_l / rmh
    b0, b1 = vn / rmh**2, -ve / rnh**2
    c1, c2 = ve * sec2 / (rnh * rmh), -ve * tan_l / rnh**2
    F[0, 8] = b0
    F[1, 7], F[1, 8] = a1, b1
    F[2, 7], F[2, 8] = a2 + c1, c2
    for i in range(3):  # -C and C (C = x[6:15] row-major)
        for j in range(3):
            F[i, 9 + j] = -x[6 + 3 * i + j]
            F[3 + i, 12 + j] = x[6 + 3 * i + j]
    fe = x[6] * f0 + x[7] * f1 + x[8] * f2
    fn = x[9] * f0 + x[10] * f1 + x[11] * f2
    fu = x[12] * f0 + x[13] * f1 + x[14] * f2
    F[3, 1], F[3, 2], F[4, 0], F[4, 2], F[5, 0], F[5, 1] = -fu, fn, fu, -fe, -fn, fe
    ux, uy, uz = wen_e, 2 * wie_n + wen_n, 2 * wie_u + wen_u
    p, q, r = 1.0 / rnh, tan_l / rnh, -1.0 / rmh
    F[3, 3], F[3, 4], F[3, 5] = vn * q - vu * p, uz, -uy
    F[4, 3], F[4, 4], F[4, 5] = -uz - ve * q, vu * r, ux
    F[5, 3], F[5, 4] = uy + ve * p, -ux - vn * r
    # v x (2 d omega_ie + d omega_en) over dp_n and dh
    d0, d1, d2 = 0.0, 2 * a1, 2 * a2 + c1
    F[3, 7], F[4, 7], F[5, 7] = vn * d2 - vu * d1, vu * d0 - ve * d2, ve * d1 - vn * d0
    d0, d1, d2 = b0, b1, c2
    F[3, 8], F[4, 8] = vn * d2 - vu * d1, vu * d0 - ve * d2
    F[5, 8] = (ve * d1 - vn * d0) + 2.0 * gravity(lat, h) / math.sqrt(rmh * rnh)
    F[6, 3], F[7, 4], F[8, 5] = 1.0, 1.0, 1.0
    F[6, 6], F[6, 7], F[6, 8] = vu / rnh - tan_l * vn / rmh, ve * tan_l / rmh, -ve / rnh
    F[7, 7], F[7, 8] = vu / rmh, -vn / rmh


@njit(cache=CACHE)
def discretise(F: np.ndarray, qc: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    """Phi = I + F T + (F T)^2 / 2 and Qd = T/2 (Phi Qc Phi^T + Qc)."""
    Phi, Qd = np.empty((15, 15)), np.empty((15, 15))
    discretise_into(F, qc, T, np.empty((15, 15)), Phi, Qd)
    return Phi, Qd


@njit(cache=CACHE, inline="always")
def discretise_into(F: np.ndarray, qc: np.ndarray, T: float, FT: np.ndarray, Phi: np.ndarray, Qd: np.ndarray) -> None:
    """`discretise` into Phi and Qd, the sums written in place (FT: room for F T)."""
    for i in range(15):
        for j in range(15):
            FT[i, j] = F[i, j] * T
    np.dot(FT, FT, Phi)
    for i in range(15):
        for j in range(15):
            Phi[i, j] = ((1.0 if i == j else 0.0) + FT[i, j]) + 0.5 * Phi[i, j]
    for i in range(15):
        for j in range(15):
            FT[i, j] = Phi[i, j] * qc[j]  # F T is not read again: its room holds Phi Qc
    np.dot(FT, Phi.T, Qd)
    for i in range(15):
        for j in range(15):
            Qd[i, j] = (0.5 * T) * Qd[i, j]
        Qd[i, i] += 0.5 * T * qc[i]


@njit(cache=CACHE, inline="always")
def correct_into(x: np.ndarray, dx: np.ndarray, out: np.ndarray, m: np.ndarray) -> None:
    """Feed an error estimate back into the nominal state (closed loop): the corrected state into `out`
    (not x), `m` (2 x 3 x 3) the room for its rotations."""
    for i in range(x.shape[0]):
        out[i] = x[i]
    rm, rn = local_radii(x[0])
    turn, C = m[0], m[1]
    _rotvec_into(dx[0], dx[1], dx[2], turn)
    for i in range(3):
        for j in range(3):
            C[i, j] = x[6 + 3 * i + j]
    for i in range(3):  # C = (I + [phi x]) C~
        for j in range(3):
            out[6 + 3 * i + j] = turn[i, 0] * C[0, j] + turn[i, 1] * C[1, j] + turn[i, 2] * C[2, j]
    for i in range(3):
        out[3 + i] = x[3 + i] - dx[3 + i]
    out[0] = x[0] - dx[7] / (rm + x[2])
    out[1] = x[1] - dx[6] / ((rn + x[2]) * math.cos(x[0]))
    out[2] = x[2] - dx[8]
    for i in range(3):
        out[15 + i] = x[15 + i] + dx[9 + i]
        out[18 + i] = x[18 + i] + dx[12 + i]


@njit(cache=CACHE)
def correct_all(states: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """`correct` of every row (a smoothed solution's states from the filtered ones and their errors)."""
    out = np.empty_like(states)
    m = np.empty((2, 3, 3))
    for k in range(states.shape[0]):
        correct_into(states[k], dx[k, :15], out[k], m)
    return out


NE = 24  # error states: 15 INS + Gauss-Markov errors of GNSS position (3), GNSS velocity (3), odometry (3)
NG = NE - 15
NM = 9  # measurement rows: GNSS position (3), GNSS velocity (3), odometry body velocity (3)


@njit(cache=CACHE, inline="always")
def measurement_matrix_into(x: np.ndarray, R_vb: np.ndarray, Hm: np.ndarray, m: np.ndarray) -> None:
    """H (9 x 24) at nominal state x into Hm, `m` (3 x 3 x 3) the room for its 3 x 3 products:
    z = INS - measured = H dx + noise.

    GNSS rows see the INS error minus the receiver's Gauss-Markov error; odometry rows compare the INS
    velocity turned into the vehicle frame, M v~ with M = R_vb C^T, with the wheels' velocity:
    M~ v~ = M v + M dv - M [v x] phi to first order (C = (I + [phi x]) C~), minus the odometry's own
    slowly varying error (wheel-radius scale, skid) as Gauss-Markov states.
    """
    Hm[:, :] = 0.0
    for i in range(3):
        Hm[i, 6 + i] = 1.0
        Hm[i, 15 + i] = -1.0
        Hm[3 + i, 3 + i] = 1.0
        Hm[3 + i, 18 + i] = -1.0
        Hm[6 + i, 21 + i] = -1.0
    M, vx, Mv = m[0], m[1], m[2]
    for i in range(3):  # M = R_vb C^T
        for j in range(3):
            M[i, j] = R_vb[i, 0] * x[6 + 3 * j] + R_vb[i, 1] * x[7 + 3 * j] + R_vb[i, 2] * x[8 + 3 * j]
    v0, v1, v2 = x[3], x[4], x[5]
    vx[0, 0], vx[1, 1], vx[2, 2] = 0.0, 0.0, 0.0
    vx[0, 1], vx[0, 2], vx[1, 0], vx[1, 2], vx[2, 0], vx[2, 1] = -v2, v1, v2, -v0, -v1, v0
    _mm3_into(M, vx, Mv)
    for i in range(3):
        for j in range(3):
            Hm[6 + i, j] = -Mv[i, j]
            Hm[6 + i, 3 + j] = M[i, j]


@njit(cache=CACHE, inline="always")
def _propagate_blocks(P: np.ndarray, Phi15: np.ndarray, a: np.ndarray, out: np.ndarray, X: np.ndarray) -> None:
    """out = Phi P Phi^T for Phi = blockdiag(Phi15, diag(a)) (X: room for 9 x n).

    The biases are random walks, so F's bias rows (9..14) are zero and Phi15's are identity rows: only
    rows 0..8 of Phi15 P are products, half the work of the dense form. A Phi15 without that shape
    takes the dense form.
    """
    for i in range(9, 15):
        for j in range(15):
            if Phi15[i, j] != (1.0 if i == j else 0.0):
                block_congruence(Phi15, a, P, out)
                return
    n = P.shape[0]
    X[:, :] = 0.0  # rows 0..8 of Phi P
    for i in range(9):
        for k in range(15):
            f = Phi15[i, k]
            if f != 0.0:
                for j in range(n):
                    X[i, j] += f * P[k, j]
    for i in range(9):
        for j in range(i + 1):
            v = 0.0
            for k in range(15):
                v += X[i, k] * Phi15[j, k]
            out[i, j] = v
            out[j, i] = v
        for j in range(9, 15):
            out[i, j] = X[i, j]
            out[j, i] = X[i, j]
    for i in range(9, 15):
        for j in range(9, 15):
            out[i, j] = P[i, j]
    for j in range(n - 15):
        for i in range(9):
            out[i, 15 + j] = X[i, 15 + j] * a[j]
            out[15 + j, i] = out[i, 15 + j]
        for i in range(9, 15):
            out[i, 15 + j] = P[i, 15 + j] * a[j]
            out[15 + j, i] = out[i, 15 + j]
        for i in range(n - 15):
            out[15 + i, 15 + j] = P[15 + i, 15 + j] * (a[i] * a[j])


@njit(cache=CACHE, nogil=True)
def filter_loop(
    stream: Stream,
    x0: np.ndarray,
    P0: np.ndarray,
    qc: np.ndarray,
    max_block_s: float,
    tf: np.ndarray,
    llh: np.ndarray,
    vel: np.ndarray,
    odo: np.ndarray,
    R_vb: np.ndarray,
    sigma: np.ndarray,
    use: np.ndarray,
    gm_tau: np.ndarray,
    gm_sigma: np.ndarray,
    g0: np.ndarray,
    keep: np.ndarray,
    compare: bool = True,
    upd_every: int = 1,
    odometry_measured: bool = True,
):
    """The closed-loop filter over all epochs; returns the per-epoch and per-block records (the updated
    covariance of every `upd_every`-th epoch only, when kept; H only once when no epoch has odometry:
    then it is the same at every epoch).

    The 15 INS error states are fed back into the nominal state and reset at every update; the six
    Gauss-Markov receiver-error states are not (they are no error of the INS) and carry their estimate.
    """
    t = stream[0]
    M = tf.shape[0]
    N = t.shape[0]
    out_z = np.full((M, NM), np.nan)
    out_nu = np.full((M, NM), np.nan)
    out_S = np.zeros((M, NM, NM))
    # the per-epoch matrices the smoother, the detectors' model and coasting comparisons need, each kept
    # only when asked (`keep`: Phi, Qd, H, P_pred, P_upd; one epoch otherwise): a noise-learning run keeps
    # none, a coast only S_all, most of the memory traffic
    keep_phi, keep_qd, keep_h, keep_pred, keep_upd = keep[0], keep[1], keep[2], keep[3], keep[4]
    # H P H^T + R of every row, used or not: what a coasting run is compared with (`compare`)
    out_S_all = np.zeros((M if compare else 1, NM, NM))
    out_R = np.zeros((M, NM, NM))
    # without odometry H's rows for it are never read, and zeroed H is the same at every epoch: one kept
    out_H = np.zeros((M if keep_h and odometry_measured else 1, NM, NE))
    nis = np.full(M, np.nan)
    dof = np.zeros(M, dtype=np.int64)
    # log det S of the used rows (the likelihood noise learning maximises); NaN where S is not positive definite
    logdet = np.full(M, np.nan)
    # Phi and Qd are block-diagonal (the INS block, then each Gauss-Markov state on its own): kept so
    out_Phi = np.zeros((M if keep_phi else 1, 15, 15))
    out_Phi_gm = np.zeros((M if keep_phi else 1, NG))
    out_Qd = np.zeros((M if keep_qd else 1, 15, 15))
    out_Qd_gm = np.zeros((M if keep_qd else 1, NG))
    P_pred = np.zeros((M if keep_pred else 1, NE, NE))
    P_upd = np.zeros(((M - 1) // upd_every + 1 if keep_upd else 1, NE, NE))
    out_dx = np.zeros((M, NE))
    gm = np.zeros((M, NG))
    states = np.zeros((M, NX))
    # room for a block per IMU sample, left unwritten (np.empty): only the blocks made take memory (the
    # zeroed form touched 0.55 GB on a day of 100 Hz for a 50 MB track)
    track = np.empty((N + 1, 7))  # t, lat, lon, h, ve, vn, vu
    track_epoch = np.empty(N + 1, dtype=np.int64)
    nt = 0
    x = x0.copy()
    P = P0.copy()
    g = g0.copy()  # Gauss-Markov sensor errors (receiver, odometry), estimated
    k = np.searchsorted(t, x[21])
    if k > N - 1:
        k = N - 1
    x[21] = t[k]
    at_k = integrals_at(stream, k)  # kept as k moves: blocks share ends
    qc15 = qc[:15].copy()
    # made once and filled in place: noise learning runs this loop ~95 times, and small arrays made afresh
    # at every block and epoch cost it allocation time, not arithmetic
    Phi_acc = np.eye(15)
    Phi_acc_gm = np.ones(NG)
    Qd_acc = np.zeros((15, 15))
    Qd_acc_gm = np.zeros(NG)
    decay = np.empty(NG)
    qg = np.empty(NG)
    z = np.empty(NM)
    nu = np.empty(NM)
    nu_used = np.empty(NM)
    no_prior = np.zeros(NE)  # the error state before an update (closed loop: reset at every update)
    # the working arrays of a block and an update, made once and swapped with what they replace (a block
    # and an epoch made some 35 small arrays: a fifth of a tuning run went to allocation and reference
    # counting)
    at_next = np.empty(10)
    dC, dv_b, dp_b = np.empty((3, 3)), np.empty(3), np.empty(3)
    F = np.zeros((15, 15))  # error_dynamics_into writes the same entries every time
    FT, Phi15, Qd15 = np.empty((15, 15)), np.empty((15, 15)), np.empty((15, 15))
    P_next = np.empty((NE, NE))
    X = np.empty((9, NE))
    x_next = np.empty(NX)
    m33 = np.empty((6, 3, 3))
    Hm = np.empty((NM, NE))
    scratch = update_scratch(NE, NM)
    rows = np.empty(NM, dtype=np.int64)
    dx = np.empty(NE)
    for e in range(M):
        target = np.searchsorted(t, tf[e], side="right") - 1
        if target < k:
            target = k
        if target > N - 1:
            target = N - 1
        if keep_phi:
            Phi_acc_gm[:] = 1.0
        if keep_qd:
            Qd_acc_gm[:] = 0.0
        blocks = 0  # of this epoch
        while k < target:
            j = np.searchsorted(t, t[k] + max_block_s, side="right") - 1
            if j > target:
                j = target
            if j <= k:
                j = k + 1
            T = step_to(stream, at_k, k, j, at_next, dC, dv_b, dp_b)
            at_k, at_next = at_next, at_k
            # a zero-length block (two samples at one time) has Phi = I and Qd = 0 whatever the force
            if T > 0:
                f0, f1, f2 = dv_b[0] / T - x[18], dv_b[1] / T - x[19], dv_b[2] / T - x[20]
            else:
                f0, f1, f2 = -x[18], -x[19], -x[20]
            error_dynamics_into(x, f0, f1, f2, F)
            discretise_into(F, qc15, T, FT, Phi15, Qd15)
            for i in range(NG):
                decay[i] = math.exp(-T / gm_tau[i])
                qg[i] = gm_sigma[i] ** 2 * (1.0 - decay[i] * decay[i])
                g[i] *= decay[i]
            propagate_into(x, dC, dv_b, dp_b, T, x_next, m33)
            x, x_next = x_next, x
            # Phi = blockdiag(Phi15, diag(a)): propagate the blocks, not 24 x 24 products
            _propagate_blocks(P, Phi15, decay, P_next, X)
            P, P_next = P_next, P
            for r in range(15):
                for c in range(15):
                    P[r, c] += Qd15[r, c]
            for i in range(NG):
                P[15 + i, 15 + i] += qg[i]
            # the epoch-to-epoch Qd and Phi, made only to be kept (nothing else reads them); an epoch's first
            # block is its own (Phi15 I and Phi15 0 Phi15^T + Qd15: no products, the same numbers)
            if keep_qd:
                if blocks == 0:
                    Qd_acc[:, :] = Qd15
                else:
                    Qd_acc = Phi15 @ Qd_acc @ Phi15.T + Qd15
                for i in range(NG):
                    Qd_acc_gm[i] = Qd_acc_gm[i] * decay[i] * decay[i] + qg[i]
            if keep_phi:
                if blocks == 0:
                    Phi_acc[:, :] = Phi15
                else:
                    Phi_acc = Phi15 @ Phi_acc
                for i in range(NG):
                    Phi_acc_gm[i] *= decay[i]
            blocks += 1
            k = j
            track[nt, 0] = x[21]
            track[nt, 1:4] = x[0:3]
            track[nt, 4:7] = x[3:6]
            track_epoch[nt] = e - 1
            nt += 1
        for r in range(NE):  # symmetric against round-off (Qd15 is a product)
            for c in range(r):
                v = 0.5 * (P[r, c] + P[c, r])
                P[r, c] = v
                P[c, r] = v
        if keep_phi:
            if blocks == 0:  # no IMU sample between two epochs: Phi = I
                out_Phi[e] = 0.0
                for i in range(15):
                    out_Phi[e, i, i] = 1.0
            else:
                out_Phi[e] = Phi_acc
            out_Phi_gm[e] = Phi_acc_gm
        if keep_qd:
            if blocks == 0:
                out_Qd[e] = 0.0
            else:
                for r in range(15):
                    for c in range(15):
                        out_Qd[e, r, c] = 0.5 * (Qd_acc[r, c] + Qd_acc[c, r])
            out_Qd_gm[e] = Qd_acc_gm
        if keep_pred:
            P_pred[e] = P
        elif e == 0:
            P_pred[0] = P  # the detectors' model starts from it
        lead = tf[e] - x[21]
        rm, rn = local_radii(x[0])
        z[:] = np.nan
        z[0] = (x[1] - llh[e, 1]) * (rn + x[2]) * math.cos(x[0]) + x[3] * lead
        z[1] = (x[0] - llh[e, 0]) * (rm + x[2]) + x[4] * lead
        z[2] = x[2] - llh[e, 2] + x[5] * lead
        for i in range(3):
            if not math.isnan(vel[e, i]):
                z[3 + i] = x[3 + i] - vel[e, i]
        measurement_matrix_into(x, R_vb, Hm, m33)
        if not odometry_measured:
            Hm[6:9, :6] = 0.0
        if odometry_measured:  # the INS velocity in the vehicle frame, R_vb C^T v
            vb = _mv3_s(
                R_vb,
                x[6] * x[3] + x[9] * x[4] + x[12] * x[5],
                x[7] * x[3] + x[10] * x[4] + x[13] * x[5],
                x[8] * x[3] + x[11] * x[4] + x[14] * x[5],
            )
            for i in range(3):
                if not math.isnan(odo[e, i]):
                    z[6 + i] = vb[i] - odo[e, i]
        nu[:] = z  # minus the predicted receiver and odometry errors: H's Gauss-Markov columns times g
        for i in range(NM):
            for j in range(NG):
                nu[i] -= Hm[i, 15 + j] * g[j]
        out_z[e] = z
        out_nu[e] = nu
        if keep_h and (odometry_measured or e == 0):
            out_H[e] = Hm
        for i in range(NM):
            out_R[e, i, i] = sigma[e, i] ** 2
        if compare:
            S_all = Hm @ P @ Hm.T
            for i in range(NM):
                S_all[i, i] += sigma[e, i] ** 2
            out_S_all[e] = S_all
        # the rows left out (not used, or not measured) are NaN: the one masked update every filter makes
        n_used = 0
        for i in range(NM):
            nu_used[i] = nu[i] if use[e, i] and not math.isnan(z[i]) else np.nan
            if not math.isnan(nu_used[i]):
                rows[n_used] = i
                n_used += 1
        if n_used > 0:
            nis_e, logdet_e = update_into(no_prior, P, Hm, out_R[e], nu_used, rows, n_used, False, scratch, dx, P_next)
            P, P_next = P_next, P
            nis[e] = nis_e
            dof[e] = n_used
            logdet[e] = logdet_e  # its Cholesky factor's; NaN where S is not positive definite
            S = scratch[3]
            for a in range(n_used):
                for b in range(n_used):
                    out_S[e, rows[a], rows[b]] = S[a, b]
            correct_into(x, dx, x_next, m33)
            x, x_next = x_next, x
            for i in range(NG):
                g[i] += dx[15 + i]
            out_dx[e] = dx
        if keep_upd and e % upd_every == 0:
            P_upd[e // upd_every] = P
        states[e] = x
        gm[e] = g
        if nt > 0 and track[nt - 1, 0] == x[21]:
            track[nt - 1, 1:4] = x[0:3]
            track[nt - 1, 4:7] = x[3:6]
            track_epoch[nt - 1] = e
    while k < N - 1:  # coast after the last fix so the track covers the whole IMU span
        j = np.searchsorted(t, t[k] + max_block_s, side="right") - 1
        if j <= k:
            j = k + 1
        T = step_to(stream, at_k, k, j, at_next, dC, dv_b, dp_b)
        at_k, at_next = at_next, at_k
        propagate_into(x, dC, dv_b, dp_b, T, x_next, m33)
        x, x_next = x_next, x
        k = j
        track[nt, 0] = x[21]
        track[nt, 1:4] = x[0:3]
        track[nt, 4:7] = x[3:6]
        track_epoch[nt] = M - 1
        nt += 1
    return (
        out_z,
        out_nu,
        out_S,
        out_S_all,
        out_R,
        out_H,
        nis,
        dof,
        logdet,
        out_Phi,
        out_Phi_gm,
        out_Qd,
        out_Qd_gm,
        P_pred,
        P_upd,
        out_dx,
        gm,
        states,
        track[:nt],
        track_epoch[:nt],
    )


@njit(cache=CACHE, nogil=True)
def rts_closed_loop(
    P_upd: np.ndarray,
    every: int,
    Phi: np.ndarray,
    Phi_gm: np.ndarray,
    Qd: np.ndarray,
    Qd_gm: np.ndarray,
    H: np.ndarray,
    R: np.ndarray,
    used: np.ndarray,
    dx: np.ndarray,
    variances: bool = True,
):
    """Rauch-Tung-Striebel smoothing of a closed-loop error-state filter (resets at every update).

    After a reset the filtered error is zero with covariance P_upd[e]; the next epoch's filtered error,
    relative to the same propagated nominal, is dx[e+1]. So the smoothed error of the corrected state at e
    is delta_e = A_e (dx[e+1] + delta_{e+1}), A_e = P_upd[e] Phi[e+1]^T P_pred[e+1]^-1, and
    P_s[e] = P_upd[e] + A_e (P_s[e+1] - P_pred[e+1]) A_e^T, with P_pred[e+1] = Phi[e+1] P_upd[e]
    Phi[e+1]^T + Qd[e+1] made here (the filter does not keep it: 166 MB per hour of 10 Hz GNSS; equal to
    the filter's block-by-block propagation up to rounding). Phi and Qd come as their blocks (the INS
    block, and the diagonal of the Gauss-Markov states).
    The filter keeps the updated covariance of every `every`-th epoch only (P_upd[i] is epoch i * every's):
    the smoother runs down in runs of `every` epochs, each run's covariances made again from its first by
    the filter's own prediction and update (H, R and the rows `used`), so it holds `every` of them.
    Returns delta and the smoothed variances (the diagonal of every P_s[e]: all any consumer reads, and
    a 24th of the memory of the full matrices). Without `variances` (M, 0) of them: the smoothed error
    alone needs A_e times one vector, pred^-1 v by one solve, not the gain A_e (24 right-hand sides)
    and the covariance recursion, about four fifths of the backward pass's arithmetic.
    """
    M, n = dx.shape
    h = Phi.shape[1]
    delta = np.zeros((M, n))
    var = np.zeros((M, n if variances else 0))
    run = np.empty((every, n, n))
    cross = np.empty((n, n))
    P_next = np.empty((n, n))
    # the re-made run's arrays, made once (as the filter's own: its update into the run's next covariance)
    p = H.shape[1]
    zero, x_new, mask = np.zeros(n), np.empty(n), np.empty(p)
    rows, scratch, pred_run = np.empty(p, dtype=np.int64), update_scratch(n, p), np.empty((n, n))
    for lo in range(((M - 1) // every) * every, -1, -every):
        hi = min(lo + every, M) - 1
        run[0] = P_upd[lo // every]
        for e in range(lo + 1, hi + 1):
            pred = block_congruence(Phi[e], Phi_gm[e], run[e - 1 - lo], pred_run)
            add_block_diagonal(pred, Qd[e], Qd_gm[e])
            for i in range(p):
                mask[i] = 0.0 if used[e, i] else np.nan
            if masked_update_into(zero, pred, H[e], R[e], mask, False, rows, scratch, x_new, run[e - lo])[0] == 0:
                run[e - lo] = pred
        for e in range(hi, lo - 1, -1):
            Pu = run[e - lo]
            if e == M - 1:
                P_next[:, :] = Pu
                for i in range(var.shape[1]):
                    var[e, i] = Pu[i, i]
                continue
            # cross = P_upd[e] Phi[e+1]^T and pred = Phi[e+1] cross + Qd[e+1], Phi block-diagonal
            cross[:, :h] = np.ascontiguousarray(Pu[:, :h]) @ np.ascontiguousarray(Phi[e + 1].T)
            for j in range(h, n):
                for i in range(n):
                    cross[i, j] = Pu[i, j] * Phi_gm[e + 1, j - h]
            pred = np.empty((n, n))
            pred[:h] = Phi[e + 1] @ np.ascontiguousarray(cross[:h])
            for i in range(h, n):
                pred[i] = Phi_gm[e + 1, i - h] * cross[i]
            pred = 0.5 * (pred + pred.T)
            add_block_diagonal(pred, Qd[e + 1], Qd_gm[e + 1])
            if not variances:  # A v = cross pred^-1 v (pred symmetric)
                delta[e] = cross @ np.linalg.solve(pred, dx[e + 1] + delta[e + 1])
                continue
            A = np.linalg.solve(pred.T, cross.T).T
            delta[e] = A @ (dx[e + 1] + delta[e + 1])
            Ps = Pu + A @ (P_next - pred) @ A.T
            P_next = 0.5 * (Ps + Ps.T)
            for i in range(n):
                var[e, i] = P_next[i, i]
    return delta, var
