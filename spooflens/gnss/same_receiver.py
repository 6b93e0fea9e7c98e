"""Are two receivers of a log two receivers? What the dual-receiver tests assume (seed 003: two antennas
with independent errors) and logs often break.

Two ways one receiver shows up twice:

- NMEA talkers of one stream: a multi-GNSS receiver sends GPGGA, GLGGA and GNRMC from one port, and the
  reader makes a receiver of each (source, talker): they are one antenna, one clock, one solution.
- one receiver relayed twice: a multiplexer passes it on under a second source, an instrument bus
  repeats its sentences, a logger records it with a delay or at another resolution. Its fixes are then
  the same numbers: identical after rounding both to the coarser resolution, at a constant delay (zero
  included). Two real receivers never agree that closely at most epochs, even under one spoofer's antenna
  (each keeps its own noise, clock and tracking loops), so an attack cannot make a pair look relayed.

Receivers are grouped; each group is one receiver, named by its first.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from spooflens.constants import NMEA_GNSS_TALKERS
from spooflens.epoch_table import EpochTable
from spooflens.gnss.resolution import angle_step_deg

if TYPE_CHECKING:
    from spooflens.pipeline.context import AnalysisContext

IDENTICAL_FRACTION = 0.9  # of common epochs, for the same fixes
MIN_COMMON_EPOCHS = 10  # fewer: too few to tell (and too few for the dual-receiver tests)
MAX_DELAY_S = 10.0  # a relay's constant delay is searched within this
DELAY_PROBES = 200  # fixes of the first receiver whose identical twins propose the delays tried


@dataclass(frozen=True)
class ReceiverGroup:
    """Receivers that are one receiver, and why."""

    receivers: tuple[str, ...]
    why: tuple[str, ...] = ()  # one reason per receiver after the first

    def describe(self) -> str:
        if len(self.receivers) == 1:
            return f"receiver {self.receivers[0]}"
        return f"receivers {', '.join(self.receivers)} are one receiver: {'; '.join(dict.fromkeys(self.why))}"


def receiver_groups(ctx: AnalysisContext) -> list[ReceiverGroup]:
    """`group_receivers` of the analysis's table (computed once per analysis)."""
    groups: list[ReceiverGroup] = ctx.cached("receiver_groups", lambda: group_receivers(ctx.table))
    return groups


def group_receivers(table: EpochTable) -> list[ReceiverGroup]:
    """The log's receivers grouped into the receivers they really are, in the log's order."""
    members: list[list[str]] = []
    reasons: list[list[str]] = []
    for rid in table.receivers():
        for k, group in enumerate(members):
            why = same_receiver(table, group[0], rid)
            if why is not None:
                group.append(rid)
                reasons[k].append(why)
                break
        else:
            members.append([rid])
            reasons.append([])
    return [ReceiverGroup(tuple(m), tuple(r)) for m, r in zip(members, reasons, strict=True)]


def same_receiver(table: EpochTable, a: str, b: str) -> str | None:
    """Why receivers a and b are one receiver, or None when their fixes are two receivers'."""
    return nmea_talkers(table, a, b) or relayed(table.fixes_of(a), table.fixes_of(b), a, b)


def nmea_talkers(table: EpochTable, a: str, b: str) -> str | None:
    """a and b are two talkers (GP, GL, GN...) of one NMEA source."""
    streams = {s.stream_id: s for s in table.streams if s.role == "fix"}
    sa, sb = streams.get(a), streams.get(b)
    if sa is None or sb is None or not (sa.msgtype.startswith("NMEA") and sb.msgtype.startswith("NMEA")):
        return None
    (src_a, _, talker_a), (src_b, _, talker_b) = a.rpartition("/"), b.rpartition("/")
    if src_a != src_b or sa.topic != sb.topic or not {talker_a, talker_b} <= NMEA_GNSS_TALKERS:
        return None
    return f"NMEA talkers of one stream ({sa.topic})"


def relayed(fa: pd.DataFrame, fb: pd.DataFrame, a: str, b: str) -> str | None:
    """b's fixes are a's: identical horizontal positions (within the coarser resolution of the two) at
    IDENTICAL_FRACTION of the common epochs, at the constant delay (within MAX_DELAY_S) that matches most."""
    ta, tb = fa["t_s"].to_numpy(dtype=float), fb["t_s"].to_numpy(dtype=float)
    if len(ta) < MIN_COMMON_EPOCHS or len(tb) < MIN_COMMON_EPOCHS:
        return None
    pa = fa[["lat_deg", "lon_deg"]].to_numpy(dtype=float)
    pb = fb[["lat_deg", "lon_deg"]].to_numpy(dtype=float)
    tol = np.array([max(angle_step_deg(pa[:, j]), angle_step_deg(pb[:, j])) for j in range(2)]) * 1.01 + 1e-9
    period = float(np.median(np.diff(tb))) if len(tb) > 1 else 1.0
    best = (0.0, 0, 0.0)  # (fraction identical, common epochs, delay)
    for delay in _delays(ta, pa, tb, pb, tol):
        j = np.clip(np.searchsorted(tb, ta + delay), 1, len(tb) - 1)
        j = np.where(np.abs(tb[j - 1] - ta - delay) < np.abs(tb[j] - ta - delay), j - 1, j)
        common = np.abs(tb[j] - ta - delay) <= 0.25 * period
        n = int(common.sum())
        if n < MIN_COMMON_EPOCHS:
            continue
        same = np.all(np.abs(pa[common] - pb[j[common]]) <= tol, axis=1)
        fraction = float(same.mean())
        if fraction > best[0]:
            best = (fraction, n, delay)
    fraction, n, delay = best
    if fraction < IDENTICAL_FRACTION:
        return None
    metres = tol[0] * 111_320.0
    common = f"at {100 * fraction:.0f}% of {n} common epochs (within the coarser resolution, {metres:.2g} m)"
    if abs(delay) < 0.25 * period:  # the same time tags: which one relays the other, the fixes cannot tell
        return f"{a} and {b} write the same fixes {common} at the same times: one receiver relayed twice"
    first, later = (a, b) if delay > 0 else (b, a)
    return f"{later} repeats {first}'s fixes {common}, {abs(delay):.2f} s later: one receiver relayed twice"


def _delays(ta: np.ndarray, pa: np.ndarray, tb: np.ndarray, pb: np.ndarray, tol: np.ndarray) -> list[float]:
    """Delays to try: zero, and the most frequent offsets from probed fixes of a to the fixes of b within
    MAX_DELAY_S that report the same position."""
    offsets: list[float] = []
    for i in np.linspace(0, len(ta) - 1, min(DELAY_PROBES, len(ta))).astype(int):
        lo, hi = np.searchsorted(tb, [ta[i] - MAX_DELAY_S, ta[i] + MAX_DELAY_S])
        same = np.all(np.abs(pb[lo:hi] - pa[i]) <= tol, axis=1)
        offsets += (tb[lo:hi][same] - ta[i]).tolist()
    if not offsets:
        return [0.0]
    values, counts = np.unique(np.round(offsets, 3), return_counts=True)
    frequent = values[np.argsort(-counts, kind="stable")[:5]]
    return list(dict.fromkeys([0.0, *(float(v) for v in frequent)]))
