"""DataFlash field names of every format revision since 2013, put on today's names.

A log carries its own FMT definitions, so every revision decodes; what changed is what the fields are
called and which clock they are on. Today's names (`TimeUS` boot time in microseconds; GPS `GWk` week
and `GMS` ms of week) are added beside the logged ones, so the readers ask for one set of names:

| revision (ArduPilot) | boot clock | GPS week / ms of week | GPS boot time |
|---|---|---|---|
| early 2013 (Copter 2.9) | none (IMU untimed) | - / `Time` | none: the receiver's time of week is the log's clock |
| 2013 (Copter 3.0, APM2) | `TimeMS` (ms) | `Week` / `TimeMS` | none: taken from the message logged before it |
| 2014-2015 (Copter 3.1-3.3, Plane 3.0-3.3) | `TimeMS` (ms) | `Week` / `TimeMS` | `T` (ms) |
| 2015 on (3.3+, 4.x) | `TimeUS` (us) | `GWk` / `GMS` | `TimeUS` |
| PX4 sdlog2 (2013-2017, `.px4log`) | `TIME.StartTime` (us) | from `GPSTime` (UTC us) | the `TIME` logged before it |

Before `TimeUS`, a GPS message's `TimeMS` is the GPS time of week, not the board's clock (ArduPilot's
`log_GPS.gps_week_ms`, with `apm_time` logged as `T`); every other message's `TimeMS` is boot time.

**PX4 sdlog2** (PX4's logger before ULog; src/modules/sdlog2/sdlog2_messages.h) writes the same container
with messages of its own. None carries a time: each logging loop writes `TIME` (`StartTime`, us since
boot) and then whatever is new, so `StartTime` is the `TimeUS` of `TIME` and every other message takes
that of the `TIME` logged before it (`DataFlash.board_time_before`). Its fields go on ArduPilot's names
(`with_todays_names(..., sdlog2=True)`): GPS `Lon` -> `Lng`, `Fix` (`FixType` in 2013) -> `Status` (the
same codes), `nSat` -> `NSats`, `EPH`/`EPV` -> `HAcc`/`VAcc` (m), `VelN`/`VelE` -> `Spd`/`GCrs`
(degrees), `VelD` -> `VZ`, `GPSTime` (UTC us since 1970, 0 before the receiver has the time) -> `GWk`/`GMS`
with the leap seconds of the day (0/0 without time); no DOP is logged (`HDop` NaN). IMU `GyroX..` ->
`GyrX..` (rad/s; `AccX..` m/s^2 as ArduPilot's). ATT `Roll/Pitch/Yaw` are radians in sdlog2, degrees
(ArduPilot's unit) under today's names.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spooflens.epoch_table import gps_ns_of_unix_ns

Columns = dict[str, NDArray]

# GPS messages: the receiver's time of week and week number under each revision's names
WEEK_NAMES = ("GWk", "Week")
WEEK_MS_NAMES = ("GMS", "TimeMS", "Time")


# today's name -> the names it had (PX4 sdlog2's GPS fields that hold the same value in the same unit)
LOGGED_NAMES = {
    "GWk": WEEK_NAMES,
    "GMS": WEEK_MS_NAMES,
    "Lng": ("Lng", "Lon"),
    "Status": ("Status", "Fix", "FixType"),
    "NSats": ("NSats", "nSat"),
    "VZ": ("VZ", "VelD"),
    "HAcc": ("HAcc", "EPH"),
    "VAcc": ("VAcc", "EPV"),
}
WEEK_NS = 604_800 * 1_000_000_000


def logged_name(fields: list[str], name: str) -> str:
    """What a message type whose FMT lists `fields` calls the field that is `name` today (a writer patching
    a 2014 GPS message writes its `Week`, not a `GWk` it does not have)."""
    return next((f for f in LOGGED_NAMES.get(name, (name,)) if f in fields), name)


def is_gps_message(cols: Columns) -> bool:
    """A receiver's fix message of any revision: position, fix status and a GPS week or time."""
    return {"Lat", "Lng", "Status"} <= cols.keys() and any(w in cols for w in (*WEEK_NAMES, "Time"))


def sdlog2_names(cols: Columns) -> Columns:
    """A PX4 sdlog2 message's columns with ArduPilot's names and units added (see the module's docstring)."""
    out = dict(cols)
    if "StartTime" in cols:  # TIME: the boot clock of the messages after it
        out["TimeUS"] = cols["StartTime"].astype(np.int64)
    if {"GPSTime", "Lat", "Lon"} <= cols.keys():
        n = len(cols["Lat"])
        for today, names in LOGGED_NAMES.items():
            logged = next((f for f in names if f in cols), None)
            if today not in out and logged is not None:
                out[today] = cols[logged]
        out.setdefault("NSats", np.full(n, np.nan))
        out["HDop"] = np.full(n, np.nan)  # sdlog2 logs accuracies (EPH/EPV), no DOP
        vn, ve = cols["VelN"].astype(np.float64), cols["VelE"].astype(np.float64)
        out["Spd"] = np.hypot(vn, ve)
        out["GCrs"] = np.degrees(np.arctan2(ve, vn)) % 360.0
        utc_us = cols["GPSTime"].astype(np.int64)
        has_time = utc_us > 0
        # UTC us since 1970 -> GPS ns since 1980-01-06 (leap seconds of the day added)
        gps_ns = np.where(has_time, gps_ns_of_unix_ns(np.where(has_time, utc_us, 0) * 1000), 0)
        out["GWk"] = np.where(has_time, gps_ns // WEEK_NS, 0).astype(np.int64)
        out["GMS"] = np.where(has_time, (gps_ns % WEEK_NS) // 1_000_000, 0).astype(np.int64)
    if {"GyroX", "GyroY", "GyroZ"} <= cols.keys():
        out |= {"GyrX": cols["GyroX"], "GyrY": cols["GyroY"], "GyrZ": cols["GyroZ"]}
    if {"Roll", "Pitch", "Yaw", "RollRate"} <= cols.keys():  # ATT: radians, ArduPilot's in degrees
        out |= {k: np.degrees(cols[k].astype(np.float64)) for k in ("Roll", "Pitch", "Yaw")}
    return out


def with_todays_names(cols: Columns, sdlog2: bool = False) -> tuple[Columns, bool]:
    """`cols` with `TimeUS` (boot, us) and for GPS messages `GWk`/`GMS` added under today's names where
    the revision logged them under others (`sdlog2`: a PX4 sdlog2 log's message). Returns the columns and
    whether the message has a boot time at all (a 2013 GPS message has none, nor any sdlog2 message but
    TIME; `DataFlash` then takes it from the message logged before it)."""
    out = sdlog2_names(cols) if sdlog2 else dict(cols)
    if is_gps_message(cols):
        if "GWk" not in out and "Week" in cols:
            out["GWk"] = cols["Week"]
        for ms_of_week in ("TimeMS", "Time"):
            if "GMS" not in out and ms_of_week in cols:
                out["GMS"] = cols[ms_of_week]
        if "TimeUS" not in out and "T" in cols:
            out["TimeUS"] = cols["T"].astype(np.int64) * 1000
        return out, "TimeUS" in out
    if "TimeUS" not in out and "TimeMS" in cols and cols["TimeMS"].dtype.kind in "iu":
        out["TimeUS"] = cols["TimeMS"].astype(np.int64) * 1000
    return out, "TimeUS" in out
