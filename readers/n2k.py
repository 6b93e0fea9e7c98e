"""NMEA 2000 logs in canboat's text formats to fixes and headings.

A boat's NMEA 2000 bus logged as text, one CAN message per line: canboat's plain format
(`2016-02-28T19:57:02.364Z,2,127250,7,255,8,ff,10,...`: time, priority, PGN, source, destination,
length, bytes; also with the older `2016-02-28-19:57:02.364` time), its FAST variant (a fast-packet PGN
on one line) and PLAIN_MIX_FAST (both), or Actisense's `A` text (`A173321.107 23FF7 1F513 012F...`).
The PGNs are decoded by the `nmea2000` package (canboat's PGN database, with fast-packet reassembly
of frames split over lines); this module only maps the decoded fields:

- fixes per source (`N2K/<src>`): PGN 129029 GNSS position data (position, altitude above the WGS84
  ellipsoid, method -> fix type, satellites, HDOP, the receiver's date and time -> `time_offset_s`);
  a source without 129029 gives its 129025 rapid positions (no altitude: height 0 m, listed). Velocity
  east/north from the source's 129026 COG/SOG (true course) nearest in time.
- headings: 127250 vessel heading, true, or magnetic made true with its deviation and variation (else the
  latest 127258 magnetic variation); `talker` "GN" when the source also sends GNSS positions (a satellite
  compass, which a spoofer can move), "HC" for a magnetic compass made true, "II" otherwise. 128259
  speed through the water joins the nearest compass heading (as NMEA 0183 VHW does).
- time: the logger's time of each line (`unix`); 126992 system time and 129029's date and time are the
  GNSS clock against it. Actisense `A` text has the time of day only: `relative`.

Why `nmea2000`: it is a maintained decoder of canboat's PGN database (the reference for these PGNs)
that reads these logger formats and reassembles fast packets, so no PGN layout is written here.

Lines the decoder cannot read (garbage, a cut last line, bad hex) are counted as lost; PGNs not used are
counted by number.
"""

from __future__ import annotations

import logging
import math
import re
from collections import Counter, defaultdict
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, date, datetime, time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from readers import ReaderFormat
from spooflens.epoch_table import EpochTable, Skipped, StreamInfo, build_table, log_clock, time_offset_s
from spooflens.errors import ReaderError
from spooflens.schema import FixType

Progress = Callable[[int, int], None]
NS = 1_000_000_000
GNSS_PGNS = {129029, 129025, 129026}
USED_PGNS = {129029, 129025, 129026, 127250, 127258, 128259, 126992}
_PLAIN = re.compile(r"^(\d{4})-(\d\d)-(\d\d)[T-](\d\d):(\d\d):(\d\d)(\.\d+)?Z?,(\d+),(\d+),(\d+),(\d+),(\d+),(.*)$")
_ACTISENSE_TIME = re.compile(r"^A(\d\d)(\d\d)(\d\d(?:\.\d+)?)\s")
_ACTISENSE = re.compile(r"^A\d+\.\d+\s+[0-9A-Fa-f]{5}\s+[0-9A-Fa-f]{5,6}\s+[0-9A-Fa-f]+$")
_METHOD = {
    "GNSS fix": FixType.FIX_3D,
    "DGNSS fix": FixType.DGNSS,
    "Precise GNSS": FixType.DGNSS,
    "RTK Fixed Integer": FixType.RTK_FIXED,
    "RTK float": FixType.RTK_FLOAT,
    "Estimated (DR) mode": FixType.UNKNOWN,
    "Manual Input": FixType.UNKNOWN,
    "Simulate mode": FixType.UNKNOWN,
}


@dataclass
class _Decoded:
    rows: dict[int, list[tuple[int, int, dict[str, Any]]]] = field(default_factory=lambda: defaultdict(list))
    unused: Counter[int] = field(default_factory=Counter)
    bad: int = 0
    first_bad: str = ""
    lines: int = 0
    whole: dict[tuple[int, int], list[bool]] = field(default_factory=lambda: defaultdict(list))
    repeated: Counter[int] = field(default_factory=Counter)


def _line_ns(m: re.Match[str]) -> int:
    y, mo, d, h, mi, s = (int(m.group(i)) for i in range(1, 7))
    frac = float(m.group(7) or 0.0)
    return int(datetime(y, mo, d, h, mi, s, tzinfo=UTC).timestamp()) * NS + round(frac * NS)


def _decoder(kind: str) -> Any:
    from nmea2000 import NMEA2000Decoder
    from nmea2000.input_formats import N2KFormat

    logging.getLogger("nmea2000").setLevel(logging.ERROR)  # it logs each PGN it has no definition for
    return NMEA2000Decoder(N2KFormat.BASIC_STRING if kind == "plain" else N2KFormat.N2K_ASCII)


def _decode(path: Path, text: str, kind: str) -> _Decoded:
    out = _Decoded()
    dec = _decoder(kind)
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        out.lines += 1
        t_ns = None
        if kind == "actisense":  # `A173321.107`: the logger's time of day, no date
            a = _ACTISENSE_TIME.match(line)
            if a is not None:
                h, mi, sec = int(a.group(1)), int(a.group(2)), float(a.group(3))
                t_ns = round((h * 3600 + mi * 60 + sec) * NS)
        if kind == "plain":
            m = _PLAIN.match(line)
            if m is None:
                out.bad += 1
                out.first_bad = out.first_bad or line[:60]
                continue
            try:
                t_ns = _line_ns(m)
            except (ValueError, OverflowError):
                out.bad += 1
                continue
            # the decoder reads canboat's current time layout only: hand it that
            stamp = datetime.fromtimestamp(t_ns / NS, tz=UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"
            line = f"{stamp},{','.join(m.group(i) for i in range(8, 13))},{m.group(13)}"
        try:
            msg = dec.decode(line)
        except (ValueError, KeyError, IndexError, TypeError, OverflowError) as err:
            out.bad += 1
            out.first_bad = out.first_bad or f"{line[:50]}: {err}"[:120]
            continue
        if msg is None:  # a frame of a fast packet still being assembled
            continue
        if msg.PGN not in USED_PGNS:
            out.unused[msg.PGN] += 1
            continue
        if t_ns is None:
            out.bad += 1
            out.first_bad = out.first_bad or f"{line[:50]}: no time"
            continue
        whole = kind != "plain" or int(line.split(",", 6)[5]) > 8  # one line, or reassembled from frames
        out.rows[msg.PGN].append((t_ns, int(msg.source), {f.id: f.value for f in msg.fields}))
        out.whole[(msg.PGN, int(msg.source))].append(whole)
    dec.close()
    _drop_repeated_fast_packets(out)
    return out


def _drop_repeated_fast_packets(out: _Decoded) -> None:
    """PLAIN_MIX_FAST logs a fast-packet PGN twice, whole on one line and as its frames: a source's
    messages reassembled from frames are dropped where the same source's PGN also came whole."""
    for pgn, rows in out.rows.items():
        forms: dict[int, list[bool]] = defaultdict(list)
        for (p, src), flags in out.whole.items():
            if p == pgn:
                forms[src] = flags
        seen: Counter[int] = Counter()
        kept = []
        for row in rows:
            src = row[1]
            flags = forms[src]
            whole = flags[seen[src]] if seen[src] < len(flags) else True
            seen[src] += 1
            if whole or not any(flags):
                kept.append(row)
            else:
                out.repeated[pgn] += 1
        out.rows[pgn] = kept


def _num(v: Any) -> float:
    return float(v) if isinstance(v, int | float) and not isinstance(v, bool) else math.nan


def _gnss_ns(day: Any, tod: Any) -> float:
    """GNSS date and time of day of a 129029 or 126992 as UTC ns (NaN when either is missing)."""
    if not isinstance(day, date) or not isinstance(tod, time):
        return math.nan
    return datetime.combine(day, tod, tzinfo=UTC).timestamp() * NS


def _fixes(dec: _Decoded, skipped: list[Skipped], meta: dict[str, str]) -> tuple[pd.DataFrame | None, list[StreamInfo]]:
    full_sources = {src for _, src, _ in dec.rows[129029]}
    rows = []
    no_fix: Counter[int] = Counter()
    for t_ns, src, f in dec.rows[129029]:
        lat, lon = _num(f.get("latitude")), _num(f.get("longitude"))
        method = str(f.get("method"))
        if not (math.isfinite(lat) and math.isfinite(lon)) or method not in _METHOD:
            no_fix[src] += 1
            continue
        alt = _num(f.get("altitude"))
        rows.append(
            {
                "t_ns": t_ns, "src": src, "lat_deg": lat, "lon_deg": lon,
                "height_m": alt if math.isfinite(alt) else 0.0,
                "no_height": not math.isfinite(alt), "sats_used": _num(f.get("numberOfSvs")),
                "hdop": _num(f.get("hdop")), "fix_type": int(_METHOD[method]),
                "gnss_ns": _gnss_ns(f.get("date"), f.get("time")), "msg": "129029",
            }
        )  # fmt: skip
    rapid_skipped: Counter[int] = Counter()
    for t_ns, src, f in dec.rows[129025]:
        if src in full_sources:
            rapid_skipped[src] += 1
            continue
        lat, lon = _num(f.get("latitude")), _num(f.get("longitude"))
        if math.isfinite(lat) and math.isfinite(lon):
            rows.append(
                {
                    "t_ns": t_ns, "src": src, "lat_deg": lat, "lon_deg": lon, "height_m": 0.0, "no_height": True,
                    "sats_used": math.nan, "hdop": math.nan, "fix_type": int(FixType.UNKNOWN), "gnss_ns": math.nan,
                    "msg": "129025",
                }
            )  # fmt: skip
    for src, n in no_fix.items():
        skipped.append(Skipped(f"N2K/{src}", "129029 without a fix (no position, or method 'no GNSS')", n))
    for src, n in rapid_skipped.items():
        skipped.append(Skipped(f"N2K/{src}", "129025 rapid positions between the source's 129029 fixes", n))
    if not rows:
        return None, []
    df = pd.DataFrame(rows).sort_values(["src", "t_ns"], kind="stable")
    cog = pd.DataFrame(
        [
            (t, s, _num(f.get("cog")), _num(f.get("sog")))
            for t, s, f in dec.rows[129026]
            if str(f.get("cogReference")) == "True"
        ],
        columns=["t_ns", "src", "cog", "sog"],
    ).dropna()
    if len(cog):
        df = pd.merge_asof(
            df.sort_values("t_ns"), cog.sort_values("t_ns"), on="t_ns", by="src", direction="nearest",
            tolerance=NS // 2,
        ).sort_values(["src", "t_ns"], kind="stable")  # fmt: skip
        df["vel_e_mps"] = df["sog"] * np.sin(df["cog"])
        df["vel_n_mps"] = df["sog"] * np.cos(df["cog"])
    df["receiver_id"] = [f"N2K/{s}" for s in df["src"]]
    offsets = np.full(len(df), np.nan)
    for rid in df["receiver_id"].unique():
        mine = (df["receiver_id"] == rid).to_numpy()
        gnss = df["gnss_ns"].to_numpy()[mine]
        valid = np.isfinite(gnss)
        if valid.any():
            offsets[mine] = time_offset_s(np.nan_to_num(gnss).astype(np.int64), df["t_ns"].to_numpy()[mine], valid)
    df["time_offset_s"] = offsets
    meta |= log_clock("the logger's time of each line", True)
    for rid, n in df[df["no_height"]].groupby("receiver_id").size().items():
        skipped.append(
            Skipped(str(rid), "no altitude (129025, or 129029 without one): height set to 0 m", int(n), "repaired")
        )
    streams = [
        StreamInfo("fix", str(rid), str(rid), "N2K " + "/".join(sorted(set(g["msg"]))), len(g))
        for rid, g in df.groupby("receiver_id", sort=True)
    ]
    keep = ["t_ns", "receiver_id", "lat_deg", "lon_deg", "height_m", "sats_used", "hdop", "fix_type", "time_offset_s"]
    keep += [c for c in ("vel_e_mps", "vel_n_mps") if c in df]
    out = df[keep].drop_duplicates(["receiver_id", "t_ns"]).reset_index(drop=True)
    out["fix_type"] = out["fix_type"].astype(np.int8)
    return out, streams


def _headings(dec: _Decoded, skipped: list[Skipped]) -> tuple[pd.DataFrame | None, list[StreamInfo]]:
    gnss_sources = {src for pgn in GNSS_PGNS for _, src, _ in dec.rows[pgn]}
    variation = sorted((t, _num(f.get("variation"))) for t, _, f in dec.rows[127258])
    var_t = np.array([t for t, v in variation if math.isfinite(v)], dtype=np.int64)
    var_v = np.array([v for _, v in variation if math.isfinite(v)])
    rows, unusable = [], Counter[str]()
    for t_ns, src, f in dec.rows[127250]:
        heading, ref = _num(f.get("heading")), str(f.get("reference"))
        hid = f"N2K/{src}/127250"
        if not math.isfinite(heading):
            unusable[hid] += 1
            continue
        if ref == "Magnetic":
            var = _num(f.get("variation"))
            if not math.isfinite(var) and len(var_t):
                k = int(np.searchsorted(var_t, t_ns, side="right")) - 1
                var = float(var_v[max(k, 0)])
            if not math.isfinite(var):
                unusable[hid] += 1
                continue
            heading += np.nan_to_num(_num(f.get("deviation"))) + var
        elif ref != "True":
            unusable[hid] += 1
            continue
        talker = "GN" if src in gnss_sources else "HC" if ref == "Magnetic" else "II"
        rows.append((t_ns, hid, math.degrees(heading) % 360.0, talker, math.nan))
    for hid, n in unusable.items():
        skipped.append(Skipped(hid, "headings without a value (or magnetic without a variation)", n))
    frame = pd.DataFrame(rows, columns=["t_ns", "heading_id", "heading_deg", "talker", "water_speed_mps"])
    water = pd.DataFrame(
        [(t, s, _num(f.get("speedWaterReferenced"))) for t, s, f in dec.rows[128259]], columns=["t_ns", "src", "v"]
    ).dropna()
    compass = frame[frame["talker"] != "GN"].sort_values("t_ns")
    if len(water) and len(compass):  # a speed log beside a compass: the VHW of NMEA 0183
        joined = pd.merge_asof(
            water.sort_values("t_ns"), compass[["t_ns", "heading_deg", "talker"]], on="t_ns",
            direction="nearest", tolerance=NS,
        ).dropna(subset=["heading_deg"])  # fmt: skip
        logged = pd.DataFrame(
            {
                "t_ns": joined["t_ns"], "heading_id": [f"N2K/{s}/128259" for s in joined["src"]],
                "heading_deg": joined["heading_deg"], "talker": joined["talker"], "water_speed_mps": joined["v"],
            }
        )  # fmt: skip
        frame = pd.concat([frame, logged], ignore_index=True)
    elif len(water):
        skipped.append(Skipped("128259", "speed through the water without a compass heading to go with it", len(water)))
    if not len(frame):
        return None, []
    streams = [
        StreamInfo("heading", str(hid), str(hid), f"N2K {str(hid).rsplit('/', 1)[-1]}", int(n))
        for hid, n in frame["heading_id"].value_counts(sort=False).items()
    ]
    return frame, streams


def read_n2k(path: Path, topics: Mapping[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8", errors="replace")
    except OSError as err:
        raise ReaderError(path, f"cannot read: {err.strerror or err}") from err
    kind = "actisense" if _ACTISENSE.match(_first_data_line(text)) else "plain"
    dec = _decode(path, text, kind)
    skipped: list[Skipped] = []
    meta: dict[str, str] = {"n2k.format": "Actisense A text" if kind == "actisense" else "canboat plain/fast text"}
    if dec.bad:
        skipped.append(Skipped("<n2k>", f"lines the NMEA 2000 decoder cannot read ({dec.first_bad})", dec.bad, "lost"))
    for pgn, n in sorted(dec.repeated.items()):
        skipped.append(Skipped(f"PGN {pgn}", "the same fast-packet messages again as frames (PLAIN_MIX_FAST)", n))
    for pgn, n in sorted(dec.unused.items()):
        skipped.append(Skipped(f"PGN {pgn}", "PGN spooflens does not use", n))
    if topics:
        skipped.append(Skipped("<n2k>", f"--topic is not used for NMEA 2000 logs ({dict(topics)})", len(topics)))
    fixes, fix_streams = _fixes(dec, skipped, meta)
    headings, heading_streams = _headings(dec, skipped)
    if fixes is None and headings is None:
        pgns = ", ".join(str(p) for p, _ in dec.unused.most_common(8))
        raise ReaderError(
            path, f"no GNSS position (PGN 129029/129025) or heading (127250) in {dec.lines} lines (PGNs: {pgns})", "n2k"
        )
    frames = {k: v for k, v in (("fixes", fixes), ("headings", headings)) if v is not None}
    if 126992 in dec.rows:
        meta["n2k.system_time"] = f"{len(dec.rows[126992])} 126992 system time messages (the bus's GNSS clock)"
    reference = "unix"
    if kind == "actisense":
        reference = "relative"
        meta["clock"] = "Actisense A text carries the logger's time of day only: relative time (seconds of the day)"
    return build_table(path, "n2k", reference, frames, [*fix_streams, *heading_streams], skipped, metadata=meta)


def _first_data_line(text: str) -> str:
    return next((ln.strip() for ln in text.splitlines() if ln.strip() and not ln.startswith("#")), "")


def _is_n2k(path: Path, head: bytes) -> bool:
    if not path.is_file():
        return False
    lines = [ln.strip() for ln in head.decode("utf-8", errors="replace").splitlines()[:-1] if ln.strip()]
    data = [ln for ln in lines if not ln.startswith("#")]
    good = sum(1 for ln in data if _PLAIN.match(ln) or _ACTISENSE.match(ln))
    return good >= 1 and good * 2 >= len(data)


FORMATS = (
    ReaderFormat(
        "n2k",
        "NMEA 2000 log (canboat plain/FAST/PLAIN_MIX_FAST text, Actisense A text)",
        read_n2k,
        _is_n2k,
    ),
)
