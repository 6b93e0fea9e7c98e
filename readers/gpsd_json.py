"""gpsd JSON reports (`gpspipe -w > drive.json`) to an EpochTable.

One JSON object per line, each with a `class`; `#` comment lines (gpsd's test logs) are kept as the log
header. `gpspipe -t/-u/-uu/-Z` prefix each line with the logging host's time ("2019-01-01 00:00:00.123:",
"1546300800.123456:", "2019-01-01T00:00:00.123Z:"), read as UTC.

- `TPV` with mode 2 or 3 is a fix of the receiver named by its `device` (several devices: several
  receivers): lat/lon; height `altHAE`, else `altMSL` (or the older `alt`, MSL) + `geoidSep` (the MSL
  altitude alone when no separation is given, listed as a repair); velocity `velN/velE/velD`, else
  `speed`/`track` (+ `climb` up); `eph` (else the RMS of `epx`, `epy`), `epv` and `eps` as the accuracies,
  as gpsd reports them (its documentation: "certainty unknown"; no scaling applied, said in metadata);
  `status` maps the fix type (dead reckoning, surveyed time and simulated fixes kept as UNKNOWN).
- `SKY`: the `satellites` frame (sv ids from `gnssid`/`svid`, u-blox numbering, else gpsd's `PRN`, only in
  its real ranges: PRN 255, a GLONASS signal of unknown slot, and the ambiguous 33-64 are skipped, counted;
  `el`, `az`, `ss` as C/N0, `used`, `health`), and its `hdop`, `vdop`, `uSat` and mean C/N0 joined to
  the receiver's TPV of the same time (a SKY without `time`: the receiver's latest TPV).
- `VERSION`, `DEVICES`, `DEVICE`, `WATCH`: metadata (the gpsd release, each device's driver and subtype);
  `PPS`, `TOFF`, `ATT`, `IMU`, `GST` and every other class are counted and skipped.

Time: the TPV `time` (UTC) is the receiver's own; plain `gpspipe -w` has no other clock, so the table is
on the receiver's time (`unix`). With host time prefixes on most lines, rows are on the host's clock and
each fix's `time_offset_s` compares the receiver's time with it. Lines that are not JSON, objects whose
fields have the wrong types or are not finite, and a cut last line are counted and skipped.
"""

from __future__ import annotations

import json
import math
import re
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from readers import NothingToJudgeError, ReaderFormat
from readers.ubx.messages import sv_ids
from spooflens.epoch_table import EpochTable, Skipped, StreamInfo, build_table, log_clock, time_offset_s
from spooflens.errors import ReaderError
from spooflens.schema import FixType

Progress = Callable[[int, int], None]
NS = 1_000_000_000
FORMAT = "gpsd_json"
DEFAULT_DEVICE = "gpsd"  # a report without `device` (one receiver)

_PREFIX = re.compile(rb"^(?P<t>\d{4}-\d\d-\d\d[ T]\d\d:\d\d:\d\d(?:\.\d+)?Z?|\d{9,11}(?:\.\d+)?): (?=\{)")
_CLASS = re.compile(rb'^\{\s*"class"\s*:\s*"[A-Za-z0-9_]+"')
META_CLASSES = ("VERSION", "DEVICES", "DEVICE", "WATCH")
READ_CLASSES = ("TPV", "SKY", *META_CLASSES)
NOT_READ = {
    "PPS": "time only (PPS edges against the host clock)",
    "TOFF": "time only (GPS time against the host clock)",
    "ATT": "attitude/IMU report: not read (axes and units vary by driver)",
    "IMU": "attitude/IMU report: not read (axes and units vary by driver)",
    "GST": "pseudorange noise report: not read (TPV's error estimates are)",
    "ERROR": "gpsd's error message",
    "POLL": "a client's poll answer",
}
FIX_MEANING = (
    "gpsd TPV mode 2 2D, 3 3D; status 2 DGPS, 3 RTK fixed, 4 RTK float; status 5 DR, 7 surveyed time and "
    "8 simulated are kept with fix_type UNKNOWN (not a GNSS fix); mode 0/1 rows are no fix (skipped)"
)
ACCURACY = (
    "h_acc_m = TPV eph (else sqrt((epx^2+epy^2)/2)), v_acc_m = epv, vel_acc_mps = eps, as gpsd reports "
    "them: gpsd documents their certainty as unknown (older releases: 95 %); not scaled to 1 sigma"
)
# gpsd's own PRN numbering when a satellite has no gnssid/svid (its NMEA driver's table: GPS 1-32, GLONASS
# 65-96, SBAS 120-158, QZSS 193-197 (u-blox to 199), BeiDou 201-235 and 401-437, Galileo 301-336; BeiDou to 37
# as gpsd maps u-blox's): (first, last, RINEX letter, offset). 33-64 is SBAS in gpsd's NMEA numbering but
# BeiDou in the u-blox numbering older gpsd passed through, so not named; 255 is u-blox's GLONASS signal whose
# slot is not known yet (newer gpsd drops it): no satellite to name.
_PRN_RANGES = (
    (1, 32, "G", 0),
    (65, 96, "R", 64),
    (120, 158, "S", 100),
    (193, 200, "J", 192),
    (201, 237, "C", 200),
    (301, 336, "E", 300),
    (401, 437, "C", 400),
)
UNKNOWN_SLOT = (
    "SKY satellites PRN 255: a GLONASS signal whose slot the u-blox has not identified (no satellite to name)"
)
PRN_33_64 = (
    "SKY satellites PRN 33-64 without gnssid/svid: SBAS in gpsd's NMEA numbering, BeiDou in the u-blox numbering "
    "older gpsd passed through (not told apart)"
)
TPV_TIME_LOST = ("TPV fixes with no time", "TPV fixes with a time that is no ISO 8601 date")
SKY_BEFORE_FIX = (
    "SKY reports before the device's first fix, with no time of their own (gpspipe -w writes gpsd's sky from "
    "the start): nothing places them in time"
)
UNMAPPED = "SKY satellites with no id spooflens can map (a PRN outside gpsd's numbering, or gnssid/svid of no system)"


@dataclass
class Report:
    """One JSON report of the file: where it is, its logger time and its object."""

    line: int
    start: int  # byte offsets of the JSON text (without a prefix and line end)
    end: int
    host_ns: int | None
    obj: dict[str, Any]

    @property
    def cls(self) -> str:
        return str(self.obj.get("class"))


@dataclass
class Scan:
    path: Path
    data: bytes
    reports: list[Report] = field(default_factory=list)
    counts: Counter[str] = field(default_factory=Counter)  # reason -> lines lost
    comments: list[str] = field(default_factory=list)
    prefixed: int = 0


def _host_ns(stamp: bytes) -> int | None:
    text = stamp.decode("ascii")
    try:
        if "-" not in text:
            whole, _, frac = text.partition(".")
            return int(whole) * NS + int((frac + "000000000")[:9])
        dt = datetime.fromisoformat(text.rstrip("Z").replace(" ", "T")).replace(tzinfo=UTC)
        return _ns_of(dt)
    except ValueError:
        return None


def _ns_of(dt: datetime) -> int:
    whole = int(dt.replace(microsecond=0).timestamp())
    return whole * NS + dt.microsecond * 1000


def iso_ns(value: Any) -> int | None:
    """A gpsd `time`: ISO 8601 UTC (or, in gpsd before 3.x's JSON, UNIX seconds) -> UNIX ns; None if not."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int | float):
        return round(value * NS) if math.isfinite(value) and 0 < value < 4.2e9 else None
    if not isinstance(value, str) or not 19 <= len(value) <= 40:
        return None
    try:
        head, _, frac = value.rstrip("Z").partition(".")
        dt = datetime.fromisoformat(head)
        if dt.tzinfo is not None:
            dt = dt.astimezone(UTC).replace(tzinfo=None)
        ns = _ns_of(dt.replace(tzinfo=UTC))
        if frac:
            if not frac.isdigit():
                return None
            ns += int((frac + "000000000")[:9])
        return ns
    except ValueError:
        return None


def scan_reports(path: Path, data: bytes | None = None) -> Scan:
    """Every JSON report of the file with its place; every other line counted by reason."""
    if data is None:
        try:
            data = Path(path).read_bytes()
        except OSError as err:
            raise ReaderError(path, f"cannot read: {err}") from err
    out = Scan(Path(path), data)
    pos = 0
    n = 0
    size = len(data)
    while pos < size:
        nl = data.find(b"\n", pos)
        end = size if nl < 0 else nl
        line = data[pos:end]
        body_end = end - 1 if line.endswith(b"\r") else end
        text = data[pos:body_end]
        start = pos
        pos, n = end + 1, n + 1
        if not text.strip():
            continue
        if text.startswith(b"#"):
            out.comments.append(text[1:].decode("utf-8", "replace").strip())
            continue
        host = None
        m = _PREFIX.match(text)
        if m:
            host = _host_ns(m.group("t"))
            start += m.end()
            text = text[m.end() :]
            out.prefixed += 1
        if not text.startswith(b"{"):
            out.counts["lines that are not gpsd JSON reports"] += 1
            continue
        try:
            obj = json.loads(text)
        except (ValueError, RecursionError):
            cut = nl < 0
            out.counts["file cut inside its last report" if cut else "lines that are not valid JSON"] += 1
            continue
        if not isinstance(obj, dict) or not isinstance(obj.get("class"), str):
            out.counts["JSON lines without a class"] += 1
            continue
        out.reports.append(Report(n - 1, start, body_end, host, obj))
    return out


def _num(obj: Mapping[str, Any], key: str, bad: Counter[str], cls: str) -> float:
    """A numeric field; NaN when absent, counted when present but not a finite number."""
    v = obj.get(key)
    if v is None:
        return math.nan
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        bad[f"{cls} {key}"] += 1
        return math.nan
    return float(v)


@lru_cache(maxsize=4096)
def _ublox_sv_id(gnss_id: int, sv: int) -> str | None:
    """u-blox numbering, as the UBX reader maps it (a few hundred pairs: each mapped once)."""
    ids, ok = sv_ids(np.array([gnss_id]), np.array([sv]))
    return str(ids[0]) if ok[0] else None


def sv_id(sat: Mapping[str, Any]) -> str | None:
    """RINEX-style id of a SKY satellite: u-blox gnssid/svid when given, else gpsd's PRN numbering."""
    g, s = sat.get("gnssid"), sat.get("svid")
    if isinstance(g, int) and isinstance(s, int) and not isinstance(g, bool) and not isinstance(s, bool):
        return _ublox_sv_id(g, s) if 0 <= g < 256 and 0 <= s < 1024 else None
    prn = sat.get("PRN")
    if isinstance(prn, bool) or not isinstance(prn, int):
        return None
    for first, last, letter, offset in _PRN_RANGES:
        if first <= prn <= last:
            return f"{letter}{prn - offset:02d}"
    return None


def unmapped_reason(sat: Mapping[str, Any]) -> str:
    """Why `sv_id` names no satellite for this SKY satellite."""
    g, s, prn = sat.get("gnssid"), sat.get("svid"), sat.get("PRN")
    if (g == 6 and s == 255) or (not isinstance(g, int) and prn == 255):
        return UNKNOWN_SLOT
    if not isinstance(g, int) and isinstance(prn, int) and 33 <= prn <= 64:
        return PRN_33_64
    return UNMAPPED


@dataclass
class _Fix:
    report: Report
    rid: str
    gnss_ns: int
    values: dict[str, float]


def _fix_type(mode: int, status: Any) -> int:
    if isinstance(status, int) and not isinstance(status, bool):
        if status in (5, 7, 8):
            return int(FixType.UNKNOWN)
        if status == 2:
            return int(FixType.DGNSS)
        if status == 3:
            return int(FixType.RTK_FIXED)
        if status == 4:
            return int(FixType.RTK_FLOAT)
    return int(FixType.FIX_3D if mode == 3 else FixType.FIX_2D)


def _tpv(r: Report, bad: Counter[str], skipped: Counter[tuple[str, str]]) -> _Fix | None:
    o = r.obj
    dev = o.get("device")
    rid = dev if isinstance(dev, str) and dev else DEFAULT_DEVICE
    mode = o.get("mode")
    if isinstance(mode, bool) or not isinstance(mode, int):
        skipped[(rid, "TPV without a numeric mode")] += 1
        return None
    if mode < 2:
        skipped[(rid, "TPV without a fix (mode 0/1)")] += 1
        return None
    t = iso_ns(o.get("time"))
    if t is None:
        what = "no time" if o.get("time") is None else "a time that is no ISO 8601 date"
        skipped[(rid, f"TPV fixes with {what}")] += 1
        return None
    lat, lon = _num(o, "lat", bad, "TPV"), _num(o, "lon", bad, "TPV")
    if not (math.isfinite(lat) and math.isfinite(lon) and abs(lat) <= 90 and abs(lon) <= 180):
        skipped[(rid, "TPV fixes without a usable lat/lon")] += 1
        return None
    hae, msl, alt, sep = (_num(o, k, bad, "TPV") for k in ("altHAE", "altMSL", "alt", "geoidSep"))
    msl = msl if math.isfinite(msl) else alt
    vn, ve, vd = (_num(o, k, bad, "TPV") for k in ("velN", "velE", "velD"))
    speed, track, climb = (_num(o, k, bad, "TPV") for k in ("speed", "track", "climb"))
    if not (math.isfinite(vn) and math.isfinite(ve)) and math.isfinite(speed) and math.isfinite(track):
        vn, ve = speed * math.cos(math.radians(track)), speed * math.sin(math.radians(track))
    vu = -vd if math.isfinite(vd) else climb
    eph, epx, epy = (_num(o, k, bad, "TPV") for k in ("eph", "epx", "epy"))
    if not math.isfinite(eph):
        eph = math.sqrt((epx**2 + epy**2) / 2)
    values = {
        "lat_deg": lat,
        "lon_deg": lon,
        "alt_hae": hae,
        "alt_msl": msl,
        "geoid_sep": sep,
        "vel_e_mps": ve,
        "vel_n_mps": vn,
        "vel_u_mps": vu,
        "h_acc_m": eph,
        "v_acc_m": _num(o, "epv", bad, "TPV"),
        "vel_acc_mps": _num(o, "eps", bad, "TPV"),
        "fix_type": float(_fix_type(mode, o.get("status"))),
    }
    return _Fix(r, rid, t, values)


@dataclass
class Assembled:
    fixes: list[_Fix]
    sky: list[tuple[Report, str, int]]  # SKY report, receiver, its epoch (receiver's time, ns)
    logger: bool
    metadata: dict[str, str]
    skipped: list[Skipped]


def assemble(scan: Scan) -> Assembled:
    """The TPV fixes and SKY epochs of a scan, with the metadata and what was skipped (shared with inject)."""
    skipped = [
        Skipped(scan.path.name, reason, n, "skipped" if reason == "lines that are not gpsd JSON reports" else "lost")
        for reason, n in scan.counts.items()
    ]
    bad: Counter[str] = Counter()
    why: Counter[tuple[str, str]] = Counter()
    other: Counter[str] = Counter()
    fixes: list[_Fix] = []
    sky: list[tuple[Report, str, int]] = []
    latest: dict[str, int] = {}
    meta: dict[str, str] = {}
    devices: dict[str, dict[str, Any]] = {}
    for r in scan.reports:
        cls = r.cls
        if cls == "TPV":
            fix = _tpv(r, bad, why)
            if fix is not None:
                fixes.append(fix)
                latest[fix.rid] = fix.gnss_ns
        elif cls == "SKY":
            dev = r.obj.get("device")
            rid = dev if isinstance(dev, str) and dev else DEFAULT_DEVICE
            t = iso_ns(r.obj.get("time"))
            if t is None:
                t = latest.get(rid)
            sats = r.obj.get("satellites")
            if t is None:
                why[(rid, SKY_BEFORE_FIX)] += 1
            elif not isinstance(sats, list):
                if sats is not None:
                    bad["SKY satellites"] += 1
                why[(rid, "SKY reports without a satellite list")] += 1
            else:
                sky.append((r, rid, t))
        elif cls == "VERSION":
            for key in ("release", "rev"):
                if isinstance(r.obj.get(key), str):
                    meta[f"gpsd.{key}"] = r.obj[key]
            if isinstance(r.obj.get("proto_major"), int):
                meta["gpsd.protocol"] = f"{r.obj['proto_major']}.{r.obj.get('proto_minor', 0)}"
        elif cls in ("DEVICES", "DEVICE"):
            listed = r.obj.get("devices") if cls == "DEVICES" else [r.obj]
            for d in listed if isinstance(listed, list) else []:
                if isinstance(d, dict) and isinstance(d.get("path"), str):
                    devices.setdefault(d["path"], {}).update(
                        {k: v for k, v in d.items() if k in ("driver", "subtype", "subtype1") and isinstance(v, str)}
                    )
        elif cls == "WATCH":
            continue
        else:
            other[cls] += 1
    for (rid, reason), n in why.items():
        # a fix whose time is missing or unreadable is lost; a sky gpsd sent before any fix is not damage
        skipped.append(Skipped(rid, reason, n, "lost" if reason in TPV_TIME_LOST else "skipped"))
    for what, n in sorted(bad.items()):
        skipped.append(Skipped(what, "fields of the wrong type or not finite (value left out)", n, "lost"))
    for cls, n in sorted(other.items()):
        skipped.append(Skipped(cls, NOT_READ.get(cls, "gpsd report class spooflens does not read"), n))
    for path, d in devices.items():
        model = " ".join(str(d[k]) for k in ("driver", "subtype", "subtype1") if d.get(k))
        if model:
            meta[f"receiver.{path}"] = model
    host = sum(r.host_ns is not None for r in scan.reports)
    logger = bool(scan.reports) and host * 2 >= len(scan.reports)
    if scan.prefixed and not logger:
        skipped.append(Skipped(scan.path.name, "host time prefixes on too few lines to be the clock", scan.prefixed))
    return Assembled(fixes, sky, logger, meta, skipped)


def _heights(rid: str, alt_hae: np.ndarray, msl: np.ndarray, sep: np.ndarray, skipped: list[Skipped]) -> np.ndarray:
    """altHAE, else MSL altitude + geoidSep, else the MSL altitude alone, else the last known height."""
    h = np.where(np.isfinite(alt_hae), alt_hae, msl + sep)
    bare = ~np.isfinite(h) & np.isfinite(msl)
    if bare.any():
        why = "no altHAE or geoidSep: MSL altitude taken as the ellipsoidal height (error up to ~100 m)"
        skipped.append(Skipped(rid, why, int(bare.sum()), "repaired"))
        h = np.where(bare, msl, h)
    missing = ~np.isfinite(h)
    if missing.all():
        why = "no altitude in this device's fixes: height set to 0 m (vertical meaningless)"
        skipped.append(Skipped(rid, why, len(h), "repaired"))
        return np.zeros(len(h))
    if missing.any():
        why = "fixes without altitude (2D): the device's last known height"
        skipped.append(Skipped(rid, why, int(missing.sum()), "repaired"))
        return np.asarray(pd.Series(h).ffill().bfill().to_numpy(), dtype=float)
    return np.asarray(h, dtype=float)


def _sky_rows(
    a: Assembled, skipped: list[Skipped]
) -> tuple[list[tuple[Any, ...]], dict[tuple[str, int], dict[str, float]]]:
    """The satellites rows (row time, receiver, sv, el, az, cn0, used, healthy) and, per (receiver, epoch),
    the SKY values the fixes carry."""
    rows: list[tuple[Any, ...]] = []
    per_epoch: dict[tuple[str, int], dict[str, float]] = {}
    unknown: Counter[tuple[str, str]] = Counter()
    bad: Counter[str] = Counter()
    for r, rid, t in a.sky:
        at = r.host_ns if a.logger else t
        if at is None:
            continue
        cn0s: list[float] = []
        used = 0
        for sat in r.obj["satellites"]:
            if not isinstance(sat, dict):
                bad["SKY satellites"] += 1
                continue
            sv = sv_id(sat)
            if sv is None:
                unknown[(rid, unmapped_reason(sat))] += 1
                continue
            el, az, ss = (_num(sat, k, bad, "SKY") for k in ("el", "az", "ss"))
            cn0 = ss if ss > 0 else math.nan
            u = sat.get("used")
            u_val = (1.0 if u else 0.0) if isinstance(u, bool) else math.nan
            health = sat.get("health")
            healthy = {1: 1.0, 2: 0.0}.get(health, math.nan) if isinstance(health, int) else math.nan
            rows.append((at, rid, sv, el, az, cn0, u_val, healthy))
            used += u_val == 1.0
            if math.isfinite(cn0):
                cn0s.append(cn0)
        u_sat = _num(r.obj, "uSat", bad, "SKY")
        per_epoch[(rid, t)] = {
            "hdop": _num(r.obj, "hdop", bad, "SKY"),
            "vdop": _num(r.obj, "vdop", bad, "SKY"),
            "sats_used": u_sat if math.isfinite(u_sat) else float(used) if r.obj["satellites"] else math.nan,
            "cn0_mean_dbhz": float(np.mean(cn0s)) if cn0s else math.nan,
        }
    for (rid, why), n in unknown.items():
        skipped.append(Skipped(rid, why, n))
    for what, n in sorted(bad.items()):
        skipped.append(Skipped(what, "fields of the wrong type or not finite (value left out)", n, "lost"))
    return rows, per_epoch


def read_gpsd_json(path: Path, topics: Mapping[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    """Read a file of gpsd JSON reports into an EpochTable."""
    path = Path(path)
    scan = scan_reports(path)
    a = assemble(scan)
    skipped = a.skipped
    if topics:
        skipped.append(Skipped("<gpsd>", f"--topic is not used for gpsd JSON logs ({dict(topics)})", len(topics)))
    if not scan.reports:
        raise ReaderError(path, f"no gpsd JSON report in the file: {'; '.join(map(str, skipped[:4]))}", FORMAT)
    sat_rows, per_epoch = _sky_rows(a, skipped)
    if not a.fixes and not sat_rows:
        classes = Counter(r.cls for r in scan.reports)
        listed = ", ".join(f"{c} x{n}" for c, n in classes.most_common(6))
        raise NothingToJudgeError(
            path, f"gpsd JSON reports without a fix (TPV mode 2 or 3) or sky view (SKY): {listed}", FORMAT, skipped
        )
    metadata = {
        **a.metadata,
        "enum.fix_type": FIX_MEANING,
        "accuracy": ACCURACY,
        "time_source": "logger" if a.logger else "gnss",
    }
    if scan.comments:
        metadata["log_header"] = " | ".join(c for c in scan.comments[:12] if c)
    if a.logger:
        metadata |= log_clock("gpspipe's host time stamps (the logging computer's clock)", False)
    else:
        metadata["clock"] = "the receiver's UTC fix time (TPV time); gpspipe -w without -t/-u logs no other clock"
    parts: list[pd.DataFrame] = []
    streams: list[StreamInfo] = []
    by_rid: dict[str, list[_Fix]] = {}
    for f in a.fixes:
        if a.logger and f.report.host_ns is None:
            skipped.append(Skipped(f.rid, "TPV lines without the host time prefix", 1, "lost"))
            continue
        by_rid.setdefault(f.rid, []).append(f)
    heights: list[str] = []
    for rid, fixes in by_rid.items():
        cols = {k: np.array([f.values[k] for f in fixes], dtype=float) for k in fixes[0].values}
        gnss_ns = np.array([f.gnss_ns for f in fixes], dtype=np.int64)
        t_ns = np.array([f.report.host_ns for f in fixes], dtype=np.int64) if a.logger else gnss_ns
        hae, msl, sep = cols.pop("alt_hae"), cols.pop("alt_msl"), cols.pop("geoid_sep")
        heights += ["altHAE"] * bool(np.isfinite(hae).any()) + ["altMSL + geoidSep"] * bool(
            (~np.isfinite(hae) & np.isfinite(msl) & np.isfinite(sep)).any()
        )
        frame = pd.DataFrame({"t_ns": t_ns, "receiver_id": rid})
        frame["height_m"] = _heights(rid, hae, msl, sep, skipped)
        fix_type = cols.pop("fix_type").astype(np.int8)
        for k, v in cols.items():
            frame[k] = v
        frame["fix_type"] = fix_type
        sky = [per_epoch.get((rid, int(t)), {}) for t in gnss_ns]
        for k in ("hdop", "vdop", "sats_used", "cn0_mean_dbhz"):
            frame[k] = np.array([s.get(k, math.nan) for s in sky], dtype=float)
        if a.logger:
            frame["time_offset_s"] = time_offset_s(gnss_ns, t_ns)
        parts.append(frame)
        streams.append(StreamInfo("fix", rid, rid, "gpsd TPV", len(frame)))
    if heights:
        metadata["height"] = ", ".join(dict.fromkeys(heights)) + " (gpsd TPV)"
    frames: dict[str, pd.DataFrame] = {}
    if parts:
        frames["fixes"] = pd.concat(parts, ignore_index=True)
    if sat_rows:
        sats = pd.DataFrame(
            sat_rows,
            columns=["t_ns", "receiver_id", "sv_id", "elevation_deg", "azimuth_deg", "cn0_dbhz", "used", "healthy"],
        )
        sats["t_ns"] = sats["t_ns"].astype(np.int64)
        frames["satellites"] = sats
        for rid, n in sats.groupby("receiver_id")["t_ns"].nunique().items():
            streams.append(StreamInfo("satellites", str(rid), str(rid), "gpsd SKY", int(n)))
    if progress:
        progress(1, 1)
    return build_table(path, FORMAT, "unix", frames, streams, skipped, metadata=metadata)


def _is_gpsd_json(path: Path, head: bytes) -> bool:
    """Most of the head's data (bytes of its lines after `#` comments, a line cut at its end included) is
    JSON objects with a `class`, after any host time prefix: a gpsd preamble before binary or NMEA data
    (gpsd's test logs of other receivers) is not this format."""
    if path.is_dir() or not head:
        return False
    good = total = 0
    for ln in head.split(b"\n"):
        ln = ln.strip()
        if not ln or ln.startswith(b"#"):
            continue
        m = _PREFIX.match(ln)
        total += len(ln)
        good += len(ln) if _CLASS.match(ln[m.end() :] if m else ln) else 0
    return good > 0 and good * 2 >= total


FORMATS = (
    ReaderFormat(
        FORMAT,
        "gpsd JSON reports (gpspipe -w, with or without -t/-u time stamps)",
        read_gpsd_json,
        _is_gpsd_json,
        rewrite="spooflens.writers.gpsd_json_rewrite:rewrite_gpsd_json",
    ),
)
