"""spooflens CSV logs: RINEX-like per-satellite observations, fixes, IMU samples and truth as text.

A CSV log is one `.csv` file or a directory of them. Each file's columns say which frame it fills:
a satellite column (`sv_id`, `sv`, `prn`, ...) makes it observations (with a pseudorange) or the
receiver's per-satellite reports (`satellites`: C/N0, elevation, used, ... without one), else latitude
makes it fixes (or truth, for a file named `truth*.csv`), else accelerometer columns make it IMU. One
row per epoch (and receiver, and satellite for observations and satellites). Several receivers share
a file through the receiver column. Column names are the epoch-table schema names (`spooflens
schema`), and common spellings are accepted too (`ALIASES`).

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
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from readers import ReaderFormat, px4_csv
from readers.csv_text import MAX_T0_NS, header_comments, parse_t0_ns, read_rows, scan
from spooflens.epoch_table import TIME_REFERENCES, EpochTable, Skipped, StreamInfo, build_table
from spooflens.errors import ReaderError
from spooflens.schema import BODY_FRAMES, FRAMES, FixType
from spooflens.truth import SUFFIX as TRUTH_SUFFIX

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


_STREAM_KEY = {"fixes": "receiver_id", "observations": "receiver_id", "satellites": "receiver_id", "imu": "imu_id"}


def _frame_of(path: Path, columns: set[str]) -> str:
    if "sv_id" in columns:
        return "observations" if "pseudorange_m" in columns else "satellites"
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


@dataclass
class _File:
    """One CSV file of a log, read: its frame, rows (`t_ns` in its own clock), clock and header comments."""

    frame: str
    df: pd.DataFrame
    reference: str
    t0_ns: int | None  # `# t0_ns:` of a t_s file, None when it has none
    meta: dict[str, str]
    time_col: str


# the clocks a time column may carry, by its magnitude: seconds since 1970/1980 today are ~1.4e9-1.8e9
_ABSOLUTE_SCALES = ((1e17, 1e-9, "nanoseconds"), (1e14, 1e-6, "microseconds"), (1e11, 1e-3, "milliseconds"))
_MAX_ABSOLUTE_S = MAX_T0_NS / 1e9
_MAX_RELATIVE_S = 1e9  # 31 years after the log start


def _read_one(path: Path, skipped: list[Skipped]) -> _File:
    meta = header_comments(path)
    names = scan(path).names
    canonical = {n: _canonical(n) for n in names}
    firsts = {c: n for n, c in reversed(canonical.items())}  # each canonical name from its first column
    frame = _frame_of(path, set(canonical.values()))
    spec = {c.name: c for c in FRAMES[frame]}
    time_col = next((c for c in _TIME_COLUMNS if c in firsts), None)
    if time_col is None:
        raise ReaderError(path, f"no time column; expected one of {list(_TIME_COLUMNS)} (or their aliases)", frame)
    wanted = {n for c, n in firsts.items() if c in spec or c == time_col}
    text = {firsts[c.name] for c in spec.values() if c.dtype == "string" and c.name in firsts}
    raw = read_rows(path, skipped, keep=lambda n: n in wanted, text_columns=text, stream=path.name)
    df = raw.rename(columns={n: canonical[n] for n in raw.columns})
    ignored = [c for c in dict.fromkeys(canonical.values()) if c not in spec and c not in _TIME_COLUMNS]
    if ignored:
        skipped.append(Skipped(path.name, f"unknown columns ignored: {ignored}", len(ignored)))
    reference = _TIME_COLUMNS[time_col]
    t = _seconds(path, df[time_col].to_numpy(dtype=float), time_col, frame, skipped)
    t0: int | None = None
    if reference == "relative":
        reference = meta.get("time_reference", "relative")
        if reference not in TIME_REFERENCES:
            raise ReaderError(path, f"# time_reference: {reference!r}; use one of {list(TIME_REFERENCES)}", frame)
        t0 = parse_t0_ns(path, meta["t0_ns"], frame) if "t0_ns" in meta else None
    limit = _MAX_RELATIVE_S if time_col == "t_s" else _MAX_ABSOLUTE_S
    bad_t = ~np.isfinite(t) | (np.abs(t) > limit) | (t < 0 if time_col != "t_s" else False)
    if bad_t.any():
        skipped.append(
            Skipped(path.name, f"rows with a missing, non-numeric or impossible time ({time_col})", int(bad_t.sum()))
        )
        df, t = df[~bad_t].reset_index(drop=True), t[~bad_t]
    if not len(df):
        raise ReaderError(path, f"no row has a usable time ({time_col})", frame)
    cols: dict[str, object] = {"t_ns": (0 if t0 is None else t0) + np.round(t * 1e9).astype(np.int64)}
    for name, col in spec.items():
        if name == "t_s" or name not in df.columns:
            continue
        if col.dtype == "string":
            cols[name] = _sv_ids(df[name]) if name == "sv_id" else df[name].astype(str).str.strip()
        elif col.dtype == "int8":
            default = FixType.FIX_3D if name == "fix_type" else 2
            values = df[name].to_numpy(dtype=float)
            ok = np.isfinite(values) & (np.abs(values) < 128)
            cols[name] = np.where(ok, values, default).astype(np.int8)
        else:
            cols[name] = df[name].to_numpy(dtype=float)
    key = _STREAM_KEY.get(frame)
    if key and key not in cols:
        cols[key] = path.stem if frame == "imu" else "rx0"
    if frame == "fixes" and "fix_type" not in cols:
        cols["fix_type"] = np.full(len(df), FixType.FIX_3D, dtype=np.int8)
    missing = [c.name for c in FRAMES[frame] if c.required and c.name != "t_s" and c.name not in cols]
    if missing:
        raise ReaderError(path, f"{frame} CSV lacks required columns {missing}", frame)
    return _File(frame, pd.DataFrame(cols, copy=False), reference, t0, meta, time_col)


def _seconds(path: Path, t: np.ndarray, time_col: str, frame: str, skipped: list[Skipped]) -> np.ndarray:
    """The time column in seconds: an absolute clock in ms, µs or ns (by its magnitude), or a `t_s` whose
    steps say milliseconds (IMU samples a second or more apart, fixes 100 s or more), scaled, listed."""
    finite = t[np.isfinite(t)]
    if not len(finite):
        return t
    if time_col != "t_s":
        level = float(np.median(np.abs(finite)))
        for above, scale, unit in _ABSOLUTE_SCALES:
            if level > above:
                skipped.append(
                    Skipped(
                        path.name, f"{time_col} in {unit} (median {level:.4g}): scaled to seconds", len(t), "repaired"
                    )
                )
                return t * scale
        return t
    steps = np.diff(np.sort(finite))
    steps = steps[steps > 0]
    if not len(steps):
        return t
    step = float(np.median(steps))
    slow = 1.0 if frame == "imu" else 100.0 if frame in ("fixes", "observations") else None
    if slow is not None and step >= slow and step / 1000 <= slow / 10:
        rate = "IMU" if frame == "imu" else "GNSS"
        skipped.append(
            Skipped(
                path.name,
                f"t_s steps by {step:g} ({rate} at {1 / step:.3g} Hz): milliseconds, scaled to seconds",
                len(t),
                "repaired",
            )
        )
        return t / 1000.0
    return t


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
    read: list[_File] = []
    unread: list[ReaderError] = []
    for f in files:
        try:
            read.append(_read_one(f, skipped))
        except ReaderError as err:
            if len(files) + len(px4_files) == 1:
                raise
            unread.append(err)
    if unread and not read and not px4_files:
        problems = "; ".join(f"{e.path.name}: {e.problem}" for e in unread)
        raise ReaderError(path, f"no CSV file could be read: {problems}")
    # one unusable file of a directory log costs that file: the others are still analysed
    skipped += [Skipped(e.path.name, f"file not read: {e.problem}", 1, "lost") for e in unread]
    files = [f for f in files if f not in {e.path for e in unread}]
    declared = {r.t0_ns for r in read if r.t0_ns is not None}
    for i, (f, r) in enumerate(zip(files, read, strict=True)):
        frame, df, reference, t0, meta = r.frame, r.df, r.reference, r.t0_ns, r.meta
        if t0 is None and declared and r.time_col == "t_s":
            # one file of a log without the start the others declare: on the others' clock
            if len(declared) > 1:
                raise ReaderError(f, "no # t0_ns: comment while the other files declare different starts", frame)
            t0 = next(iter(declared))
            df["t_ns"] += t0
            skipped.append(Skipped(f.name, f"no # t0_ns: comment: took the other files' start {t0}", 1, "repaired"))
        # provenance a writer kept: `# metadata <key>: <value>` (firmware, the meaning of enum codes)
        metadata |= {k.removeprefix(METADATA_PREFIX): v for k, v in meta.items() if k.startswith(METADATA_PREFIX)}
        if meta.get("body_frame", "FLU").upper() in BODY_FRAMES:
            body_frame = meta.get("body_frame", "FLU").upper()
        frames.setdefault(frame, []).append(df)
        references.add(reference)
        if t0 is not None:
            t0s.add(t0)
        key = _STREAM_KEY.get(frame)
        role = {"fixes": "fix", "observations": "observations", "imu": "imu", "truth": "truth"}.get(frame, frame)
        counts = df[key].astype(str).value_counts(sort=False) if key else pd.Series({"truth": len(df)})
        for sid, n in counts.items():
            streams.append(
                StreamInfo(
                    role, str(sid), f.name, f"csv/{frame}", int(n), body_frame=body_frame if frame == "imu" else None
                )
            )
        if progress:
            progress(i + 1, len(files))
    if len(references) > 1:
        raise ReaderError(path, f"files use different clocks {sorted(references)}; use one time column kind")
    reference = references.pop() if references else "relative"
    t0 = min(t0s) if t0s and reference != "relative" else None
    merged = {k: v[0] if len(v) == 1 else pd.concat(v, ignore_index=True) for k, v in frames.items()}
    frames.clear()
    read.clear()  # build_table consumes the frames: nothing here may keep a second reference
    if files:
        del df, r  # the loop's last file holds its frame too
    if topics:
        skipped.append(Skipped("<csv>", f"--topic ignored for CSV logs ({dict(topics)})", len(topics)))
    return build_table(path, "csv", reference, merged, streams, skipped, t0_ns=t0, metadata=metadata)


# a header naming one of these (or an alias) makes a file a CSV log whatever its name
_LOG_COLUMNS = {"sv_id", "lat_deg", "ax_mps2", *_TIME_COLUMNS}


def _is_truth_file(path: Path) -> bool:
    """A log's ground truth beside it (`LOG.truth.csv`): data for that log, not a log (nor does it make
    its folder a CSV log)."""
    return path.name.endswith(TRUTH_SUFFIX)


def _is_csv(path: Path, head: bytes) -> bool:
    """A `.csv` file of text with commas; a file of another name only when its header row names a time,
    satellite, latitude or accelerometer column (a README or SOURCE.md with a comma in it is no log)."""
    if path.is_dir():
        return any(not _is_truth_file(p) for p in path.glob("*.csv"))
    text = head.decode("utf-8", errors="replace")
    if "\ufffd" in text or "," not in text or not text.lstrip().startswith(("#", *"abcdefghijklmnopqrstuvwxyz")):
        return False
    if path.suffix.lower() == ".csv":
        return True
    header = next((ln for ln in text.splitlines() if ln.strip() and not ln.startswith("#")), "")
    if header.lstrip().startswith(("$", "!")):  # an NMEA sentence, not a header row
        return False
    return any(_canonical(name) in _LOG_COLUMNS for name in header.split(","))


FORMATS = (
    ReaderFormat(
        "csv",
        "spooflens CSV log (a .csv file or a directory of them)",
        read_csv,
        _is_csv,
        rewrite="spooflens.writers.rewrite:rewrite_with_writer",
        folder_of_files=True,
        companion=_is_truth_file,
    ),
)
