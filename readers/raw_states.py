"""Satellite states for logs of raw observations that carry no ephemerides (GnssLogger, DataFlash GRXS).

The navigation file is the one named with `--topic nav=FILE`, else a RINEX navigation file in the log's
directory whose records cover the log's time (the one covering most of it when several do;
`hour1820.16n` beside a log of 2016-06-30). Satellite positions, velocities and clocks then come from
`spooflens.gnss.ephemeris.states_at_transmission`, as for RINEX observation files.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from readers.orbits import state_columns
from readers.rinex import NavFile, is_broadcast_nav, read_rinex_nav_file
from spooflens.epoch_table import Skipped, StreamInfo
from spooflens.errors import ReaderError
from spooflens.gnss.ephemeris import GpsEphemerides

COVER_S = 2 * 3600.0  # a broadcast record serves +-2 h around its toe


def _coverage(nav: NavFile, t_gps_s: NDArray[np.float64]) -> float:
    """Fraction of the log's epochs within COVER_S of some record of the file."""
    toe = np.sort(nav.ephemerides.toe_s)
    k = np.clip(np.searchsorted(toe, t_gps_s), 1, max(len(toe) - 1, 1))
    near = np.minimum(np.abs(t_gps_s - toe[k - 1]), np.abs(t_gps_s - toe[np.minimum(k, len(toe) - 1)]))
    return float(np.mean(near <= COVER_S)) if len(t_gps_s) else 0.0


def navigation_for(
    log: Path, topics: Mapping[str, str] | None, t_gps_s: NDArray[np.float64], skipped: list[Skipped]
) -> NavFile | None:
    """The navigation file for a log whose epochs are at GPS seconds `t_gps_s` (None if there is none)."""
    if topics and topics.get("nav"):
        nav_path = Path(topics["nav"])
        if not nav_path.is_file():
            raise ReaderError(nav_path, "navigation file given with --topic nav= does not exist", "nav")
        nav = read_rinex_nav_file(nav_path)
        skipped.extend(nav.skipped)
        if _coverage(nav, t_gps_s) == 0:
            skipped.append(Skipped(nav_path.name, "navigation file does not cover the log's time", 1, "no ephemeris"))
        return nav
    t = np.unique(np.round(np.asarray(t_gps_s, dtype=float)))
    best: tuple[float, NavFile] | None = None
    for p in sorted(q for q in log.parent.iterdir() if q.is_file() and q != log and is_broadcast_nav(q)):
        try:
            nav = read_rinex_nav_file(p)
        except ReaderError as err:
            skipped.append(Skipped(p.name, f"navigation file unusable: {err.problem}", 1, "lost"))
            continue
        cover = _coverage(nav, t)
        if cover > 0 and (best is None or cover > best[0]):
            best = (cover, nav)
    if best is None:
        return None
    skipped.extend(best[1].skipped)
    return best[1]


def ephemeris_stream(
    eph: GpsEphemerides, stream_id: str, topic: str, msgtype: str, count: int, t0_ns: int
) -> StreamInfo:
    """The `nav` stream of a log's broadcast ephemerides, spanning their toe on the table's time axis."""
    toe = eph.toe_s
    return StreamInfo(
        "nav", stream_id, topic, msgtype, count, float(toe.min() - t0_ns / 1e9), float(toe.max() - t0_ns / 1e9)
    )


def nav_stream(nav: NavFile, t0_ns: int) -> StreamInfo:
    name = nav.path.name
    return ephemeris_stream(nav.ephemerides, name, name, nav.label, nav.records, t0_ns)


NO_NAV_FILE = "no navigation file covers the log (give one with --topic nav=FILE); no satellite states"


def add_satellite_states(
    rows: pd.DataFrame,
    ephemerides: GpsEphemerides | None,
    receiver_id: str,
    skipped: list[Skipped],
    none_reason: str = NO_NAV_FILE,
) -> pd.DataFrame:
    """`rows` (t_ns on the GPS clock, sv_id, pseudorange_m) with the sv_* columns of the satellites whose
    orbits are modelled (`readers.orbits`); `none_reason` says why there are no ephemerides when
    `ephemerides` is None."""
    columns = state_columns(
        ephemerides,
        rows["sv_id"].to_numpy(str),
        rows["t_ns"].to_numpy(np.int64) / 1e9,
        rows["pseudorange_m"].to_numpy(float),
        receiver_id,
        skipped,
        none_reason,
    )
    return rows.assign(**columns) if columns else rows.copy()
