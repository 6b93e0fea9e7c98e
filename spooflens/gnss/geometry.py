"""Receiver-satellite geometry and the signal path's delays: what a pseudorange is made of.

pseudorange = range (with Earth rotation during the flight) + c dt_rx - c dt_sv + troposphere
              + ionosphere + noise

`expected_pseudorange` writes this sum: the simulator makes pseudoranges with it, and the
single-point solver explains them with the same pieces (`sagnac_range`, `atmospheric_delay`), so both
meet one model. Models are
RTKLIB's (Saastamoinen with a standard atmosphere, broadcast Klobuchar), which is what receivers use.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spooflens.constants import WGS84_E2
from spooflens.gnss.ephemeris import C_MPS, OMEGA_E_GPS, SECONDS_PER_WEEK, Klobuchar

FloatArray = NDArray[np.float64]


def sagnac_range(sv_ecef: FloatArray, rx_ecef: FloatArray) -> FloatArray:
    """Range from a satellite position (ECEF at transmission) to the receiver (ECEF at reception).

    The Earth turns while the signal flies: to first order that adds omega_e (x_s y_r - y_s x_r) / c
    (up to ~40 m), exact to well below a millimetre for GNSS orbits.
    """
    d = np.linalg.norm(sv_ecef - rx_ecef, axis=-1)
    return d + OMEGA_E_GPS * (sv_ecef[..., 0] * rx_ecef[..., 1] - sv_ecef[..., 1] * rx_ecef[..., 0]) / C_MPS


def line_of_sight(sv_ecef: FloatArray, rx_ecef: FloatArray) -> FloatArray:
    """Unit vector from the receiver to the satellite, ECEF."""
    d = sv_ecef - rx_ecef
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def azimuth_elevation(sv_ecef: FloatArray, rx_ecef: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Azimuth (from north, clockwise) and elevation (rad) of each satellite seen from the receiver."""
    x, y, z = rx_ecef[..., 0], rx_ecef[..., 1], rx_ecef[..., 2]
    lon = np.arctan2(y, x)
    # geodetic latitude is what the horizon is referred to; spherical is within 0.2 deg, plenty here
    lat = np.arctan2(z, np.hypot(x, y) * (1.0 - WGS84_E2))
    u = line_of_sight(sv_ecef, rx_ecef)
    sl, cl, sp, cp = np.sin(lon), np.cos(lon), np.sin(lat), np.cos(lat)
    e = -sl * u[..., 0] + cl * u[..., 1]
    n = -sp * cl * u[..., 0] - sp * sl * u[..., 1] + cp * u[..., 2]
    up = cp * cl * u[..., 0] + cp * sl * u[..., 1] + sp * u[..., 2]
    return np.arctan2(e, n), np.arcsin(np.clip(up, -1.0, 1.0))


def tropospheric_delay(lat: FloatArray, h: FloatArray, elevation: FloatArray) -> FloatArray:
    """Saastamoinen slant delay (m) with a standard atmosphere (15 C, 1013.25 hPa, 70% humidity at sea level).

    Heights are clamped to 0-10 km rather than switching the model off outside (RTKLIB returns 0 below
    -100 m): a solution dragged there by a spoofer must still see a smooth model, or its offsets jump.
    """
    lat, h, el = np.broadcast_arrays(np.asarray(lat, float), np.asarray(h, float), np.asarray(elevation, float))
    hgt = np.clip(h, 0.0, 1e4)
    pressure = 1013.25 * (1.0 - 2.2557e-5 * hgt) ** 5.2568
    temp = 15.0 - 6.5e-3 * hgt + 273.16
    vapour = 6.108 * 0.7 * np.exp((17.15 * temp - 4684.0) / (temp - 38.45))
    cos_z = np.sin(np.maximum(el, 1e-3))
    dry = 0.0022768 * pressure / (1.0 - 0.00266 * np.cos(2.0 * lat) - 0.00028 * hgt / 1e3) / cos_z
    wet = 0.002277 * (1255.0 / temp + 0.05) * vapour / cos_z
    return np.where(el > 0, dry + wet, 0.0)


def klobuchar_delay(
    iono: Klobuchar, lat: FloatArray, lon: FloatArray, azimuth: FloatArray, elevation: FloatArray, t_gps_s: FloatArray
) -> FloatArray:
    """Broadcast (Klobuchar) ionospheric delay on GPS L1, metres (IS-GPS-200 20.3.3.5.2.5)."""
    el_sc = np.asarray(elevation, float) / np.pi  # semicircles
    psi = 0.0137 / (el_sc + 0.11) - 0.022
    phi = np.clip(np.asarray(lat, float) / np.pi + psi * np.cos(azimuth), -0.416, 0.416)
    lam = np.asarray(lon, float) / np.pi + psi * np.sin(azimuth) / np.cos(phi * np.pi)
    phi_m = phi + 0.064 * np.cos((lam - 1.617) * np.pi)
    t_local = np.mod(43200.0 * lam + np.mod(t_gps_s, SECONDS_PER_WEEK), 86400.0)
    slant = 1.0 + 16.0 * (0.53 - el_sc) ** 3
    a, b = iono.alpha, iono.beta
    amp = np.maximum(a[0] + phi_m * (a[1] + phi_m * (a[2] + phi_m * a[3])), 0.0)
    per = np.maximum(b[0] + phi_m * (b[1] + phi_m * (b[2] + phi_m * b[3])), 72000.0)
    x = 2.0 * np.pi * (t_local - 50400.0) / per
    delay = np.where(np.abs(x) < 1.57, 5e-9 + amp * (1.0 - x * x / 2.0 + x**4 / 24.0), 5e-9)
    return np.where(elevation > 0, C_MPS * slant * delay, 0.0)


def atmospheric_delay(
    rx_ecef: FloatArray, sv_ecef: FloatArray, t_gps_s: FloatArray | None, iono: Klobuchar | None
) -> FloatArray:
    """Troposphere plus (when the broadcast coefficients and the GPS time are known) ionosphere on L1, metres."""
    from spooflens.geodesy import ecef_to_geodetic

    lat_deg, lon_deg, h = ecef_to_geodetic(rx_ecef)
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    az, el = azimuth_elevation(sv_ecef, rx_ecef)
    delay = tropospheric_delay(lat, h, el)
    if iono is not None and t_gps_s is not None:
        delay = delay + klobuchar_delay(iono, lat, lon, az, el, t_gps_s)
    return delay


def expected_pseudorange(
    sv_ecef: FloatArray,
    sv_clock_bias_m: FloatArray,
    rx_ecef: FloatArray,
    rx_clock_bias_m: FloatArray,
    t_gps_s: FloatArray | None,
    iono: Klobuchar | None,
) -> FloatArray:
    """The pseudorange a receiver at `rx_ecef` with clock bias `rx_clock_bias_m` measures, noise aside."""
    return (
        sagnac_range(sv_ecef, rx_ecef)
        + rx_clock_bias_m
        - sv_clock_bias_m
        + atmospheric_delay(rx_ecef, sv_ecef, t_gps_s, iono)
    )


def expected_range_rate(
    sv_ecef: FloatArray,
    sv_vel: FloatArray,
    sv_clock_drift_mps: FloatArray,
    rx_ecef: FloatArray,
    rx_vel: FloatArray,
    rx_clock_drift_mps: FloatArray,
) -> FloatArray:
    """Pseudorange rate (m/s): relative velocity along the line of sight, both clock drifts, and the
    rate of the Earth-rotation term of `sagnac_range` (a few mm/s)."""
    u = line_of_sight(sv_ecef, rx_ecef)
    sagnac_rate = (
        OMEGA_E_GPS
        * (
            sv_vel[..., 0] * rx_ecef[..., 1]
            + sv_ecef[..., 0] * rx_vel[..., 1]
            - sv_vel[..., 1] * rx_ecef[..., 0]
            - sv_ecef[..., 1] * rx_vel[..., 0]
        )
        / C_MPS
    )
    return np.sum(u * (sv_vel - rx_vel), axis=-1) + sagnac_rate + rx_clock_drift_mps - sv_clock_drift_mps
