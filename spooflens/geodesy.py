"""WGS84 geodesy: frame conversions through pymap3d, curvature radii and normal gravity.

Angles in radians unless a name says `_deg`. Local-level frame is ENU throughout spooflens.
"""

from __future__ import annotations

import numpy as np
import pymap3d
from numpy.typing import ArrayLike, NDArray

from spooflens.constants import SPEED_OF_LIGHT_MPS as C_MPS
from spooflens.constants import WGS84_A_M as A_M
from spooflens.constants import WGS84_B_M as B_M
from spooflens.constants import WGS84_E2 as E2
from spooflens.constants import WGS84_F as F
from spooflens.constants import WGS84_GAMMA_E as _GAMMA_E
from spooflens.constants import WGS84_GM as GM
from spooflens.constants import WGS84_K_SOMIGLIANA as _K_SOMIGLIANA
from spooflens.constants import WGS84_M_GEO as _M_GEO
from spooflens.constants import WGS84_OMEGA_IE as OMEGA_IE

__all__ = ["A_M", "B_M", "C_MPS", "E2", "GM", "OMEGA_IE", "F"]

FloatArray = NDArray[np.float64]


def small_move_en_m(dlat_deg: ArrayLike, dlon_deg: ArrayLike, lat_deg: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """East and north metres of a small move given in degrees, on a flat earth at `lat_deg`: within a
    fraction of a percent over the few kilometres between two fixes, where the indicators need no more."""
    east = np.asarray(dlon_deg, dtype=float) * 111_320.0 * np.cos(np.radians(lat_deg))
    return east, np.asarray(dlat_deg, dtype=float) * 110_540.0


def radii(lat: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Meridian (R_M) and transverse (R_N) radii of curvature at geodetic latitude `lat` (rad)."""
    s2 = np.sin(np.asarray(lat, dtype=float)) ** 2
    w = np.sqrt(1.0 - E2 * s2)
    return A_M * (1.0 - E2) / w**3, A_M / w


def normal_gravity(lat: ArrayLike, h: ArrayLike) -> FloatArray:
    """Magnitude of WGS84 normal gravity (m/s^2) at latitude `lat` (rad) and height `h` (m).

    Somigliana on the ellipsoid with the second-order free-air correction (NIMA TR8350.2 eq. 4-3).
    """
    lat = np.asarray(lat, dtype=float)
    h = np.asarray(h, dtype=float)
    s2 = np.sin(lat) ** 2
    g0 = _GAMMA_E * (1.0 + _K_SOMIGLIANA * s2) / np.sqrt(1.0 - E2 * s2)
    return np.asarray(g0 * (1.0 - 2.0 / A_M * (1.0 + F + _M_GEO - 2.0 * F * s2) * h + 3.0 / A_M**2 * h**2), dtype=float)


def earth_rate_enu(lat: ArrayLike) -> FloatArray:
    """Earth rotation vector in the local ENU frame, shape (..., 3)."""
    lat = np.asarray(lat, dtype=float)
    return np.stack([np.zeros_like(lat), OMEGA_IE * np.cos(lat), OMEGA_IE * np.sin(lat)], axis=-1)


def transport_rate_enu(lat: ArrayLike, h: ArrayLike, v_enu: ArrayLike) -> FloatArray:
    """Rotation of ENU relative to the Earth, omega_en^n = [-vN/(RM+h), vE/(RN+h), vE tanL/(RN+h)]."""
    lat = np.asarray(lat, dtype=float)
    h = np.asarray(h, dtype=float)
    v = np.asarray(v_enu, dtype=float)
    rm, rn = radii(lat)
    return np.stack([-v[..., 1] / (rm + h), v[..., 0] / (rn + h), v[..., 0] * np.tan(lat) / (rn + h)], axis=-1)


def geodetic_to_enu(
    lat_deg: ArrayLike, lon_deg: ArrayLike, h: ArrayLike, lat0_deg: ArrayLike, lon0_deg: ArrayLike, h0: ArrayLike
) -> FloatArray:
    """Geodetic (deg, m) to local ENU metres about (lat0, lon0, h0) (scalars, or arrays that broadcast);
    shape (..., 3)."""
    e, n, u = pymap3d.geodetic2enu(
        np.asarray(lat_deg, float),
        np.asarray(lon_deg, float),
        np.asarray(h, float),
        np.asarray(lat0_deg, float),
        np.asarray(lon0_deg, float),
        np.asarray(h0, float),
    )
    return np.stack([np.asarray(e), np.asarray(n), np.asarray(u)], axis=-1)


def enu_to_geodetic(
    enu: ArrayLike, lat0_deg: float, lon0_deg: float, h0: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Local ENU metres to geodetic latitude, longitude (deg) and height (m)."""
    enu = np.asarray(enu, dtype=float)
    lat, lon, h = pymap3d.enu2geodetic(enu[..., 0], enu[..., 1], enu[..., 2], lat0_deg, lon0_deg, h0)
    return np.asarray(lat, float), np.asarray(lon, float), np.asarray(h, float)


def geodetic_to_ecef(lat_deg: ArrayLike, lon_deg: ArrayLike, h: ArrayLike) -> FloatArray:
    x, y, z = pymap3d.geodetic2ecef(np.asarray(lat_deg, float), np.asarray(lon_deg, float), np.asarray(h, float))
    return np.stack([np.asarray(x), np.asarray(y), np.asarray(z)], axis=-1)


def ecef_to_geodetic(xyz: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    xyz = np.asarray(xyz, dtype=float)
    lat, lon, h = pymap3d.ecef2geodetic(xyz[..., 0], xyz[..., 1], xyz[..., 2])
    return np.asarray(lat, float), np.asarray(lon, float), np.asarray(h, float)


def enu_rotation(lat_deg: ArrayLike, lon_deg: ArrayLike) -> FloatArray:
    """Rotation matrix taking ECEF vectors into ENU at (lat, lon): (3, 3), or (..., 3, 3) for arrays."""
    lat, lon = np.radians(np.asarray(lat_deg, dtype=float)), np.radians(np.asarray(lon_deg, dtype=float))
    sl, cl, sp, cp = np.sin(lon), np.cos(lon), np.sin(lat), np.cos(lat)
    zero = np.zeros_like(sl)
    rows = [[-sl, cl, zero], [-sp * cl, -sp * sl, cp], [cp * cl, cp * sl, sp]]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def ecef_to_enu_vectors(lat_deg: ArrayLike, lon_deg: ArrayLike, d_ecef: ArrayLike) -> FloatArray:
    """ECEF vectors (N, 3) (velocities, displacements) in the local ENU frame of each point."""
    return np.einsum("...ij,...j->...i", enu_rotation(lat_deg, lon_deg), np.asarray(d_ecef, dtype=float))


def metres_per_radian(lat: ArrayLike, h: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Metres per radian of latitude and of longitude at (lat, h): (RM+h, (RN+h) cos lat)."""
    lat = np.asarray(lat, dtype=float)
    height = np.asarray(h, dtype=float)
    rm, rn = radii(lat)
    return rm + height, (rn + height) * np.cos(lat)


def add_enu_offset(
    lat_deg: ArrayLike, lon_deg: ArrayLike, h: ArrayLike, d_enu: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Geodetic position moved by small local ENU offsets (m), each at its own latitude; shapes (...), (..., 3).

    First order in offset/radius: exact to a millimetre for offsets of kilometres, which is what
    noise, attacks and lever arms are.
    """
    lat = np.asarray(lat_deg, dtype=float)
    h = np.asarray(h, dtype=float)
    d = np.asarray(d_enu, dtype=float)
    rm, rn = radii(np.radians(lat))
    return (
        lat + np.degrees(d[..., 1] / (rm + h)),
        np.asarray(lon_deg, dtype=float) + np.degrees(d[..., 0] / ((rn + h) * np.cos(np.radians(lat)))),
        h + d[..., 2],
    )
