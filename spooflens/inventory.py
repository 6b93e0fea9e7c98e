"""What a log holds, worded once for every front end (`inspect`, the console summary, the HTML report).

A stream's count is in what the stream is made of: messages for a topic, epochs (one per receiver
time, with the satellite observations in it) for raw observations, records for a navigation file
(which has no rate: its span is that of its records' times of ephemeris). Reader notes are split by
what happened: rows skipped or repaired are losses or fixes of the input; fixes *computed* from raw
observations are an addition, listed apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from spooflens.epoch_table import HOLDS, EpochTable, Skipped, StreamInfo
from spooflens.schema import FIX_COLUMNS, SpoofingFlag

COMPUTED = "computed"


@dataclass(frozen=True)
class StreamRow:
    role: str
    stream: str
    source: str  # topic, file, or what it was computed from
    type: str
    count: str  # with its unit
    rate: str  # Hz, "-" when the stream has none
    span: str  # seconds since the log start, "first to last"
    body_frame: str


def format_rate(hz: float) -> str:
    if not math.isfinite(hz) or hz <= 0:
        return "-"
    if hz >= 0.995:
        return f"{hz:.2f}"
    return f"{hz:.3g} (1 per {1 / hz:.3g} s)"


def format_span(first_s: float, last_s: float) -> str:
    if not (math.isfinite(first_s) and math.isfinite(last_s)):
        return "-"
    return f"{first_s:.1f} to {last_s:.1f}"


def _count(table: EpochTable, s: StreamInfo) -> str:
    if s.role == "observations":
        obs = table.observations
        rows = int((obs["receiver_id"].astype(str) == s.stream_id).sum()) if len(obs) else 0
        return f"{s.count} epochs ({rows} observations)"
    if s.role == "satellites":
        sats = table.satellites
        rows = sats[sats["receiver_id"].astype(str) == s.stream_id] if len(sats) else sats
        return f"{s.count} epochs ({rows['sv_id'].nunique() if len(rows) else 0} satellites)"
    if s.role == "nav":
        return f"{s.count} records"
    return f"{s.count} messages" if s.frame_id != COMPUTED else f"{s.count} fixes"


def _rate(s: StreamInfo) -> str:
    if s.role == "nav":  # broadcast records are issued per satellite every few hours, not a rate
        return "-"
    return format_rate(s.rate_hz)


def _span(s: StreamInfo) -> str:
    span = format_span(s.first_s, s.last_s)
    return f"toe {span}" if s.role == "nav" and span != "-" else span


def stream_rows(table: EpochTable) -> list[StreamRow]:
    rows = []
    for s in table.streams:
        source = "computed" if s.frame_id == COMPUTED else s.topic  # type says how: "single-point solution"
        rows.append(
            StreamRow(s.role, s.stream_id, source, s.msgtype, _count(table, s), _rate(s), _span(s), s.body_frame or "")
        )
    return rows


def has_gnss(table: EpochTable) -> bool:
    """Whether the log holds anything a GNSS detector reads: fixes, raw observations, satellite reports or
    a receiver's monitor messages (its jamming state, AGC, noise)."""
    return bool(len(table.fixes) or len(table.observations) or len(table.satellites) or len(table.receiver_status))


def fixless_receivers(table: EpochTable) -> list[str]:
    """Each receiver that reported epochs but never a fix, with what became of its epochs (a receiver that
    saw no satellite all log long: indoors, cold, its antenna off, or jammed; the log cannot tell which)."""
    never = {s.stream_id for s in table.streams if s.role == "fix" and not s.count}
    return [
        f"receiver {s.stream} never had a fix: {s.count} {s.reason}"
        for s in table.skipped
        if s.stream in never and s.action != "lost" and s.count
    ]


def without_gnss(table: EpochTable) -> str:
    """Why a log without GNSS data has nothing to judge, in what it holds instead ('' for a log with GNSS
    data, and for one that holds no data at all: that is an empty log, refused)."""
    if has_gnss(table):
        return ""
    fixless = fixless_receivers(table)
    held = [f"{s.role} {s.topic} ({s.count})" for s in table.streams if s.count]
    holds = [table.metadata[HOLDS]] if HOLDS in table.metadata else []
    if not fixless and not held and not holds:
        return ""
    return "no GNSS data to judge: " + "; ".join(
        fixless + holds + ([f"the log holds {', '.join(held)}"] if held else [])
    )


def skipped_or_repaired(table: EpochTable) -> list[Skipped]:
    return [s for s in table.skipped if s.action != COMPUTED]


def computed(table: EpochTable) -> list[Skipped]:
    return [s for s in table.skipped if s.action == COMPUTED]


# fixes columns that are not receiver quality (time, identity, position, velocity): every other column the
# schema declares is what the receiver says about itself, drawn when the log has it, so a receiver-evidence
# column added to the schema appears in the recording and the report by itself
_NOT_QUALITY = {"t_s", "receiver_id", "lat_deg", "lon_deg", "height_m", "vel_e_mps", "vel_n_mps", "vel_u_mps"}


def quality_columns(fixes: pd.DataFrame) -> list[tuple[str, str]]:
    """(column, label with unit) of the receiver-quality columns this receiver's fixes actually hold."""
    out = []
    for col in FIX_COLUMNS:
        if col.name in _NOT_QUALITY or col.name not in fixes.columns:
            continue
        v = fixes[col.name].to_numpy(dtype=float)
        if not np.isfinite(v).any():
            continue
        if col.name == "spoofing_flag" and np.all(v == SpoofingFlag.UNKNOWN):
            continue  # the log has no spoofing flag
        if col.name == "fix_type" and np.nanmin(v) == np.nanmax(v):
            continue  # one fix type throughout says nothing over time
        unit = "" if col.unit in ("-", "FixType", "SpoofingFlag") else f" ({col.unit})"
        out.append((col.name, col.description.split(", NaN")[0].split(" (")[0] + unit))
    return out
