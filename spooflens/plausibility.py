"""Physical plausibility of what a log says, checked where every reader hands its frames over.

In depth: docs/formats.md."""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.constants import STANDARD_GRAVITY

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
Columns = Mapping[str, np.ndarray]

# exact values loggers write for "no data"
SENTINELS = np.array([999.0, -999.0, 9999.0, -9999.0, 99999.0, -99999.0, 999999.0, -999999.0, 9.999e9])
# anything larger in magnitude is no measurement of anything spooflens reads
MAGNITUDE_LIMIT = 1e15
ACCEL_LIMIT_MPS2 = 2000.0  # 200 g: beyond any IMU's range
GYRO_LIMIT_RADPS = 200.0
GYRO_DEGREES_P99 = 35.0  # rad/s; vehicles stay far below (2000 deg/s is a consumer gyro's full scale)
HEIGHT_RANGE_M = (-2000.0, 100_000.0)
STRAY_GAP_NS = 3_600_000_000_000  # an hour without a sample of a stream
TURN_SPACING_M = 50.0  # GNSS course taken over this much track, well above position noise
PSEUDORANGE_RANGE_M = (1e6, 1e8)  # every GNSS orbit, with receiver clock offsets of milliseconds
SV_ID_PATTERN = r"[GRECJSI]\d{1,3}"
IMU_MOTION = ("ax_mps2", "ay_mps2", "az_mps2", "wx_radps", "wy_radps", "wz_radps")
QUATERNION = ("qw", "qx", "qy", "qz")
SV_STATE = (
    "sv_x_m",
    "sv_y_m",
    "sv_z_m",
    "sv_vx_mps",
    "sv_vy_mps",
    "sv_vz_mps",
    "sv_clock_bias_m",
    "sv_clock_drift_mps",
)


@dataclass(frozen=True)
class Finding:
    """One repair or loss in a stream: what, how many rows or values, and the action (as `Skipped`)."""

    reason: str
    count: int
    action: str


@dataclass(frozen=True)
class Scale:
    """Multiply `columns` of a stream by `factor` (a unit the check recognised)."""

    columns: tuple[str, ...]
    factor: float
    reason: str


# --- 1. units ---------------------------------------------------------------------------------------


def _finite_rows(cols: Columns, names: tuple[str, ...]) -> BoolArray:
    ok = np.isfinite(cols[names[0]])
    for n in names[1:]:  # column by column: no stacked copy of a day's columns
        ok &= np.isfinite(cols[n])
    return ok


def imu_unit(cols: Columns) -> tuple[list[Scale], str]:
    """Scales that put an IMU stream in m/s^2 and rad/s, or a reason it is in no unit we know ("")."""
    ok = _finite_rows(cols, IMU_MOTION)
    for n in IMU_MOTION:
        ok &= np.abs(cols[n]) < 1e7  # beyond any unit: bad_rows' business
    if not ok.any():
        return [], ""
    every = bool(ok.all())

    def at_ok(name: str) -> FloatArray:
        return cols[name] if every else cols[name][ok]

    f = np.sqrt(sum(np.square(at_ok(n)) for n in IMU_MOTION[:3]))
    g = float(np.median(f))
    scales = []
    if g < 6.0 or g > 14.0:
        unit = next(
            (
                (factor, what)
                for low, high, factor, what in (
                    (0.6, 1.4, STANDARD_GRAVITY, "g"),
                    (600.0, 1400.0, STANDARD_GRAVITY / 1000.0, "milli-g"),
                    (6000.0, 14000.0, 1e-3, "mm/s^2"),
                )
                if low <= g <= high
            ),
            None,
        )
        if unit is None:
            return [], (
                f"median specific force |f| = {g:.3g} m/s^2, not gravity's 9.8 (gravity removed, or an unknown "
                "unit): the IMU cannot be integrated and is left out"
            )
        scales.append(
            Scale(IMU_MOTION[:3], unit[0], f"specific force in {unit[1]} (median |f| = {g:.4g}): scaled to m/s^2")
        )
    w = np.sqrt(sum(np.square(at_ok(n)) for n in IMU_MOTION[3:]))
    p99 = float(np.percentile(w, 99))
    if p99 > GYRO_DEGREES_P99:
        scales.append(
            Scale(
                IMU_MOTION[3:],
                np.pi / 180.0,
                f"angular rate in deg/s (99th percentile |w| = {p99:.3g}): scaled to rad/s",
            )
        )
    return scales, ""


def _local_steps(lat: FloatArray, lon: FloatArray, t_s: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Horizontal distance (m, spherical Earth: only ratios matter here) and time between consecutive fixes."""
    lat_r, lon_r = np.radians(lat), np.radians(lon)
    dn = np.diff(lat_r) * 6.371e6
    de = np.diff(np.unwrap(lon_r)) * 6.371e6 * np.cos(lat_r[1:])
    return np.hypot(de, dn), np.diff(t_s)


def fix_units(cols: Columns, t_s: FloatArray) -> list[Scale]:
    """Scales that put a fix stream's latitude/longitude in degrees and height in metres."""
    lat, lon, h = cols["lat_deg"], cols["lon_deg"], cols["height_m"]
    ok = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(h) & ~((lat == 0) & (lon == 0)) & np.isfinite(t_s)
    ok &= (np.abs(lat) <= 90) & (np.abs(lon) <= 180) & (np.abs(h) < 1e9)  # garbage is bad_rows' business
    if ok.sum() < 10:
        return []
    lat, lon, h, t = lat[ok], lon[ok], h[ok], t_s[ok]
    scales = []
    dist, dt = _local_steps(lat, lon, t)
    step = dt > 0
    speed_pos = dist[step] / dt[step]
    ve, vn = cols.get("vel_e_mps"), cols.get("vel_n_mps")
    if (
        ve is not None
        and vn is not None
        and np.all(np.abs(lat) <= np.pi / 2)
        and np.all(np.abs(lon) <= np.pi)
        and len(speed_pos) >= 10
    ):
        speed = np.hypot(ve[ok], vn[ok])
        moving = np.isfinite(speed) & (speed > 1.0)
        if moving.sum() >= 10:
            ratio = float(np.median(speed_pos)) / float(np.median(speed[moving]))
            if 1 / 80 < ratio < 1 / 40:
                scales.append(
                    Scale(
                        ("lat_deg", "lon_deg"),
                        180.0 / np.pi,
                        f"latitude/longitude in radians (the track moves {ratio:.4f} times the reported speed): "
                        "scaled to degrees",
                    )
                )
    dh = np.abs(np.diff(h))[step] / dt[step]
    if len(dh) >= 10:
        climb = float(np.median(dh))
        level = float(np.median(np.abs(h)))
        horizontal = float(np.median(speed_pos)) if len(speed_pos) else 0.0
        if (climb > 50.0 and climb / 1000 < 50.0 and horizontal < 50.0) or (
            level > HEIGHT_RANGE_M[1] and level / 1000 < HEIGHT_RANGE_M[1] / 10
        ):
            scales.append(
                Scale(
                    ("height_m",),
                    1e-3,
                    f"height in millimetres (median {level:.4g}, consecutive fixes {climb:.3g} apart per second): "
                    "scaled to metres",
                )
            )
    return scales


def stray_stamps(t_ns: np.ndarray) -> BoolArray:
    """Rows (of a stream sorted by time) in a small group that an hour or more of silence separates from
    the rest: a corrupt stamp, not a recording. A log paused for hours keeps both of its parts, each far
    larger than the 0.1% (at least 3 rows) a stray group may hold. Where every group is that small there is
    no rest to stray from (a few sentences of sessions years apart): nothing is dropped."""
    t = np.asarray(t_ns, dtype=np.int64)
    out = np.zeros(len(t), dtype=bool)
    if len(t) < 4:
        return out
    gaps = np.flatnonzero(np.diff(t) > STRAY_GAP_NS)
    if not len(gaps):
        return out
    bounds = np.concatenate(([0], gaps + 1, [len(t)]))
    small = max(3, len(t) // 1000)
    groups = list(itertools.pairwise(bounds.tolist()))
    if all(b - a <= small for a, b in groups):
        return out
    for a, b in groups:
        if b - a <= small:
            out[a:b] = True
    return out


# --- 2. rows no sensor produces ---------------------------------------------------------------------


def _sentinel(x: FloatArray, tolerance: float) -> BoolArray:
    """Exact no-data values that stand far from the stream's own values."""
    hit = np.zeros(len(x), dtype=bool)
    for value in SENTINELS:  # one comparison each: np.isin would sort a copy of a long column
        hit |= x == value
    if not hit.any() or hit.all():
        return hit
    rest = x[~hit & np.isfinite(x)]
    if not len(rest):
        return hit
    return hit & (np.abs(x - np.median(rest)) > tolerance)


def bad_rows(frame: str, cols: Columns) -> list[tuple[BoolArray, str]]:
    """(mask, reason) of the rows to drop, in order; a row counts under the first reason that hits it."""
    out: list[tuple[BoolArray, str]] = []
    if frame in ("fixes", "truth"):
        lat, lon, h = cols["lat_deg"], cols["lon_deg"], cols["height_m"]
        far = np.abs(np.nanmedian(np.where(np.isfinite(lat), lat, np.nan))) > 1.0 if np.isfinite(lat).any() else False
        far_lon = (
            np.abs(np.nanmedian(np.where(np.isfinite(lon), lon, np.nan))) > 1.0 if np.isfinite(lon).any() else False
        )
        out += [
            (
                ~np.isfinite(lat) | ~np.isfinite(lon) | ~np.isfinite(h) | ((lat == 0) & (lon == 0)),
                "NaN or zero latitude/longitude/height (no fix)",
            ),
            ((np.abs(lat) > 90) | (np.abs(lon) > 180), "latitude/longitude out of range"),
            (
                ((lat == 0) & bool(far)) | ((lon == 0) & bool(far_lon)),
                "latitude or longitude exactly 0 far from the track (no fix)",
            ),
            ((h < HEIGHT_RANGE_M[0]) | (h > HEIGHT_RANGE_M[1]), "height outside -2 km .. 100 km"),
            (
                _sentinel(lat, 1.0) | _sentinel(lon, 1.0) | _sentinel(h, 100.0),
                "no-data sentinel (999, 9999, ...) as position",
            ),
        ]
    elif frame == "imu":
        motion = [cols[n] for n in IMU_MOTION]
        out.append((~np.all([np.isfinite(x) for x in motion], axis=0), "NaN specific force or angular rate"))
        accel = np.any([np.abs(x) > ACCEL_LIMIT_MPS2 for x in motion[:3]], axis=0)
        gyro = np.any([np.abs(x) > GYRO_LIMIT_RADPS for x in motion[3:]], axis=0)
        out.append((accel | gyro, "specific force above 200 g or angular rate above 200 rad/s (beyond any sensor)"))
        out.append(
            (np.any([_sentinel(x, 50.0) for x in motion], axis=0), "no-data sentinel (999, 9999, ...) as a sample")
        )
    elif frame == "observations":
        pr = cols["pseudorange_m"]
        out.append((~np.isfinite(pr), "NaN or infinite pseudorange"))
        out.append(
            ((pr < PSEUDORANGE_RANGE_M[0]) | (pr > PSEUDORANGE_RANGE_M[1]), "pseudorange outside 1,000 .. 100,000 km")
        )
        ids = pd.Series(cols["sv_id"], dtype="string")
        out.append((~ids.str.fullmatch(SV_ID_PATTERN).fillna(False).to_numpy(dtype=bool), "unreadable satellite id"))
    elif frame == "headings":
        hd = cols["heading_deg"]
        out.append((~np.isfinite(hd) | (hd < 0) | (hd > 360), "heading outside 0 .. 360 deg"))
    elif frame == "satellites":
        ids = pd.Series(cols["sv_id"], dtype="string")
        out.append((~ids.str.fullmatch(SV_ID_PATTERN).fillna(False).to_numpy(dtype=bool), "unreadable satellite id"))
    if frame in ("odometry", "autopilot_ekf", "truth", "fixes", "observations", "imu", "headings", "satellites"):
        big = np.zeros(len(next(iter(cols.values()))) if cols else 0, dtype=bool)
        for name, x in cols.items():
            if name in _REQUIRED.get(frame, ()) and x.dtype.kind == "f":
                big |= ~np.isfinite(x) | (np.abs(x) > MAGNITUDE_LIMIT)
        out.append((big, "non-finite or impossible value in a required column"))
    return out


def _required() -> dict[str, tuple[str, ...]]:
    from spooflens.schema import FRAMES

    return {f: tuple(c.name for c in spec if c.required and c.name != "t_s") for f, spec in FRAMES.items()}


_REQUIRED = _required()


# --- 3. optional values out of range ----------------------------------------------------------------

# frame -> (columns, low, high, what): a value outside [low, high] becomes NaN (the group together)
_OPTIONAL_BOUNDS: dict[str, tuple[tuple[tuple[str, ...], float, float, str], ...]] = {
    "fixes": (
        (("vel_e_mps", "vel_n_mps", "vel_u_mps"), -1e4, 1e4, "velocity above 10 km/s"),
        (("h_acc_m",), 1e-6, 1e7, "horizontal accuracy of 0, negative or above 10,000 km"),
        (("v_acc_m",), 1e-6, 1e7, "vertical accuracy of 0, negative or above 10,000 km"),
        (("vel_acc_mps",), 1e-6, 1e5, "speed accuracy of 0, negative or above 100 km/s"),
        (("sats_used",), 0.0, 1000.0, "satellites used outside 0 .. 1000"),
        (("hdop",), 0.0, 1e4, "HDOP outside 0 .. 10,000"),
        (("vdop",), 0.0, 1e4, "VDOP outside 0 .. 10,000"),
        (("cn0_mean_dbhz",), 0.0, 100.0, "mean C/N0 outside 0 .. 100 dB-Hz"),
    ),
    "satellites": ((("cn0_dbhz",), 0.0, 100.0, "C/N0 outside 0 .. 100 dB-Hz"),),
    "headings": ((("water_speed_mps",), 0.0, 50.0, "speed through the water outside 0 .. 50 m/s"),),
    "truth": ((("vel_e_mps", "vel_n_mps", "vel_u_mps"), -1e4, 1e4, "velocity above 10 km/s"),),
    "observations": (
        (("pseudorange_rate_mps",), -1e5, 1e5, "pseudorange rate above 100 km/s"),
        (("doppler_hz",), -1e6, 1e6, "Doppler above 1 MHz"),
        (("carrier_phase_cycles",), -1e13, 1e13, "carrier phase above 1e13 cycles"),
        (("carrier_freq_hz",), 1e8, 1e10, "carrier frequency outside 0.1 .. 10 GHz"),
        (("cn0_dbhz",), 0.0, 100.0, "C/N0 outside 0 .. 100 dB-Hz"),
        (("sv_vx_mps", "sv_vy_mps", "sv_vz_mps"), -2e4, 2e4, "satellite velocity above 20 km/s"),
        (("sv_clock_bias_m",), -1e7, 1e7, "satellite clock bias above 33 ms"),
        (("sv_clock_drift_mps",), -1e4, 1e4, "satellite clock drift above 10 km/s"),
    ),
}


# signal strengths written as C/N0 (RINEX 2's S observations are "as given by the receiver", in its own units)
_CN0_COLUMNS = {"observations": "cn0_dbhz", "satellites": "cn0_dbhz", "fixes": "cn0_mean_dbhz"}
_DBHZ_MIN_VALUES = 5  # fewer values say nothing of their units
_DBHZ_MAX_SHARE_ABOVE_100 = 0.1  # a rare corrupt value is cleared alone; a tenth is the column's units
_DBHZ_MIN_MEDIAN = 10.0  # no receiver tracks below ~10 dB-Hz: a median under it is a 1-9 strength scale


def not_dbhz(x: np.ndarray) -> str:
    """Why a stream's signal strengths are not C/N0 in dB-Hz ('' when they may be): a tenth of them above
    100 (a spacecraft receiver's raw counts: 359, 631 ...), or a median under 10 (RINEX 2's 1-9 scale)."""
    v = x[np.isfinite(x)]
    if len(v) < _DBHZ_MIN_VALUES:
        return ""
    above = int(np.sum(v > 100.0))
    if above >= _DBHZ_MAX_SHARE_ABOVE_100 * len(v):
        return f"signal strengths not in dB-Hz ({above} of {len(v)} above 100: the receiver's own units)"
    tracked = v[v > 0]
    if len(tracked) >= _DBHZ_MIN_VALUES and (median := float(np.median(tracked))) < _DBHZ_MIN_MEDIAN:
        return f"signal strengths not in dB-Hz (median {median:.1f}, below any C/N0 a receiver tracks: a 1-9 scale)"
    return ""


def clean_optional(frame: str, cols: Columns) -> list[tuple[tuple[str, ...], BoolArray, Finding]]:
    """Optional values out of range, to be set to NaN ("not known"): (columns, rows, finding) each."""
    out: list[tuple[tuple[str, ...], BoolArray, Finding]] = []
    cleared: dict[str, BoolArray] = {}  # a value counts under the first reason that clears it

    def clear(names: tuple[str, ...], bad: BoolArray, what: str) -> None:
        new = bad & ~np.any([cleared[n] for n in names if n in cleared], axis=0) if cleared else bad
        if np.any(new):
            out.append((names, new, Finding(f"{what}: set to NaN (not known)", int(np.sum(new)), "repaired")))
            for n in names:
                cleared[n] = cleared[n] | new if n in cleared else new

    cn0 = _CN0_COLUMNS.get(frame, "")
    if cn0 in cols and (units := not_dbhz(cols[cn0])):
        clear((cn0,), np.isfinite(cols[cn0]), units)
    for names, low, high, what in _OPTIONAL_BOUNDS.get(frame, ()):
        present = tuple(n for n in names if n in cols)
        if present:
            clear(
                present, np.any([(cols[n] < low) | (cols[n] > high) | np.isinf(cols[n]) for n in present], axis=0), what
            )
    if frame == "imu" and all(q in cols for q in QUATERNION):
        norm = np.sqrt(sum(cols[n] ** 2 for n in QUATERNION))  # no stacked copy of a day's four columns
        some = np.any([np.isfinite(cols[n]) for n in QUATERNION], axis=0)
        bad = (np.isfinite(norm) & (np.abs(norm - 1.0) > 0.1)) | (some & ~np.isfinite(norm))
        clear(QUATERNION, bad, "orientation quaternion not of unit length")
    if frame == "satellites" and "elevation_deg" in cols:
        # an elevation outside +/-90 deg is a receiver's "not known" (u-blox and gpsd write -91: "unknown if out
        # of range; azimuth unknown if elevation is out of range"), never a satellite below the horizon
        el = cols["elevation_deg"]
        clear(
            tuple(n for n in ("elevation_deg", "azimuth_deg") if n in cols),
            (el < -90) | (el > 90) | np.isinf(el),
            "elevation outside -90 .. 90 deg (the receiver's 'not known', e.g. u-blox/gpsd -91): elevation and azimuth",
        )
    if frame == "satellites" and "azimuth_deg" in cols:
        az = cols["azimuth_deg"]
        # 360 is north to receivers that write 0 .. 360; trigonometry reads it as 0
        clear(("azimuth_deg",), (az < 0) | (az > 360) | np.isinf(az), "azimuth outside 0 .. 360 deg")
    if frame == "observations" and all(n in cols for n in SV_STATE[:3]):
        with np.errstate(over="ignore"):  # 1e300 squared is inf, which is out of orbit all the same
            r = np.sqrt(sum(cols[n] ** 2 for n in SV_STATE[:3]))
        bad = (np.isfinite(r) & ((r < 6.4e6) | (r > 1e8))) | (
            np.any([np.isfinite(cols[n]) for n in SV_STATE[:3]], axis=0) & ~np.isfinite(r)
        )
        clear(tuple(n for n in SV_STATE if n in cols), bad, "satellite position not in an orbit: satellite state")
    for n, x in cols.items():
        if x.dtype.kind == "f" and n not in _REQUIRED.get(frame, ()) and n != "t_s":
            clear((n,), np.abs(x) > MAGNITUDE_LIMIT, f"{n} infinite or above 1e15")  # NaN: False
    return out


# --- cross-stream -----------------------------------------------------------------------------------


def gyro_turn_ratio(imu_t_s: FloatArray, imu: Columns, fix_t_s: FloatArray, fixes: Columns) -> float | None:
    """How many times the IMU's turn about the vertical exceeds the GNSS course's (1 for rad/s, 57.3 for
    deg/s read as rad/s); None when the vehicle did not turn enough to tell.

    The vertical is the mean specific force's direction in the body (gravity dominates it). The GNSS
    course comes from the reported velocity where the vehicle moves faster than 3 m/s, else from the
    track between points `TURN_SPACING_M` apart. Course and integrated gyro yaw are compared as levels
    (noise does not accumulate in the course, the turns do), by the geometric mean of the two regression
    slopes, which neither variable's noise shrinks.
    """
    ok = _finite_rows(imu, IMU_MOTION)
    if ok.sum() < 100 or len(fix_t_s) < 10:
        return None
    every = bool(ok.all())  # the usual case: no copy of the six columns
    t = imu_t_s if every else imu_t_s[ok]
    up = np.array([(imu[n] if every else imu[n][ok]).mean() for n in IMU_MOTION[:3]])
    if np.linalg.norm(up) == 0:
        return None
    up /= np.linalg.norm(up)
    yaw_rate = sum(u * (imu[n] if every else imu[n][ok]) for u, n in zip(up, IMU_MOTION[3:], strict=True))
    turned = np.concatenate(([0.0], np.cumsum(0.5 * (yaw_rate[1:] + yaw_rate[:-1]) * np.diff(t))))
    course_t = _gnss_course(fix_t_s, fixes, t[0], t[-1])
    if course_t is None:
        return None
    tc, course = course_t
    heading = np.unwrap(course)
    if np.ptp(heading) < np.radians(60.0):
        return None
    gyro = np.interp(tc, t, turned)
    h, g = heading - heading.mean(), gyro - gyro.mean()
    cov = float(np.sum(h * g))
    if cov == 0.0:
        return None
    return float(np.sqrt(np.sum(g * g) / np.sum(h * h)))


def _gnss_course(fix_t_s: FloatArray, fixes: Columns, start: float, end: float) -> tuple[FloatArray, FloatArray] | None:
    """(times, course clockwise from north) of a moving receiver, from its velocity or its track."""
    inside = np.isfinite(fix_t_s) & (fix_t_s >= start) & (fix_t_s <= end)
    ve, vn = fixes.get("vel_e_mps"), fixes.get("vel_n_mps")
    if ve is not None and vn is not None:
        moving = inside & (np.hypot(ve, vn) > 3.0)
        if moving.sum() >= 10:
            return fix_t_s[moving], np.arctan2(ve[moving], vn[moving])
    lat, lon = fixes["lat_deg"], fixes["lon_deg"]
    good = inside & np.isfinite(lat) & np.isfinite(lon)
    if good.sum() < 10:
        return None
    lat_r, tf = np.radians(lat[good]), fix_t_s[good]
    north = (lat_r - lat_r[0]) * 6.371e6
    east = (np.unwrap(np.radians(lon[good])) - np.radians(lon[good][0])) * 6.371e6 * np.cos(lat_r[0])
    travelled = np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(east), np.diff(north)))))
    marks = np.searchsorted(travelled, np.arange(0.0, travelled[-1], TURN_SPACING_M))
    if len(marks) < 10:
        return None
    e, n, tm = east[marks], north[marks], tf[marks]
    fast = TURN_SPACING_M / np.maximum(np.diff(tm), 1e-9) > 3.0
    if fast.sum() < 10:
        return None
    return (0.5 * (tm[1:] + tm[:-1]))[fast], np.arctan2(np.diff(e), np.diff(n))[fast]


def problems(frames: Mapping[str, pd.DataFrame]) -> list[str]:
    """What is still implausible in finished frames (the pipeline's last guard), one phrase each."""
    from spooflens.schema import STREAM_KEY

    out = []
    for frame, df in frames.items():
        if not len(df):
            continue
        key = STREAM_KEY[frame]  # stream ids are never judged; as numpy they are a Python string a row
        cols = {c: df[c].to_numpy() for c in df.columns if c not in ("t_s", key)}
        t = df["t_s"].to_numpy(dtype=float)
        if not np.all(np.isfinite(t)) or np.any(np.abs(t) > 1e10):
            out.append(f"{frame}: times not finite or beyond 300 years")
        hit = np.zeros(len(df), dtype=bool)
        for mask, reason in bad_rows(frame, cols):  # a row counts under the first reason, as readers list it
            new = mask & ~hit
            if new.any():
                out.append(f"{frame}: {int(new.sum())} rows with {reason}")
                hit |= mask
    return out
