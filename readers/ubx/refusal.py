"""Why a u-blox capture holds nothing to analyse, said by what it does hold.

A capture with no fix, raw observation, satellite report (NAV-SAT, or GSV in its NMEA), monitor message
(MON-RF, MON-HW, SEC-SIG: read into `receiver_status`), heading or IMU sample is refused in one line
that names its kind: a timing receiver's time-only output, a receiver that never had a fix, a session
of configuration and status messages, navigation messages alone, the receiver's stored log read back.
"""

from __future__ import annotations

from collections import Counter
from typing import TYPE_CHECKING

from readers.ubx import messages as m

if TYPE_CHECKING:
    from readers.nmea.assembly import Assembled
    from readers.ubx.frames import Frames

# what each UBX class is, for naming what a capture holds
CLASS_KIND = {
    "ACK": "acknowledgements",
    "CFG": "configuration",
    "INF": "text messages",
    "MON": "receiver status",
    "MGA": "assistance data",
    "AID": "assistance data",
    "SEC": "security status",
    "UPD": "firmware update",
    "LOG": "the receiver's stored log read back",
    "ESF": "sensor status",
    "RXM": "receiver manager data",
    "TIM": "timing",
    "NAV": "navigation status",
    "HNR": "high-rate navigation",
}


def _listed(counts: Counter[str], limit: int = 8) -> str:
    names = sorted(counts, key=lambda k: -counts[k])
    return ", ".join(f"{n} x{counts[n]}" for n in names[:limit]) + (" ..." if len(names) > limit else "")


def refusal(held: Counter[str], time_only: int, epochs_without_fix: int, frames: Frames, nmea: Assembled | None) -> str:
    """One line: what the capture holds (`held`: each UBX message's count, used or not), and that it holds
    no position, velocity or raw observation; `time_only`: its time-only fixes, `epochs_without_fix`: the
    epochs it had with no fix at all."""
    nothing = "no position, velocity or raw observations"
    if time_only or (held and all(n in m.TIME_ONLY or n.startswith("TIM-") for n in held)):
        extra = f" ({time_only} time-only fixes of a receiver at a fixed position)" if time_only else ""
        return f"this capture holds time only: {nothing}{extra}; it holds {_listed(held)}"
    none = "no fix, raw observation or IMU sample in the capture"
    if epochs_without_fix:
        return f"{none}: the receiver had no fix in any of its {epochs_without_fix} epochs; it holds {_listed(held)}"
    if nmea is not None and nmea.fixes is None and frames.nmea:
        return (
            f"{none}: the receiver had no fix (its {len(frames.nmea)} NMEA sentences report none); "
            f"UBX: {_listed(held) or 'none'}"
        )
    if held.keys() == {"RXM-SFRBX"}:
        return f"{none}: it holds navigation messages only (RXM-SFRBX x{held['RXM-SFRBX']})"
    if not held:
        return f"{none}: no UBX message either"
    kinds = sorted({CLASS_KIND.get(name.split("-")[0], "other") for name in held})
    return f"{none}: it holds {', '.join(kinds)} only ({_listed(held)})"
