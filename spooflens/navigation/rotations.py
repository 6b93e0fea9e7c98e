"""Quaternion and rotation helpers, vectorised over leading axes.

Quaternions are (w, x, y, z), Hamilton convention; q rotates vectors from frame B to frame A when it
represents the attitude of B in A (v_A = q v_B q*).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def skew(v: ArrayLike) -> FloatArray:
    v = np.asarray(v, dtype=float)
    z = np.zeros(v.shape[:-1])
    return np.stack(
        [
            np.stack([z, -v[..., 2], v[..., 1]], -1),
            np.stack([v[..., 2], z, -v[..., 0]], -1),
            np.stack([-v[..., 1], v[..., 0], z], -1),
        ],
        -2,
    )


def quat_multiply(p: FloatArray, q: FloatArray) -> FloatArray:
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def quat_conjugate(q: FloatArray) -> FloatArray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_from_rotvec(theta: ArrayLike) -> FloatArray:
    """exp of a rotation vector; a series for tiny angles keeps full precision."""
    theta = np.asarray(theta, dtype=float)
    a = np.linalg.norm(theta, axis=-1, keepdims=True)
    half = 0.5 * a
    small = a < 1e-6
    sinc = np.where(small, 0.5 - a**2 / 48.0, np.sin(half) / np.where(small, 1.0, a))
    return np.concatenate([np.cos(half), theta * sinc], axis=-1)


def quat_to_rotvec(q: FloatArray) -> FloatArray:
    q = np.where(q[..., :1] < 0, -q, q)
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    small = s < 1e-9
    return v * np.where(small, 2.0 / np.maximum(q[..., :1], 1e-300), angle / np.where(small, 1.0, s))


def quat_to_matrix(q: FloatArray) -> FloatArray:
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def matrix_to_quat(m: FloatArray) -> FloatArray:
    """Rotation matrices to unit quaternions (w >= 0), robust for every angle (Shepperd)."""
    m = np.asarray(m, dtype=float)
    tr = np.trace(m, axis1=-2, axis2=-1)
    cand = np.stack([tr, m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]], -1)
    k = np.argmax(cand, axis=-1)
    q = np.empty((*m.shape[:-2], 4))
    s = np.sqrt(np.maximum(1.0 + 2.0 * np.take_along_axis(cand, k[..., None], -1)[..., 0] - tr, 1e-300))
    for i in range(4):
        sel = k == i
        if not np.any(sel):
            continue
        mm, ss = m[sel], s[sel]
        if i == 0:
            q[sel] = np.stack(
                [
                    0.5 * ss,
                    (mm[:, 2, 1] - mm[:, 1, 2]) / (2 * ss),
                    (mm[:, 0, 2] - mm[:, 2, 0]) / (2 * ss),
                    (mm[:, 1, 0] - mm[:, 0, 1]) / (2 * ss),
                ],
                -1,
            )
        elif i == 1:
            q[sel] = np.stack(
                [
                    (mm[:, 2, 1] - mm[:, 1, 2]) / (2 * ss),
                    0.5 * ss,
                    (mm[:, 0, 1] + mm[:, 1, 0]) / (2 * ss),
                    (mm[:, 0, 2] + mm[:, 2, 0]) / (2 * ss),
                ],
                -1,
            )
        elif i == 2:
            q[sel] = np.stack(
                [
                    (mm[:, 0, 2] - mm[:, 2, 0]) / (2 * ss),
                    (mm[:, 0, 1] + mm[:, 1, 0]) / (2 * ss),
                    0.5 * ss,
                    (mm[:, 1, 2] + mm[:, 2, 1]) / (2 * ss),
                ],
                -1,
            )
        else:
            q[sel] = np.stack(
                [
                    (mm[:, 1, 0] - mm[:, 0, 1]) / (2 * ss),
                    (mm[:, 0, 2] + mm[:, 2, 0]) / (2 * ss),
                    (mm[:, 1, 2] + mm[:, 2, 1]) / (2 * ss),
                    0.5 * ss,
                ],
                -1,
            )
    return np.where(q[..., :1] < 0, -q, q)


def quat_rotate(q: FloatArray, v: FloatArray) -> FloatArray:
    """Rotate vectors v by unit quaternions q (broadcasting)."""
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def euler_to_matrix(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> FloatArray:
    """C_b^n for a FLU body in ENU: yaw about up (from east, counter-clockwise), pitch nose up, roll."""
    roll, pitch, yaw = (np.asarray(a, dtype=float) for a in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    z, o = np.zeros_like(cr), np.ones_like(cr)
    rz = np.stack([np.stack([cy, -sy, z], -1), np.stack([sy, cy, z], -1), np.stack([z, z, o], -1)], -2)
    ry = np.stack([np.stack([cp, z, -sp], -1), np.stack([z, o, z], -1), np.stack([sp, z, cp], -1)], -2)
    rx = np.stack([np.stack([o, z, z], -1), np.stack([z, cr, -sr], -1), np.stack([z, sr, cr], -1)], -2)
    return rz @ ry @ rx


def matrix_to_euler(c: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Inverse of euler_to_matrix: (roll, pitch, yaw)."""
    pitch = np.arcsin(np.clip(c[..., 2, 0], -1.0, 1.0))
    roll = np.arctan2(c[..., 2, 1], c[..., 2, 2])
    yaw = np.arctan2(c[..., 1, 0], c[..., 0, 0])
    return roll, pitch, yaw


def rotvec_to_matrix(theta: ArrayLike) -> FloatArray:
    return quat_to_matrix(quat_from_rotvec(theta))


# --- single-vector versions for the per-block loop: plain float arithmetic, no array dispatch -------


def cross3(a: FloatArray, b: FloatArray) -> FloatArray:
    a0, a1, a2 = a
    b0, b1, b2 = b
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def skew3(v: FloatArray) -> FloatArray:
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def quat_to_matrix3(w: float, x: float, y: float, z: float) -> FloatArray:
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def rotvec_to_matrix3(v: FloatArray) -> FloatArray:
    """Rodrigues for one rotation vector."""
    x, y, z = v
    a2 = x * x + y * y + z * z
    if a2 < 1e-18:
        return np.array([[1.0, -z, y], [z, 1.0, -x], [-y, x, 1.0]])
    a = math.sqrt(a2)
    s, c = math.sin(a) / a, (1.0 - math.cos(a)) / a2
    return np.array(
        [
            [1 - c * (y * y + z * z), c * x * y - s * z, c * x * z + s * y],
            [c * x * y + s * z, 1 - c * (x * x + z * z), c * y * z - s * x],
            [c * x * z - s * y, c * y * z + s * x, 1 - c * (x * x + y * y)],
        ]
    )
