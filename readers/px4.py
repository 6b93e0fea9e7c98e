"""PX4 conventions shared by the ULog reader and the PX4 CSV dialect (`ulog2csv` exports).

PX4 writes one record per uORB message; a topic instance (`sensor_gps` multi_id 0, 1, ...) is a dict of
field name -> array here (pyulog's `Data.data`, or the columns of a CSV export), so both readers map a
record to epoch-table columns the same way. What this module knows about PX4:

- GPS topics. `sensor_gps` (PX4 >= 1.12) is one instance per receiver, straight from its driver; the
  `vehicle_gps_position` topic is the selected receiver or the blend of several (PX4 < 1.12: one
  instance per receiver). The default logger profile records `sensor_gps` at 1 Hz and
  `vehicle_gps_position` at the full rate, so `select_receivers` takes, for each receiver, whichever of
  the two holds more of that receiver's rows (matched by `device_id`, or `selected` in older logs) and
  never a blend.
- Field names and units across versions: `lat`/`lon` int 1e-7 deg and `alt`/`alt_ellipsoid` int mm
  (PX4 <= 1.14), `latitude_deg`/`longitude_deg`/`altitude_ellipsoid_m` float64 (PX4 >= 1.15), and the
  unit-free names of the SensorGnss rename (`latitude`, `noise`, `vel_north`, `speed_accuracy`, ...).
- The receiver's state enums, whose meaning changed: before the 2025 GNSS-integrity change (the
  definition has no `authentication_state`) spoofing_state is 0 unknown, 1 none, 2 indicated,
  3 multiple indications and jamming_state 0 unknown, 1 OK, 2 warning, 3 critical; after it (the
  definition has `authentication_state`) both are 0 unknown, 1 OK, 2 mitigated, 3 detected.
- `device_id` (bus type, bus, address and device type bit fields) and `ver_sw_release` (0xMMmmppTT).
- Attitude: `vehicle_attitude.q` rotates body FRD into NED; the epoch table wants body FLU into ENU.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from readers.svinfo_numbering import SVINFO_IDS, svinfo_sv_id
from spooflens.epoch_table import Skipped, StreamInfo, log_clock, time_offset_s
from spooflens.navigation.rotations import quat_from_rotvec, quat_multiply, quat_to_rotvec
from spooflens.schema import FixType, SpoofingFlag

FloatArray = NDArray[np.float64]
Record = dict[str, np.ndarray]

RAW_GPS_TOPICS = ("sensor_gps", "sensor_gnss")  # one instance per receiver, from its driver
SELECTED_GPS_TOPICS = ("vehicle_gps_position", "vehicle_gnss")  # selected receiver or blend
GPS_TOPICS = RAW_GPS_TOPICS + SELECTED_GPS_TOPICS
IMU_TOPIC = "sensor_combined"
ATTITUDE_TOPIC = "vehicle_attitude"
BARO_TOPIC = "vehicle_air_data"
SATELLITE_TOPIC = "satellite_info"  # per-satellite C/N0, logged when GPS_SAT_INFO is set
# EKF2's GNSS innovations (state minus measurement) and their test ratios, one instance per estimator:
# topic -> {field: autopilot_ekf column}; for the ratios, column -> the fields whose largest it is
INNOVATION_TOPICS: dict[str, dict[str, str]] = {
    "estimator_innovations": {  # PX4 >= 1.11
        "gps_hvel[0]": "vel_innov_n_mps",
        "gps_hvel[1]": "vel_innov_e_mps",
        "gps_vvel": "vel_innov_d_mps",
        "gps_hpos[0]": "pos_innov_n_m",
        "gps_hpos[1]": "pos_innov_e_m",
        "gps_vpos": "pos_innov_d_m",
    },
    "ekf2_innovations": {  # PX4 <= 1.10: velocity then position, NED
        **{f"vel_pos_innov[{i}]": f"vel_innov_{a}_mps" for i, a in enumerate("ned")},
        **{f"vel_pos_innov[{i + 3}]": f"pos_innov_{a}_m" for i, a in enumerate("ned")},
    },
}
RATIO_TOPICS: dict[str, dict[str, tuple[str, ...]]] = {
    "estimator_innovation_test_ratios": {  # PX4 >= 1.11, per axis
        "vel_test_ratio": ("gps_hvel[0]", "gps_hvel[1]"),
        "pos_test_ratio": ("gps_hpos[0]", "gps_hpos[1]"),
        "hgt_test_ratio": ("gps_vpos",),
    },
    "estimator_status": {  # every release (the only ratios before 1.11)
        "vel_test_ratio": ("vel_test_ratio",),
        "pos_test_ratio": ("pos_test_ratio",),
        "hgt_test_ratio": ("hgt_test_ratio",),
    },
}
EKF_TOPICS = (*INNOVATION_TOPICS, *RATIO_TOPICS)
EKF_MAX_DT_US = 200_000  # a test-ratio message belongs to the innovation message this close to it

# newer (SensorGnss rename) field names -> the SensorGps names this module reads
RENAMED_FIELDS = {
    "latitude": "latitude_deg",
    "longitude": "longitude_deg",
    "altitude_msl": "altitude_msl_m",
    "altitude_ellipsoid": "altitude_ellipsoid_m",
    "speed_accuracy": "s_variance_m_s",
    "course_accuracy": "c_variance_rad",
    "noise": "noise_per_ms",
    "ground_speed": "vel_m_s",
    "vel_north": "vel_n_m_s",
    "vel_east": "vel_e_m_s",
    "vel_down": "vel_d_m_s",
    "course": "cog_rad",
}

# PX4 fix_type: 0-1 no fix, 2 2D, 3 3D, 4 RTCM code differential (u-blox: any differential solution,
# SBAS included), 5 RTK float, 6 RTK fixed, 8 extrapolated (dead reckoning: not a GNSS measurement)
FIX_TYPES = {
    0: FixType.NO_FIX,
    1: FixType.NO_FIX,
    2: FixType.FIX_2D,
    3: FixType.FIX_3D,
    4: FixType.DGNSS,
    5: FixType.RTK_FLOAT,
    6: FixType.RTK_FIXED,
}
PX4_FIX_OF = {
    FixType.NO_FIX: 1,
    FixType.FIX_2D: 2,
    FixType.FIX_3D: 3,
    FixType.SBAS: 4,
    FixType.DGNSS: 4,
    FixType.RTK_FLOAT: 5,
    FixType.RTK_FIXED: 6,
    FixType.UNKNOWN: 8,
}

# device_id bit fields (PX4 Device.hpp): bus_type:3, bus:5, address:8, devtype:8
BUS_TYPES = {0: "unknown bus", 1: "I2C", 2: "SPI", 3: "DroneCAN", 4: "simulation", 5: "serial", 6: "MAVLink"}
# DRV_GPS_DEVTYPE_* of src/drivers/drv_sensor.h
GPS_DEVICE_TYPES = {
    0x85: "DroneCAN GNSS node",
    0xA0: "Ashtech",
    0xA1: "Emlid Reach",
    0xA2: "Femtomes",
    0xA3: "MTK",
    0xA4: "Septentrio (SBF)",
    0xA5: "u-blox",
    0xA6: "u-blox 6",
    0xA7: "u-blox 7",
    0xA8: "u-blox 8 (M8)",
    0xA9: "u-blox 9 (M9)",
    0xAA: "u-blox F9P",
    0xAB: "NMEA",
    0xAC: "u-blox 10",
    0xAD: "u-blox X20",
    0xAF: "simulated GPS",
}


# --- receiver state enums ---------------------------------------------------------------------------


@dataclass(frozen=True)
class StateEnums:
    """The meaning of spoofing_state / jamming_state codes in one SensorGps definition."""

    name: str
    spoofing: dict[int, str]
    jamming: dict[int, str]
    flag: dict[int, SpoofingFlag]  # spoofing_state code -> decoded spoofing_flag (else UNKNOWN)

    def describe(self, which: str) -> str:
        codes = self.spoofing if which == "spoofing_state" else self.jamming
        return f"{self.name}: " + ", ".join(f"{k} {v}" for k, v in codes.items())


LEGACY_STATES = StateEnums(
    "PX4 SensorGps without authentication_state (jamming_state since v1.12, spoofing_state since v1.14, "
    "until the 2025 GNSS-integrity change)",
    {0: "unknown", 1: "none", 2: "indicated", 3: "multiple indications"},
    {0: "unknown", 1: "OK", 2: "warning", 3: "critical"},
    {1: SpoofingFlag.CLEAR, 2: SpoofingFlag.INDICATED, 3: SpoofingFlag.INDICATED},
)
CURRENT_STATES = StateEnums(
    "PX4 SensorGps with authentication_state (the 2025 GNSS-integrity definition, MAVLink GNSS_INTEGRITY)",
    {0: "unknown", 1: "OK", 2: "mitigated", 3: "detected"},
    {0: "unknown", 1: "OK", 2: "mitigated", 3: "detected"},
    # mitigated means the receiver saw spoofing and countered it: still an indication
    {1: SpoofingFlag.CLEAR, 2: SpoofingFlag.INDICATED, 3: SpoofingFlag.INDICATED},
)
AUTHENTICATION_STATES = {0: "unknown", 1: "initializing", 2: "error", 3: "OK", 4: "disabled"}


def state_enums(fields: Collection[str]) -> StateEnums:
    """Which meaning the state codes have, from the fields of the message definition in the log."""
    return CURRENT_STATES if "authentication_state" in fields else LEGACY_STATES


def enum_metadata(fields: Collection[str], basis: str, firmware: str = "") -> dict[str, str]:
    """`enum.<column>` metadata saying which meaning was applied to each state column present, and why."""
    enums = state_enums(fields)
    why = f"chosen because authentication_state is {'present' if enums is CURRENT_STATES else 'absent'} in {basis}" + (
        f"; firmware {firmware}" if firmware else ""
    )
    out: dict[str, str] = {}
    for column in ("spoofing_state", "jamming_state"):
        if column in fields:
            out[f"enum.{column}"] = f"{enums.describe(column)}; {why}"
    if "spoofing_state" in fields:
        out["enum.spoofing_flag"] = (
            "decoded from spoofing_state: "
            + ", ".join(f"{k} -> {v.name}" for k, v in enums.flag.items())
            + ", any other code -> UNKNOWN"
        )
    if "authentication_state" in fields:
        out["enum.authentication_state"] = "PX4 SensorGps: " + ", ".join(
            f"{k} {v}" for k, v in AUTHENTICATION_STATES.items()
        )
    return out


def legacy_meaning(metadata: Mapping[str, str]) -> bool:
    """Whether a table's state codes carry the legacy meaning (a writer must then keep that definition)."""
    return any(
        metadata.get(f"enum.{c}", "").startswith(LEGACY_STATES.name) for c in ("spoofing_state", "jamming_state")
    )


# --- versions and devices ---------------------------------------------------------------------------


def release_name(ver_sw_release: int) -> str:
    """PX4 ver_sw_release 0xMMmmppTT as 'v1.14.0 (release)'; TT < 64 dev, < 128 alpha, < 192 beta, < 255 RC."""
    v = int(ver_sw_release)
    major, minor, patch, kind = (v >> 24) & 0xFF, (v >> 16) & 0xFF, (v >> 8) & 0xFF, v & 0xFF
    label = (
        "dev" if kind < 64 else "alpha" if kind < 128 else "beta" if kind < 192 else "RC" if kind < 255 else "release"
    )
    return f"v{major}.{minor}.{patch} ({label})"


def firmware_description(info: Mapping[str, object]) -> str:
    """One line from a ULog's info messages (sys_name, ver_sw_release, ver_sw, ver_sw_branch, ver_hw)."""
    parts: list[str] = []
    name = str(info.get("sys_name", "PX4") or "PX4")
    release = info.get("ver_sw_release")
    parts.append(f"{name} {release_name(int(release))}" if isinstance(release, int) and release else name)
    if info.get("ver_sw"):
        parts.append(f"git {info['ver_sw']}")
    if info.get("ver_sw_branch"):
        parts.append(f"branch {info['ver_sw_branch']}")
    if info.get("ver_hw"):
        parts.append(f"hardware {info['ver_hw']}")
    return ", ".join(parts)


def device_description(device_id: int) -> str:
    """A PX4 GPS device_id decoded: 'u-blox 8 (M8) on serial bus 2 (device_id 0xA80015)'."""
    d = int(device_id)
    if d == 0:
        return "device unknown (device_id 0)"
    bus_type, bus, address, devtype = d & 0x7, (d >> 3) & 0x1F, (d >> 8) & 0xFF, (d >> 16) & 0xFF
    what = GPS_DEVICE_TYPES.get(devtype, f"device type 0x{devtype:02X}")
    where = f"{BUS_TYPES.get(bus_type, f'bus type {bus_type}')} bus {bus}"
    if address:
        where += f" address 0x{address:02X}"
    return f"{what} on {where} (device_id 0x{d:X})"


# --- records ----------------------------------------------------------------------------------------


def canonical_record(rec: Mapping[str, np.ndarray]) -> Record:
    """Field names of any PX4 version as the SensorGps names (vehicle_gnss nests the receiver's sample)."""
    out: Record = {}
    for name, values in rec.items():
        key = name.removeprefix("receiver.")
        out[RENAMED_FIELDS.get(key, key)] = np.asarray(values)
    return out


def _f(rec: Mapping[str, np.ndarray], name: str) -> FloatArray | None:
    return rec[name].astype(float) if name in rec else None


@dataclass(frozen=True)
class PositionUnits:
    """Which fields hold position and their scale to degrees / metres, with the reason if it was a guess."""

    lat: tuple[str, float]
    lon: tuple[str, float]
    height: tuple[str, float]
    msl_fallback: tuple[str, float] | None  # MSL altitude, used where the ellipsoidal one is missing (0)
    notes: tuple[str, ...] = ()


def position_units(rec: Mapping[str, np.ndarray], by_magnitude: bool) -> PositionUnits | None:
    """Position fields and units; None if the record has no latitude/longitude/altitude.

    With `by_magnitude` False the definition fixes the units (ULog: `lat` is int32 1e-7 deg, `alt*` int32
    mm). With True (a CSV export, where a hand-made table may carry degrees and metres under PX4's names)
    they are decided from the values: |lat| > 90 or |lon| > 180 means 1e-7 deg; an altitude with fractional
    values is metres, integers beside 1e-7-degree positions are millimetres, else |median| > 20 km is mm.
    """
    notes: list[str] = []
    lat = next(((n, 1.0) for n in ("latitude_deg",) if n in rec), None)
    lon = next(((n, 1.0) for n in ("longitude_deg",) if n in rec), None)
    scaled_1e7 = False
    if lat is None or lon is None:
        if "lat" not in rec or "lon" not in rec:
            return None
        scale = 1e-7
        if by_magnitude:
            la, lo = np.abs(rec["lat"].astype(float)), np.abs(rec["lon"].astype(float))
            big = (np.nanmax(la, initial=0.0) > 90.0) or (np.nanmax(lo, initial=0.0) > 180.0)
            scale = 1e-7 if big else 1.0
            notes.append("lat/lon in 1e-7 deg (|lat| > 90)" if big else "lat/lon in degrees (|lat| <= 90)")
        lat, lon, scaled_1e7 = ("lat", scale), ("lon", scale), scale == 1e-7

    def height_field(name_m: str, name_mm: str) -> tuple[str, float, str] | None:
        """(field, scale to metres, why that unit) of an altitude, None if the record has neither."""
        if name_m in rec:
            return (name_m, 1.0, "")
        if name_mm not in rec:
            return None
        if not by_magnitude:
            return (name_mm, 1e-3, "")
        v = rec[name_mm].astype(float)
        v = v[np.isfinite(v) & (v != 0)]
        if len(v) and np.any(v != np.round(v)):
            return (name_mm, 1.0, f"{name_mm} in metres (fractional values)")
        if scaled_1e7:
            return (name_mm, 1e-3, f"{name_mm} in mm (integers beside 1e-7 deg positions)")
        median = abs(float(np.median(v))) if len(v) else 0.0
        if median > 20_000.0:
            return (name_mm, 1e-3, f"{name_mm} in mm (|median| {median:.0f} is not a plausible height in m)")
        return (name_mm, 1.0, f"{name_mm} in metres (integer values of plausible size)")

    ellipsoid = height_field("altitude_ellipsoid_m", "alt_ellipsoid")
    msl = height_field("altitude_msl_m", "alt")
    if ellipsoid is None and msl is None:
        return None
    if ellipsoid is None:
        assert msl is not None
        notes += [msl[2]] if msl[2] else []
        notes.append(f"no ellipsoidal altitude: height is {msl[0]} (above mean sea level, geoid not applied)")
        return PositionUnits(lat, lon, msl[:2], None, tuple(notes))
    notes += [ellipsoid[2]] if ellipsoid[2] else []
    # the MSL altitude's unit is said where it is used (gps_columns' repair note)
    return PositionUnits(lat, lon, ellipsoid[:2], msl[:2] if msl else None, tuple(notes))


def _codes(values: np.ndarray | None, table: Mapping[int, int], default: int, n: int) -> NDArray[np.int8]:
    out = np.full(n, default, dtype=np.int8)
    if values is not None:
        v = np.asarray(values, dtype=float)
        for code, mapped in table.items():
            out[v == code] = mapped
    return out


def _unavailable_as_nan(values: FloatArray | None, sentinel: str) -> FloatArray | None:
    """PX4's 'not available' values as NaN: negative noise / jamming indicator, AGC 65535."""
    if values is None:
        return None
    bad = values < 0 if sentinel == "negative" else values == 65535
    return np.where(bad, np.nan, values)


# what `time_offset_s` is against in a PX4 log (ULog or CSV export)
PX4_LOG_CLOCK = log_clock("the autopilot's boot clock (timestamp + timestamp_time_relative)", True)


def _time_offset(rec: Mapping[str, np.ndarray]) -> FloatArray:
    """The receiver's UTC (`time_utc_usec`, 0 = unknown) against the boot clock at the moment it refers
    to (`timestamp` + `timestamp_time_relative`, which the u-blox driver fills): `time_offset_s`."""
    utc = np.nan_to_num(np.asarray(rec["time_utc_usec"], dtype=float)).astype(np.int64)
    boot = np.asarray(rec["timestamp"]).astype(np.int64)
    if "timestamp_time_relative" in rec:
        boot = boot + np.nan_to_num(np.asarray(rec["timestamp_time_relative"], dtype=float)).astype(np.int64)
    return time_offset_s(utc * 1000, boot * 1000, utc > 0)


@dataclass
class GpsColumns:
    columns: dict[str, np.ndarray]
    notes: list[tuple[str, int]] = field(default_factory=list)  # (what was repaired or lost, rows)


def gps_columns(rec: Mapping[str, np.ndarray], units: PositionUnits) -> GpsColumns:
    """Schema `fixes` columns (without t_ns / receiver_id) of one canonical GPS record."""
    n = len(rec["timestamp"])
    lat = rec[units.lat[0]].astype(float) * units.lat[1]
    lon = rec[units.lon[0]].astype(float) * units.lon[1]
    h = rec[units.height[0]].astype(float) * units.height[1]
    notes: list[tuple[str, int]] = []
    if units.msl_fallback is not None:
        msl = rec[units.msl_fallback[0]].astype(float) * units.msl_fallback[1]
        missing = (h == 0) & (msl != 0) & np.isfinite(msl)
        if missing.any():
            h = np.where(missing, msl, h)
            notes.append(
                (
                    f"{units.height[0]} is 0 (the driver does not fill it): height from {units.msl_fallback[0]} "
                    f"({'mm' if units.msl_fallback[1] == 1e-3 else 'm'}) above mean sea level",
                    int(missing.sum()),
                )
            )
    cols: dict[str, np.ndarray] = {"lat_deg": lat, "lon_deg": lon, "height_m": h}
    vn, ve, vd = (_f(rec, f"vel_{a}_m_s") for a in "ned")
    if vn is not None and ve is not None:
        valid = rec["vel_ned_valid"].astype(float) != 0 if "vel_ned_valid" in rec else np.ones(n, bool)
        if (~valid).any():
            notes.append(("vel_ned_valid false: velocity left out", int((~valid).sum())))
        cols["vel_e_mps"] = np.where(valid, ve, np.nan)
        cols["vel_n_mps"] = np.where(valid, vn, np.nan)
        # east/north without down is kept: the up component alone is unknown
        cols["vel_u_mps"] = np.where(valid, -vd, np.nan) if vd is not None else np.full(n, np.nan)
    optional = {
        "h_acc_m": _f(rec, "eph"),
        "v_acc_m": _f(rec, "epv"),
        "vel_acc_mps": _f(rec, "s_variance_m_s"),
        "sats_used": _f(rec, "satellites_used"),
        "hdop": _f(rec, "hdop"),
        "vdop": _f(rec, "vdop"),
        "noise_per_ms": _unavailable_as_nan(_f(rec, "noise_per_ms"), "negative"),
        "jamming_indicator": _unavailable_as_nan(_f(rec, "jamming_indicator"), "negative"),
        "agc": _unavailable_as_nan(_f(rec, "automatic_gain_control"), "65535"),
        "jamming_state": _f(rec, "jamming_state"),
        "spoofing_state": _f(rec, "spoofing_state"),
        "authentication_state": _f(rec, "authentication_state"),
    }
    cols |= {k: v for k, v in optional.items() if v is not None}
    if "time_utc_usec" in rec:
        cols["time_offset_s"] = _time_offset(rec)
    fix = rec.get("fix_type")
    cols["fix_type"] = (
        _codes(fix, FIX_TYPES, FixType.UNKNOWN, n) if fix is not None else np.full(n, FixType.FIX_3D, dtype=np.int8)
    )
    if fix is not None and np.any(np.asarray(fix) == 8):
        notes.append(("fix_type 8 (extrapolated, dead reckoning) kept as fix type UNKNOWN", int(np.sum(fix == 8))))
    if "spoofing_state" in rec:
        enums = state_enums(rec)
        cols["spoofing_flag"] = _codes(rec["spoofing_state"], enums.flag, SpoofingFlag.UNKNOWN, n)
    return GpsColumns(cols, notes)


# --- which topic instance is which receiver ----------------------------------------------------------


@dataclass(frozen=True)
class GpsSource:
    """The rows of one receiver: a topic instance, or the rows of the selected topic that came from it."""

    receiver_id: str
    topic: str
    multi_id: int
    rows: NDArray[np.bool_]
    description: str


def dominant_device_id(ids: np.ndarray) -> int:
    """The device_id most rows carry (0 if none)."""
    ids = np.asarray(ids).astype(np.int64)
    if not len(ids):
        return 0
    values, counts = np.unique(ids, return_counts=True)
    return int(values[np.argmax(counts)])


def receiver_metadata(sources: list[tuple[GpsSource, Mapping[str, np.ndarray]]]) -> dict[str, str]:
    """`receiver` (each receiver's device decoded) and `px4.device_id.<receiver>` where device_id is known."""
    out: dict[str, str] = {}
    described = []
    for s, rec in sources:
        if "device_id" not in rec:
            continue
        dev = dominant_device_id(np.nan_to_num(np.asarray(rec["device_id"], dtype=float)[s.rows]))
        if dev:
            described.append(f"{s.receiver_id}: {device_description(dev)}")
            out[f"px4.device_id.{s.receiver_id}"] = str(dev)
    if described:
        out["receiver"] = "; ".join(described)
    return out


def _device_ids(rec: Mapping[str, np.ndarray]) -> np.ndarray | None:
    return np.asarray(rec["device_id"]).astype(np.int64) if "device_id" in rec else None


def select_receivers(records: Mapping[tuple[str, int], Record]) -> tuple[list[GpsSource], list[Skipped]]:
    """Each receiver once, from the topic instance that logged most of its rows; blends never.

    `records` maps (topic, multi_id) to a canonical record. A raw topic instance (`sensor_gps` k) is
    receiver k. The selected topic's rows belong to receiver k when their device_id is k's (or `selected`
    is k, in logs without device_id); a lone raw instance owns them all if neither field exists. Rows of
    a blend (device_id 0 beside several receivers, or `selected` 3) are skipped. Without any raw topic,
    each instance of the selected topic is a receiver (PX4 < 1.12 published one per receiver).
    """
    skipped: list[Skipped] = []
    raw_topic = next((t for t in RAW_GPS_TOPICS if any(k[0] == t for k in records)), None)
    sel_topic = next((t for t in SELECTED_GPS_TOPICS if any(k[0] == t for k in records)), None)
    if raw_topic is None:
        if sel_topic is None:
            return [], []
        out = []
        for (topic, m), rec in sorted(records.items()):
            if topic != sel_topic:
                continue
            rows = np.ones(len(rec["timestamp"]), dtype=bool)
            what = f"px4/{topic} (no raw sensor_gps in the log: the selected/blended output, instance {m})"
            out.append(GpsSource(f"{topic}/{m}", topic, m, rows, what))
        return out, skipped
    raws = sorted((m, rec) for (t, m), rec in records.items() if t == raw_topic)
    sel = records.get((sel_topic, 0)) if sel_topic else None
    taken = np.zeros(len(sel["timestamp"]), dtype=bool) if sel is not None else None
    out = []
    for m, rec in raws:
        own = np.ones(len(rec["timestamp"]), dtype=bool)
        choice = GpsSource(f"{raw_topic}/{m}", raw_topic, m, own, f"px4/{raw_topic} (raw receiver, instance {m})")
        if sel is not None and sel_topic is not None and taken is not None:
            mine = _rows_of_receiver(sel, rec, m, len(raws))
            if mine is not None and mine.sum() > own.sum():
                taken |= mine
                skipped.append(
                    Skipped(
                        f"{raw_topic}/{m}",
                        f"not read: this receiver's {int(mine.sum())} rows in {sel_topic} were read instead",
                        int(own.sum()),
                    )
                )
                choice = GpsSource(
                    f"{raw_topic}/{m}",
                    sel_topic,
                    0,
                    mine,
                    f"px4/{sel_topic} rows of this receiver ({int(mine.sum())} against {int(own.sum())} in "
                    f"{raw_topic} {m}, which the logger records at a lower rate)",
                )
        out.append(choice)
    if sel is not None and sel_topic is not None and taken is not None and (~taken).any():
        used = [s for s in out if s.topic == sel_topic]
        reason = (
            f"selected/blended output of the receivers; {raw_topic} instances read instead"
            if not used
            else "rows not read: a blend of the receivers, or a receiver read from its own instance"
        )
        skipped.append(Skipped(sel_topic, reason, int((~taken).sum())))
    return out, skipped


def _rows_of_receiver(sel: Record, raw: Record, m: int, n_receivers: int) -> NDArray[np.bool_] | None:
    ids, raw_ids = _device_ids(sel), _device_ids(raw)
    if ids is not None and raw_ids is not None and np.any(raw_ids != 0):
        return ids == dominant_device_id(raw_ids[raw_ids != 0])
    if "selected" in sel:
        return np.asarray(sel["selected"]).astype(int) == m
    if n_receivers == 1:
        return np.ones(len(sel["timestamp"]), dtype=bool)
    return None


# --- clock ------------------------------------------------------------------------------------------


def utc_offset_us(records: list[Mapping[str, np.ndarray]]) -> int | None:
    """Median of time_utc_usec - timestamp over the GPS rows with a UTC time, or None without any."""
    diffs = []
    for rec in records:
        if "time_utc_usec" not in rec:
            continue
        utc = np.asarray(rec["time_utc_usec"]).astype(np.int64)
        ts = np.asarray(rec["timestamp"]).astype(np.int64)
        ok = utc > 0
        diffs.append(utc[ok] - ts[ok])
    alld = np.concatenate(diffs) if diffs else np.array([], dtype=np.int64)
    return int(np.median(alld)) if len(alld) else None


# --- attitude ---------------------------------------------------------------------------------------

_H = np.sqrt(0.5)
Q_ENU_NED = np.array([0.0, _H, _H, 0.0])  # pi about (x + y)/sqrt(2): swaps x/y, flips z
Q_FRD_FLU = np.array([0.0, 1.0, 0.0, 0.0])  # pi about x: flips y and z


def ned_frd_to_enu_flu(q_ned_frd: FloatArray) -> FloatArray:
    """PX4 attitude (w, x, y, z), body FRD -> NED, as body FLU -> ENU (the epoch table's convention)."""
    q = quat_multiply(quat_multiply(Q_ENU_NED, np.asarray(q_ned_frd, dtype=float)), Q_FRD_FLU)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0, -q, q)


def enu_flu_to_ned_frd(q_enu_flu: FloatArray) -> FloatArray:
    """The inverse of `ned_frd_to_enu_flu` (both constant rotations are half turns: their own inverses)."""
    q = quat_multiply(quat_multiply(Q_ENU_NED, np.asarray(q_enu_flu, dtype=float)), Q_FRD_FLU)
    return np.where(q[..., :1] < 0, -q, q)


def interpolate_attitude(t: np.ndarray, t_att: np.ndarray, q_att: FloatArray, max_gap: float) -> FloatArray:
    """Quaternions at times `t` by slerp between the attitude samples around each; NaN outside the samples'
    span or across a gap longer than `max_gap` (same units as the times)."""
    out = np.full((len(t), 4), np.nan)
    ok_att = np.isfinite(q_att).all(axis=1) & (np.linalg.norm(q_att, axis=1) > 0)
    t_att, q_att = np.asarray(t_att)[ok_att], q_att[ok_att]
    if len(t_att) == 0:
        return out
    order = np.argsort(t_att, kind="stable")
    t_att, q_att = t_att[order], q_att[order] / np.linalg.norm(q_att[order], axis=1, keepdims=True)
    if len(t_att) == 1:
        near = np.abs(t - t_att[0]) <= max_gap / 2
        out[near] = q_att[0]
        return out
    i = np.clip(np.searchsorted(t_att, t, side="right") - 1, 0, len(t_att) - 2)
    t0, t1 = t_att[i], t_att[i + 1]
    # a time on a sample takes it, even beside a gap
    inside = (t >= t_att[0]) & (t <= t_att[-1]) & (((t1 - t0) <= max_gap) | (t == t0) | (t == t1))
    q0, q1 = q_att[i], q_att[i + 1]
    q1 = np.where(np.sum(q0 * q1, axis=1, keepdims=True) < 0, -q1, q1)  # the short way round
    span = np.where(t1 > t0, (t1 - t0).astype(float), 1.0)
    u = np.clip((t - t0).astype(float) / span, 0.0, 1.0)
    delta = quat_to_rotvec(quat_multiply(q0 * np.array([1.0, -1.0, -1.0, -1.0]), q1))
    q = quat_multiply(q0, quat_from_rotvec(delta * u[:, None]))
    out[inside] = q[inside]
    return out


# --- satellite_info: C/N0 per fix, and every satellite ---------------------------------------------


# u-blox NAV-SVINFO numbering, which PX4's u-blox driver writes into satellite_info.svid
_svinfo_sv_id = svinfo_sv_id
_SVINFO_IDS = SVINFO_IDS


def satellites_frame(
    rec: Mapping[str, np.ndarray], rid: str, topic: str, offset_us: int, skipped: list[Skipped]
) -> tuple[pd.DataFrame, StreamInfo] | None:
    """satellite_info as receiver `rid`'s per-satellite report (`satellite_rows`), stamped in absolute
    ns on the fixes' clock (boot µs + `offset_us`)."""
    rows = satellite_rows(rec, skipped, topic)
    if rows is None:
        return None
    t_us = rows.pop("timestamp").to_numpy()
    df = pd.DataFrame({"t_ns": (t_us + offset_us) * 1000, "receiver_id": rid} | dict(rows.items()))
    epochs = len(np.unique(t_us))
    return df, StreamInfo("satellites", rid, topic, f"px4/{SATELLITE_TOPIC} (per satellite)", epochs)


def satellite_rows(rec: Mapping[str, np.ndarray], skipped: list[Skipped], stream: str) -> pd.DataFrame | None:
    """One row per satellite and satellite_info message: `timestamp` (µs, the message's), sv_id and the
    satellites-frame columns. None when the record has no per-satellite arrays.

    PX4 packs what the receiver reports into uint8 arrays: `svid` in u-blox's NAV-SVINFO numbering (older
    drivers wrote the raw per-constellation svId, so two satellites can share a number in one message:
    those are left out, counted, as their identity is unknown), `snr` = C/N0 in dB-Hz (0: not tracked),
    `elevation` in degrees with negatives wrapped (the driver casts a signed value; -91 is u-blox's
    "unknown"), `azimuth` scaled 0-255 for 0-360 deg, `used` 0/1. Health and residual are not carried.
    """
    n_max = sum(1 for k in rec if k.startswith("svid["))
    if not n_max or any(f"{name}[{i}]" not in rec for name in ("svid", "snr") for i in range(n_max)):
        return None

    def matrix(name: str) -> NDArray[np.float64]:
        """The (messages, n_max) array of one field; NaN where a layout does not carry it."""
        if any(f"{name}[{i}]" not in rec for i in range(n_max)):
            return np.full((len(rec["timestamp"]), n_max), np.nan)
        return np.stack([np.asarray(rec[f"{name}[{i}]"]).astype(np.float64) for i in range(n_max)], axis=1)

    svid, snr = matrix("svid"), matrix("snr")
    count = np.asarray(rec["count"]).astype(np.int64) if "count" in rec else np.full(len(svid), n_max)
    slot = np.arange(n_max)[None, :] < np.clip(count, 0, n_max)[:, None]
    valid = slot & (svid > 0) & (svid < 256)
    ids = np.where(valid, _SVINFO_IDS[np.clip(np.nan_to_num(svid), 0, 255).astype(np.int64)], "")
    known = valid & (ids != "")
    # a number twice in one message: a numbering that collides across constellations
    msg, slot_of = np.nonzero(known)
    twins = pd.DataFrame({"msg": msg, "svid": svid[msg, slot_of]}).duplicated(keep=False).to_numpy()
    repeated = np.zeros_like(known)
    repeated[msg[twins], slot_of[twins]] = True
    if repeated.any():
        reason = "satellites sharing an svid in one message (identity unknown)"
        skipped.append(Skipped(stream, reason, int(repeated.sum())))
    keep = known & ~repeated
    if not keep.any():
        return None
    elev = matrix("elevation")
    elev = np.where(elev > 127, elev - 256, elev)  # the driver's uint8 cast of a signed angle
    elev = np.where((elev >= -90) & (elev <= 90), elev, np.nan)
    row, col = np.nonzero(keep)
    cn0, used = snr[row, col], matrix("used")[row, col]
    return pd.DataFrame(
        {
            "timestamp": np.asarray(rec["timestamp"]).astype(np.int64)[row],
            "sv_id": ids[row, col].astype(str),
            "cn0_dbhz": np.where(cn0 > 0, cn0, np.nan),
            "elevation_deg": elev[row, col],
            "azimuth_deg": matrix("azimuth")[row, col] * (360.0 / 255.0),
            "used": np.where(np.isfinite(used), used > 0, np.nan),
            "residual_m": np.nan,
            "healthy": np.nan,
        }
    )


def cn0_mean(rec: Mapping[str, np.ndarray]) -> FloatArray | None:
    """Mean C/N0 (dB-Hz) of the satellites tracked (snr > 0) in each satellite_info message.

    PX4's satellite_info carries up to 40 satellites: `count` valid entries of `snr[i]` (u-blox cno,
    dB-Hz). None when the record has no snr fields.
    """
    snr_cols = sorted((int(k[4:-1]), k) for k in rec if k.startswith("snr[") and k.endswith("]"))
    if not snr_cols:
        return None
    snr = np.stack([rec[k].astype(float) for _, k in snr_cols], axis=1)
    count = rec["count"].astype(float) if "count" in rec else np.full(len(snr), snr.shape[1])
    valid = (np.arange(snr.shape[1])[None, :] < count[:, None]) & (snr > 0)
    total = np.where(valid, snr, 0.0).sum(axis=1)
    n = valid.sum(axis=1)
    return np.where(n > 0, total / np.maximum(n, 1), np.nan)


def nearest_values(t: np.ndarray, t_src: np.ndarray, values: FloatArray, max_dt: float) -> FloatArray:
    """values[j] of the source sample nearest each time in `t`, NaN if none within `max_dt`."""
    out = np.full(len(t), np.nan)
    if not len(t_src):
        return out
    order = np.argsort(t_src, kind="stable")
    ts, vs = np.asarray(t_src)[order], values[order]
    i = np.clip(np.searchsorted(ts, t), 1, max(len(ts) - 1, 1)) if len(ts) > 1 else np.zeros(len(t), dtype=int)
    left = np.maximum(i - 1, 0)
    j = np.where(np.abs(t - ts[left]) <= np.abs(ts[i] - t), left, i)
    ok = np.abs(ts[j] - t) <= max_dt
    out[ok] = vs[j[ok]]
    return out


def _has_rows(rec: Mapping[str, np.ndarray]) -> bool:
    return "timestamp" in rec and len(rec["timestamp"]) > 0


def autopilot_ekf_frame(
    records: Mapping[tuple[str, int], Mapping[str, np.ndarray]], offset_us: int
) -> tuple[pd.DataFrame, list[StreamInfo]] | None:
    """EKF2's GNSS innovations and test ratios, per estimator instance, as the `autopilot_ekf` frame
    (source 'EKF2 instance k'), stamped in absolute ns on the fixes' clock (boot µs + `offset_us`). The
    ratios come from the first of `RATIO_TOPICS` the instance logged, nearest each innovation message."""
    frames, streams = [], []
    for (topic, k), innov in sorted(records.items()):
        fields = INNOVATION_TOPICS.get(topic)
        if fields is None or not _has_rows(innov):
            continue
        ts = np.asarray(innov["timestamp"]).astype(np.int64)
        order = np.argsort(ts, kind="stable")
        ts = ts[order]
        cols: dict[str, object] = {"t_ns": (ts + offset_us) * 1000, "source": f"EKF2 instance {k}"}
        for field_name, column in fields.items():
            if field_name in innov:
                cols[column] = np.asarray(innov[field_name], dtype=float)[order]
        described = f"px4/{topic}"
        for ratio_topic, ratio_fields in RATIO_TOPICS.items():
            ratios = records.get((ratio_topic, k))
            if ratios is None or not _has_rows(ratios):
                continue
            t_ratio = np.asarray(ratios["timestamp"]).astype(np.int64)
            for column, names in ratio_fields.items():
                present = [np.asarray(ratios[n], dtype=float) for n in names if n in ratios]
                if present:
                    cols[column] = nearest_values(ts, t_ratio, np.max(np.stack(present), axis=0), EKF_MAX_DT_US)
            described += f" + {ratio_topic}"
            break
        if len(cols) > 2:
            frames.append(pd.DataFrame(cols))
            streams.append(StreamInfo("autopilot_ekf", f"EKF2 instance {k}", topic, described, len(ts)))
    if not frames:
        return None
    return pd.concat(frames, ignore_index=True), streams
