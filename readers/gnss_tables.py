"""Tables of derived GNSS measurements (one row per satellite and epoch) to raw observations and fixes.

Phone datasets ship their measurements already derived, as CSV tables with one column per quantity:

- Google Smartphone Decimeter Challenge 2022/2023 `device_gnss.csv` (GnssLogger's Raw columns plus
  `RawPseudorangeMeters`, `SvPosition*EcefMeters`, `SvVelocity*EcefMetersPerSecond`,
  `SvClockBiasMeters`, `IsrbMeters`, the dataset's own `WlsPosition*EcefMeters`);
- its 2021 `*_derived.csv` (`millisSinceGpsEpoch`, `svid`, `constellationType`, `rawPrM`, `xSatPosM`...);
- gnss_lib_py's names for the same (`gps_millis`, `gnss_id`, `sv_id`, `raw_pr_m`, `x_sv_m`, `b_sv_m`,
  `intersignal_bias_m`, `x_rx_wls_m`...);
- smartLoc (TU Chemnitz): u-blox RXM-RAWX rows (`prMes`, `cpMes`, `doMes`, `gnssId`, `svId`, `cno`)
  with the reference trajectory (`GT Lat`, `GT Lon`, `GT Height`) on each row, `;`-separated.

Columns are found by name, so each dialect is a list of aliases (`ALIASES`). One receiver, `phone` (or
`ublox` for smartLoc). Observations: the raw pseudorange less the table's inter-signal range bias (a
receiver-side bias, as gnss_lib_py's corrected pseudorange removes it), satellite ECEF position and
velocity at transmission and clock bias/drift where the table has them, C/N0, pseudorange rate or
Doppler, carrier phase from a valid accumulated delta range (smartLoc: cpMes with cpValid), those the
receiver says are not continuous marked (`carrier_arc_start`, `readers.carrier_arcs`); one L1-band
signal per satellite and epoch
(L5/E5a rows are counted and left out). Fixes: the table's receiver position per epoch (the dataset's
weighted-least-squares solution, not the phone's own). Time: GPS time (`ArrivalTimeNanosSinceGpsEpoch`,
`millisSinceGpsEpoch`, `gps_millis`, week + time of week), else UNIX (`utcTimeMillis`).

Ground-truth tables (`*ground_truth.csv` and the like: a reference trajectory, no measurements) are a
log's companions, not logs: beside a table they fill its `truth` frame; given alone they are refused
as what they are.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from readers import ReaderFormat
from readers.android_gnss import (
    ADR_CYCLE_SLIP,
    ADR_RESET,
    ADR_VALID,
    HALF_CYCLE_ANDROID,
    L1_BAND_HZ,
    SYSTEM,
    adr_half_cycle_unresolved,
    android_sv_ids,
)
from readers.carrier_arcs import CP_VALID, arc_starts, ublox_breaks
from readers.csv_text import read_rows
from spooflens.epoch_table import EpochTable, Skipped, StreamInfo, build_table, gps_ns_of_unix_ns
from spooflens.errors import ReaderError
from spooflens.geodesy import ecef_to_geodetic
from spooflens.gnss.ephemeris import C_MPS
from spooflens.schema import FixType

Progress = Callable[[int, int], None]
FloatArray = NDArray[np.float64]
NS = 1_000_000_000
WEEK_S = 604_800

ALIASES: dict[str, tuple[str, ...]] = {
    "t_gps_ns": ("ArrivalTimeNanosSinceGpsEpoch",),
    "t_gps_ms": ("gps_millis", "millisSinceGpsEpoch"),
    "t_unix_ms": ("utcTimeMillis", "unix_millis"),
    "week": ("GPS week number (week) [weeks]",),
    "tow_s": ("Measurement time of week (rcvTow) [s]",),
    "constellation": ("ConstellationType", "constellationType"),
    "gnss_name": ("gnss_id", "GNSS identifier (gnssId) []"),
    "svid": ("Svid", "svid", "sv_id", "Satellite identifier (svId) []"),
    "signal": ("SignalType", "signalType", "signal_type"),
    "freq": ("CarrierFrequencyHz", "carrier_frequency_hz"),
    "glonass_slot": ("Frequency slot - only Glonass (freqId) []",),
    "pr": ("RawPseudorangeMeters", "rawPrM", "raw_pr_m", "Pseudorange measurement (prMes) [m]"),
    "prr": ("PseudorangeRateMetersPerSecond",),
    "doppler": ("Doppler measurement (doMes) [Hz]", "doppler_hz"),
    "phase_cycles": ("Carrier phase measurement (cpMes) [cycles]",),
    "adr": ("AccumulatedDeltaRangeMeters", "accumulated_delta_range_m"),
    "adr_state": ("AccumulatedDeltaRangeState", "accumulated_delta_range_state"),
    "cn0": ("Cn0DbHz", "cn0_dbhz", "Carrier-to-noise density ratio (cno) [dbHz]"),
    "trk": ("Tracking status (trkStat) []",),
    "locktime": ("Carrier phase locktime counter (locktime) [ms]",),
    "sv_x": ("SvPositionXEcefMeters", "xSatPosM", "x_sv_m"),
    "sv_y": ("SvPositionYEcefMeters", "ySatPosM", "y_sv_m"),
    "sv_z": ("SvPositionZEcefMeters", "zSatPosM", "z_sv_m"),
    "sv_vx": ("SvVelocityXEcefMetersPerSecond", "xSatVelMps", "vx_sv_mps"),
    "sv_vy": ("SvVelocityYEcefMetersPerSecond", "ySatVelMps", "vy_sv_mps"),
    "sv_vz": ("SvVelocityZEcefMetersPerSecond", "zSatVelMps", "vz_sv_mps"),
    "sv_clk": ("SvClockBiasMeters", "satClkBiasM", "b_sv_m"),
    "sv_drift": ("SvClockDriftMetersPerSecond", "satClkDriftMps", "b_dot_sv_mps"),
    "isrb": ("IsrbMeters", "isrbM", "intersignal_bias_m"),
    "rx_x": ("WlsPositionXEcefMeters", "x_rx_wls_m", "x_rx_m"),
    "rx_y": ("WlsPositionYEcefMeters", "y_rx_wls_m", "y_rx_m"),
    "rx_z": ("WlsPositionZEcefMeters", "z_rx_wls_m", "z_rx_m"),
    "rx_lat": ("lat_rx_wls_deg", "lat_rx_deg"),
    "rx_lon": ("lon_rx_wls_deg", "lon_rx_deg"),
    "rx_alt": ("alt_rx_wls_m", "alt_rx_m"),
    "gt_lat": ("Latitude (GT Lat) [deg]",),
    "gt_lon": ("Longitude (GT Lon) [deg]",),
    "gt_h": ("Height above ellipsoid (GT Height) [m]",),
    "gt_week": ("GPSWeek [weeks]",),
    "gt_tow": ("GPSSecondsOfWeek [s]",),
}
TEXT = ("gnss_name", "signal")
TIME_KEYS = ("t_gps_ns", "t_gps_ms", "t_unix_ms", "tow_s")
NEEDED = {"a time": TIME_KEYS, "a satellite": ("svid",), "a pseudorange": ("pr",)}
# names only a derived measurement table has (a spooflens CSV or a GnssLogger log has none of them)
SIGNATURE = {
    a
    for k in ("pr", "sv_x", "t_gps_ns", "t_gps_ms", "constellation", "gnss_name", "isrb", "rx_x", "gt_lat")
    for a in ALIASES[k]
}
GNSS_NAMES = {"gps": "G", "glonass": "R", "galileo": "E", "beidou": "C", "qzss": "J", "sbas": "S", "irnss": "I"}
GNSS_NAMES |= {"glo": "R", "gal": "E", "bds": "C", "qzs": "J", "navic": "I"}
UBX_GNSS = {"0": "G", "1": "S", "2": "E", "3": "C", "5": "J", "6": "R", "7": "I"}
# ground truth: a trajectory and a time, no satellite
TRUTH_NAMES = {
    "lat": ("latDeg", "LatitudeDegrees", "lat_rx_gt_deg"),
    "lon": ("lngDeg", "LongitudeDegrees", "lon_rx_gt_deg"),
    "h": ("heightAboveWgs84EllipsoidM", "AltitudeMeters", "alt_rx_gt_m"),
    "t_gps_ms": ("millisSinceGpsEpoch", "gps_millis"),
    "t_unix_ms": ("UnixTimeMillis", "unix_millis"),
}


def _header(path: Path, head: bytes) -> tuple[list[str], str]:
    """The column names of a table's first line and its separator (`,` or `;`)."""
    line = head.split(b"\n", 1)[0].decode("utf-8", errors="replace").strip().lstrip("\ufeff")
    sep = ";" if line.count(";") > line.count(",") else ","
    return [c.strip() for c in line.split(sep)], sep


def _find(names: list[str], key: str) -> str | None:
    return next((a for a in ALIASES[key] if a in names), None)


def is_ground_truth(names: list[str]) -> bool:
    has = {k for k, aliases in TRUTH_NAMES.items() if any(a in names for a in aliases)}
    return {"lat", "lon"} <= has and bool({"t_gps_ms", "t_unix_ms"} & has) and not _find(names, "pr")


def _looks_like_table(path: Path, head: bytes) -> bool:
    if not path.is_file() or b"\0" in head[:4096]:
        return False
    names, _ = _header(path, head)
    return len(SIGNATURE.intersection(names)) >= 2 or is_ground_truth(names)


def _is_truth_companion(path: Path) -> bool:
    try:
        with path.open("rb") as f:
            names, _ = _header(path, f.read(4096))
    except OSError:
        return False
    return is_ground_truth(names)


def _rows(path: Path, names: list[str], sep: str, skipped: list[Skipped]) -> pd.DataFrame:
    """The table's rows under our keys (numbers, the two text columns as text)."""
    wanted: dict[str, str] = {}
    for key in ALIASES:
        name = _find(names, key)
        if name is not None:
            wanted[name] = key
    if sep == ",":
        text = [a for a, k in wanted.items() if k in TEXT]
        df = read_rows(path, skipped, keep=lambda n: n in wanted, text_columns=text)
    else:
        lost: list[int] = []

        def count_bad(line: list[str]) -> None:
            lost.append(1)

        try:
            df = pd.read_csv(
                path, sep=sep, usecols=lambda n: str(n).strip() in wanted, dtype=str, engine="python",
                on_bad_lines=count_bad, encoding_errors="replace",
            )  # fmt: skip
        except (pd.errors.ParserError, pd.errors.EmptyDataError, ValueError, UnicodeDecodeError) as err:
            raise ReaderError(path, f"not a readable table: {err}") from err
        df.columns = [str(c).strip() for c in df.columns]
        for col in df.columns:
            if wanted.get(col) not in TEXT:
                df[col] = pd.to_numeric(df[col], errors="coerce")
        if lost:
            skipped.append(Skipped(path.name, "rows whose number of fields is not the header's", len(lost), "lost"))
    return df.rename(columns=wanted)


def _f(df: pd.DataFrame, key: str) -> FloatArray:
    return df[key].to_numpy(dtype=float) if key in df else np.full(len(df), np.nan)


def _times(df: pd.DataFrame) -> tuple[NDArray[np.int64], str, NDArray[np.bool_]]:
    """Each row's time in ns on its clock, the clock, and which rows have one. A GPS time column with
    holes (GSDC leaves ArrivalTimeNanosSinceGpsEpoch blank where it derived nothing) takes those rows'
    time from their UNIX time."""
    if "t_gps_ns" in df:
        t, ref = _f(df, "t_gps_ns"), "gps"
    elif "t_gps_ms" in df:
        t, ref = _f(df, "t_gps_ms") * 1e6, "gps"
    elif "tow_s" in df and "week" in df:
        t, ref = (_f(df, "week") * WEEK_S + _f(df, "tow_s")) * 1e9, "gps"
    else:
        t, ref = _f(df, "t_unix_ms") * 1e6, "unix"
    unix = _f(df, "t_unix_ms") * 1e6
    if ref == "gps" and "t_unix_ms" in df:
        hole = ~np.isfinite(t) & np.isfinite(unix) & (unix > 0) & (unix < 2**62)
        if hole.any():  # the GPS time of the row's epoch (same UNIX time), else its UNIX time converted
            t = t.copy()
            epoch_gps = pd.Series(t).groupby(unix).transform("min").to_numpy()
            t[hole] = epoch_gps[hole]
            still = hole & ~np.isfinite(t)
            t[still] = gps_ns_of_unix_ns(np.round(unix[still]).astype(np.int64))
    ok = np.isfinite(t) & (t > 0) & (t < 2**62)
    return np.where(ok, np.round(np.where(ok, t, 0)), 0).astype(np.int64), ref, ok


def _sv_ids(df: pd.DataFrame) -> NDArray[np.str_]:
    svid = _f(df, "svid")
    if "constellation" in df:
        system = np.array([SYSTEM.get(int(c), "") if np.isfinite(c) else "" for c in _f(df, "constellation")])
    elif "gnss_name" in df:
        names = df["gnss_name"].astype(str).str.strip().str.lower()
        system = np.array([GNSS_NAMES.get(n, UBX_GNSS.get(n, "")) for n in names])
    else:
        system = np.full(len(df), "G")  # a table with bare PRNs: GPS, as the spooflens CSV reads them
    return np.asarray(android_sv_ids(system, svid), dtype="<U3")  # strings even when there is no row


def _l1(df: pd.DataFrame) -> NDArray[np.bool_]:
    """Rows of an L1-band signal: by carrier frequency where given, else by the signal's name."""
    freq = _f(df, "freq")
    by_freq = (freq >= L1_BAND_HZ[0]) & (freq <= L1_BAND_HZ[1])
    if "signal" in df:
        name = df["signal"].astype(str).str.upper()
        by_name = ~name.str.contains(r"5|B2|E6|L2", regex=True).to_numpy(dtype=bool)
    else:
        by_name = np.ones(len(df), dtype=bool)
    return np.where(np.isfinite(freq), by_freq, by_name)


def _observations(
    df: pd.DataFrame, t_ns: NDArray[np.int64], rid: str, skipped: list[Skipped], meta: dict[str, str]
) -> pd.DataFrame:
    sv = _sv_ids(df)
    pr = _f(df, "pr")
    if "trk" in df:  # u-blox trkStat bit 0: the pseudorange is valid
        pr = np.where(np.nan_to_num(_f(df, "trk")).astype(np.int64) & 1, pr, np.nan)
    freq = _f(df, "freq")
    if not np.isfinite(freq).any():  # the L1-band signal's carrier; GLONASS by its frequency slot (u-blox freqId)
        freq = np.where(np.char.startswith(sv, "C"), 1561.098e6, 1575.42e6)
        glonass = np.char.startswith(sv, "R")
        freq[glonass] = 1602.0e6 + (_f(df, "glonass_slot")[glonass] - 7) * 0.5625e6
    isrb = np.nan_to_num(_f(df, "isrb"))
    if "isrb" in df:
        meta["tables.isrb"] = "the table's inter-signal range bias removed from each raw pseudorange"
    prr = _f(df, "prr")
    doppler = _f(df, "doppler")
    prr = np.where(np.isfinite(prr), prr, -doppler * C_MPS / freq)
    doppler = np.where(np.isfinite(doppler), doppler, -prr * freq / C_MPS)
    phase = _f(df, "phase_cycles")
    trk = np.nan_to_num(_f(df, "trk")).astype(np.int64)
    if "trk" in df:  # u-blox trkStat bit 1: the carrier phase is valid
        phase = np.where(trk & CP_VALID, phase, np.nan)
    half_cycle = np.zeros(len(df), dtype=bool)
    if "adr" in df:
        state = np.nan_to_num(_f(df, "adr_state")).astype(np.int64)
        ok = ((state & ADR_VALID) != 0) & ((state & (ADR_RESET | ADR_CYCLE_SLIP)) == 0)
        phase = np.where(ok, _f(df, "adr") * freq / C_MPS, np.nan)
        half_cycle = adr_half_cycle_unresolved(state)
    out = pd.DataFrame(
        {
            "t_ns": t_ns,
            "receiver_id": rid,
            "sv_id": sv,
            "pseudorange_m": pr - isrb,
            "pseudorange_rate_mps": prr,
            "doppler_hz": doppler,
            "carrier_phase_cycles": phase,
            "carrier_freq_hz": freq,
            "cn0_dbhz": _f(df, "cn0"),
            "sv_x_m": _f(df, "sv_x"),
            "sv_y_m": _f(df, "sv_y"),
            "sv_z_m": _f(df, "sv_z"),
            "sv_vx_mps": _f(df, "sv_vx"),
            "sv_vy_mps": _f(df, "sv_vy"),
            "sv_vz_mps": _f(df, "sv_vz"),
            "sv_clock_bias_m": _f(df, "sv_clk"),
            "sv_clock_drift_mps": _f(df, "sv_drift"),
            "half_cycle": half_cycle,
            "trk": trk,
            "locktime": _f(df, "locktime"),
        }
    )
    keep = np.ones(len(out), dtype=bool)
    for reason, bad in (
        ("no satellite id (constellation, svid)", sv == ""),
        ("no valid pseudorange", ~np.isfinite(pr) | (pr <= 0)),
        ("signal outside the L1 band (L5/E5a/B2a): one L1 signal per satellite is used", ~_l1(df)),
    ):
        bad = bad & keep
        if bad.any():
            skipped.append(Skipped(rid, reason, int(bad.sum())))
        keep &= ~bad
    out = out[keep]
    dup = out.duplicated(["t_ns", "sv_id"], keep="first").to_numpy()
    if dup.any():
        skipped.append(
            Skipped(rid, "a second L1 signal of the same satellite and epoch (the first kept)", int(dup.sum()))
        )
    return _carrier_arc_starts(out[~dup].reset_index(drop=True), "trk" in df, "locktime" in df, rid, skipped)


def _carrier_arc_starts(
    out: pd.DataFrame, ublox: bool, has_locktime: bool, rid: str, skipped: list[Skipped]
) -> pd.DataFrame:
    """The carriers the receiver says are not continuous marked (`readers.carrier_arcs`): the phone's
    unresolved half-cycle state; u-blox rows' half-cycle bits and lock time (smartLoc)."""
    half, trk, lock = (out.pop(c).to_numpy() for c in ("half_cycle", "trk", "locktime"))
    breaks = {HALF_CYCLE_ANDROID: half.astype(bool)}
    if ublox:
        sv, t_ns = out["sv_id"].to_numpy(), out["t_ns"].to_numpy(np.int64)
        breaks |= ublox_breaks(sv, t_ns, trk, np.nan_to_num(lock).astype(np.int64) if has_locktime else None)
    out["carrier_arc_start"] = arc_starts(rid, out["carrier_phase_cycles"].to_numpy(float), breaks, skipped)
    return out


def _fixes(df: pd.DataFrame, t_ns: NDArray[np.int64], rid: str, meta: dict[str, str]) -> pd.DataFrame | None:
    """The table's receiver position at each epoch (ECEF, or geodetic), the first row of each epoch."""
    xyz = np.stack([_f(df, k) for k in ("rx_x", "rx_y", "rx_z")], axis=1)
    has_xyz = np.isfinite(xyz).all(axis=1) & (np.linalg.norm(np.nan_to_num(xyz), axis=1) > 6.0e6)
    llh = np.stack([_f(df, k) for k in ("rx_lat", "rx_lon", "rx_alt")], axis=1)
    has_llh = np.isfinite(llh).all(axis=1)
    use = has_xyz | has_llh
    if not use.any():
        return None
    lat, lon, h = (np.full(len(df), np.nan) for _ in range(3))
    if has_xyz.any():
        la, lo, hh = ecef_to_geodetic(xyz[has_xyz])
        lat[has_xyz], lon[has_xyz], h[has_xyz] = la, lo, hh
    only_llh = has_llh & ~has_xyz
    lat[only_llh], lon[only_llh], h[only_llh] = llh[only_llh].T
    fixes = pd.DataFrame(
        {"t_ns": t_ns, "receiver_id": rid, "lat_deg": lat, "lon_deg": lon, "height_m": h, "fix_type": FixType.UNKNOWN}
    )[use]
    meta["tables.fixes"] = "the table's own receiver positions (the dataset's least-squares solution), one per epoch"
    return fixes.drop_duplicates("t_ns", keep="first").reset_index(drop=True)


def _truth_rows(df: pd.DataFrame, t_ns: NDArray[np.int64]) -> pd.DataFrame | None:
    """smartLoc's reference trajectory on each measurement row."""
    if not {"gt_lat", "gt_lon", "gt_h"} <= set(df.columns):
        return None
    t = t_ns
    if {"gt_week", "gt_tow"} <= set(df.columns):
        t = np.round((_f(df, "gt_week") * WEEK_S + _f(df, "gt_tow")) * 1e9).astype(np.int64)
    truth = pd.DataFrame(
        {"t_ns": t, "lat_deg": _f(df, "gt_lat"), "lon_deg": _f(df, "gt_lon"), "height_m": _f(df, "gt_h")}
    )
    truth = truth[np.isfinite(truth[["lat_deg", "lon_deg", "height_m"]].to_numpy()).all(axis=1)]
    return truth.drop_duplicates("t_ns").reset_index(drop=True)


def ground_truth_beside(path: Path) -> Path | None:
    """The ground-truth table shipped beside a measurement table: `ground_truth.csv` in the same folder
    (the GSDC layout), or the table's name with its last part replaced (`x_device_gnss.csv` ->
    `x_ground_truth.csv`, `x_derived.csv` -> `x_ground_truth.csv`)."""
    stem = path.stem
    candidates = [path.with_name("ground_truth.csv")]
    for i in range(stem.count("_"), 0, -1):
        candidates.append(path.with_name("_".join(stem.split("_")[:i]) + "_ground_truth.csv"))
    return next((p for p in candidates if p.is_file() and p != path and _is_truth_companion(p)), None)


def read_ground_truth(path: Path, reference: str) -> pd.DataFrame:
    """A GSDC ground-truth table as truth rows (t_ns on `reference`'s clock)."""
    with path.open("rb") as f:
        names, _ = _header(path, f.read(4096))
    pick = {k: next((a for a in aliases if a in names), None) for k, aliases in TRUTH_NAMES.items()}
    df = read_rows(path, [], keep=lambda n: n in pick.values())
    if pick["t_gps_ms"]:
        t = df[pick["t_gps_ms"]].to_numpy(float) * 1e6
        t_ns = t if reference == "gps" else None
    else:
        t_unix = df[str(pick["t_unix_ms"])].to_numpy(float) * 1e6
        t_ns = gps_ns_of_unix_ns(np.round(np.nan_to_num(t_unix)).astype(np.int64)) if reference == "gps" else t_unix
    if t_ns is None:
        raise ReaderError(path, "ground truth on GPS time beside a table on UNIX time", "truth")
    h = df[pick["h"]].to_numpy(float) if pick["h"] else np.zeros(len(df))
    truth = pd.DataFrame(
        {"t_ns": np.round(np.nan_to_num(t_ns)).astype(np.int64), "lat_deg": df[pick["lat"]].to_numpy(float),
         "lon_deg": df[pick["lon"]].to_numpy(float), "height_m": h}
    )  # fmt: skip
    return truth[np.isfinite(truth[["lat_deg", "lon_deg", "height_m"]].to_numpy()).all(axis=1) & (truth["t_ns"] > 0)]


def read_gnss_table(
    path: Path, topics: Mapping[str, str] | None = None, progress: Progress | None = None
) -> EpochTable:
    path = Path(path)
    try:
        with path.open("rb") as f:
            names, sep = _header(path, f.read(1 << 16))
    except OSError as err:
        raise ReaderError(path, f"cannot read: {err.strerror or err}") from err
    if is_ground_truth(names):
        raise ReaderError(
            path,
            "a ground-truth table (a reference trajectory), not a log: analyse the measurement log it belongs "
            "to (a `device_gnss.csv`, `*_derived.csv` or GnssLogger log beside it, which reads it as its truth)",
        )
    missing = [what for what, keys in NEEDED.items() if not any(_find(names, k) for k in keys)]
    if missing:
        wanted = {what: [a for k in keys for a in ALIASES[k]][:4] for what, keys in NEEDED.items() if what in missing}
        raise ReaderError(path, f"a table of GNSS measurements without {', '.join(missing)} (columns {wanted})")
    skipped: list[Skipped] = []
    meta: dict[str, str] = {"tables.columns": ", ".join(n for n in names if any(n in a for a in ALIASES.values()))}
    df = _rows(path, names, sep, skipped)
    t_ns, reference, timed = _times(df)
    if (~timed).any():
        skipped.append(Skipped(path.name, "rows without a time", int((~timed).sum()), "lost"))
    df, t_ns = df[timed].reset_index(drop=True), t_ns[timed]
    rid = "ublox" if "trk" in df else "phone"
    obs = _observations(df, t_ns, rid, skipped, meta)
    if not len(obs):
        raise ReaderError(path, "no usable measurement row: " + ("; ".join(str(s) for s in skipped[:4]) or "none"))
    frames: dict[str, pd.DataFrame] = {"observations": obs}
    streams = [StreamInfo("observations", rid, path.name, "derived measurement table", int(obs["t_ns"].nunique()))]
    fixes = _fixes(df, t_ns, rid, meta)
    if fixes is not None:
        frames["fixes"] = fixes
        streams.append(StreamInfo("fix", rid, path.name, "table receiver position (least squares)", len(fixes)))
    truth = _truth_rows(df, t_ns)
    companion = ground_truth_beside(path)
    if truth is None and companion is not None:
        try:
            truth = read_ground_truth(companion, reference)
        except ReaderError as err:
            skipped.append(Skipped(companion.name, f"ground truth not used: {err.problem}", 1))
    if truth is not None and len(truth):
        frames["truth"] = truth
        source = companion.name if companion is not None and "gt_lat" not in df else path.name
        streams.append(StreamInfo("truth", "truth", source, "ground truth", len(truth)))
    if topics:
        skipped.append(Skipped("<table>", f"--topic is not used for measurement tables ({dict(topics)})", len(topics)))
    if not math.isfinite(float(obs["sv_x_m"].notna().mean())) or not obs["sv_x_m"].notna().any():
        meta["tables.satellites"] = "no satellite positions in the table"
    return build_table(path, "gnss_table", reference, frames, streams, skipped, metadata=meta)


def _name_says_truth(path: Path) -> bool:
    return bool(re.search(r"ground_?truth", path.name, flags=re.IGNORECASE))


FORMATS = (
    ReaderFormat(
        "gnss_table",
        "derived GNSS measurement table (GSDC device_gnss.csv / derived.csv, gnss_lib_py, smartLoc); "
        "ground-truth tables beside them",
        read_gnss_table,
        _looks_like_table,
        companion=lambda path: path.is_file() and (_is_truth_companion(path) or _name_says_truth(path)),
    ),
)
