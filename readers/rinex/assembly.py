"""A RINEX log: its observation files (one receiver each), their navigation data, one EpochTable."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from readers.carrier_arcs import arc_starts
from readers.orbits import state_columns
from readers.rinex.navigation import NavFile, find_nav_files, read_rinex_nav_file
from readers.rinex.observation import ObsScan, extract_l1, is_rinex_obs, scan_obs
from readers.rinex.packaging import archive_folder
from readers.rinex.text import header_lines
from spooflens.epoch_table import EpochTable, Skipped, StreamInfo, build_table
from spooflens.errors import ReaderError
from spooflens.gnss.ephemeris import C_MPS, GpsEphemerides

Progress = Callable[[int, int], None]


def obs_files(path: Path) -> list[tuple[Path, str]]:
    """The observation files of a log (a file or a directory) with their receiver ids, in a fixed order."""
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.is_file() and is_rinex_obs(p))
        if not files:
            raise ReaderError(path, "directory holds no RINEX observation file")
    else:
        files = [path]
    markers = []
    for f in files:
        marker = ""
        for line in header_lines(f):
            if line[60:80].strip() == "MARKER NAME":
                marker = line[:60].strip()
        markers.append(marker or f.stem)
    dup = {m for m in markers if markers.count(m) > 1}
    return [(f, f"{m}_{f.name}" if m in dup else m) for f, m in zip(files, markers, strict=True)]


LOST_LOCK_RINEX = "carriers across a loss of lock (RINEX LLI bit 0, or epoch flag 1: power failure)"
HALF_CYCLE_RINEX = "carriers with a half-cycle ambiguity or slip possible (RINEX LLI bit 1)"

# table.metadata key (+ ".<receiver id>") holding the header's APPROX POSITION XYZ, "x y z" in ECEF metres
APPROX_POSITION_KEY = "rinex.approx_position_xyz_m"


@dataclass
class _FileResult:
    rows: dict[str, np.ndarray]
    stream: StreamInfo
    navs: list[NavFile]
    skipped: list[Skipped]
    approx_xyz: tuple[float, float, float] | None = None


def _observation_rows(scan: ObsScan, receiver_id: str, skipped: list[Skipped]) -> dict[str, np.ndarray]:
    """The rows of one file (t_ns instead of t_s), skipping satellites with garbage or no L1 code."""
    cols = extract_l1(scan)
    if cols.bad.any():
        skipped.append(
            Skipped(receiver_id, "satellite rows with a field that is not a number", int(cols.bad.sum()), "lost")
        )
    no_code = ~np.isfinite(cols.pr) & ~cols.bad
    if no_code.any():
        skipped.append(
            Skipped(receiver_id, "satellite rows without an L1 pseudorange (see the priority list)", int(no_code.sum()))
        )
    idx = np.flatnonzero(np.isfinite(cols.pr) & ~cols.bad)
    doppler, freq = cols.doppler[idx], cols.freq[idx]
    lli = cols.lli[idx]
    breaks = {
        LOST_LOCK_RINEX: ((lli & 1) != 0) | scan.epoch_power_failure[scan.row_epoch[idx]],
        HALF_CYCLE_RINEX: (lli & 2) != 0,
    }
    phase = cols.phase[idx]
    arc_start = arc_starts(receiver_id, phase, breaks, skipped)
    return {
        "t_ns": scan.epoch_ns[scan.row_epoch[idx]],
        "sv_id": scan.row_sv[idx],
        "pseudorange_m": cols.pr[idx],
        "pseudorange_rate_mps": -doppler * C_MPS / freq,
        "doppler_hz": doppler,
        "carrier_phase_cycles": phase,
        "carrier_arc_start": arc_start,
        "carrier_freq_hz": freq,
        "cn0_dbhz": cols.cn0[idx],
    }


def _add_satellite_states(
    rows: dict[str, np.ndarray],
    navs: list[NavFile],
    unusable: list[str],
    obs_name: str,
    receiver_id: str,
    skipped: list[Skipped],
) -> None:
    """Fill the sv_* columns of the modelled systems' rows from the broadcast orbits; count every row left
    without. `unusable`: the navigation files found for it that could not be read."""
    eph = (navs[0].ephemerides if len(navs) == 1 else merge_navs(navs)) if navs else None
    reason = (
        f"the navigation file found for {obs_name} ({', '.join(unusable)}) could not be read; no satellite states"
        if unusable
        else f"no navigation file found for {obs_name} (give one with --topic nav=FILE); no satellite states"
    )
    rows |= state_columns(eph, rows["sv_id"], rows["t_ns"] / 1e9, rows["pseudorange_m"], receiver_id, skipped, reason)


def _navigation(
    obs: Path, topics: Mapping[str, str] | None, cache: dict[Path, NavFile | None], skipped: list[Skipped]
) -> tuple[list[NavFile], list[str]]:
    """The navigation files for `obs`, each read once per log, and the names of those found unreadable.

    A nav file the search found that cannot be read costs only the satellite states (listed as lost);
    one named with --topic nav= is the user's explicit choice, so its problem is an error.
    """
    navs, unusable = [], []
    for nav_path in find_nav_files(obs, topics):
        if nav_path not in cache:
            try:
                cache[nav_path] = read_rinex_nav_file(nav_path)
            except ReaderError as err:
                if topics and topics.get("nav"):
                    raise
                cache[nav_path] = None
                skipped.append(Skipped(nav_path.name, f"navigation file unusable: {err.problem}", 1, "lost"))
        nav = cache[nav_path]
        if nav is not None:
            navs.append(nav)
        else:
            unusable.append(nav_path.name)
    return navs, unusable


def _read_obs_file(
    path: Path, receiver_id: str, topics: Mapping[str, str] | None, nav_cache: dict[Path, NavFile | None]
) -> _FileResult:
    scan = scan_obs(path)
    skipped = list(scan.skipped)
    rows = _observation_rows(scan, receiver_id, skipped)
    navs, unusable = _navigation(path, topics, nav_cache, skipped)
    _add_satellite_states(rows, navs, unusable, path.name, receiver_id, skipped)
    epochs = len(np.unique(rows["t_ns"]))
    stream = StreamInfo("observations", receiver_id, path.name, f"RINEX {scan.version:.2f} obs", epochs)
    xyz = scan.header.approx_xyz
    return _FileResult(rows, stream, navs, skipped, None if xyz is None or not any(xyz) else xyz)


def merge_navs(navs: list[NavFile]) -> GpsEphemerides:
    """Several navigation files as one set of records (duplicates are harmless: the nearest toe wins)."""
    return GpsEphemerides.combined([n.ephemerides for n in navs])


def _assemble(path: Path, parts: list[_FileResult], skipped: list[Skipped]) -> EpochTable:
    """Every receiver's rows through `build_table` (time base = first epoch, sorting, duplicates)."""
    n_rows = [len(p.rows["t_ns"]) for p in parts]
    names = sorted({k for p in parts for k in p.rows})
    cols: dict[str, np.ndarray] = {
        k: np.concatenate([p.rows.get(k, np.full(n, np.nan)) for p, n in zip(parts, n_rows, strict=True)])
        for k in names
    }
    cols["t_ns"] = cols["t_ns"].astype(np.int64)
    cols["receiver_id"] = np.repeat([p.stream.stream_id for p in parts], n_rows)
    t0 = int(cols["t_ns"].min())
    streams = [p.stream for p in parts]
    seen: set[Path] = set()
    for p in parts:
        for nav in p.navs:
            if nav.path in seen:
                continue
            seen.add(nav.path)
            toe_ns = np.round(nav.ephemerides.toe_s * 1e9).astype(np.int64)
            span = (float((toe_ns.min() - t0) / 1e9), float((toe_ns.max() - t0) / 1e9))
            streams.append(StreamInfo("nav", nav.path.name, nav.path.name, nav.label, nav.records, *span))
            skipped.extend(nav.skipped)
    # The header's APPROX POSITION: a static station's surveyed site (the known-station detectors decide
    # whether the receiver really stayed there; a moving receiver's header is only where it started).
    metadata = {
        f"{APPROX_POSITION_KEY}.{p.stream.stream_id}": " ".join(f"{v:.4f}" for v in p.approx_xyz)
        for p in parts
        if p.approx_xyz is not None
    }
    table = build_table(
        path, "rinex", "gps", {"observations": pd.DataFrame(cols)}, streams, skipped, t0_ns=t0, metadata=metadata
    )
    navs = list({n.path: n for p in parts for n in p.navs}.values())
    table.ephemerides = (navs[0].ephemerides if len(navs) == 1 else merge_navs(navs)) if navs else None
    return table


def read_rinex(path: Path, topics: Mapping[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    """Read a RINEX observation file, or a directory of them (one receiver each), into an EpochTable."""
    path = Path(path)
    with archive_folder(path) as folder:  # a zip of several files: read from a folder of its members
        if folder is None:
            return _read_rinex(path, path, topics, progress)
        try:
            return _read_rinex(path, folder, topics, progress)
        except ReaderError as err:  # name the archive (and the member), not the temporary folder
            member = "" if err.path == folder else f"{err.path.name}: "
            raise ReaderError(path, f"{member}{err.problem}".replace("directory", "zip archive"), err.stream) from err


def _read_rinex(path: Path, inner: Path, topics: Mapping[str, str] | None, progress: Progress | None) -> EpochTable:
    files = obs_files(inner)
    skipped: list[Skipped] = []
    if topics and set(topics) - {"nav"}:
        other = {k: v for k, v in topics.items() if k != "nav"}
        skipped.append(Skipped("<rinex>", f"--topic ignored for RINEX logs except nav= ({other})", len(other)))
    nav_cache: dict[Path, NavFile | None] = {}
    parts = []
    for i, (f, rid) in enumerate(files):
        part = _read_obs_file(f, rid, topics, nav_cache)
        parts.append(part)
        skipped.extend(part.skipped)
        if progress:
            progress(i + 1, len(files))
    if not any(len(p.rows["t_ns"]) for p in parts):
        reasons = "; ".join(str(s) for s in skipped) or "no epochs after the header"
        raise ReaderError(path, f"no usable observation in the file(s): {reasons}", "observations")
    return _assemble(path, parts, skipped)
