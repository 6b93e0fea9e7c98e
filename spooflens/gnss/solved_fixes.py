"""Fixes solved from raw pseudoranges for the receivers that logged none of their own (a RINEX file holds
pseudoranges, not positions), with RAIM's fault detection and exclusion as a receiver would."""

from __future__ import annotations

import copy

import numpy as np
import pandas as pd

from spooflens.epoch_table import EpochTable, Skipped, StreamInfo
from spooflens.gnss.fault_exclusion import solve_with_fde
from spooflens.gnss.single_point import SV_COLUMNS, SinglePointOptions
from spooflens.schema import make_frame


def with_solved_fixes(table: EpochTable) -> EpochTable:
    """`table` plus fixes solved from the observations of every receiver that logged none of its own.

    A RINEX file, for one, holds pseudoranges and no positions; the analyses need positions. The
    addition is listed among the table's repairs so the user sees where the fixes came from.
    """
    obs = table.observations
    if not len(obs):
        return table
    have = set(table.receivers())
    need = [r for r in dict.fromkeys(obs["receiver_id"].astype(str)) if r not in have]
    if not need:
        return table
    rows = obs[obs["receiver_id"].astype(str).isin(need)]
    rows = rows[np.isfinite(rows[SV_COLUMNS].to_numpy(float)).all(axis=1)]
    if not len(rows):
        return table
    # a receiver excludes satellites that disagree with the others (RAIM FDE); so do the fixes solved here
    fde = solve_with_fde(
        rows, table.gps_seconds(rows["t_s"].to_numpy(float)), SinglePointOptions(iono=table.ionosphere)
    )
    sol = fde.solution
    solved = make_frame("fixes", sol.fixes_columns())
    out = copy.copy(table)
    flags = pd.Series(fde.flag, index=rows.index, dtype="int8")
    out.observations = table.observations.copy()
    out.observations.loc[flags.index, "fault_flag"] = flags
    out.fixes = pd.concat([table.fixes, solved], ignore_index=True) if len(table.fixes) else solved
    out.streams = [*table.streams]
    out.skipped = [*table.skipped]
    for rid in need:
        n = int((solved["receiver_id"] == rid).sum())
        epochs = int((sol.receiver_id == rid).sum())
        out.skipped.append(
            Skipped(
                rid, f"fixes solved from raw pseudoranges (single-point); {epochs - n} epochs unsolved", n, "computed"
            )
        )
        t = solved.loc[solved["receiver_id"] == rid, "t_s"].to_numpy()
        out.streams.append(
            StreamInfo(
                "fix",
                rid,
                rid,
                "single-point solution",
                n,
                float(t[0]) if n else float("nan"),
                float(t[-1]) if n else float("nan"),
                frame_id="computed",
            )
        )
    out.validate()
    return out
