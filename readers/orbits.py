"""Which rows of raw observations get satellite states, and what is said of the rest: one rule for every
reader of pseudoranges (RINEX, u-blox, GnssLogger, DataFlash).

GPS, Galileo and BeiDou orbits are modelled (`spooflens.gnss.ephemeris`); a GLONASS, QZSS or SBAS row
keeps its measurements without a satellite position, and the reader's skipped list says so.
"""

from __future__ import annotations

from datetime import UTC, datetime

import numpy as np
from numpy.typing import NDArray

from spooflens.epoch_table import GPS_EPOCH_UNIX_NS, Skipped
from spooflens.gnss.ephemeris import FIT_INTERVAL_S, GpsEphemerides, states_at_transmission

ORBIT_SYSTEMS = {"G": "GPS", "E": "Galileo", "C": "BeiDou"}
FloatArray = NDArray[np.float64]


def _system_names(systems: set[str]) -> str:
    names = [ORBIT_SYSTEMS[s] for s in ORBIT_SYSTEMS if s in systems]
    return ", ".join(names[:-1]) + " and " + names[-1] if len(names) > 1 else "".join(names)


def _gps_minute(t_gps_s: float) -> str:
    return datetime.fromtimestamp(GPS_EPOCH_UNIX_NS / 1e9 + float(t_gps_s), UTC).strftime("%Y-%m-%d %H:%M")


def _other_span(ephemerides: GpsEphemerides, system: str, t_gps_s: FloatArray, observed: NDArray[np.str_]) -> str:
    """Why no row of a system with orbits got one: the orbits are of another time than the observations (a
    navigation file of another day, or hours that do not cover the log's), or of the same hours but of other
    satellites than those observed (a navigation file cut, or kept from another receiver)."""
    ids = ephemerides.sv_id.astype(str)
    toe = ephemerides.toe_s[np.char.startswith(ids, system)]
    orbits, observations = (
        f"{_gps_minute(toe.min())} to {_gps_minute(toe.max())}",
        f"{_gps_minute(t_gps_s.min())} to {_gps_minute(t_gps_s.max())}",
    )
    reach = FIT_INTERVAL_S / 2  # a broadcast orbit serves its fit interval about its reference time
    if toe.min() - reach <= t_gps_s.max() and toe.max() + reach >= t_gps_s.min():
        without = sorted(set(observed.tolist()) - set(ids.tolist()))
        listed = ", ".join(without[:8]) + (f" and {len(without) - 8} more" if len(without) > 8 else "")
        return (
            f"the navigation data's {ORBIT_SYSTEMS[system]} orbits ({orbits}) are of the observations' hours "
            f"({observations} GPS time) but none is of a satellite observed ({listed})"
        )
    return (
        f"the navigation data's {ORBIT_SYSTEMS[system]} orbits are for {orbits}, the observations {observations} "
        + ("GPS time (a navigation file of another day or hour?)")
    )


def state_columns(
    ephemerides: GpsEphemerides | None,
    sv_id: NDArray[np.str_],
    t_gps_s: FloatArray,
    pseudorange_m: FloatArray,
    receiver_id: str,
    skipped: list[Skipped],
    none_reason: str,
) -> dict[str, FloatArray]:
    """The `sv_*` columns (NaN where there is no state) for rows of satellites `sv_id` received at GPS
    time `t_gps_s`; empty when no row could have one. `none_reason` says why when `ephemerides` is None."""
    sv = np.asarray(sv_id).astype(str)
    system = np.char.ljust(sv, 1).astype("U1") if len(sv) else np.zeros(0, dtype="U1")
    modelled = np.isin(system, list(ORBIT_SYSTEMS))
    out: dict[str, FloatArray] = {}
    if ephemerides is not None and modelled.any():
        g = np.flatnonzero(modelled)
        states = states_at_transmission(ephemerides, sv[g], t_gps_s[g], pseudorange_m[g])
        for name, values in states.columns().items():
            out[name] = np.full(len(sv), np.nan)
            out[name][g] = values
        have = {s[:1] for s in ephemerides.satellites()}
        for s, name in ORBIT_SYSTEMS.items():
            rows = system[g] == s
            missing = int((rows & ~states.valid).sum())
            if not missing:
                continue
            if s not in have:
                why = "without satellite states: the navigation data holds no orbit of this system"
            elif not states.valid[rows].any():
                why = "without satellite states: " + _other_span(ephemerides, s, t_gps_s[g][rows], sv[g][rows])
            else:
                sick = rows & ~states.valid & np.isin(sv[g], ephemerides.unhealthy_satellites())
                if sick.any():
                    flagged = ", ".join(sorted(set(sv[g][sick].tolist())))
                    why = f"of satellites the broadcast flags unhealthy ({flagged}): not used, satellite states NaN"
                    skipped.append(Skipped(receiver_id, f"{name} rows {why}", int(sick.sum()), "unhealthy"))
                    missing -= int(sick.sum())
                    if not missing:
                        continue
                why = "without a valid broadcast ephemeris; satellite states NaN"
            skipped.append(Skipped(receiver_id, f"{name} rows {why}", missing, "no ephemeris"))
    elif modelled.any():
        skipped.append(Skipped(receiver_id, none_reason, int(modelled.sum()), "no ephemeris"))
    if (~modelled).any():
        others = sorted(set(system[~modelled].tolist()))
        skipped.append(
            Skipped(
                receiver_id,
                f"rows of systems {', '.join(others)}: no satellite states (only {_system_names(set(ORBIT_SYSTEMS))} "
                "orbits are modelled)",
                int((~modelled).sum()),
                "no ephemeris",
            )
        )
    return out
