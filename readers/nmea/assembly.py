"""Decoded NMEA sentences -> receivers, their epochs, fixes and headings on one clock.

**Receivers.** A receiver is a (source, talker) pair of position sentences (GGA, GNS, RMC, GLL): the
source is the file (in a directory of logs) and a TAG block's `s:`; so `GPGGA` and `GNGGA` in one
file are two receivers, and so are two files. A sentence without a position of its own (GST, ZDA, VTG,
GSA, GSV) belongs to the receiver of its source with the same talker, else to that source's `GN`
receiver (a multi-GNSS receiver sends GPGSV, GLGSV, GAGSV... beside GNGGA), else to the source's only
receiver; otherwise it is counted and skipped.

**Epochs.** Sentences carrying a UTC time of day (GGA, GNS, RMC, GLL, GST, ZDA) are grouped by that time;
VTG, GSA and GSV join their receiver's latest position epoch in file order (talkers send an epoch as a
burst), or, where a logger stamped every line finely enough to tell bursts apart, the epoch whose position
sentence it stamped nearest (a phone's burst ends with its RMC and GGA). A receiver whose time of day moves
in coarser steps than its fixes puts several fixes in one epoch: the first is kept, the others are said
(`extra_fixes`). Per epoch: the position from GGA, else GNS, else RMC, else GLL (the first of its kind),
among the sentences that call it valid; height = GGA/GNS MSL altitude + geoid
separation (the MSL altitude alone when the separation is blank, the receiver's last known height when the
epoch has none, 0 m when the receiver never gives one: each listed as a repair); velocity from RMC, else VTG
(speed over ground and course, no vertical); satellites used from GGA/GNS, else the GSA lists (each
satellite once: one system's list repeated in an epoch is not summed); HDOP/VDOP
from GSA, else GGA; 1-sigma horizontal accuracy sqrt((sigma_lat^2 + sigma_lon^2)/2) and vertical sigma from
GST; `cn0_mean_dbhz` the mean over the satellites GSV reports with a C/N0 (per satellite the strongest
signal). The GSV of every epoch with a fix, and of the epochs without one from the receiver's first fix on,
is the `satellites` frame: a receiver that loses its fix to jamming keeps the C/N0 collapse that lost it
(`_fixless_sky_placed` says which fix-less epochs are placed).

**Time.** A receiver's time of day is unwrapped across midnight (a drop of more than 12 h is the next
day) and cut into stretches where it goes back (a log joining recordings) or on after an hour without
a sentence (a log appended from another day, a receiver's default clock before it knew the time). Each
stretch takes the date most of its RMC/ZDA sentences give it (a stretch without one, and a receiver that
sends none, the receiver's or the log's most common date), so the recordings of a joined log keep their
own days. A date that disagrees with its stretch's continuous clock is not followed, and said where it
jumps, by how much and which date the stretch is read on: a GPS week rollover, a receiver's default date
before its almanac, a simulator's date under a time of day that carries on all look like this. When most
sentences carry a logger's time (see lines.py), the logger's clock is the time
base (independent of GNSS: a spoofer cannot move it) and the median GNSS-minus-logger offset is kept
in the metadata; otherwise the GNSS time is. Without any date or logger time, times are seconds of
the first day (`relative`). Headings have no time field: they take the logger's time of their line or
one interpolated by their position in the file between the epochs of the file's main receiver (a
talker sends in real time, so file order is time order). A magnetic heading without a variation of its own
is made true with the variation of the log's RMC nearest in time (`Variations`).
"""

from __future__ import annotations

import datetime as dt
import math
from collections import Counter, defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from readers.nmea.lines import NS, SentenceScan
from readers.nmea.sentences import (
    FIX_MEANING,
    HEADING_KINDS,
    POSITION_KINDS,
    PROPRIETARY_FIX_MEANING,
    SELF_CONTAINED_KINDS,
    Decoded,
)
from spooflens.epoch_table import EpochTable, Skipped, StreamInfo, build_table, clock_runs, log_clock, time_offset_s
from spooflens.plausibility import STRAY_GAP_NS
from spooflens.schema import FixType

DAY_S = 86_400
STALE_REPEATS = 5
GNSS_TALKERS = ("GN", "GP", "GL", "GA", "GB", "BD", "GQ", "QZ", "GI")
POSITION_PRIORITY = {"GGA": 0, "GNS": 1, "RMC": 2, "GLL": 3, **{k: 4 for k in SELF_CONTAINED_KINDS}}
JUMPS_SAID = 3  # a stretch's date jumps said one by one, the rest counted
WEEK_ROLLOVER_S = 1024 * 7 * DAY_S  # a receiver that counts the GPS week in 10 bits dates a day this far off
EpochKey = tuple[bool, int, int]  # (keyed by the receiver's time of day, its stretch, key)


@dataclass
class DecodedFile:
    """One scanned file's decoded sentences (wanted kinds only) and what its scan and decoding skipped."""

    label: str  # "" for a single-file log, the file name in a directory
    scan: SentenceScan
    decoded: list[Decoded]
    skipped: list[Skipped]


@dataclass
class Epoch:
    """One receiver epoch: its sentences and where it starts in the file."""

    key: int  # unwrapped time of day in ms; logger time in ms when `gnss` is False
    first_line: int
    gnss: bool = True  # keyed by the receiver's own time of day (else by the logger's time)
    stretch: int = 0  # the stretch of the receiver's time of day it is in (its date)
    sentences: list[Decoded] = field(default_factory=list)


@dataclass
class Stretch:
    """A run of a receiver's timed sentences (file order) on one continuous time of day, and its date."""

    first_key: int
    last_key: int
    anchor_s: float = math.nan  # its date: unwrapped time of day + anchor = seconds since 1970
    dated: int = 0  # its sentences with a date (RMC, ZDA)
    followed: int = 0  # those whose date it is read on
    jumps: list[str] = field(default_factory=list)  # where its date jumps against its time of day, said
    rolled_s: float = math.nan  # its own date, where that was a whole number of GPS week rollovers off


@dataclass
class Receiver:
    receiver_id: str
    file: DecodedFile
    antenna: str = ""  # "H": a Unicore receiver's secondary antenna
    sentences: list[Decoded] = field(default_factory=list)
    epochs: dict[EpochKey, Epoch] = field(default_factory=dict)
    stretches: list[Stretch] = field(default_factory=list)
    day_anchor_s: float = math.nan  # the most common date of its sentences (or the log's): stretches without one
    untimed: int = 0  # sentences without a time of day in a receiver that never gave one

    def anchor_s(self, epoch: Epoch) -> float:
        """The date an epoch of the receiver's own time of day is read on (NaN: none known)."""
        own = self.stretches[epoch.stretch].anchor_s if epoch.stretch < len(self.stretches) else math.nan
        return own if math.isfinite(own) else self.day_anchor_s

    def clock_s(self, epoch: Epoch) -> float:
        anchor = self.anchor_s(epoch)
        return epoch.key / 1000 + (anchor if math.isfinite(anchor) else 0.0)


def _source(file: DecodedFile, d: Decoded) -> str:
    return "/".join(p for p in (file.label, d.sentence.source) if p)


def _rid(source: str, talker: str) -> str:
    return f"{source}/{talker}" if source else talker


def receivers_of(files: list[DecodedFile], skipped: list[Skipped]) -> list[Receiver]:
    """Every receiver of the log with its sentences (file order), by the association rule above."""
    out: dict[str, Receiver] = {}
    for f in files:
        sources: dict[str, str] = {}
        positions: Counter[str] = Counter()  # position sentences per receiver
        positioned: set[str] = set()
        for d in f.decoded:
            if d.kind in POSITION_KINDS:
                source = _source(f, d)
                rid = _rid(source, d.receiver)
                out.setdefault(rid, Receiver(rid, f, d.antenna))
                sources[rid] = source
                positions[rid] += 1
                if math.isfinite(d.lat) and math.isfinite(d.lon):
                    positioned.add(rid)
        # a multi-system receiver's per-system lines ($GPGNS, $GLGNS with no position beside its $GNGNS, NMEA
        # 4.11) are no receiver of their own: read with its GN receiver, they leave it its GPS and GLONASS sky
        for rid, source in sources.items():
            gn = _rid(source, "GN" + out[rid].antenna)
            if rid not in positioned and gn in positioned and rid != gn:
                skipped.append(Skipped(rid, f"position sentences without a position, read as {gn}'s", positions[rid]))
                del out[rid]
        orphans: Counter[str] = Counter()
        for d in f.decoded:
            if d.kind in HEADING_KINDS:
                continue
            source = _source(f, d)
            rid = _rid(source, d.receiver)
            if rid not in out:
                # never across antennas: a secondary antenna's sky and DOPs are not the primary's
                mine = [
                    r
                    for r in out.values()
                    if r.file is f and r.receiver_id.rpartition("/")[0] == source and r.antenna == d.antenna
                ]
                gn = _rid(source, "GN" + d.antenna)
                rid = gn if gn in out else (mine[0].receiver_id if len(mine) == 1 else "")
            if rid:
                out[rid].sentences.append(d)
            else:
                orphans[f"{d.talker}{d.kind}"] += 1
        for what, n in orphans.items():
            skipped.append(Skipped(what, "no receiver to attach to (no position sentences from this source)", n))
    return list(out.values())


def _unwrapped_ms(tods: np.ndarray) -> np.ndarray:
    """Times of day (s, file order) -> ms on a continuous clock: a drop of more than 12 h is midnight."""
    step = np.diff(tods, prepend=tods[:1])
    days = np.cumsum(np.where(step < -DAY_S / 2, 1, 0) - np.where(step > DAY_S / 2, 1, 0))
    return np.round((tods + days * DAY_S) * 1000).astype(np.int64)


def _iso_day(day: float) -> str:
    try:
        return (dt.date(1970, 1, 1) + dt.timedelta(days=math.floor(day))).isoformat()
    except OverflowError:
        return f"day {math.floor(day)} since 1970"


def _tod(key_ms: int) -> str:
    """An unwrapped time of day as hh:mm:ss (its fraction where it has one)."""
    ms = key_ms % (DAY_S * 1000)
    text = f"{ms // 3_600_000:02d}:{ms // 60_000 % 60:02d}:{ms // 1000 % 60:02d}"
    return text + (f".{ms % 1000:03d}".rstrip("0") if ms % 1000 else "")


def _days(delta_s: float) -> str:
    n = round(delta_s / DAY_S)
    weeks = f" ({abs(n) // 7} weeks)" if n % 7 == 0 and abs(n) >= 14 else ""
    return f"{abs(n)} day{'s' if abs(n) != 1 else ''}{weeks} {'forward' if n > 0 else 'back'}"


def _date_stretch(stretch: Stretch, dated: list[tuple[Decoded, int]]) -> Counter[float]:
    """Date one stretch by its dated sentences (and their unwrapped times of day), file order: the date
    most of them give it; every place its date changes against its time of day is said. Its dates, counted."""
    anchors = [round(((d.day or 0) * DAY_S + d.tod_s - k / 1000) / DAY_S) * DAY_S for d, k in dated]
    counts = Counter(float(a) for a in anchors)
    if not counts:
        return counts
    stretch.anchor_s, stretch.followed = counts.most_common(1)[0]
    stretch.dated = len(anchors)
    for (before, k0), (after, k1), a0, a1 in zip(dated, dated[1:], anchors, anchors[1:], strict=False):
        if a1 != a0 and before.day is not None and after.day is not None:
            stretch.jumps.append(
                f"at {_tod(k1)} {after.kind}'s date is {_iso_day(after.day)} where the time of day, carried on "
                f"from {_iso_day(before.day)} {_tod(k0)}, gives {_iso_day((a0 + k1 / 1000) / DAY_S)}: {_days(a1 - a0)}"
            )
    return counts


def assign_epochs(rx: Receiver) -> None:
    """Group the receiver's sentences into epochs (by unwrapped time of day) and date its stretches."""
    timed = [d for d in rx.sentences if math.isfinite(d.tod_s)]
    keys = _unwrapped_ms(np.array([d.tod_s for d in timed])) if timed else np.zeros(0, dtype=np.int64)
    # a new stretch where the time of day goes back as the table's recordings are cut, or on after an hour
    runs = clock_runs(keys * 1_000_000, max_gap_ns=STRAY_GAP_NS)
    key_of = {id(d): (int(r), int(k)) for d, r, k in zip(timed, runs.tolist(), keys.tolist(), strict=True)}
    members: dict[int, list[tuple[Decoded, int]]] = defaultdict(list)
    for d, r, k in zip(timed, runs.tolist(), keys.tolist(), strict=True):
        members[r].append((d, k))
    dates: Counter[float] = Counter()
    for r in range(len(members)):
        rx.stretches.append(Stretch(min(k for _, k in members[r]), max(k for _, k in members[r])))
        dates += _date_stretch(rx.stretches[r], [(d, k) for d, k in members[r] if d.day is not None])
    if dates:
        rx.day_anchor_s = float(dates.most_common(1)[0][0])
    for stretch in rx.stretches:  # a GPS week rollover: the receiver's own day, read on its other date
        off = stretch.anchor_s - rx.day_anchor_s
        if math.isfinite(off) and off and off % WEEK_ROLLOVER_S == 0:
            stretch.rolled_s, stretch.anchor_s = stretch.anchor_s, rx.day_anchor_s
    current: EpochKey | None = None
    pending: list[Decoded] = []
    for d in rx.sentences:
        key: EpochKey | None = None
        if id(d) in key_of:
            key = (True, *key_of[id(d)])
        elif d.kind in POSITION_KINDS and d.sentence.host_ns is not None:
            key = (False, 0, d.sentence.host_ns // 1_000_000)  # a talker that sends no time: logger time
        if key is None:
            if current is None:
                pending.append(d)
            else:
                rx.epochs[current].sentences.append(d)
            continue
        epoch = rx.epochs.setdefault(key, Epoch(key[2], d.sentence.line, key[0], key[1]))
        epoch.sentences.append(d)
        if d.kind in POSITION_KINDS:
            if current is None and pending:
                epoch.sentences.extend(pending)
                pending = []
            current = key
    rx.untimed = len(pending)
    _place_by_logger_time(rx)


def _place_by_logger_time(rx: Receiver) -> None:
    """Move each sentence without a time of day (GSV, GSA, VTG) to the epoch whose position sentence the
    logger stamped nearest it, where the stamps are fine enough to tell bursts apart: a phone writes its
    second as GSV, GSA, VTG, then RMC and GGA (GnssLogger's NMEA), so file order put its sky a second early."""
    anchors: list[tuple[int, EpochKey]] = []
    for key, epoch in rx.epochs.items():
        stamps = [d.sentence.host_ns for d in epoch.sentences if d.kind in POSITION_KINDS]
        if stamps and all(ns is not None for ns in stamps):
            anchors.append((min(ns for ns in stamps if ns is not None), key))
    if len(anchors) < 3:
        return
    anchors.sort()
    at = np.array([a for a, _ in anchors], dtype=np.int64)
    spacing = float(np.median(np.diff(at)))
    movable = [
        (key, d, d.sentence.host_ns)
        for key, epoch in rx.epochs.items()
        for d in epoch.sentences
        if not math.isfinite(d.tod_s) and d.kind not in POSITION_KINDS and d.sentence.host_ns is not None
    ]
    if not movable or spacing <= 0:
        return
    host = np.array([ns for _, _, ns in movable], dtype=np.int64)
    if _stamp_resolution_ns(host.tolist()) > 0.1 * spacing:
        return
    k = np.clip(np.searchsorted(at, host), 1, len(at) - 1)
    nearest = np.where(np.abs(at[k] - host) < np.abs(host - at[k - 1]), k, k - 1)
    close = np.abs(at[nearest] - host) < 0.5 * spacing
    moved: set[EpochKey] = set()
    for (key, d, _), i, near in zip(movable, nearest.tolist(), close.tolist(), strict=True):
        target = anchors[i][1]
        if near and target != key:
            rx.epochs[key].sentences.remove(d)
            rx.epochs[target].sentences.append(d)
            moved |= {key, target}
    for key in moved:
        rx.epochs[key].sentences.sort(key=lambda d: d.sentence.line)


def _same_fix(d: Decoded) -> tuple[str, str, str]:
    """A position sentence's kind and position, alike for every repeat of one fix (a blank position too)."""
    return d.kind, repr(d.lat), repr(d.lon)


def drop_stale_epochs(rxs: list[Receiver], skipped: list[Skipped]) -> None:
    """Drop the epochs in which a receiver repeats one fix while the log goes on: a relay (an autopilot's
    `$APGLL`, a multiplexer) re-sending a position it took long before, under that position's old time.
    Read as a fix it would be one epoch minutes off the log, its start or end. An epoch is stale when one
    position sentence kind comes STALE_REPEATS times or more in it, spread over as many epochs of another
    receiver of the file (a receiver at 5 Hz writing whole seconds repeats its time within one second). One
    fix: the same position each time; a receiver whose time moves in coarser steps than its fixes writes
    several positions under one time, each a fix of its own (`extra_fixes`), no relay."""
    for rx in rxs:
        others = np.sort(
            [e.first_line for o in rxs if o is not rx and o.file is rx.file for e in o.epochs.values()]
        ).astype(np.int64)
        for key, epoch in list(rx.epochs.items()):
            repeats = Counter(_same_fix(d) for d in epoch.sentences if d.kind in POSITION_KINDS)
            if not repeats or max(repeats.values()) < STALE_REPEATS:
                continue
            repeated = repeats.most_common(1)[0][0]
            lines = [d.sentence.line for d in epoch.sentences if d.kind in POSITION_KINDS and _same_fix(d) == repeated]
            between = int(np.searchsorted(others, max(lines), "right") - np.searchsorted(others, min(lines), "left"))
            if between < STALE_REPEATS:
                continue
            del rx.epochs[key]
            (kind, _, _), n = repeats.most_common(1)[0]
            hours, minutes = int(epoch.key // 3_600_000) % 24, int(epoch.key // 60_000) % 60
            stamp = f"{hours:02d}:{minutes:02d}:{epoch.key / 1000 % 60:04.1f}"
            what = "its time of day" if epoch.gnss else "one logger time"
            skipped.append(
                Skipped(
                    rx.receiver_id,
                    f"{kind} repeating one fix at {stamp} ({what}) {n} times across {between} epochs of other "
                    "receivers: a relay holding a stale fix, not read as one",
                    len(epoch.sentences),
                )
            )


def _own_time_ns(rx: Receiver, epoch: Epoch) -> int:
    """The receiver's time of an epoch with its own date where a sentence of the epoch carries one (RMC,
    ZDA): a spoofer's date moves it, while the log's clock follows the date most of its stretch has."""
    dated = next((d for d in epoch.sentences if d.day is not None and math.isfinite(d.tod_s)), None)
    if dated is not None and dated.day is not None:
        return round((dated.day * DAY_S + dated.tod_s) * NS)
    return round(rx.clock_s(epoch) * NS)


@dataclass
class FixRow:
    key: int
    first_line: int
    host_ns: int | None
    values: dict[str, float]


def _first(values: Iterable[float]) -> float:
    return next((v for v in values if math.isfinite(v)), math.nan)


def _gsa_used(gsa: list[Decoded]) -> set[tuple[str, int]]:
    """The satellites an epoch's GSA list as used, each once: the lists of distinct systems add up (a GN
    receiver sends one GSA per system), a system's list repeated in one epoch does not (an epoch holding
    several of the receiver's cycles under one time of day)."""
    return {(_GSA_SYSTEM_TALKER.get(g.gsa_system, g.talker), v) for g in gsa for v in g.used_svids}


def extra_fixes(epoch: Epoch) -> int:
    """How many fixes of an epoch beyond its first have a position of their own: a receiver whose time of day
    moves in coarser steps than its fixes writes several under one time (a chartplotter's GGA, GLL and RMC
    every ~2 s under a time moving in 10 s steps). Counted per sentence kind, the most any kind has: the GGA
    and the RMC of one cycle may differ in their last digit; a sentence repeated word for word (a relay, a bus
    echo) is no fix of its own."""
    positions: dict[str, set[tuple[float, float]]] = defaultdict(set)
    for d in epoch.sentences:
        if d.kind in POSITION_KINDS and d.valid and math.isfinite(d.lat) and math.isfinite(d.lon):
            positions[d.kind].add((d.lat, d.lon))
    return max((len(p) - 1 for p in positions.values()), default=0)


def _extra_fixes_said(rx: Receiver, per_epoch: list[tuple[Epoch, int]]) -> Skipped | None:
    """The line for the fixes `extra_fixes` counts: the epoch keeps its first fix, whose time its time field
    states best (the first written under a new time); the others' times are not known finer than the
    receiver's time step, and a time made up for them (spread over the step) would set a position change
    against a time the receiver never gave, which the detectors that weigh position change against velocity
    would read as an error of the receiver. Said with the receiver's time step and fix interval where its
    times hold several fixes as a rule (median), else with how many of its times hold several."""
    extra = sum(n for _, n in per_epoch)
    if not extra:
        return None
    crowded = sum(n > 0 for _, n in per_epoch)
    gnss = all(e.gnss for e, n in per_epoch if n)
    what = "a time of day" if gnss else "a logger time"
    keys = np.unique([e.key for e, _ in per_epoch if e.gnss == gnss])
    per_time = float(np.median([n + 1 for _, n in per_epoch]))
    if per_time > 1 and len(keys) > 1:
        step_s = float(np.median(np.diff(keys))) / 1000
        how = (
            f"the receiver's time moves in {step_s:g} s steps, its fixes come every ~{step_s / per_time:.2g} s; "
            f"{crowded} of its {len(per_epoch)} times hold several"
        )
    elif len(per_epoch) == 1:
        how = f"the receiver's only time holds {extra + 1}"
    else:
        how = f"{crowded} of the receiver's {len(per_epoch)} times hold several"
    why = f"fixes with a position of their own under {what} already used ({how}): their times are not known, not used"
    return Skipped(rx.receiver_id, why, extra)


def epoch_fix(epoch: Epoch) -> tuple[dict[str, float], str] | None:
    """The fix of one epoch (schema names, height still MSL + separation), or None (no valid position)."""
    positions = sorted(
        (d for d in epoch.sentences if d.kind in POSITION_KINDS),
        key=lambda d: POSITION_PRIORITY[d.kind],
    )
    usable = [d for d in positions if d.valid and math.isfinite(d.lat) and math.isfinite(d.lon)]
    if not usable:
        return None if not positions else ({}, "invalid")
    pos = usable[0]
    by_kind: dict[str, list[Decoded]] = defaultdict(list)
    for d in epoch.sentences:
        by_kind[d.kind].append(d)
    fix_type = pos.fix_type
    gsa = by_kind["GSA"]
    if fix_type == FixType.FIX_3D and gsa and all(g.nav_mode == 2 for g in gsa):
        fix_type = int(FixType.FIX_2D)
    own = [d for k in SELF_CONTAINED_KINDS for d in by_kind[k]]  # their own height, satellites, velocity
    moving = by_kind["RMC"] + by_kind["VTG"] + own
    speed = _first(d.speed_mps for d in moving)
    course = _first(d.course_deg for d in moving if math.isfinite(d.speed_mps))
    if speed == 0.0 and not math.isfinite(course):
        course = 0.0
    gga = by_kind["GGA"] + by_kind["GNS"] + own
    gsa_used = len(_gsa_used(gsa))
    gst = by_kind["GST"]
    std_lat, std_lon = _first(g.std_lat_m for g in gst), _first(g.std_lon_m for g in gst)
    cn0: dict[tuple[str, int], float] = {}
    for g in by_kind["GSV"]:
        for sv, _, _, c, _ in g.satellites:
            if math.isfinite(c) and c > 0:
                cn0[(g.talker, sv)] = max(c, cn0.get((g.talker, sv), 0.0))
    alt, sep = _first(d.alt_msl_m for d in gga), _first(d.geoid_sep_m for d in gga)
    if math.isfinite(pos.height_m):  # already above the ellipsoid: no separation to add
        alt, sep = pos.height_m, 0.0
    values = {
        "lat_deg": pos.lat,
        "lon_deg": pos.lon,
        "alt_msl_m": alt,
        "geoid_sep_m": sep,
        "vel_e_mps": speed * math.sin(math.radians(course)),
        "vel_n_mps": speed * math.cos(math.radians(course)),
        "speed_mps": speed if not math.isfinite(course) else math.nan,  # a speed without a course
        "sats_used": _first([*(d.sats_used for d in gga), float(gsa_used) if gsa_used else math.nan]),
        "hdop": _first([*(g.hdop for g in gsa), *(d.hdop for d in gga)]),
        "vdop": _first(g.vdop for g in gsa),
        "h_acc_m": math.sqrt((std_lat**2 + std_lon**2) / 2),
        "v_acc_m": _first(g.std_alt_m for g in gst),
        "cn0_mean_dbhz": float(np.mean(list(cn0.values()))) if cn0 else math.nan,
        "fix_type": float(fix_type),
    }
    return values, pos.kind


_TALKER_SYSTEM = {"GP": "G", "GL": "R", "GA": "E", "GB": "C", "BD": "C", "GQ": "J", "QZ": "J", "GI": "I"}
# NMEA 4.10 GSA system IDs, as the talker of that system
_GSA_SYSTEM_TALKER = {1: "GP", 2: "GL", 3: "GA", 4: "GB", 5: "GQ", 6: "GI"}


def nmea_sv_id(talker: str, svid: int) -> str | None:
    """RINEX-style id of an NMEA satellite number (NMEA 0183 numbering: GPS 1-32, SBAS 33-64, GLONASS
    65-96, QZSS 193-202; Galileo, BeiDou and NavIC by their talker); None when it cannot be told."""
    if 193 <= svid <= 202:
        return f"J{svid - 192:02d}"
    system = _TALKER_SYSTEM.get(talker)
    if system in (None, "G"):
        if 1 <= svid <= 32:
            return f"G{svid:02d}"
        if 33 <= svid <= 64:
            return f"S{svid + 87 - 100:02d}"
        if 65 <= svid <= 96:
            return f"R{svid - 64:02d}"
        return None
    if system == "R":
        return f"R{svid - 64:02d}" if 65 <= svid <= 96 else (f"R{svid:02d}" if 1 <= svid <= 24 else None)
    if system == "C" and 201 <= svid <= 263:
        svid -= 200
    return f"{system}{svid:02d}" if 1 <= svid <= 99 else None


def epoch_satellites(epoch: Epoch) -> list[tuple[str, float, float, float, float]]:
    """The epoch's GSV satellites (sv id, elevation, azimuth, strongest C/N0, used per GSA: 1/0, NaN when
    the epoch has no GSA), one per satellite."""
    sky: dict[str, list[float]] = {}
    used: set[str] = set()
    has_gsa = False
    for d in epoch.sentences:
        if d.kind == "GSV":
            for svid, el, az, c, _ in d.satellites:
                sv = nmea_sv_id(d.talker, svid)
                if sv is None:
                    continue
                row = sky.setdefault(sv, [math.nan, math.nan, math.nan])
                row[0] = el if math.isfinite(el) else row[0]
                row[1] = az if math.isfinite(az) else row[1]
                if math.isfinite(c) and c > 0 and not (c <= row[2]):
                    row[2] = c
        elif d.kind == "GSA":
            has_gsa = True
            talker = _GSA_SYSTEM_TALKER.get(d.gsa_system, d.talker)
            used.update(sv for v in d.used_svids if (sv := nmea_sv_id(talker, v)) is not None)
    return [(sv, el, az, c, (1.0 if sv in used else 0.0) if has_gsa else math.nan) for sv, (el, az, c) in sky.items()]


def _stretch_dates_said(rx: Receiver, spans: dict[int, list[int]]) -> list[Skipped]:
    """What the dating of the receiver's stretches repaired, each line with its stretch's span on the log's
    clock (so a log joining recordings lists it in its own): the dates not followed in a stretch, where and
    by how much they jumped and which date the stretch is read on; and, where its stretches are on more than
    one date, the stretches with no date of their own, given the receiver's most common one."""
    out: list[Skipped] = []
    days = {s.anchor_s for s in rx.stretches if math.isfinite(s.anchor_s)}
    for i, s in enumerate(rx.stretches):
        span = (min(spans[i]), max(spans[i])) if spans.get(i) else None
        start, end = s.anchor_s + s.first_key / 1000, s.anchor_s + s.last_key / 1000
        if math.isfinite(s.rolled_s):
            own_day = _iso_day(s.rolled_s / DAY_S + s.first_key / 1000 / DAY_S)
            why = (
                f"dates of a stretch of the time of day ({_tod(s.first_key)} to {_tod(s.last_key)}) "
                f"{_days(s.rolled_s - s.anchor_s)} from the receiver's most common date, whole GPS week rollovers "
                f"(1024 weeks each): read on {_iso_day(start / DAY_S)} as the rest, not on {own_day}"
            )
            out.append(Skipped(rx.receiver_id, why, s.followed, "repaired", span_ns=span))
        if s.jumps:
            said = "; ".join(s.jumps[:JUMPS_SAID])
            if len(s.jumps) > JUMPS_SAID:
                said += f"; and {len(s.jumps) - JUMPS_SAID} more"
            end_day = "" if math.floor(start / DAY_S) == math.floor(end / DAY_S) else _iso_day(end / DAY_S) + " "
            on = f"{_iso_day(start / DAY_S)} {_tod(s.first_key)} to {end_day}{_tod(s.last_key)}"
            why = (
                f"dates that jump against the continuous time of day, not followed: {said}. The stretch is read as "
                f"{on}, the date of {s.followed} of its {s.dated} dated sentences"
            )
            out.append(Skipped(rx.receiver_id, why, s.dated - s.followed, "repaired", span_ns=span))
        elif len(days) > 1 and not math.isfinite(s.anchor_s) and math.isfinite(rx.day_anchor_s):
            n = sum(e.stretch == i and e.gnss for e in rx.epochs.values())
            why = (
                f"epochs of a stretch of the time of day without a date of its own ({_tod(s.first_key)} to "
                f"{_tod(s.last_key)}) among stretches of other dates: the receiver's most common date "
                f"({_iso_day(rx.day_anchor_s / DAY_S)}) taken"
            )
            out.append(Skipped(rx.receiver_id, why, n, "repaired", span_ns=span))
    return out


def _heights(rid: str, cols: dict[str, np.ndarray], skipped: list[Skipped]) -> np.ndarray:
    """Ellipsoidal heights: MSL altitude + geoid separation, with the repairs the docstring lists."""
    alt, sep = cols.pop("alt_msl_m"), cols.pop("geoid_sep_m")
    no_sep = np.isfinite(alt) & ~np.isfinite(sep)
    if no_sep.any():
        reason = "no geoid separation: MSL altitude taken as the ellipsoidal height (error up to ~100 m)"
        skipped.append(Skipped(rid, reason, int(no_sep.sum()), "repaired"))
    h = alt + np.where(np.isfinite(sep), sep, 0.0)
    missing = ~np.isfinite(h)
    if missing.all():
        skipped.append(
            Skipped(
                rid,
                "no altitude in this receiver's sentences: height set to 0 m (vertical meaningless)",
                len(h),
                "repaired",
            )
        )
        return np.zeros(len(h))
    if missing.any():
        filled = pd.Series(h).ffill().bfill().to_numpy()
        before_first = int(np.argmax(~missing))  # epochs before the receiver's first height have no last one
        reason = "epochs without altitude: the receiver's last known height" + (
            f" (the {before_first} before its first: that first height)" if before_first else ""
        )
        skipped.append(Skipped(rid, reason, int(missing.sum()), "repaired"))
        return filled
    return h


def _fixless_sky_placed(fix_ns: list[int], fixless_ns: list[int]) -> tuple[list[bool], list[bool]]:
    """Which fix-less epochs' sky goes into the satellites frame: those from the receiver's first fix on that no
    hour of silence separates from its fixes (every one of a receiver that never had a fix). Before its first
    fix a receiver is acquiring: a cold start's sky, no level a later loss is measured against. And a receiver
    that does not know the time stamps its epochs with its own default clock (gpsd's MTK-3301 and RGM3800
    logs: 1980-01-05 23:59, hours from their fixes; GP-320FW's after a reboot): such a time would stretch
    the log over hours it never recorded. Also which of those not placed are on such a clock: an hour of
    silence from every fix, before the first or after it (the others are the acquisition before it)."""
    if not fix_ns:
        return [True] * len(fixless_ns), [False] * len(fixless_ns)
    t = np.array(fix_ns + fixless_ns, dtype=np.int64)
    is_fix = np.arange(len(t)) < len(fix_ns)
    order = np.argsort(t, kind="stable")
    run = np.empty(len(t), dtype=np.int64)
    run[order] = np.cumsum(np.concatenate(([0], np.diff(t[order]) > STRAY_GAP_NS)))
    placed = np.isin(run, run[is_fix]) & (t >= min(fix_ns))
    acquiring = (run == run[is_fix].min()) & (t < min(fix_ns))
    return placed[len(fix_ns) :].tolist(), (~placed & ~acquiring)[len(fix_ns) :].tolist()


SatRow = tuple[int, str, str, float, float, float, float]  # t_ns, receiver, sv, elevation, azimuth, C/N0, used


def _receiver_sky(
    rx: Receiver,
    sky_epochs: list[tuple[int, Epoch, bool]],
    fixless_epochs: dict[tuple[str, int], tuple[Epoch, Path]],
    skipped: list[Skipped],
) -> list[SatRow]:
    """The satellites rows of the receiver's epochs (time, epoch, has a fix), in file order: every epoch with
    a fix, and those without one that `_fixless_sky_placed` places (each recorded in `fixless_epochs`; those
    on another clock are counted). File order, because a time that goes back in it is where a log joins
    recordings."""
    fix_ns = [t for t, _, has_fix in sky_epochs if has_fix]
    fixless_ns = [t for t, _, has_fix in sky_epochs if not has_fix]
    placed_fixless, other_clock_fixless = (iter(x) for x in _fixless_sky_placed(fix_ns, fixless_ns))
    out: list[SatRow] = []
    astray = 0  # on another clock: an hour or more from the fixes (the acquisition before the first fix: not counted)
    for at_ns, epoch, has_fix in sky_epochs:
        keep = has_fix or next(placed_fixless)
        other_clock = not has_fix and next(other_clock_fixless)
        sky = epoch_satellites(epoch)
        if sky and other_clock:
            astray += 1
        elif sky and keep:
            out += [(at_ns, rx.receiver_id, *sat) for sat in sky]
            if not has_fix:
                fixless_epochs.setdefault((rx.receiver_id, at_ns), (epoch, rx.file.scan.path))
    if astray:
        why = (
            "sky (GSV) of epochs without a fix, an hour or more from any fix (the receiver's own clock before it "
            "knew the time): not placed"
        )
        skipped.append(Skipped(rx.receiver_id, why, astray))
    return out


@dataclass
class Clock:
    """How table times are made: the logger's clock or GNSS time (`reference` as EpochTable has it)."""

    logger: bool
    reference: str


def line_times(file: DecodedFile, anchors: list[tuple[int, int]], clock: Clock) -> dict[int, int]:
    """Time (ns) of every decoded sentence's line, interpolated by file position between anchors.

    Anchors are the GNSS epochs of the file's main receiver, or with the logger's clock the first line
    of each run of equal logger times. A logger that stamps whole seconds stamps a burst alike: the lines
    of a run are spread by their position over the stamps' resolution (at most up to the next stamp); a
    logger that stamps milliseconds (GnssLogger) stamped each line when it came, and its lines keep their
    stamps (spread up to the next stamp, its fixes came most of a second late).
    """
    lines = np.array([d.sentence.line for d in file.decoded], dtype=np.int64)
    resolution = np.inf
    if clock.logger:
        stamped = sorted((d.sentence.line, d.sentence.host_ns) for d in file.decoded if d.sentence.host_ns is not None)
        known = [(ln, t) for i, (ln, t) in enumerate(stamped) if i == 0 or t != stamped[i - 1][1]]
        resolution = _stamp_resolution_ns([t for _, t in known])
    else:
        known = sorted(dict(anchors).items())
    if not known:
        return {}
    x = np.array([k for k, _ in known], dtype=np.float64)
    y = np.maximum.accumulate(np.array([v for _, v in known], dtype=np.float64))
    if len(x) > 1:
        i = np.clip(np.searchsorted(x, lines, side="right") - 1, 0, len(x) - 2)
        step = np.minimum(np.diff(y), resolution)[i]
        t = y[i] + np.clip((lines - x[i]) / np.maximum(x[i + 1] - x[i], 1), 0.0, 1.0) * step
        # beyond the first/last anchor: extrapolate at the median seconds per line
        slope = float(np.median(np.minimum(np.diff(y), resolution) / np.maximum(np.diff(x), 1)))
        t = np.where(lines < x[0], y[0] - (x[0] - lines) * slope, t)
        t = np.where(lines > x[-1], y[-1] + np.minimum((lines - x[-1]) * slope, resolution), t)
    else:
        t = np.full(len(lines), y[0])
    return dict(zip(lines.tolist(), np.round(t).astype(np.int64).tolist(), strict=True))


def _stamp_resolution_ns(stamps: list[int]) -> float:
    """The coarsest power of ten (1 ns to 1 s) every logger stamp is a whole multiple of."""
    values = np.asarray(stamps, dtype=np.int64)
    for exponent in range(9, 0, -1):
        if not np.any(values % (10**exponent)):
            return float(10**exponent)
    return 1.0


@dataclass
class Assembled:
    fixes: pd.DataFrame | None
    headings: pd.DataFrame | None
    streams: list[StreamInfo]
    time_reference: str
    metadata: dict[str, str]
    # (receiver id, fix time in ns on the log's clock) -> the epoch behind that fix row and its file (inject)
    fix_epochs: dict[tuple[str, int], tuple[Epoch, Path]] = field(default_factory=dict)
    satellites: pd.DataFrame | None = None
    # the same for the epochs without a fix whose sky is in `satellites` (inject: a jammer's C/N0 in their GSV)
    fixless_epochs: dict[tuple[str, int], tuple[Epoch, Path]] = field(default_factory=dict)


def assemble(files: list[DecodedFile], skipped: list[Skipped]) -> Assembled:
    """Every file's receivers and headings on one clock (see the module docstring)."""
    rxs = receivers_of(files, skipped)
    for rx in rxs:
        assign_epochs(rx)
    drop_stale_epochs(rxs, skipped)
    dated = [rx for rx in rxs if math.isfinite(rx.day_anchor_s)]
    log_anchor = dated[0].day_anchor_s if dated else math.nan
    for rx in rxs:
        if not math.isfinite(rx.day_anchor_s) and dated and rx.epochs:
            rx.day_anchor_s = log_anchor
            skipped.append(Skipped(rx.receiver_id, "no RMC/ZDA date: the log's date taken", len(rx.epochs), "repaired"))
        if rx.untimed:
            skipped.append(Skipped(rx.receiver_id, "sentences without a time of day, in no epoch", rx.untimed))
    all_sentences = [d for f in files for d in f.decoded]
    with_host = sum(d.sentence.host_ns is not None for d in all_sentences)
    logger = bool(all_sentences) and with_host >= len(all_sentences) / 2
    reference = "unix" if (logger or dated) else "relative"
    clock = Clock(logger, reference)
    meaning = FIX_MEANING
    if any(d.kind in SELF_CONTAINED_KINDS for d in all_sentences):
        meaning += ". " + PROPRIETARY_FIX_MEANING
    metadata: dict[str, str] = {"enum.fix_type": meaning, "time_source": "logger" if logger else "gnss"}
    comments = [c for f in files for c in f.scan.comments if c][:12]
    if comments:
        metadata["log_header"] = " | ".join(comments)

    fix_parts: list[pd.DataFrame] = []
    sat_rows: list[SatRow] = []
    fix_epochs: dict[tuple[str, int], tuple[Epoch, Path]] = {}
    fixless_epochs: dict[tuple[str, int], tuple[Epoch, Path]] = {}
    streams: list[StreamInfo] = []
    offsets: list[float] = []
    times_by_file: dict[int, dict[int, int]] = {}
    for f in files:
        mine = [rx for rx in rxs if rx.file is f and rx.epochs]
        main = max(mine, key=lambda r: len(r.epochs), default=None)
        anchors = (
            [(e.first_line, round(main.clock_s(e) * NS)) for e in main.epochs.values() if e.gnss]
            if main is not None
            else []
        )
        times_by_file[id(f)] = line_times(f, anchors, clock)
    for rx in rxs:
        rows: list[tuple[int, dict[str, float]]] = []
        own_ns: list[int | None] = []  # the receiver's own date and time of each row, against the logger's
        invalid = 0
        kinds = Counter(d.kind for d in rx.sentences)
        line_t = times_by_file[id(rx.file)]
        sky_epochs: list[tuple[int, Epoch, bool]] = []  # every timed epoch in file order, and whether it has a fix
        spans: dict[int, list[int]] = defaultdict(list)  # each stretch's epochs' times on the log's clock
        crowded: list[tuple[Epoch, int]] = []  # every epoch with a fix, and its fixes beyond its first
        for epoch in rx.epochs.values():
            got = epoch_fix(epoch)
            if got is None:
                continue
            values, _ = got
            if values:
                crowded.append((epoch, extra_fixes(epoch)))
            gnss_ns = round(rx.clock_s(epoch) * NS) if epoch.gnss else epoch.key * 1_000_000
            if not values:  # no fix, but its sky (GSV) is what the receiver saw: a fix lost to jamming shows there
                invalid += 1
                at_ns = line_t.get(epoch.first_line) if logger else gnss_ns
                if at_ns is not None:
                    sky_epochs.append((int(at_ns), epoch, False))
                    if epoch.gnss:
                        spans[epoch.stretch].append(int(at_ns))
                continue
            own: int | None = None
            if logger:
                t_ns = line_t.get(epoch.first_line)
                if t_ns is not None and epoch.gnss and math.isfinite(rx.anchor_s(epoch)):
                    offsets.append((gnss_ns - t_ns) / NS)
                    own = _own_time_ns(rx, epoch)
            else:
                t_ns = gnss_ns
            if t_ns is None:
                continue
            rows.append((int(t_ns), values))
            if epoch.gnss:
                spans[epoch.stretch].append(int(t_ns))
            own_ns.append(own)
            fix_epochs.setdefault((rx.receiver_id, int(t_ns)), (epoch, rx.file.scan.path))
            sky_epochs.append((int(t_ns), epoch, True))
        if invalid:
            skipped.append(
                Skipped(rx.receiver_id, "epochs without a valid position (GGA quality 0, RMC/GLL void)", invalid)
            )
        if (said := _extra_fixes_said(rx, crowded)) is not None:
            skipped.append(said)
        skipped += _stretch_dates_said(rx, spans)
        sat_rows += _receiver_sky(rx, sky_epochs, fixless_epochs, skipped)
        msgtype = "NMEA " + " ".join(f"{k}" for k in sorted(kinds))
        if not rows:  # a receiver that never had a fix
            streams.append(StreamInfo("fix", rx.receiver_id, rx.file.scan.path.name, msgtype, 0))
            continue
        cols = {k: np.array([v[k] for _, v in rows], dtype=float) for k in rows[0][1]}
        cols["height_m"] = _heights(rx.receiver_id, cols, skipped)
        fix_type = cols.pop("fix_type").astype(np.int8)
        frame = pd.DataFrame({"t_ns": np.array([t for t, _ in rows], dtype=np.int64), "receiver_id": rx.receiver_id})
        for k, v in cols.items():
            frame[k] = v
        frame["fix_type"] = fix_type
        if any(o is not None for o in own_ns):
            known = np.array([o is not None for o in own_ns])
            own_arr = np.array([o if o is not None else 0 for o in own_ns], dtype=np.int64)
            frame["time_offset_s"] = time_offset_s(own_arr, frame["t_ns"].to_numpy(np.int64), known)
        fix_parts.append(frame)
        streams.append(StreamInfo("fix", rx.receiver_id, rx.file.scan.path.name, msgtype, len(rows)))
    if offsets:
        metadata["clock.gnss_minus_logger_s"] = f"{float(np.median(offsets)):.3f}"
        metadata |= log_clock("the logger's time stamps (a host's clock)", False)

    heading_parts, heading_streams = _headings(files, times_by_file, skipped)
    satellites = None
    if sat_rows:
        satellites = pd.DataFrame(
            sat_rows, columns=["t_ns", "receiver_id", "sv_id", "elevation_deg", "azimuth_deg", "cn0_dbhz", "used"]
        )
        for rid, n in satellites.groupby("receiver_id")["t_ns"].nunique().items():
            streams.append(StreamInfo("satellites", str(rid), str(rid), "NMEA GSV/GSA", int(n)))
    return Assembled(
        pd.concat(fix_parts, ignore_index=True) if fix_parts else None,
        heading_parts,
        streams + heading_streams,
        reference,
        metadata,
        fix_epochs,
        satellites,
        fixless_epochs,
    )


VARIATION_MAX_AGE_S = 600  # an RMC's magnetic variation is applied to magnetic headings this close in time


@dataclass
class Variations:
    """The magnetic variation (east positive) of every valid RMC of a log on the log's clock, and which
    sentences gave it.

    RMC's variation is the receiver's own: a model (WMM) or a chart's table at the position it fixed. So it
    follows that position, a spoofed one too; but it changes slowly with the place (some degrees over hundreds
    of km at mid latitudes), far less than the course a spoofer's track sets against the compass, and the
    variations applied to a log's headings are said with their range."""

    t_ns: np.ndarray
    deg: np.ndarray
    names: list[str]

    @classmethod
    def of(cls, files: list[DecodedFile], times_by_file: dict[int, dict[int, int]]) -> Variations:
        found = sorted(
            (t, d.variation_deg, d.name)
            for f in files
            for d in f.decoded
            if d.kind == "RMC" and d.valid and math.isfinite(d.variation_deg)
            if (t := times_by_file[id(f)].get(d.sentence.line)) is not None
        )
        return cls(
            np.array([t for t, _, _ in found], dtype=np.int64),
            np.array([v for _, v, _ in found], dtype=float),
            sorted({n for _, _, n in found}),
        )

    def at(self, t_ns: int) -> float:
        """The variation of the RMC nearest in time, NaN when none is within VARIATION_MAX_AGE_S."""
        if not len(self.t_ns):
            return math.nan
        k = int(np.searchsorted(self.t_ns, t_ns))
        near = min((i for i in (k - 1, k) if 0 <= i < len(self.t_ns)), key=lambda i: abs(int(self.t_ns[i]) - t_ns))
        return float(self.deg[near]) if abs(int(self.t_ns[near]) - t_ns) <= VARIATION_MAX_AGE_S * NS else math.nan


def _variation_text(deg: list[float]) -> str:
    """A variation, or the range of them, as `15.0 deg E` (`1.5 deg W to 2.0 deg E`)."""

    def one(v: float) -> str:
        return f"{abs(v):.1f} deg {'W' if v < 0 else 'E'}"

    low, high = min(deg), max(deg)
    return one(low) if low == high else f"{one(low)} to {one(high)}"


def _headings(
    files: list[DecodedFile], times_by_file: dict[int, dict[int, int]], skipped: list[Skipped]
) -> tuple[pd.DataFrame | None, list[StreamInfo]]:
    rows: list[tuple[int, str, float, str, float]] = []
    no_value: Counter[str] = Counter()
    untimed: Counter[str] = Counter()
    magnetic: Counter[str] = Counter()  # magnetic headings with no variation near them: taken as true
    made_true: dict[str, list[float]] = defaultdict(list)  # magnetic headings made true: the variations applied
    outside: Counter[str] = Counter()
    labels: dict[str, str] = {}  # heading id -> its sentence (HDT, THS2, ASHR, SSNHRP)
    variations = Variations.of(files, times_by_file)
    for f in files:
        line_t = times_by_file[id(f)]
        for d in f.decoded:
            if d.kind not in HEADING_KINDS:
                continue
            hid = _rid(_source(f, d), d.name)
            if not d.valid or not math.isfinite(d.heading_deg):
                no_value[hid] += 1
                continue
            t = line_t.get(d.sentence.line)
            if t is None and not line_t:  # a file with no time at all: its headings in file order
                t = d.sentence.line * NS
                untimed[hid] += 1
            elif t is None:
                outside[hid] += 1
                continue
            heading = d.heading_deg
            if d.magnetic_only and math.isfinite(variation := variations.at(t)):
                heading += variation
                made_true[hid].append(variation)
            else:
                magnetic[hid] += d.magnetic_only
            rows.append((t, hid, heading % 360.0, d.heading_talker or d.talker, d.water_speed_mps))
            labels[hid] = d.name[len(d.talker) :]
    for hid, n in no_value.items():
        reason = "headings without a value (invalid, or a speed log without heading)"
        skipped.append(Skipped(hid, reason, n))
    for hid, n in untimed.items():
        why = "headings of a file with no time at all (no epoch, no logger time): placed by line number, 1 s a line"
        skipped.append(Skipped(hid, why, n, "repaired"))
    for hid, n in outside.items():
        skipped.append(Skipped(hid, "headings where the file has no time to give them", n))
    for hid, applied in made_true.items():
        why = (
            f"magnetic headings (HDM, HDG, VHW) made true with {'/'.join(variations.names)}'s magnetic variation "
            f"({_variation_text(applied)}), the nearest in time"
        )
        skipped.append(Skipped(hid, why, len(applied), "repaired"))
    for hid, n in magnetic.items():
        if n:
            far = f"; no RMC variation within {VARIATION_MAX_AGE_S // 60} min" if len(variations.t_ns) else ""
            why = (
                f"magnetic headings without a variation (HDM, HDG, VHW{far}), taken as true: off by the local variation"
            )
            skipped.append(Skipped(hid, why, n, "repaired"))
    if not rows:
        return None, []
    frame = pd.DataFrame(rows, columns=["t_ns", "heading_id", "heading_deg", "talker", "water_speed_mps"])
    streams = [
        StreamInfo("heading", str(hid), str(hid), f"NMEA {labels[str(hid)]}", int(n))
        for hid, n in frame["heading_id"].value_counts(sort=False).items()
    ]
    return frame, streams


def build(path: Path, files: list[DecodedFile], skipped: list[Skipped]) -> EpochTable:
    """The EpochTable of a log's decoded files."""
    out = assemble(files, skipped)
    frames = {"fixes": out.fixes, "headings": out.headings, "satellites": out.satellites}
    return build_table(
        path,
        "nmea",
        out.time_reference,
        {k: v for k, v in frames.items() if v is not None},
        out.streams,
        skipped,
        metadata=out.metadata,
    )
