"""Ground truth kept beside a log (`LOG.truth.csv`, as `spooflens simulate` and the sample logs write it).

A log is what the vehicle recorded and the truth is what an investigator rarely has, so the truth of a
simulated or surveyed run lives in a file of its own. When it is there, it joins the table's `truth`
frame (unless the log has a truth topic of its own) so the recording draws it in blue and the report
beside the reported and reconstructed tracks. No analysis reads the truth: it is only drawn.

Time, as in a spooflens CSV log: `t_s` seconds since the log start (a `# t0_ns: <int>` header comment
gives its absolute start in the log's clock), or `unix_time_s` / `gps_time_s`.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pandas as pd

from readers.csv_text import header_comments, parse_t0_ns, read_rows
from spooflens.epoch_table import (
    EpochTable,
    Skipped,
    StreamInfo,
    gps_seconds_of_unix_ns,
    unix_ns_of_gps_seconds,
)
from spooflens.errors import ReaderError
from spooflens.schema import TRUTH_COLUMNS, make_frame

SUFFIX = ".truth.csv"
_ALIASES = {"lat": "lat_deg", "latitude": "lat_deg", "lon": "lon_deg", "longitude": "lon_deg", "height": "height_m"}


def truth_path(log: Path) -> Path:
    """Where a log's truth file would be: the log's name (file or directory) with `.truth.csv` added."""
    return Path(str(log).rstrip("/") + SUFFIX)


def _table_seconds(table: EpochTable, df: pd.DataFrame, meta: dict[str, str], path: Path) -> np.ndarray:
    """The truth file's times on the table's time base (seconds since the log start)."""
    if "t_s" in df.columns:
        t = df["t_s"].to_numpy(dtype=float)
        if "t0_ns" in meta:
            return t + (parse_t0_ns(path, meta["t0_ns"], "truth") - table.t0_ns) / 1e9
        return t
    for col, clock in (("unix_time_s", "unix"), ("gps_time_s", "gps")):
        if col not in df.columns:
            continue
        ns = np.round(df[col].to_numpy(dtype=float) * 1e9).astype(np.int64)
        if table.time_reference == clock:
            return (ns - table.t0_ns) / 1e9
        if {clock, table.time_reference} == {"unix", "gps"}:
            converted = (
                np.round(gps_seconds_of_unix_ns(ns) * 1e9).astype(np.int64)
                if clock == "unix"
                else unix_ns_of_gps_seconds(ns / 1e9)
            )
            return (converted - table.t0_ns) / 1e9
        raise ReaderError(path, f"{col} cannot be placed on a log whose clock is {table.time_reference!r}", "truth")
    raise ReaderError(path, "no time column: expected t_s, unix_time_s or gps_time_s", "truth")


def read_truth(path: Path, table: EpochTable) -> pd.DataFrame:
    """A truth CSV as the table's `truth` frame (schema `truth`); raises ReaderError naming the problem."""
    meta = header_comments(path)
    df = read_rows(path, [], stream="truth")
    df.columns = [_ALIASES.get(str(c).strip().lower(), str(c).strip().lower()) for c in df.columns]
    df = df.loc[:, ~df.columns.duplicated()]
    missing = [c for c in ("lat_deg", "lon_deg", "height_m") if c not in df.columns]
    if missing:
        raise ReaderError(path, f"truth CSV lacks columns {missing}", "truth")
    t = _table_seconds(table, df, meta, path)
    known = {c.name for c in TRUTH_COLUMNS}
    cols: dict[str, object] = {c: df[c].to_numpy(dtype=float) for c in df.columns if c in known and c != "t_s"}
    cols["t_s"] = t
    frame = make_frame("truth", cols, len(df))
    good = np.isfinite(frame[["t_s", "lat_deg", "lon_deg", "height_m"]].to_numpy(dtype=float)).all(axis=1)
    return frame[good].sort_values("t_s", kind="stable").reset_index(drop=True)


def with_truth_beside(table: EpochTable, log: Path) -> EpochTable:
    """The table with the truth file beside `log` in its truth frame, if there is one and the log has none.

    A truth file that cannot be read is listed among the skipped (the analysis does not need it).
    """
    path = truth_path(log)
    if len(table.truth) or not path.is_file():
        return table
    out = copy.copy(table)
    out.skipped = [*table.skipped]
    try:
        truth = read_truth(path, table)
    except ReaderError as err:
        out.skipped.append(Skipped(path.name, f"truth file not used: {err.problem}", 1))
        return out
    out.truth = truth
    t = truth["t_s"].to_numpy()
    out.streams = [
        *table.streams,
        StreamInfo(
            "truth",
            "truth",
            path.name,
            "truth CSV beside the log",
            len(truth),
            float(t[0]) if len(t) else float("nan"),
            float(t[-1]) if len(t) else float("nan"),
        ),
    ]
    return out
