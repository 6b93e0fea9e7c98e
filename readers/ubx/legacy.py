"""A fix assembled from the messages u-blox receivers gave before NAV-PVT (u-blox 5-7, timing firmware).

One navigation epoch (iTOW) spreads over NAV-POSLLH (geodetic position, hAcc/vAcc) or NAV-POSECEF /
NAV-SOL (ECEF position), NAV-VELNED (NED velocity) or NAV-VELECEF / NAV-SOL (ECEF velocity), and
NAV-SOL or NAV-STATUS (fix type and validity). `legacy_fix` joins what the epoch has into the values
NAV-PVT would have given.
"""

from __future__ import annotations

import math

import numpy as np

from spooflens.geodesy import ecef_to_enu_vectors, ecef_to_geodetic
from spooflens.schema import FixType

# why an epoch with a position is no fix
NO_FIX = "no fix (gpsFix 0 or gpsFixOk 0)"
TIME_ONLY = "time-only fix (gpsFix 5: a timing receiver at a fixed position)"
DEAD_RECKONING = "dead reckoning only (gpsFix 1)"


def fix_type(gps_fix: float, diff_soln: float) -> FixType:
    """u-blox gpsFix (2 2-D, 3 3-D, 4 GNSS + dead reckoning) as a FixType."""
    if gps_fix == 2:
        return FixType.FIX_2D
    return FixType.DGNSS if diff_soln == 1 else FixType.FIX_3D


def legacy_fix(parts: dict[str, float]) -> tuple[dict[str, float] | None, str]:
    """Schema values of one epoch's fix from the merged values of its legacy messages, or (None, why)."""
    gps_fix, ok = parts.get("gps_fix", math.nan), parts.get("fix_ok", math.nan)
    if math.isfinite(gps_fix):
        if gps_fix == 5:
            return None, TIME_ONLY
        if gps_fix == 1:
            return None, DEAD_RECKONING
        if gps_fix == 0 or ok == 0:
            return None, NO_FIX
    out: dict[str, float] = {}
    if math.isfinite(parts.get("lat_deg", math.nan)):
        out |= {k: parts[k] for k in ("lat_deg", "lon_deg", "height_m")}
    elif all(math.isfinite(parts.get(f"ecef_{a}_m", math.nan)) for a in "xyz"):
        xyz = np.array([parts[f"ecef_{a}_m"] for a in "xyz"])
        if np.linalg.norm(xyz) < 6.0e6:  # the receiver's zeros before a fix, not a place on Earth
            return None, NO_FIX
        lat, lon, h = ecef_to_geodetic(xyz)
        out |= {"lat_deg": float(lat), "lon_deg": float(lon), "height_m": float(h)}
    else:
        return None, "velocity without a position"
    if out["lat_deg"] == 0 and out["lon_deg"] == 0:
        return None, NO_FIX
    if math.isfinite(parts.get("vel_n_mps", math.nan)):
        out |= {k: parts[k] for k in ("vel_e_mps", "vel_n_mps", "vel_u_mps")}
    elif all(math.isfinite(parts.get(f"ecef_v{a}_mps", math.nan)) for a in "xyz"):
        v = ecef_to_enu_vectors(out["lat_deg"], out["lon_deg"], [parts[f"ecef_v{a}_mps"] for a in "xyz"])
        out |= {"vel_e_mps": float(v[0]), "vel_n_mps": float(v[1]), "vel_u_mps": float(v[2])}
    for key in ("h_acc_m", "v_acc_m", "vel_acc_mps", "sats_used"):
        if math.isfinite(parts.get(key, math.nan)):
            out[key] = parts[key]
    # no fix status in the capture (a bare NAV-POSLLH): a position, of unknown quality
    known = math.isfinite(gps_fix)
    out["fix_type"] = float(fix_type(gps_fix, parts.get("diff_soln", 0.0)) if known else FixType.UNKNOWN)
    return out, ""
