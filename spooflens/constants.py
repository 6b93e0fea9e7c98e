"""Physical constants, each written once: WGS84 (NIMA TR8350.2), the speed of light, standard gravity; and
the NMEA talkers of GNSS receivers.

The GPS interface specification uses its own values for orbits (IS-GPS-200's GM and Earth rotation
rate); those stay in `spooflens.gnss.ephemeris` beside the orbit code that must use exactly them.
"""

from __future__ import annotations

WGS84_A_M = 6378137.0  # semi-major axis
WGS84_F = 1.0 / 298.257223563  # flattening
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)  # first eccentricity squared
WGS84_B_M = WGS84_A_M * (1.0 - WGS84_F)  # semi-minor axis
WGS84_OMEGA_IE = 7.292115e-5  # Earth rotation rate, rad/s
WGS84_GM = 3.986004418e14  # m^3/s^2
# Somigliana normal gravity (NIMA TR8350.2 eq. 4-1, 4-3)
WGS84_GAMMA_E = 9.7803253359  # normal gravity at the equator, m/s^2
WGS84_K_SOMIGLIANA = 0.00193185265241
WGS84_M_GEO = WGS84_OMEGA_IE**2 * WGS84_A_M**2 * WGS84_B_M / WGS84_GM
SPEED_OF_LIGHT_MPS = 299792458.0
STANDARD_GRAVITY = 9.80665  # m/s^2, the g of "specific force in g"
KNOT_MPS = 1852.0 / 3600.0  # the nautical mile an hour
# NMEA talker ids that name a satellite system (GN: several), not a device: a GNSS receiver's sentences
NMEA_GNSS_TALKERS = frozenset({"GP", "GL", "GA", "GB", "BD", "GN", "GQ", "QZ", "GI"})
