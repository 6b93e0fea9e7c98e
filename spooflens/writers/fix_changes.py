"""What an attack changed at each fix, as the binary rewriters write it back: its values before and after
(or lost), and how far it moved the receiver's own time (what a spoofed copy writes into the format's
time field: ArduPilot GWk/GMS, GnssLogger UnixTimeMillis, ROS TimeReference)."""

from __future__ import annotations

import math
from collections.abc import Sequence

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


def fix_changes(table: EpochTable, spoofed: EpochTable, columns: Sequence[str], by_order: bool = False) -> pd.DataFrame:
    """One row per fix of `table`: `receiver_id`, `t_s`, `t_ns` (on the log's clock), its `columns` as read
    (`<column>_0`) and as attacked (NaN where the attack lost it: `lost`), and `shift_s`, how far the attack
    moved the receiver's time. `by_order`: fixes of one receiver at one stamp are told apart by their order
    (`nth`), which the reader and the attack both keep."""
    key = ["receiver_id", "t_s"]
    before, after = (f[[*key, *columns]] for f in (table.fixes, spoofed.fixes))
    on = key
    if by_order:
        before, after = (f.assign(nth=f.groupby(key, sort=False).cumcount()) for f in (before, after))
        on = [*key, "nth"]
    change = before.merge(after, on=on, how="left", suffixes=("_0", ""), indicator=True)
    change["lost"] = (change.pop("_merge") == "left_only").to_numpy()
    change["t_ns"] = table.absolute_ns(change["t_s"].to_numpy())
    shifts = clock_shifts(table, spoofed.fixes)
    if by_order:
        shifts = shifts.drop_duplicates(["receiver_id", "t_ns"])
    change = change.merge(shifts, on=["receiver_id", "t_ns"], how="left")
    change["shift_s"] = change["shift_s"].fillna(0.0)
    return change


def moved(new: float, old: float) -> bool:
    """Whether the attack changed a value the log had (a value it lacked stays lacking)."""
    return math.isfinite(new) and math.isfinite(old) and new != old
