"""A receiver's report of its sky (NAV-SAT, GSV, PX4 satellite_info): per satellite and epoch its C/N0,
elevation, azimuth and whether the receiver used it, from satellite geometry.

C/N0 follows elevation as a small antenna's gain pattern does (about 12 dB between the horizon and the
zenith), around the receiver's mean level, with a fixed offset per satellite (its transmitter, the
antenna's pattern in azimuth), a slow wander (multipath, attitude) and epoch noise, in whole dB-Hz as
receivers report them. Satellites below the elevation mask are not listed; those at 10 degrees or more
with a C/N0 of 25 dB-Hz or more are used.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.gnss.ephemeris import GpsEphemerides, satellite_states
from spooflens.gnss.geometry import azimuth_elevation
from spooflens.simulation.gauss_markov import gauss_markov

FloatArray = NDArray[np.float64]
MASK_DEG = 5.0
USED_MIN_ELEVATION_DEG = 10.0
USED_MIN_CN0_DBHZ = 25.0
ELEVATION_GAIN_DB = 12.0


def sky_reports(
    receiver_id: str,
    t_s: FloatArray,
    t_gps_s: FloatArray,
    rx_ecef: FloatArray,
    eph: GpsEphemerides,
    mean_cn0_dbhz: float,
    rng: np.random.Generator,
) -> pd.DataFrame:
    """Rows of the `satellites` frame (t_s relative) for a receiver at `rx_ecef` at times t_s (GPS t_gps_s)."""
    sats = np.array(eph.satellites())
    n_e, n_s = len(t_s), len(sats)
    ep, sv = np.repeat(np.arange(n_e), n_s), np.tile(sats, n_e)
    st = satellite_states(eph, sv, t_gps_s[ep])
    az, el = azimuth_elevation(st.pos_m, rx_ecef[ep])
    el_deg, az_deg = np.degrees(el), np.degrees(az) % 360.0
    # each satellite's own offset and slow wander, and noise per epoch
    offset = dict(zip(sats, rng.normal(0.0, 1.5, n_s), strict=True))
    dt = float(np.median(np.diff(t_s))) if n_e > 1 else 1.0
    wander = gauss_markov(n_e, dt, np.ones(n_s), 60.0, rng)
    shape = np.sin(np.clip(el, 0.0, None)) - 0.6  # zero about the median satellite's elevation
    cn0 = (
        mean_cn0_dbhz
        + ELEVATION_GAIN_DB * shape
        + np.array([offset[s] for s in sv])
        + 1.0 * np.asarray(wander).reshape(-1)
        + rng.normal(0.0, 0.7, len(sv))
    )
    seen = st.valid & (el_deg >= MASK_DEG)
    used = (el_deg >= USED_MIN_ELEVATION_DEG) & (cn0 >= USED_MIN_CN0_DBHZ)
    return pd.DataFrame(
        {
            "t_s": t_s[ep],
            "receiver_id": receiver_id,
            "sv_id": sv,
            "cn0_dbhz": np.round(cn0),
            "elevation_deg": np.round(el_deg),
            "azimuth_deg": np.round(az_deg),
            "used": used.astype(float),
            "residual_m": np.nan,
            "healthy": 1.0,
        }
    )[seen].reset_index(drop=True)
