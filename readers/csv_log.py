"""spooflens CSV logs: RINEX-like per-satellite observations, fixes, IMU samples and truth as text.

A CSV log is one `.csv` file or a directory of them. Each file's columns say which frame it fills:
a satellite column (`sv_id`, `sv`, `prn`, ...) makes it observations, else latitude makes it fixes
(or truth, for a file named `truth*.csv`), else accelerometer columns make it IMU. One row per epoch
(and receiver, and satellite for observations). Several receivers share a file through the receiver
column. Column names are the epoch-table schema names (`spooflens schema`), and common spellings are
accepted too (`ALIASES`).

Time, in seconds, from the first of these columns present:
- `t_s` (aliases `t`, `time_s`, `time`): seconds since the log start; the absolute start may be given
  in a header comment `# t0_ns: <int>` with `# time_reference: unix|gps`;
- `gps_time_s` (aliases `gps_time`, `gpst`, `tow_abs_s`): GPS seconds since 1980-01-06;
- `unix_time_s` (aliases `unix_time`, `utc_s`, `timestamp`): UNIX seconds.
Header comments `# key: value` before the header row may also declare `body_frame: FLU|FRD|RFU`
for IMU files (default FLU), and `# metadata <key>: <value>` lines carry the table's metadata (the
firmware, the meaning applied to each logged enum). Tables with PX4's own field names (ulog2csv
exports) are the PX4 dialect, read by `readers.px4_csv`. Satellite ids may be RINEX style (G05) or
bare PRN numbers (taken as GPS).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from readers import ReaderFormat, px4_csv
from spooflens.epoch_table import EpochTable, Skipped, StreamInfo, build_table
from spooflens.errors import ReaderError
from spooflens.schema import BODY_FRAMES, FRAMES, FixType

Progress = Callable[[int, int], None]

ALIASES: dict[str, tuple[str, ...]] = {
    "t_s": ("t", "time_s", "time"),
    "gps_time_s": ("gps_time", "gpst", "tow_abs_s"),
    "unix_time_s": ("unix_time", "utc_s", "timestamp"),
    "receiver_id": ("receiver", "rx", "station", "rx_id"),
    "imu_id": ("imu",),
    "sv_id": ("sv", "prn", "svid", "sat", "satellite"),
    "pseudorange_m": ("pseudorange", "pr", "pr_m", "raw_pr_m", "c1"),
    "pseudorange_rate_mps": ("pseudorange_rate", "prr", "prr_mps", "range_rate"),
    "doppler_hz": ("doppler", "d1"),
    "carrier_phase_cycles": ("carrier_phase", "phase", "l1", "accumulated_delta_range_cycles"),
    "carrier_freq_hz": ("carrier_frequency_hz", "freq_hz"),
    "cn0_dbhz": ("cn0", "snr", "cno", "s1", "cn0_db_hz"),
    "sv_x_m": ("x_sv_m", "sv_x", "sat_x"),
    "sv_y_m": ("y_sv_m", "sv_y", "sat_y"),
    "sv_z_m": ("z_sv_m", "sv_z", "sat_z"),
    "sv_vx_mps": ("vx_sv_mps", "sv_vx"),
    "sv_vy_mps": ("vy_sv_mps", "sv_vy"),
    "sv_vz_mps": ("vz_sv_mps", "sv_vz"),
    "sv_clock_bias_m": ("b_sv_m", "sv_clock_bias"),
    "sv_clock_drift_mps": ("b_dot_sv_mps", "sv_clock_drift"),
    "lat_deg": ("lat", "latitude", "lat_rx_deg"),
    "lon_deg": ("lon", "lng", "longitude", "lon_rx_deg"),
    "height_m": ("height", "alt", "altitude", "alt_m", "h", "alt_rx_m"),
    "vel_e_mps": ("ve", "vel_e", "v_east", "ve_mps"),
    "vel_n_mps": ("vn", "vel_n", "v_north", "vn_mps"),
    "vel_u_mps": ("vu", "vel_u", "v_up", "vu_mps"),
    "h_acc_m": ("hacc", "h_acc", "eph", "horizontal_accuracy_m"),
    "v_acc_m": ("vacc", "v_acc", "epv", "vertical_accuracy_m"),
    "vel_acc_mps": ("sacc", "speed_acc", "speed_accuracy_mps", "s_variance_m_s"),
    "sats_used": ("sats", "num_sats", "nsat", "satellites_used"),
    "fix_type": ("fix",),
    "spoofing_flag": ("spoofing", "spoofed_flag"),
    "jamming_indicator": ("jamming",),
    "ax_mps2": ("ax", "acc_x", "accel_x"),
    "ay_mps2": ("ay", "acc_y", "accel_y"),
    "az_mps2": ("az", "acc_z", "accel_z"),
    "wx_radps": ("wx", "gyro_x", "gx"),
    "wy_radps": ("wy", "gyro_y", "gy"),
    "wz_radps": ("wz", "gyro_z", "gz"),
    "roll_rad": ("roll",),
    "pitch_rad": ("pitch",),
    "yaw_rad": ("yaw", "heading_rad"),
}
METADATA_PREFIX = "metadata "
_TIME_COLUMNS = {"t_s": "relative", "gps_time_s": "gps", "unix_time_s": "unix"}


def _canonical(name: str) -> str:
    key = re.sub(r"[^a-z0-9_]", "_", name.strip().lower())
    for canon, aliases in ALIASES.items():
        if key == canon or key in aliases:
            return canon
    return key


def _header_comments(path: Path) -> dict[str, str]:
    meta: dict[str, str] = {}
    with path.open(encoding="utf-8", errors="replace") as f:
        for line in f:
            if not line.startswith("#"):
                break
            key, sep, value = line[1:].partition(":")
            if sep:
                meta[key.strip().lower()] = value.strip()
    return meta


def _frame_of(path: Path, columns: set[str]) -> str:
    if "sv_id" in columns:
        return "observations"
    if "lat_deg" in columns:
        return "truth" if path.stem.lower().startswith("truth") else "fixes"
    if "ax_mps2" in columns:
        return "imu"
    raise ReaderError(
        path,
        f"cannot tell what this CSV holds: no satellite, latitude or accelerometer column (columns: {sorted(columns)})",
    )


def _sv_ids(values: pd.Series) -> pd.Series:
    s = values.astype(str).str.strip().str.upper()
    numeric = s.str.fullmatch(r"\d+")
    return s.where(~numeric, "G" + s.str.zfill(2))


def _read_one(path: Path, skipped: list[Skipped]) -> tuple[str, pd.DataFrame, str, int | None, dict[str, str]]:
    meta = _header_comments(path)
    try:
        df = pd.read_csv(path, comment="#", skipinitialspace=True, on_bad_lines="skip")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, ValueError) as err:
        raise ReaderError(path, f"not a readable CSV: {err}") from err
    if df.empty:
        raise ReaderError(path, "CSV has a header but no rows")
    df.columns = [_canonical(c) for c in df.columns]
    df = df.loc[:, ~pd.Index(df.columns).duplicated()]
    frame = _frame_of(path, set(df.columns))
    time_col = next((c for c in _TIME_COLUMNS if c in df.columns), None)
    if time_col is None:
        raise ReaderError(path, f"no time column; expected one of {list(_TIME_COLUMNS)} (or their aliases)", frame)
    t = pd.to_numeric(df[time_col], errors="coerce").to_numpy(dtype=float)
    bad_t = ~np.isfinite(t)
    if bad_t.any():
        skipped.append(Skipped(f"{path.name}", "rows with a missing or non-numeric time", int(bad_t.sum())))
        df, t = df[~bad_t].reset_index(drop=True), t[~bad_t]
    reference = _TIME_COLUMNS[time_col]
    t0: int | None = None
    if reference == "relative":
        reference = meta.get("time_reference", "relative")
        t0 = int(meta["t0_ns"]) if "t0_ns" in meta else 0
        t_ns = t0 + np.round(t * 1e9).astype(np.int64)
    else:
        t_ns = np.round(t * 1e9).astype(np.int64)
    spec = {c.name: c for c in FRAMES[frame]}
    cols: dict[str, object] = {"t_ns": t_ns}
    ignored = [c for c in df.columns if c not in spec and c not in _TIME_COLUMNS]
    if ignored:
        skipped.append(Skipped(path.name, f"unknown columns ignored: {ignored}", len(ignored)))
    for name, col in spec.items():
        if name == "t_s":
            continue
        if name in df.columns:
            if col.dtype == "string":
                cols[name] = _sv_ids(df[name]) if name == "sv_id" else df[name].astype(str).str.strip()
            elif col.dtype == "int8":
                default = FixType.FIX_3D if name == "fix_type" else 2
                cols[name] = pd.to_numeric(df[name], errors="coerce").fillna(default).astype(np.int8)
            else:
                cols[name] = pd.to_numeric(df[name], errors="coerce").to_numpy(dtype=float)
    key = {"fixes": "receiver_id", "observations": "receiver_id", "imu": "imu_id"}.get(frame)
    if key and key not in cols:
        cols[key] = path.stem if frame == "imu" else "rx0"
    if frame == "fixes" and "fix_type" not in cols:
        cols["fix_type"] = np.full(len(df), FixType.FIX_3D, dtype=np.int8)
    missing = [c.name for c in FRAMES[frame] if c.required and c.name != "t_s" and c.name not in cols]
    if missing:
        raise ReaderError(path, f"{frame} CSV lacks required columns {missing}", frame)
    return frame, pd.DataFrame(cols), reference, t0, meta


def read_csv(path: Path, topics: Mapping[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    path = Path(path)
    files = sorted(path.glob("*.csv")) if path.is_dir() else [path]
    skipped: list[Skipped] = []
    frames: dict[str, list[pd.DataFrame]] = {}
    references, t0s, streams = set(), set(), []
    metadata: dict[str, str] = {}
    px4_files, files = px4_csv.split(files)
    if px4_files:
        part = px4_csv.read_px4(px4_files, skipped)
        for name, df in part.frames.items():
            frames.setdefault(name, []).append(df)
        references.add(part.reference)
        streams += part.streams
        metadata |= part.metadata
    body_frame = "FLU"
    for i, f in enumerate(files):
        frame, df, reference, t0, meta = _read_one(f, skipped)
        # provenance a writer kept: `# metadata <key>: <value>` (firmware, the meaning of enum codes)
        metadata |= {k.removeprefix(METADATA_PREFIX): v for k, v in meta.items() if k.startswith(METADATA_PREFIX)}
        if meta.get("body_frame", "FLU").upper() in BODY_FRAMES:
            body_frame = meta.get("body_frame", "FLU").upper()
        frames.setdefault(frame, []).append(df)
        references.add(reference)
        if t0 is not None:
            t0s.add(t0)
        key = {"fixes": "receiver_id", "observations": "receiver_id", "imu": "imu_id"}.get(frame)
        role = {"fixes": "fix", "observations": "observations", "imu": "imu", "truth": "truth"}[frame]
        ids = list(dict.fromkeys(df[key].astype(str))) if key else ["truth"]
        for sid in ids:
            n = int((df[key].astype(str) == sid).sum()) if key else len(df)
            streams.append(
                StreamInfo(role, sid, f.name, f"csv/{frame}", n, body_frame=body_frame if frame == "imu" else None)
            )
        if progress:
            progress(i + 1, len(files))
    if len(references) > 1:
        raise ReaderError(path, f"files use different clocks {sorted(references)}; use one time column kind")
    reference = references.pop() if references else "relative"
    t0 = min(t0s) if t0s and reference != "relative" else None
    merged = {k: pd.concat(v, ignore_index=True) for k, v in frames.items()}
    if topics:
        skipped.append(Skipped("<csv>", f"--topic ignored for CSV logs ({dict(topics)})", len(topics)))
    return build_table(path, "csv", reference, merged, streams, skipped, t0_ns=t0, metadata=metadata)


def _is_csv(path: Path, head: bytes) -> bool:
    if path.is_dir():
        return any(path.glob("*.csv"))
    text = head.decode("utf-8", errors="replace")
    return "\ufffd" not in text and "," in text and text.lstrip().startswith(("#", *"abcdefghijklmnopqrstuvwxyz"))


FORMATS = (
    ReaderFormat(
        "csv",
        "spooflens CSV log (a .csv file or a directory of them)",
        read_csv,
        _is_csv,
        rewrite="spooflens.writers.rewrite:rewrite_with_writer",
    ),
)
