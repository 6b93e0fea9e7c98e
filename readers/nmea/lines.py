"""An NMEA 0183 log as its sentences: logger prefixes taken off, checksums verified, nothing decoded yet.

A line of a log is an NMEA sentence (`$GPGGA,...*hh`, `!AIVDM,...*hh`), possibly wrapped by the
logger that recorded it:

- `#` comment lines (gpsd test logs start with a header of them): kept as the log's description;
- NMEA 4 TAG blocks `\\s:GPS1,c:1533064290*hh\\$GPRMC,...`: `c:` the logger's UNIX time (seconds, or
  milliseconds when the value is that large), `s:` the source, which makes a receiver of its own;
- a leading logger time: `1533064290.123 $GPRMC...` (space, tab, `,` or `;` after it), Signal K's
  multiplexed log `1533064290123;N;$GPRMC...`, a router's `[1494938987296][**] $GPRMC...`, or an ISO-8601
  UTC time `2018-08-20T09:47:36.123Z $GP...`;
- Android GnssLogger's `NMEA,$GPRMC,...*hh,1699400577561` (a trailing logger time in ms after the
  checksum; AIS loggers append `,<unix seconds>` the same way).

Lines end in LF, CR LF or a bare CR (classic Mac OS and some serial loggers); sentences written back to
back with no line break between them (`...*4B$GPGGA,...`) are split after the checksum.

Checksums are verified for every sentence (vectorised over the file); a sentence whose checksum does
not match is skipped and counted. A sentence without a checksum is accepted only in a file where no
sentence carries one (an old talker that never sends them), or where no sentence of its type does (a
logger's own marks); elsewhere it is most likely cut short.
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from spooflens.errors import ReaderError

NS = 1_000_000_000
UNVERIFIED = "sentences without a checksum, taken unverified (no sentence in the file has one)"
# a device's own sentence that never carries one where the receiver's do (an AMOD logger's `$ADPMB,5,0`
# button marks): whole, not cut short
UNVERIFIED_TYPE = "sentences of a type that never carries a checksum in this file, taken unverified"

_TIME = rb"(\d{9,19}(?:\.\d*)?)"
_NUMERIC_PREFIX = re.compile(rb"^" + _TIME + rb"[ \t;,]+(?:[A-Za-z];)?")
# a router's `[1494938987296][**] $GPRMC,...`: the logger's time in brackets, then bracketed tags
_BRACKET_PREFIX = re.compile(rb"^\[" + _TIME + rb"\](?:\[[^\]\r\n]{0,16}\])*[ \t]*")
_ISO_PREFIX = re.compile(rb"^(\d{4}-\d\d-\d\d[T ]\d\d:\d\d:\d\d(?:\.\d+)?)(?:Z|[+-]00:?00)?[ \t;,]+")
_TRAILING_TIME = re.compile(rb"^,?\s*" + _TIME + rb"\s*$")
# a talker is two letters, or a bus address's two digits (canboat's n2kd writes `$04HDM`); a proprietary
# address is P, a maker's three letters and its own sentence name, often longer ($PQTMCFGUART); SkyTraq's
# loader writes three letters ($STI); a device's own sentences may be longer (a dashcam's $GSENSORD)
_ADDRESS = re.compile(rb"^[$!](P[A-Z0-9]{3,15}|[A-Z0-9][A-Z0-9]{2,9}),")
_HEX = b"0123456789ABCDEFabcdef"
BoolArray = NDArray[np.bool_]
# where a line may end other than in LF or CR LF: a bare CR, or the next sentence glued to a checksum
_ODD_BREAK = re.compile(rb"\r(?!\n)|\*[0-9A-Fa-f]{2}[$!]")
_BREAK = re.compile(rb"\r\n|\n|\r|(?<=\*[0-9A-Fa-f]{2})(?=[$!])")
_HEX_VALUE = np.full(256, -256, dtype=np.int64)  # byte -> its hex digit value (negative: not one)
for _i, _c in enumerate(b"0123456789ABCDEF"):
    _HEX_VALUE[_c] = _i
    _HEX_VALUE[bytes([_c]).lower()[0]] = _i


def logger_ns(text: bytes) -> int | None:
    """A logger's UNIX time field -> ns: seconds, or ms / us / ns when the number is that large."""
    try:
        value = float(text)
    except ValueError:
        return None
    for limit, scale in ((1e11, 1e9), (1e14, 1e6), (1e17, 1e3)):
        if value < limit:
            return round(value * scale)
    return round(value)


def _iso_ns(text: bytes) -> int | None:
    try:
        stamp = datetime.fromisoformat(text.decode().replace(" ", "T")).replace(tzinfo=UTC)
    except ValueError:
        return None
    return round(stamp.timestamp() * NS)


class Sentence(NamedTuple):
    """One NMEA sentence as found in the file, before decoding.

    `start`/`end`: byte span of the sentence (`$` to the last checksum digit) in the file, which is what
    the rewriter edits; `line`: the line number (0-based); `host_ns`: the logger's time, if any.
    """

    line: int
    start: int
    end: int
    text: bytes
    talker: str
    kind: str
    source: str
    host_ns: int | None


@dataclass
class SentenceScan:
    """Every sentence of one file with a valid (or, in a checksum-less file, absent) checksum."""

    path: Path
    data: bytes
    sentences: list[Sentence]
    comments: list[str]
    lines: int
    counts: Counter[str] = field(default_factory=Counter)  # skipped, by reason


@dataclass
class _Candidate:
    line: int
    start: int
    end: int  # end of the sentence proper (after the checksum, or the end of the line)
    star: int  # file offset of '*'; -1 no checksum, -2 a '*' without two hex digits
    source: str
    host_ns: int | None


def _unwrap(line: bytes) -> tuple[int, str, int | None, bool]:
    """Logger wrapping at the start of a line -> (offset of the sentence, source, logger ns, tag ok)."""
    pos, source, host, tag_ok = 0, "", None, True
    if line[:2] == b"$$":  # a logger that doubles the start character (`$$GNGSA,...`)
        return 1, source, host, tag_ok
    if line[:1] in (b"$", b"!"):
        return pos, source, host, tag_ok
    for _ in range(4):  # prefixes may be stacked: a time, then a TAG block
        rest = line[pos:]
        if rest[:1] == b"\\":
            close = rest.find(b"\\", 1)
            if close < 0:
                break
            tag = rest[1:close]
            body, _, check = tag.partition(b"*")
            tag_ok = not check or _xor(body) == _hex_value(check[:2])
            for part in body.split(b","):
                key, _, value = part.partition(b":")
                if key == b"c" and tag_ok:
                    host = logger_ns(value) if host is None else host
                elif key == b"s":
                    source = value.decode("latin-1")
            pos += close + 1
            continue
        if rest[:5] == b"NMEA,":  # Android GnssLogger
            pos += 5
            continue
        m = _NUMERIC_PREFIX.match(rest) or _BRACKET_PREFIX.match(rest) or _ISO_PREFIX.match(rest)
        if m is None:
            break
        t = _iso_ns(m.group(1)) if m.re is _ISO_PREFIX else logger_ns(m.group(1))
        host = t if host is None else host
        pos += m.end()
    return pos, source, host, tag_ok


def _xor(body: bytes) -> int:
    out = 0
    for b in body:
        out ^= b
    return out


def _hex_value(text: bytes) -> int:
    try:
        return int(text, 16)
    except ValueError:
        return -1


def split_lines(data: bytes) -> list[tuple[int, bytes]]:
    """(file offset, line without its break) of each line of `data`; the empty line after a final break is
    no line."""
    if not _ODD_BREAK.search(data):
        out: list[tuple[int, bytes]] = []
        offset = 0
        raw_lines = data.split(b"\n")
        if data.endswith(b"\n"):
            raw_lines.pop()
        for raw in raw_lines:
            out.append((offset, raw[:-1] if raw.endswith(b"\r") else raw))
            offset += len(raw) + 1
        return out
    out, start = [], 0
    for m in _BREAK.finditer(data):
        out.append((start, data[start : m.start()]))
        start = m.end()
    if start < len(data):
        out.append((start, data[start:]))
    return out


def scan_sentences(path: Path, data: bytes | None = None) -> SentenceScan:
    """Split one file into sentences; every line that is not one is counted by why."""
    if data is None:
        try:
            data = path.read_bytes()
        except OSError as err:
            raise ReaderError(path, f"cannot read: {err.strerror or err}") from err
    counts: Counter[str] = Counter()
    comments: list[str] = []
    candidates: list[_Candidate] = []
    terminated = data.endswith((b"\n", b"\r"))
    lines = split_lines(data)
    n_lines = len(lines)
    for i, (line_start, line) in enumerate(lines):
        if not line.strip():
            continue
        if line[:1] == b"#":
            comments.append(line[1:].decode("utf-8", errors="replace").strip())
            continue
        pos, source, host, tag_ok = _unwrap(line)
        if not tag_ok:
            counts["TAG blocks with a bad checksum (their time and source ignored)"] += 1
        if line[pos : pos + 1] not in (b"$", b"!"):
            if b"\x00" in line or any(b > 126 for b in line[:64]):
                counts["binary garbage (not text)"] += 1
            else:
                counts["lines that are not NMEA sentences"] += 1
            continue
        star = line.find(b"*", pos)
        end = len(line)
        if (
            star >= 0
            and star + 3 <= len(line)
            and line[star + 1 : star + 2] in _HEX
            and line[star + 2 : star + 3] in _HEX
        ):
            end = star + 3
            tail = line[end:]
            if tail.strip():
                m = _TRAILING_TIME.match(tail)
                if m and host is None:
                    host = logger_ns(m.group(1))
                elif not m:
                    counts["text after the checksum (ignored)"] += 1
        elif star >= 0:
            star = -2  # a '*' without two hex digits after it: cut inside the checksum
        cut = i == n_lines - 1 and not terminated
        star_at = line_start + star if star >= 0 else star
        candidates.append(_Candidate(i, line_start + pos, line_start + end, star_at, source, host))
        if cut and star < 0:
            counts["file cut inside its last sentence"] += 1
            candidates.pop()
    sentences = _verified(data, candidates, counts)
    return SentenceScan(path, data, sentences, comments, n_lines, counts)


def _address_at(data: bytes, c: _Candidate) -> bytes | None:
    m = _ADDRESS.match(data[c.start : c.end])
    return m.group(1) if m else None


def _dollar_in_checksum(
    data: bytes, with_sum: list[_Candidate], good: BoolArray, with_dollar: BoolArray, counts: Counter[str]
) -> BoolArray:
    """Sentences of a type whose every checksum is the XOR with the leading `$` taken in (an LG phone's own
    `$GPGLG`), two or more: whole, as their type's convention has it. Never a type with right checksums."""
    if good.all() or not with_dollar.any():
        return np.zeros(len(with_sum), dtype=bool)
    addresses = [_address_at(data, c) for c in with_sum]
    convention: dict[bytes | None, bool] = {}
    for a, g, d in zip(addresses, good.tolist(), with_dollar.tolist(), strict=True):
        convention[a] = convention.get(a, True) and not g and d
    seen = Counter(addresses)
    kept = np.array([a is not None and convention[a] and seen[a] >= 2 for a in addresses], dtype=bool)
    if kept.any():
        counts["sentences of a type whose checksums take in the '$', taken as whole"] += int(kept.sum())
    return kept


def _verified(data: bytes, candidates: list[_Candidate], counts: Counter[str]) -> list[Sentence]:
    """Sentences whose checksum matches (XOR of the bytes between `$` and `*`), vectorised."""
    with_sum = [c for c in candidates if c.star >= 0]
    no_sum = [c for c in candidates if c.star == -1]
    broken = [c for c in candidates if c.star == -2]
    if broken:
        counts["sentences with a broken checksum field"] += len(broken)
    ok: list[_Candidate] = []
    if with_sum:
        buf = np.frombuffer(data, dtype=np.uint8)
        acc = np.bitwise_xor.accumulate(buf)
        starts = np.array([c.start for c in with_sum], dtype=np.int64)
        stars = np.array([c.star for c in with_sum], dtype=np.int64)
        body = acc[stars - 1] ^ acc[starts]
        given = (_HEX_VALUE[buf[stars + 1]] << 4) | _HEX_VALUE[buf[stars + 2]]
        good = body.astype(np.int64) == given
        good |= _dollar_in_checksum(data, with_sum, good, (body ^ ord("$")).astype(np.int64) == given, counts)
        ok = [c for c, g in zip(with_sum, good.tolist(), strict=True) if g]
        if (~good).any():
            counts["sentences with a bad checksum"] += int((~good).sum())
    if no_sum:
        if with_sum:
            summed = {_address_at(data, c) for c in with_sum}
            cut: list[_Candidate] = []
            never: list[_Candidate] = []
            for c in no_sum:
                named = _address_at(data, c)
                (cut if named is None or named in summed else never).append(c)
            if cut:
                counts["sentences without a checksum (cut short?)"] += len(cut)
            if never:
                ok += never
                counts[UNVERIFIED_TYPE] += len(never)
        else:
            ok += no_sum
            counts[UNVERIFIED] += len(no_sum)
    ok.sort(key=lambda c: c.line)
    out: list[Sentence] = []
    for c in ok:
        text = data[c.start : c.end]
        m = _ADDRESS.match(text)
        if m is None:
            counts["sentences without a valid address field"] += 1
            continue
        address = m.group(1).decode()
        talker, kind = (address[:1], address[1:]) if address[0] == "P" else (address[:2], address[2:])
        out.append(Sentence(c.line, c.start, c.end, text, talker, kind, c.source, c.host_ns))
    return out
