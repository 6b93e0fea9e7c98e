"""Where a receiver says its carrier phase is not continuous: the epoch table's `carrier_arc_start`.

The range-rate detector differences each satellite's carrier between epochs (a 2 mm/s velocity
measurement) and screens slips by the Doppler only down to `doppler_slip_m` (0.1 m): a half-cycle slip
on L1 (0.095 m) would pass and read as a 0.095 m/s rate error. Receivers flag such carriers themselves;
the readers mark (`carrier_arc_start` 1) the carrier of an observation

- whose lock was lost since the previous one (RINEX LLI bit 0 or epoch flag 1; u-blox lock time that
  did not run on by the time between the epochs; a change of the tracked signal), and
- whose half-cycle ambiguity is unresolved or changed (RINEX LLI bit 1; u-blox halfCyc 0, or
  subHalfCyc toggling; Android HALF_CYCLE_REPORTED without HALF_CYCLE_RESOLVED).

The carrier is kept as logged: a method in metres (the pseudorange-change test, which smooths code with
carrier) needs no fractional-cycle continuity, and clearing it there made a clean station's reflected code
an alarm. The range-rate test takes no carrier difference into a marked observation: the Doppler stands
in (weighed with its own noise), as for a slip its own screening finds. The readers count each kind
under action "flagged" (`arc_starts`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spooflens.epoch_table import Skipped

BoolArray = NDArray[np.bool_]

# u-blox RXM-RAWX trkStat bits (ArduPilot GRXS `trk` is the same byte)
PR_VALID, CP_VALID, HALF_CYC, SUB_HALF_CYC = 1, 2, 4, 8
LOCKTIME_MAX_MS = 64500  # RXM-RAWX locktime saturates here
LOCKTIME_SLACK_MS = 50  # measurement times and the ms lock-time count need not agree to the ms

LOST_LOCK_UBLOX = "carriers across a loss of lock (u-blox lock time restarted since the previous epoch)"
SIGNAL_CHANGED_UBLOX = "carriers of another signal than the satellite's previous epoch (u-blox sigId changed)"
HALF_CYCLE_UBLOX = "carriers with an unresolved half-cycle ambiguity (u-blox trkStat halfCyc 0)"
SUB_HALF_UBLOX = "carriers whose half-cycle correction changed since the previous epoch (u-blox subHalfCyc toggled)"
CONTINUITY = ": not taken as continuous by the rate test (the Doppler stands in; the carrier is kept)"
EVERY_CARRIER = "; that is every carrier the receiver gave: its rates come from the Doppler (if any)"


@dataclass(frozen=True)
class Previous:
    """Each row's previous row of the same signal (`index`, valid where `has`), ordered by time."""

    index: NDArray[np.int64]
    has: BoolArray

    @classmethod
    def of(cls, key: NDArray[np.generic], t_ns: NDArray[np.int64]) -> Previous:
        order = np.lexsort((t_ns, key))
        index = np.zeros(len(key), dtype=np.int64)
        has = np.zeros(len(key), dtype=bool)
        if len(order) > 1:
            index[order[1:]] = order[:-1]
            has[order[1:]] = key[order[1:]] == key[order[:-1]]
        return cls(index, has)


def ublox_breaks(
    key: NDArray[np.generic],
    t_ns: NDArray[np.int64],
    trk: NDArray[np.integer],
    locktime_ms: NDArray[np.integer] | None,
    signal: NDArray[np.integer] | None = None,
) -> dict[str, BoolArray]:
    """u-blox RAWX (or GRXS) rows whose carrier must not be taken as continuous, by reason.

    `key` names a satellite's signal across epochs (rows of one key are one carrier); `signal`, where
    known, the sigId tracked (a change is a different carrier). Only rows with cpValid are marked.
    """
    trk = trk.astype(np.int64)
    cp = (trk & CP_VALID) != 0
    prev = Previous.of(key, t_ns)
    p = prev.index
    after = cp & prev.has & cp[p]  # this row and the previous one of its signal both carry a carrier
    out: dict[str, BoolArray] = {}
    if signal is not None:
        out[SIGNAL_CHANGED_UBLOX] = after & (signal != signal[p])
        after &= ~out[SIGNAL_CHANGED_UBLOX]
    if locktime_ms is not None:
        lock = locktime_ms.astype(np.int64)
        dt_ms = (t_ns - t_ns[p]) / 1e6
        # continuously tracked since the previous epoch: the count ran on by the time between them
        expected = np.minimum(lock[p] + dt_ms, LOCKTIME_MAX_MS)
        out[LOST_LOCK_UBLOX] = after & ((lock < lock[p]) | (lock + LOCKTIME_SLACK_MS < expected))
    unresolved = cp & ((trk & HALF_CYC) == 0)
    out[HALF_CYCLE_UBLOX] = unresolved
    out[SUB_HALF_UBLOX] = after & ~unresolved & (((trk ^ trk[p]) & SUB_HALF_CYC) != 0)
    return out


def arc_starts(
    stream: str,
    carrier: NDArray[np.float64],
    breaks: dict[str, BoolArray],
    skipped: list[Skipped],
) -> NDArray[np.float64]:
    """`carrier_arc_start` of each row: 1 where a carrier is marked, 0 where one is not, NaN without a carrier.
    Each reason counted once per row (first reason wins) as "flagged"; a reason that marks every carrier the
    receiver gave says so."""
    present = np.isfinite(carrier)
    total = int(present.sum())
    left = present.copy()
    for reason, mask in breaks.items():
        hit = mask & left
        n = int(hit.sum())
        if n:
            why = reason + CONTINUITY + (EVERY_CARRIER if n == total else "")
            skipped.append(Skipped(stream, why, n, "flagged"))
        left &= ~hit
    return np.where(present, np.where(left, 0.0, 1.0), np.nan)
