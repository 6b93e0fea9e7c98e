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

Before `TimeUS`, a GPS message's `TimeMS` is the GPS time of week, not the board's clock (ArduPilot's
`log_GPS.gps_week_ms`, with `apm_time` logged as `T`); every other message's `TimeMS` is boot time.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Columns = dict[str, NDArray]

# GPS messages: the receiver's time of week and week number under each revision's names
WEEK_NAMES = ("GWk", "Week")
WEEK_MS_NAMES = ("GMS", "TimeMS", "Time")


LOGGED_NAMES = {"GWk": WEEK_NAMES, "GMS": WEEK_MS_NAMES}  # today's name -> the names it had


def logged_name(fields: list[str], name: str) -> str:
    """What a message type whose FMT lists `fields` calls the field that is `name` today (a writer patching
    a 2014 GPS message writes its `Week`, not a `GWk` it does not have)."""
    return next((f for f in LOGGED_NAMES.get(name, (name,)) if f in fields), name)


def is_gps_message(cols: Columns) -> bool:
    """A receiver's fix message of any revision: position, fix status and a GPS week or time."""
    return {"Lat", "Lng", "Status"} <= cols.keys() and any(w in cols for w in (*WEEK_NAMES, "Time"))


def with_todays_names(cols: Columns) -> tuple[Columns, bool]:
    """`cols` with `TimeUS` (boot, us) and for GPS messages `GWk`/`GMS` added under today's names where
    the revision logged them under others. Returns the columns and whether the message has a boot time
    at all (a 2013 GPS message has none; `DataFlash` then takes it from the message logged before it)."""
    out = dict(cols)
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
