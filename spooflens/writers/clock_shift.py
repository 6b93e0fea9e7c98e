"""How far an attack moved the receiver's own time at each fix: what a spoofed copy writes into the
format's time field (ArduPilot GWk/GMS, GnssLogger UnixTimeMillis, ROS TimeReference)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from spooflens.epoch_table import EpochTable


def clock_shifts(table: EpochTable, spoofed_fixes: pd.DataFrame) -> pd.DataFrame:
    """One row per fix the attack kept: `receiver_id`, `t_ns` (the fix on the log's clock) and `shift_s`,
    the spoofed `time_offset_s` minus the original (0 where either is unknown)."""
    key = ["receiver_id", "t_s"]
    moved = table.fixes[[*key, "time_offset_s"]].merge(
        spoofed_fixes[[*key, "time_offset_s"]], on=key, suffixes=("_0", "")
    )
    return pd.DataFrame(
        {
            "receiver_id": moved["receiver_id"].to_numpy(),
            "t_ns": table.absolute_ns(moved["t_s"].to_numpy()),
            "shift_s": np.nan_to_num(moved["time_offset_s"].to_numpy(float) - moved["time_offset_s_0"].to_numpy(float)),
        }
    )
