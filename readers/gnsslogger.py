"""Android GnssLogger text logs (every version since 1.4) into an EpochTable.

A log is comma-separated records, one per line, named by their first field (`Raw`, `Fix`, `Accel`,
...); `# Raw,...` header comments give each record's columns for this file's version, so the parser
reads fields by name (v1.4's `Fix,Provider,Latitude,...,(UTC)TimeInMs` and v3's
`Fix,Provider,LatitudeDegrees,...,UnixTimeMillis,...` alike). Lines whose field count does not match
their header are skipped and counted. A lean parser of our own: gnss_lib_py pins pandas < 3.

**Raw -> observations** (receiver `phone`; the GnssMeasurement clock model of Android's
GnssClock/GnssMeasurement documentation, as Google's gps-measurement-tools apply it):
- receive time t_rx = TimeNanos + TimeOffsetNanos - (FullBiasNanos + BiasNanos), in GPS nanoseconds,
  with each epoch's own FullBiasNanos/BiasNanos (integer arithmetic for the 1e18-ns terms). The epoch
  tag is TimeNanos - FullBiasNanos - BiasNanos rounded to the nanosecond; the table is on the GPS clock.
- ReceivedSvTimeNanos is per constellation: time of week for GPS, Galileo, QZSS, SBAS, NavIC; BeiDou
  time of week (GPS - 14 s); GLONASS time of day (UTC + 3 h, leap seconds from the log's LeapSecond
  field or the table). pseudorange = c * (t_rx in that scale - ReceivedSvTimeNanos), folded across the
  week (day) rollover.
- a measurement is kept only when its State says the time is known: TOW decoded/known (GPS, Galileo,
  BeiDou, QZSS, SBAS, NavIC) or time of day decoded/known (GLONASS), not millisecond-ambiguous, with
  ReceivedSvTimeUncertaintyNanos <= 500 ns and a pseudorange between 1e7 and 5e7 m; each reason to skip
  is counted. One L1-band signal per satellite (L5/E5a rows are counted and left out), as for RINEX.
- pseudorange rate: PseudorangeRateMetersPerSecond; Doppler = -rate * f / c; carrier phase (cycles)
  = AccumulatedDeltaRangeMeters * f / c where AccumulatedDeltaRangeState is valid and not reset or
  cycle-slipped; a carrier half-cycle unresolved (HALF_CYCLE_REPORTED without HALF_CYCLE_RESOLVED) is
  marked (`carrier_arc_start`, `readers.carrier_arcs`, counted as flagged); C/N0: Cn0DbHz. Satellite ids
  RINEX style (SBAS
  svid - 100, QZSS svid - 192; GLONASS rows without a known slot are skipped).
- GPS satellite states from a RINEX navigation file: `--topic nav=FILE`, else one in the log's
  directory that covers its time (`readers.raw_states`).

**Fix -> fixes.** Only `GPS`-provider fixes are the receiver's own (FLP fuses Wi-Fi and sensors, NLP is
network location): the others are counted as skipped. Android altitude is above the WGS84 ellipsoid;
AccuracyMeters (68 % horizontal radius) -> h_acc_m, VerticalAccuracyMeters -> v_acc_m,
SpeedAccuracyMps -> vel_acc_mps; velocity from speed and bearing (horizontal only); MockLocation 1 ->
spoofing_flag INDICATED (the OS says an app supplied the location). Each fix gets the mean C/N0 of the
raw measurements and the mean AgcDb of the L1 band at the nearest raw epoch within 1 s.

**Status -> satellites.** GnssStatus as logged (`UnixTimeMillis`, `ConstellationType`, `Svid`,
`CarrierFrequencyHz`, `Cn0DbHz`, `AzimuthDegrees`, `ElevationDegrees`, `UsedInFix`): what the phone
says of every satellite it sees, one row per satellite and time (its L1-band signal), for the
per-satellite detectors; time UTC -> the table's clock.

**IMU.** Accel + Gyro (calibrated) when logged, else UncalAccel + UncalGyro as measured (the navigation
filter estimates biases); the gyro is interpolated to the accelerometer's stamps. Body frame ANDROID
(x right, y toward the top of the screen, z out of the screen). OrientationDeg (yaw = azimuth, pitch,
roll of SensorManager.getOrientation) -> quaternion device->ENU, R = Rz(-azimuth) Rx(-pitch) Ry(roll),
the inverse of getOrientation's formulas; nearest within 0.5 s. Sensor stamps are elapsedRealtimeNanos,
put on UTC with the median offset to the GPS fixes' UnixTimeMillis (else the lines' utcTimeMillis).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from readers import NothingToJudgeError, ReaderFormat
from readers.android_gnss import (
    ADR_CYCLE_SLIP,
    ADR_RESET,
    ADR_VALID,
    HALF_CYCLE_ANDROID,
    L1_BAND_HZ,
    adr_half_cycle_unresolved,
    android_sv_ids,
    android_systems,
)
from readers.carrier_arcs import arc_starts
from readers.inav import InavDecoder
from readers.lnav import LnavDecoder
from readers.raw_states import add_satellite_states, ephemeris_stream, nav_stream, navigation_for
from spooflens.epoch_table import (
    EpochTable,
    Skipped,
    StreamInfo,
    build_table,
    gps_ns_of_unix_ns,
    gps_utc_offset_ns,
    log_clock,
    time_offset_s,
)
from spooflens.errors import ReaderError
from spooflens.gnss.ephemeris import C_MPS, GpsEphemerides
from spooflens.navigation.rotations import matrix_to_quat
from spooflens.schema import FixType, SpoofingFlag

Progress = Callable[[int, int], None]
FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

RECEIVER = "phone"
WEEK_NS = 604_800 * 1_000_000_000
MAX_UNIX_MS = 4_102_444_800_000  # 2100-01-01
MAX_GPS_NS = (MAX_UNIX_MS * 1_000_000) - 315_964_800_000_000_000  # 2100-01-01 in GPS ns (without leap seconds)
DAY_NS = 86_400 * 1_000_000_000
BDS_GPS_NS = 14 * 1_000_000_000
GLO_UTC_NS = 3 * 3600 * 1_000_000_000
MAX_TIME_UNCERTAINTY_NS = 500.0
PR_RANGE_M = (1.0e7, 5.0e7)
RECORDS = (
    "Raw",
    "Fix",
    "Accel",
    "Gyro",
    "UncalAccel",
    "UncalGyro",
    "OrientationDeg",
    "Agc",
    "Status",
    "Nav",
    "Mag",
    "UncalMag",
)
USED = {"Raw", "Fix", "Accel", "Gyro", "UncalAccel", "UncalGyro", "OrientationDeg", "Agc", "Status"}

# GnssMeasurement.State bits
TOW_DECODED, MSEC_AMBIGUOUS, GLO_TOD_DECODED, TOW_KNOWN, GLO_TOD_KNOWN = 8, 16, 128, 16384, 32768
# AccumulatedDeltaRangeState bits
DEFAULT_L1_HZ = {"G": 1575.42e6, "S": 1575.42e6, "J": 1575.42e6, "E": 1575.42e6, "C": 1561.098e6}

# Column names that changed between versions: canonical name -> names in the file
FIX_NAMES = {
    "lat": ("LatitudeDegrees", "Latitude"),
    "lon": ("LongitudeDegrees", "Longitude"),
    "alt": ("AltitudeMeters", "Altitude"),
    "speed": ("SpeedMps", "Speed"),
    "accuracy": ("AccuracyMeters", "Accuracy"),
    "bearing": ("BearingDegrees", "Bearing"),
    "time_ms": ("UnixTimeMillis", "(UTC)TimeInMs", "TimeInMs"),
    "elapsed_ns": ("elapsedRealtimeNanos",),
    "v_acc": ("VerticalAccuracyMeters",),
    "speed_acc": ("SpeedAccuracyMps",),
    "mock": ("MockLocation",),
}


@dataclass
class Records:
    """The lines of one record type, split, with the column names its header gave."""

    columns: list[str]
    rows: list[list[str]] = field(default_factory=list)

    def frame(self) -> pd.DataFrame:
        """The rows by column name; of a name the header gives twice (v2.0.0.x's `CarrierFrequencyHz` in
        Raw), the first column."""
        df = pd.DataFrame(self.rows, columns=self.columns, dtype=object)
        return df.loc[:, ~df.columns.duplicated()]


GPS_L1CA_NAV = 0x0101  # GnssNavigationMessage TYPE_GPS_L1CA
GALILEO_INAV = 0x0601  # TYPE_GAL_I


@dataclass(frozen=True)
class NavRecord:
    """One `Nav` line: a navigation-message subframe the phone demodulated, and how many Raw lines came
    before it (Nav lines carry no time of their own: the Raw measurement before one dates it)."""

    svid: int
    type: int
    data: bytes
    raw_lines_before: int


def _nav_record(fields: list[str], raw_lines_before: int) -> NavRecord | None:
    """`Nav,Svid,Type,Status,MessageId,Sub-messageId,Data(Bytes)`: the data are the bytes, comma-separated
    (signed, as Java prints them)."""
    try:
        svid, kind = int(fields[1]), int(fields[2])
        data = bytes(int(b) & 0xFF for b in fields[6:] if b.strip())
    except (IndexError, ValueError):
        return None
    return NavRecord(svid, kind, data, raw_lines_before)


def split_file(
    path: Path, skipped: list[Skipped], nav: list[NavRecord] | None = None
) -> tuple[dict[str, Records], dict[str, str]]:
    try:
        text = path.read_bytes().decode("utf-8", errors="replace")
    except OSError as err:
        raise ReaderError(path, f"cannot read: {err.strerror or err}") from err
    headers: dict[str, list[str]] = {}
    meta: dict[str, str] = {}
    records: dict[str, Records] = {}
    bad: dict[str, int] = {}
    unknown: dict[str, int] = {}
    unused: dict[str, int] = {}
    lines = text.splitlines()
    cut = bool(text) and not text.endswith(("\n", "\r"))
    bad_nav = 0
    for i, line in enumerate(lines):
        if not line.strip():
            continue
        if line.startswith("#"):
            body = line.lstrip("# \t").strip()  # "# # Version: ..." in some v2.0 logs
            name = body.split(",", 1)[0].strip()
            if (name in RECORDS or re.fullmatch(r"[A-Za-z]\w*", name)) and "," in body:
                headers[name] = [c.strip() for c in body.split(",")][1:]
                twice = sorted({c for c in headers[name] if headers[name].count(c) > 1})
                if twice and name in USED:
                    skipped.append(Skipped(name, f"header names {', '.join(twice)} twice: the first column read", 1))
            elif body.startswith("Version:"):
                meta["firmware"] = body[len("Version:") :].strip()
            continue
        fields = line.split(",")
        name = fields[0].strip()
        if name == "Nav" and nav is not None and not (cut and i == len(lines) - 1):
            record = _nav_record(fields, len(records["Raw"].rows) if "Raw" in records else 0)
            if record is None:
                bad_nav += 1
            else:
                nav.append(record)
            continue
        if name not in RECORDS and name not in headers:
            unknown[name[:20]] = unknown.get(name[:20], 0) + 1
            continue
        if name not in USED:
            unused[name] = unused.get(name, 0) + 1
            continue
        cols = headers.get(name)
        if cols is None:
            bad[f"{name}: no '# {name},...' header line defines its columns"] = (
                bad.get(f"{name}: no '# {name},...' header line defines its columns", 0) + 1
            )
            continue
        values = [f.strip() for f in fields[1:]]
        if len(values) > len(cols) and not any(values[len(cols) :]):
            values = values[: len(cols)]
        if len(values) != len(cols) or (cut and i == len(lines) - 1):
            reason = f"{name}: {len(values)} fields where its header has {len(cols)} (cut or damaged line)"
            bad[reason] = bad.get(reason, 0) + 1
            continue
        records.setdefault(name, Records(cols)).rows.append(values)
    if bad_nav:
        skipped.append(Skipped("Nav", "navigation-message lines that cannot be read", bad_nav, "lost"))
    for reason, n in bad.items():
        name, _, why = reason.partition(": ")
        skipped.append(Skipped(name, why, n, "lost"))
    for name, n in unused.items():
        skipped.append(Skipped(name, "record type not used", n))
    if unknown:
        total = sum(unknown.values())
        skipped.append(
            Skipped("<gnsslogger>", f"lines that are no GnssLogger record ({sorted(unknown)[:5]})", total, "lost")
        )
    return records, meta


def _col(df: pd.DataFrame, *names: str) -> pd.Series | None:
    return next((df[n] for n in names if n in df.columns), None)


def _float(s: pd.Series | None, n: int) -> FloatArray:
    if s is None:
        return np.full(n, np.nan)
    return pd.to_numeric(s, errors="coerce").to_numpy(dtype=float)


def _int64(s: pd.Series | None, n: int) -> tuple[IntArray, NDArray[np.bool_]]:
    """Integer fields exactly (TimeNanos, FullBiasNanos ~1e18 do not fit a float); (values, present)."""
    if s is None:
        return np.zeros(n, dtype=np.int64), np.zeros(n, dtype=bool)
    text = s.astype(str).str.strip()
    # up to 18 digits always fits an int64; a 19-digit value is checked against its range one by one
    whole = text.str.fullmatch(r"[-+]?\d{1,18}").to_numpy(dtype=bool, copy=True)
    out = np.zeros(n, dtype=np.int64)
    if whole.any():
        out[whole] = text[whole].astype(np.int64).to_numpy()
    for i in np.flatnonzero(text.str.fullmatch(r"[-+]?\d{19,}").to_numpy(dtype=bool)):
        value = int(text.iloc[i])
        if -(2**63) <= value < 2**63:
            out[i], whole[i] = value, True
    # a value written as a float ("1.2E18", "72076939000000.0") is taken as well as a float can hold it
    other = ~whole & (text != "").to_numpy(dtype=bool) & ~text.str.fullmatch(r"[-+]?\d{19,}").to_numpy(dtype=bool)
    as_float = pd.to_numeric(text[other], errors="coerce").to_numpy(dtype=float)
    ok_float = np.isfinite(as_float) & (np.abs(as_float) < 9.2e18)
    idx = np.flatnonzero(other)
    out[idx[ok_float]] = np.round(as_float[ok_float]).astype(np.int64)
    present = whole.copy()
    present[idx[ok_float]] = True
    return out, present


def status_satellites(status: pd.DataFrame, skipped: list[Skipped]) -> pd.DataFrame | None:
    """`Status` records (GnssStatus: what the phone says of each satellite it sees) -> satellites-frame
    rows with `unix_ns`: C/N0, elevation, azimuth, used in the fix. One row per satellite and time, its
    L1-band signal (a dual-frequency phone reports L5/E5a as another signal of the same satellite); a
    record without a time, or of a satellite without an id, is left out and counted."""
    n = len(status)
    unix_ms = _float(_col(status, "UnixTimeMillis"), n)
    system = android_systems(_float(_col(status, "ConstellationType"), n))
    sv_id = android_sv_ids(system, _float(_col(status, "Svid"), n))
    freq = _float(_col(status, "CarrierFrequencyHz"), n)
    l1 = ~np.isfinite(freq) | ((freq >= L1_BAND_HZ[0]) & (freq <= L1_BAND_HZ[1]))
    timed = np.isfinite(unix_ms) & (unix_ms > 0)
    for reason, bad in (
        ("no UnixTimeMillis", ~timed),
        ("no satellite id (constellation, svid)", timed & (sv_id == "")),
    ):
        if bad.any():
            skipped.append(Skipped("Status", reason, int(bad.sum())))
    keep = timed & (sv_id != "") & l1
    if not keep.any():
        return None
    used_text = _col(status, "UsedInFix")
    used = (
        np.full(n, np.nan)
        if used_text is None
        else used_text.astype(str).str.strip().str.lower().map({"1": 1.0, "true": 1.0, "0": 0.0, "false": 0.0})
    )
    cn0 = _float(_col(status, "Cn0DbHz"), n)
    rows = pd.DataFrame(
        {
            "unix_ns": unix_ms * 1e6,  # whole ns once the rows without a time are gone
            "sv_id": sv_id,
            "cn0_dbhz": np.where(cn0 > 0, cn0, np.nan),
            "elevation_deg": _float(_col(status, "ElevationDegrees"), n),
            "azimuth_deg": _float(_col(status, "AzimuthDegrees"), n),
            "used": np.asarray(used, dtype=float),
            "residual_m": np.nan,
            "healthy": np.nan,
        }
    )[keep]
    rows["unix_ns"] = np.round(rows["unix_ns"].to_numpy()).astype(np.int64)
    # the strongest signal of a satellite at a time (two L1-band signals: GLONASS FDMA, or duplicates)
    rows = rows.sort_values("cn0_dbhz", ascending=False, na_position="last", kind="stable")
    rows = rows.drop_duplicates(["unix_ns", "sv_id"]).sort_values(["unix_ns", "sv_id"], kind="stable")
    return rows.reset_index(drop=True)


@dataclass
class RawResult:
    rows: pd.DataFrame  # observation rows with t_ns (GPS clock)
    epochs: pd.DataFrame  # per epoch: t_ns, cn0 mean, agc mean


def pseudoranges(raw: pd.DataFrame, skipped: list[Skipped]) -> RawResult:
    """Observation rows (GPS-clock t_ns) from Raw records, each skipped measurement counted by reason."""
    n = len(raw)
    time_nanos, has_time = _int64(_col(raw, "TimeNanos"), n)
    full_bias, has_bias = _int64(_col(raw, "FullBiasNanos"), n)
    rx_sv_time, has_sv_time = _int64(_col(raw, "ReceivedSvTimeNanos"), n)
    bias = np.nan_to_num(_float(_col(raw, "BiasNanos"), n))
    offset = np.nan_to_num(_float(_col(raw, "TimeOffsetNanos"), n))
    leap_logged = _float(_col(raw, "LeapSecond"), n)
    svid = _float(_col(raw, "Svid"), n)
    constellation = _float(_col(raw, "ConstellationType"), n)
    state = np.nan_to_num(_float(_col(raw, "State"), n)).astype(np.int64)
    uncertainty = _float(_col(raw, "ReceivedSvTimeUncertaintyNanos"), n)
    freq = _float(_col(raw, "CarrierFrequencyHz"), n)
    system = android_systems(constellation)
    reasons: dict[str, NDArray[np.bool_]] = {}

    def reject(reason: str, mask: NDArray[np.bool_]) -> None:
        new = mask & ~np.any(list(reasons.values()), axis=0) if reasons else mask
        if new.any():
            reasons[reason] = new

    reject(
        "no TimeNanos/FullBiasNanos/ReceivedSvTimeNanos (receiver clock not set)", ~(has_time & has_bias & has_sv_time)
    )
    reject("unknown constellation type", system == "")
    glo = system == "R"
    # GLONASS svid 93-106 is a frequency channel (slot unknown): no RINEX id
    reject("GLONASS satellite without a known slot (svid is a frequency channel)", glo & ((svid < 1) | (svid > 24)))
    fill = np.where(np.isfinite(freq), freq, [DEFAULT_L1_HZ.get(s, np.nan) for s in system])
    in_l1 = (fill >= L1_BAND_HZ[0]) & (fill <= L1_BAND_HZ[1])
    reject("signal outside the L1 band (L5/E5a/B2a): one L1 signal per satellite is used", np.isfinite(fill) & ~in_l1)
    known = np.where(glo, (state & (GLO_TOD_DECODED | GLO_TOD_KNOWN)) != 0, (state & (TOW_DECODED | TOW_KNOWN)) != 0)
    reject("State: time of week/day not decoded (measurement not locked)", ~known | ((state & MSEC_AMBIGUOUS) != 0))
    reject(
        f"ReceivedSvTimeUncertaintyNanos above {MAX_TIME_UNCERTAINTY_NS:.0f} ns",
        ~(uncertainty <= MAX_TIME_UNCERTAINTY_NS),
    )
    reject("BiasNanos infinite or beyond a second", np.isinf(bias) | (np.abs(np.nan_to_num(bias)) >= 1e9))
    bias = np.where(np.isfinite(bias) & (np.abs(bias) < 1e9), bias, 0.0)
    # GPS nanoseconds of the epoch tag; the sub-nanosecond rest stays a float
    bias_int = np.round(bias).astype(np.int64)
    with np.errstate(over="ignore"):  # damaged fields wrap around int64: caught just below
        tag_ns = time_nanos - full_bias - bias_int
    reject("receiver time outside 1980 .. 2100", (tag_ns <= 0) | (tag_ns >= MAX_GPS_NS))
    rest_ns = (bias_int - bias) + offset
    leap_ns = np.where(np.isfinite(leap_logged), np.nan_to_num(leap_logged) * 1e9, gps_utc_offset_ns(tag_ns)).astype(
        np.int64
    )
    period = np.where(glo, DAY_NS, WEEK_NS)
    scale_ns = np.where(glo, tag_ns - leap_ns + GLO_UTC_NS, np.where(system == "C", tag_ns - BDS_GPS_NS, tag_ns))
    rx_in_scale = np.mod(scale_ns, period)
    pr_ns = (rx_in_scale - rx_sv_time).astype(np.float64) + rest_ns
    pr_ns = np.where(pr_ns > period / 2, pr_ns - period, np.where(pr_ns < -period / 2, pr_ns + period, pr_ns))
    pr_m = pr_ns * C_MPS / 1e9
    reject(
        f"pseudorange outside {PR_RANGE_M[0]:.0e}-{PR_RANGE_M[1]:.0e} m",
        ~((pr_m >= PR_RANGE_M[0]) & (pr_m <= PR_RANGE_M[1])),
    )
    sv_id = android_sv_ids(system, svid)
    rate = _float(_col(raw, "PseudorangeRateMetersPerSecond"), n)
    adr = _float(_col(raw, "AccumulatedDeltaRangeMeters"), n)
    adr_state = np.nan_to_num(_float(_col(raw, "AccumulatedDeltaRangeState"), n)).astype(np.int64)
    adr_ok = ((adr_state & ADR_VALID) != 0) & ((adr_state & (ADR_RESET | ADR_CYCLE_SLIP)) == 0)
    carrier_hz = np.where(glo & ~np.isfinite(freq), np.nan, fill)
    cn0 = _float(_col(raw, "Cn0DbHz"), n)
    agc = _float(_col(raw, "AgcDb"), n)
    rows = pd.DataFrame(
        {
            "t_ns": tag_ns,
            "receiver_id": RECEIVER,
            "sv_id": sv_id,
            "pseudorange_m": pr_m,
            "pseudorange_rate_mps": rate,
            "doppler_hz": -rate * carrier_hz / C_MPS,
            "carrier_phase_cycles": np.where(adr_ok, adr * carrier_hz / C_MPS, np.nan),
            "carrier_freq_hz": carrier_hz,
            "cn0_dbhz": cn0,
            "half_cycle": adr_half_cycle_unresolved(adr_state),
        }
    )
    bad = np.any(list(reasons.values()), axis=0) if reasons else np.zeros(n, dtype=bool)
    for reason, mask in reasons.items():
        skipped.append(Skipped(RECEIVER, reason, int(mask.sum())))
    # one row per satellite and epoch: the first L1 signal (two L1 codes of one satellite are rare)
    good = rows[~bad]
    dup = good.duplicated(["t_ns", "sv_id"], keep="first").to_numpy()
    if dup.any():
        skipped.append(Skipped(RECEIVER, "second L1 signal of the same satellite in an epoch", int(dup.sum())))
    epochs = (
        pd.DataFrame({"t_ns": tag_ns, "cn0": cn0, "agc": np.where(in_l1, agc, np.nan)})[has_time & has_bias]
        .groupby("t_ns", as_index=False)
        .mean()
    )
    kept = good[~dup].reset_index(drop=True)
    half = {HALF_CYCLE_ANDROID: kept.pop("half_cycle").to_numpy(bool)}
    kept["carrier_arc_start"] = arc_starts(RECEIVER, kept["carrier_phase_cycles"].to_numpy(), half, skipped)
    return RawResult(kept, epochs)


def agc_epochs(agc: pd.DataFrame) -> pd.DataFrame:
    """Agc records (v3: one per band and constellation) -> mean L1-band AgcDb per epoch (GPS t_ns)."""
    n = len(agc)
    time_nanos, ok_t = _int64(_col(agc, "TimeNanos"), n)
    full_bias, ok_b = _int64(_col(agc, "FullBiasNanos"), n)
    bias = np.nan_to_num(_float(_col(agc, "BiasNanos"), n))
    freq = _float(_col(agc, "CarrierFrequencyHz"), n)
    db = _float(_col(agc, "AgcDb"), n)
    keep = ok_t & ok_b & (freq >= L1_BAND_HZ[0]) & (freq <= L1_BAND_HZ[1]) & np.isfinite(db)
    t_ns = time_nanos - full_bias - np.round(bias).astype(np.int64)
    return pd.DataFrame({"t_ns": t_ns[keep], "agc_rec": db[keep]}).groupby("t_ns", as_index=False).mean()


def gps_fixes(path: Path, records: dict[str, Records], skipped: list[Skipped]) -> pd.DataFrame | None:
    """The GPS provider's fixes with their `unix_ms` (the fix's own time) and `elapsed_ns`, or None."""
    return _fixes(path, records["Fix"].frame(), skipped) if "Fix" in records else None


def fix_clock(fixes: pd.DataFrame) -> tuple[int | None, IntArray]:
    """(UnixTimeMillis minus elapsedRealtimeNanos, median over the fixes with both, ns; or None) and each
    fix's time on the phone's clock (UNIX ns): elapsedRealtimeNanos plus that offset, else UnixTimeMillis.
    A fix is placed by when the phone made it, not by the time it carries, which a spoofer moves (that
    difference is `time_offset_s`)."""
    unix_ns = fixes["unix_ms"].to_numpy(np.int64) * 1_000_000
    elapsed = fixes["elapsed_ns"].to_numpy(np.int64)
    known = elapsed > 0
    if not known.any():
        return None, unix_ns
    offset = int(np.median(unix_ns[known] - elapsed[known]))
    return offset, np.where(known, elapsed + offset, unix_ns)


def _fixes(path: Path, fix: pd.DataFrame, skipped: list[Skipped]) -> pd.DataFrame:
    n = len(fix)
    provider = _col(fix, "Provider")
    prov = provider.astype(str).str.strip().str.upper().to_numpy() if provider is not None else np.full(n, "GPS")
    others = prov != "GPS"
    for p in sorted(set(prov[others])):
        skipped.append(
            Skipped(
                f"Fix/{p}",
                "not the receiver's own fix (FLP fuses Wi-Fi/sensors, NLP is network location)",
                int((prov == p).sum()),
            )
        )
    f = {k: (_col(fix, *names)) for k, names in FIX_NAMES.items()}
    time_ms, has_time = _int64(f["time_ms"], n)
    if not has_time[~others].any():
        raise ReaderError(path, "Fix records without a time column (UnixTimeMillis or (UTC)TimeInMs)", "Fix")
    speed, bearing = _float(f["speed"], n), np.radians(_float(f["bearing"], n))
    still = speed == 0
    ve = np.where(np.isfinite(bearing), speed * np.sin(bearing), np.where(still, 0.0, np.nan))
    vn = np.where(np.isfinite(bearing), speed * np.cos(bearing), np.where(still, 0.0, np.nan))
    mock = _float(f["mock"], n)
    out = pd.DataFrame(
        {
            "unix_ms": time_ms,
            "elapsed_ns": _int64(f["elapsed_ns"], n)[0] if f["elapsed_ns"] is not None else np.zeros(n, np.int64),
            "receiver_id": RECEIVER,
            "lat_deg": _float(f["lat"], n),
            "lon_deg": _float(f["lon"], n),
            "height_m": _float(f["alt"], n),
            "vel_e_mps": ve,
            "vel_n_mps": vn,
            "speed_mps": np.where(np.isfinite(ve), np.nan, speed),
            "h_acc_m": _float(f["accuracy"], n),
            "v_acc_m": _float(f["v_acc"], n),
            "vel_acc_mps": _float(f["speed_acc"], n),
            "fix_type": np.full(n, FixType.UNKNOWN, dtype=np.int8),
            "spoofing_flag": np.where(
                mock == 1, SpoofingFlag.INDICATED, np.where(mock == 0, SpoofingFlag.CLEAR, SpoofingFlag.UNKNOWN)
            ).astype(np.int8),
        }
    )
    # a UNIX time in ms from 1970 to 2100: anything else is a damaged field, not a time (and would wrap
    # around int64 once in nanoseconds)
    bad_time = has_time & ((time_ms <= 0) | (time_ms >= MAX_UNIX_MS))
    if (~others & bad_time).any():
        skipped.append(Skipped("Fix/GPS", "UnixTimeMillis outside 1970 .. 2100", int((~others & bad_time).sum())))
    has_time &= ~bad_time
    keep = ~others & has_time
    if (~others & ~has_time & ~bad_time).any():
        skipped.append(Skipped("Fix/GPS", "fix without a time", int((~others & ~has_time & ~bad_time).sum()), "lost"))
    return out[keep].reset_index(drop=True)


def _sensor(rec: Records | None, value_cols: tuple[str, ...]) -> pd.DataFrame | None:
    if rec is None:
        return None
    df = rec.frame()
    n = len(df)
    elapsed, has_elapsed = _int64(_col(df, "elapsedRealtimeNanos"), n)
    utc, has_utc = _int64(_col(df, "utcTimeMillis"), n)
    has_utc &= (utc > 0) & (utc < MAX_UNIX_MS)  # else a damaged field, not a time
    has_elapsed &= (elapsed >= 0) & (elapsed < 10**17)  # three years of uptime
    out = pd.DataFrame({"elapsed_ns": elapsed, "utc_ms": utc, "has_elapsed": has_elapsed, "has_utc": has_utc})
    for i, c in enumerate(value_cols):
        out[f"v{i}"] = _float(_col(df, c), n)
    return out


def _orientation_quaternion(yaw_deg: FloatArray, roll_deg: FloatArray, pitch_deg: FloatArray) -> FloatArray:
    """getOrientation's azimuth/pitch/roll -> quaternion rotating device axes into ENU."""
    a, p, r = (np.radians(x) for x in (yaw_deg, pitch_deg, roll_deg))
    n = len(a)

    def rot(axis: int, ang: FloatArray) -> FloatArray:
        c, s = np.cos(ang), np.sin(ang)
        m = np.zeros((n, 3, 3))
        i, j = [(1, 2), (2, 0), (0, 1)][axis]
        m[:, axis, axis] = 1.0
        m[:, i, i], m[:, i, j], m[:, j, i], m[:, j, j] = c, -s, s, c
        return m

    R = rot(2, -a) @ rot(0, -p) @ rot(1, r)
    return np.asarray(matrix_to_quat(R), dtype=float)


def _truth_beside(
    path: Path, reference: str, frames: dict[str, pd.DataFrame], streams: list[StreamInfo], skipped: list[Skipped]
) -> None:
    """A dataset's ground-truth table shipped beside the log (GSDC's `ground_truth.csv`) as its truth."""
    from readers.gnss_tables import ground_truth_beside, read_ground_truth

    companion = ground_truth_beside(path)
    if companion is None:
        return
    try:
        truth = read_ground_truth(companion, reference)
    except ReaderError as err:
        skipped.append(Skipped(companion.name, f"ground truth not used: {err.problem}", 1))
        return
    if len(truth):
        frames["truth"] = truth
        streams.append(StreamInfo("truth", "truth", companion.name, "ground truth", len(truth)))


def read_gnsslogger(
    path: Path, topics: Mapping[str, str] | None = None, progress: Progress | None = None
) -> EpochTable:
    path = Path(path)
    skipped: list[Skipped] = []
    nav_records: list[NavRecord] = []
    records, meta = split_file(path, skipped, nav_records)
    if progress:
        progress(1, 3)
    frames: dict[str, pd.DataFrame] = {}
    streams: list[StreamInfo] = []
    raw_lines = records["Raw"].frame() if "Raw" in records else None
    raw = pseudoranges(raw_lines, skipped) if raw_lines is not None else None
    have_raw = raw is not None and len(raw.rows) > 0
    reference = "gps" if have_raw else "unix"

    def from_unix_ns(unix_ns: IntArray) -> IntArray:
        return gps_ns_of_unix_ns(unix_ns) if reference == "gps" else unix_ns

    fixes = gps_fixes(path, records, skipped)
    clock_offset, phone_ns = fix_clock(fixes) if fixes is not None else (None, np.zeros(0, np.int64))
    if clock_offset is not None and fixes is not None:
        good = int((fixes["elapsed_ns"] > 0).sum())
        meta["sensor_clock"] = f"elapsedRealtimeNanos + median offset to {good} GPS fixes' UnixTimeMillis"
        meta |= log_clock("elapsedRealtimeNanos, the phone's boot clock", True)
    if fixes is not None and len(fixes):
        # the fix's own (GNSS) time against the monotonic clock at which the phone made it
        elapsed = fixes["elapsed_ns"].to_numpy(np.int64)
        offset = time_offset_s(fixes["unix_ms"].to_numpy(np.int64) * 1_000_000, elapsed, elapsed > 0)
        fx = fixes.drop(columns=["unix_ms", "elapsed_ns"]).assign(t_ns=from_unix_ns(phone_ns), time_offset_s=offset)
        if raw is not None and len(raw.epochs):
            ep = raw.epochs.sort_values("t_ns")
            if "Agc" in records:
                rec = agc_epochs(records["Agc"].frame())
                ep = pd.merge_asof(ep, rec, on="t_ns", direction="nearest", tolerance=500_000_000)
                ep["agc"] = ep["agc"].fillna(ep.pop("agc_rec"))
            joined = pd.merge_asof(fx.sort_values("t_ns"), ep, on="t_ns", direction="nearest", tolerance=1_000_000_000)
            fx = joined.rename(columns={"cn0": "cn0_mean_dbhz", "agc": "agc"})
            meta["units.agc"] = "dB (Android AgcDb of the Raw or Agc records, mean over the L1 band)"
        frames["fixes"] = fx
        streams.append(StreamInfo("fix", RECEIVER, "Fix (GPS provider)", "gnsslogger/Fix", len(fx)))
    nav, ephemerides = None, None
    if have_raw and raw is not None:
        rows = raw.rows
        nav = navigation_for(path, topics, rows["t_ns"].to_numpy() / 1e9, skipped)
        ephemerides = (
            nav.ephemerides if nav is not None else _decoded_ephemerides(nav_records, raw_lines, rows, skipped)
        )
        reason = (
            "no navigation file covers the log (give one with --topic nav=FILE) and no GPS navigation message "
            "in its Nav records; no satellite states"
        )
        rows = add_satellite_states(rows, ephemerides, RECEIVER, skipped, reason)
        frames["observations"] = rows
        streams.append(StreamInfo("observations", RECEIVER, "Raw", "gnsslogger/Raw", int(rows["t_ns"].nunique())))
    sky = status_satellites(records["Status"].frame(), skipped) if "Status" in records else None
    if sky is not None:
        frames["satellites"] = sky.assign(t_ns=from_unix_ns(sky.pop("unix_ns").to_numpy()), receiver_id=RECEIVER)
        n_epochs = int(frames["satellites"]["t_ns"].nunique())
        streams.append(StreamInfo("satellites", RECEIVER, "Status", "gnsslogger/Status (GnssStatus)", n_epochs))
    if progress:
        progress(2, 3)
    imu = _imu(records, clock_offset, from_unix_ns, skipped, meta)
    if imu is not None:
        frames["imu"] = imu[0]
        streams.append(imu[1])
    if topics and set(topics) - {"nav"}:
        other = {k: v for k, v in topics.items() if k != "nav"}
        skipped.append(
            Skipped("<gnsslogger>", f"--topic ignored for GnssLogger logs except nav= ({other})", len(other))
        )
    if not frames:
        held = sorted(((name, len(r.rows)) for name, r in records.items() if len(r.rows)), key=lambda kv: -kv[1])
        if any(s.action == "lost" for s in skipped) or not held:
            raise ReaderError(path, "no Raw, Fix or sensor record could be read from this GnssLogger log")
        # sound: a phone stopped while still acquiring (no time of week decoded, so no pseudorange), indoors
        listed = ", ".join(f"{name} x{n}" for name, n in held)
        raise NothingToJudgeError(
            path, f"GnssLogger log with no usable fix, measurement or sensor ({listed})", None, skipped
        )
    _truth_beside(path, reference, frames, streams, skipped)
    meta["receiver"] = "phone: the GPS-provider fixes and the Raw measurements of one phone"
    table = build_table(path, "gnsslogger", reference, frames, streams, skipped, metadata=meta)
    if nav is not None:
        table.ephemerides = nav.ephemerides
        table.streams.append(nav_stream(nav, table.t0_ns))
    elif ephemerides is not None:
        table.ephemerides = ephemerides
        msgtype = "gnsslogger/Nav (GPS LNAV ephemerides)"
        table.streams.append(ephemeris_stream(ephemerides, RECEIVER, "Nav", msgtype, len(ephemerides), table.t0_ns))
    if progress:
        progress(3, 3)
    return table


def _raw_line_gps_s(raw_lines: pd.DataFrame) -> FloatArray:
    """GPS time (s) of the latest dated Raw line at or before each one: TimeNanos - (FullBiasNanos +
    BiasNanos), carried forward over lines without it."""
    n = len(raw_lines)
    time_nanos, has_time = _int64(_col(raw_lines, "TimeNanos"), n)
    full_bias, has_bias = _int64(_col(raw_lines, "FullBiasNanos"), n)
    ns = (time_nanos - full_bias) - np.nan_to_num(_float(_col(raw_lines, "BiasNanos"), n))
    gps_s = np.where(has_time & has_bias & (ns > 0), ns / 1e9, np.nan)
    return pd.Series(gps_s).ffill().to_numpy(dtype=float)


def _decoded_ephemerides(
    nav_records: list[NavRecord], raw_lines: pd.DataFrame, rows: pd.DataFrame, skipped: list[Skipped]
) -> GpsEphemerides | None:
    """GPS and Galileo ephemerides from the log's own Nav records (GPS L1 C/A subframes: ten 30-bit
    words, each in the low 30 bits of a big-endian 4-byte word; Galileo I/NAV pages, `InavDecoder`),
    with when each was received."""
    if not nav_records:
        return None
    ref_s = float(rows["t_ns"].min()) / 1e9
    line_s = _raw_line_gps_s(raw_lines)
    lnav, inav = LnavDecoder(), InavDecoder()
    other = 0
    for r in nav_records:
        before = line_s[r.raw_lines_before - 1] if r.raw_lines_before > 0 else math.nan
        now = float(before) if math.isfinite(before) else ref_s
        if r.type == GALILEO_INAV:
            inav.add_android(r.svid, r.data, now)
            continue
        if r.type != GPS_L1CA_NAV or len(r.data) != 40:
            other += 1
            continue
        words = [int.from_bytes(r.data[4 * k : 4 * k + 4], "big") for k in range(10)]
        lnav.add_words(r.svid, words, ref_s, now)
    if other:
        skipped.append(
            Skipped("Nav", "navigation messages of other signals (GPS L1 C/A and Galileo I/NAV are decoded)", other)
        )
    skipped.extend(lnav.dropped("Nav") + inav.dropped("Nav"))
    records = lnav.records() + inav.records()
    return GpsEphemerides.from_records(records, lnav.iono) if records else None


def _imu(
    records: dict[str, Records],
    clock_offset: int | None,
    from_unix_ns: Callable[[IntArray], IntArray],
    skipped: list[Skipped],
    meta: dict[str, str],
) -> tuple[pd.DataFrame, StreamInfo] | None:
    if "Accel" in records and "Gyro" in records:
        kind, acc_name, gyro_name = "calibrated", "Accel", "Gyro"
        acc_cols, gyro_cols = (
            ("AccelXMps2", "AccelYMps2", "AccelZMps2"),
            ("GyroXRadPerSec", "GyroYRadPerSec", "GyroZRadPerSec"),
        )
    elif "UncalAccel" in records and "UncalGyro" in records:
        kind, acc_name, gyro_name = "uncalibrated (biases left in)", "UncalAccel", "UncalGyro"
        acc_cols = ("UncalAccelXMps2", "UncalAccelYMps2", "UncalAccelZMps2")
        gyro_cols = ("UncalGyroXRadPerSec", "UncalGyroYRadPerSec", "UncalGyroZRadPerSec")
    else:
        for name in ("Accel", "Gyro", "UncalAccel", "UncalGyro"):
            if name in records:
                skipped.append(
                    Skipped(name, "accelerometer and gyro are both needed for an IMU stream", len(records[name].rows))
                )
        return None
    acc, gyro = _sensor(records[acc_name], acc_cols), _sensor(records[gyro_name], gyro_cols)
    assert acc is not None and gyro is not None

    def stamps(df: pd.DataFrame) -> IntArray:
        if clock_offset is not None and df["has_elapsed"].all():
            return df["elapsed_ns"].to_numpy(np.int64) + clock_offset
        return df["utc_ms"].to_numpy(np.int64) * 1_000_000

    if clock_offset is None:
        meta["sensor_clock"] = "utcTimeMillis of each sensor line (no GPS fix to tie elapsedRealtimeNanos to)"
    ta, tg = stamps(acc), stamps(gyro)
    order = np.argsort(tg, kind="stable")
    tg = tg[order]
    inside = (ta >= tg[0]) & (ta <= tg[-1]) if len(tg) else np.zeros(len(ta), dtype=bool)
    if (~inside).any():
        skipped.append(Skipped(acc_name, "accelerometer samples outside the gyro's time span", int((~inside).sum())))
    cols: dict[str, object] = {"imu_id": "phone_imu"}
    for i, axis in enumerate("xyz"):
        cols[f"a{axis}_mps2"] = acc[f"v{i}"].to_numpy()[inside]
        g = gyro[f"v{i}"].to_numpy()[order]
        cols[f"w{axis}_radps"] = np.interp(ta[inside].astype(float), tg.astype(float), g)
    t_unix = ta[inside]
    if "OrientationDeg" in records:
        o = _sensor(records["OrientationDeg"], ("yawDeg", "rollDeg", "pitchDeg"))
        assert o is not None
        to = stamps(o)
        q = _orientation_quaternion(o["v0"].to_numpy(), o["v1"].to_numpy(), o["v2"].to_numpy())
        k = np.clip(np.searchsorted(to, t_unix), 0, len(to) - 1)
        k = np.where((k > 0) & (np.abs(to[k - 1] - t_unix) < np.abs(to[k] - t_unix)), k - 1, k)
        near = np.abs(to[k] - t_unix) <= 500_000_000
        for j, c in enumerate(("qw", "qx", "qy", "qz")):
            cols[c] = np.where(near, q[k, j], np.nan)
    meta["imu"] = f"{acc_name} + {gyro_name} ({kind}); gyro interpolated to the accelerometer stamps"
    df = pd.DataFrame(cols)
    df["t_ns"] = from_unix_ns(t_unix)
    info = StreamInfo(
        "imu", "phone_imu", f"{acc_name}+{gyro_name}", "gnsslogger/sensors", len(df), body_frame="ANDROID"
    )
    return df, info


_RECORD_LINE = re.compile(rb"^(?:#\s*)?(Raw|Fix|UncalAccel|UncalGyro|Accel|Gyro|OrientationDeg|Agc|Status|Nav),", re.M)


def _is_gnsslogger(path: Path, head: bytes) -> bool:
    if path.is_dir() or b"\0" in head:
        return False
    return (
        b"Header Description" in head
        or len(_RECORD_LINE.findall(head)) >= 2
        or (head.lstrip().startswith(b"#") and bool(_RECORD_LINE.search(head)))
    )


FORMATS = (
    ReaderFormat(
        "gnsslogger",
        "Android GnssLogger text log (v1.4 and later: Raw, Fix, sensors)",
        read_gnsslogger,
        _is_gnsslogger,
        rewrite="spooflens.writers.gnsslogger_rewrite:rewrite_gnsslogger",
    ),
)
