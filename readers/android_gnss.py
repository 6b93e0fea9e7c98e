"""Android's GNSS measurement conventions (GnssMeasurement, GnssStatus), shared by the GnssLogger reader and
the tables derived from its logs (GSDC, gnss_lib_py)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
ADR_VALID, ADR_RESET, ADR_CYCLE_SLIP = 1, 2, 4  # GnssMeasurement.accumulatedDeltaRangeState bits
ADR_HALF_CYCLE_RESOLVED, ADR_HALF_CYCLE_REPORTED = 8, 16  # (API 28+)
HALF_CYCLE_ANDROID = (
    "carriers with an unresolved half-cycle ambiguity (Android ADR state HALF_CYCLE_REPORTED without "
    "HALF_CYCLE_RESOLVED)"
)


def adr_half_cycle_unresolved(state: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Where the phone reports its half-cycle state (bit 16) and says it is not resolved (bit 8 clear)."""
    return ((state & ADR_HALF_CYCLE_REPORTED) != 0) & ((state & ADR_HALF_CYCLE_RESOLVED) == 0)


# GnssStatus constellation types -> RINEX letter
SYSTEM = {1: "G", 2: "S", 3: "R", 4: "J", 5: "C", 6: "E", 7: "I"}


def android_systems(constellation: FloatArray) -> NDArray[np.str_]:
    """RINEX system letter of each Android ConstellationType ("" for unknown or missing)."""
    return np.array([SYSTEM.get(int(c), "") if np.isfinite(c) else "" for c in constellation])


def android_sv_ids(system: NDArray[np.str_], svid: FloatArray) -> NDArray[np.str_]:
    """RINEX-style ids of Android (constellation, svid) pairs: SBAS 120-158 -> S20-S58, QZSS 193-200 ->
    J01-J08; "" where there is none (no constellation; a GLONASS satellite known only by its frequency
    channel, svid 93-106)."""
    prn = np.where(system == "S", svid - 100, np.where(system == "J", svid - 192, svid))
    ok = (system != "") & np.isfinite(prn) & (prn >= 1) & (prn <= 99) & ~((system == "R") & (prn > 24))
    return np.array([f"{s}{int(p):02d}" if good else "" for s, p, good in zip(system, prn, ok, strict=True)])


L1_BAND_HZ = (1559e6, 1611e6)  # GPS/Galileo/QZSS/SBAS L1, BeiDou B1I, GLONASS L1OF
