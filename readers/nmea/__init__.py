"""NMEA 0183 logs (a ship's voyage record, a receiver's text output) to an EpochTable.

A log is one file of sentences, or a directory of them (each file a source of its own). Sentences are
split off their logger's wrapping and checked (`lines.py`), decoded with pynmeagps (`sentences.py`;
proprietary and variant sentences in `proprietary.py`), and assembled into receivers, epochs and
headings on one clock (`assembly.py`):

- `fixes`: one row per receiver epoch, from GGA/GNS/RMC/GLL with VTG, GSA, GSV and GST (and from the
  proprietary position sentences: Trimble PTNL,GGK, Feyman FMI, Fugro FUGDP, Unicore HPD; Unicore's
  secondary-antenna GGAH... as a receiver of their own);
- `headings`: true headings from HDT, THS, HDG and VHW (a gyrocompass is a reference a spoofer cannot
  move; a GNSS dual-antenna THS can be moved, its talker says which it is), with VHW's speed through the
  water from the vessel's log; and the headings of proprietary attitude sentences (PASHR, PTNL,AVR,
  PSSN,HRP, Unicore HPR/TRA2/THS2), filed as GNSS headings.

Time reference `unix` when the log has dates (RMC, ZDA) or logger times, else `relative`. Every
sentence that is not used is counted by type; bad checksums, cut lines and garbage are counted and
skipped. `inject` writes a spoofed copy with GGA/GNS/RMC/GLL positions edited in place
(`spooflens.writers.nmea_rewrite`), every other byte unchanged (proprietary positions are not edited).
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Callable, Mapping
from pathlib import Path

from readers import NothingToJudgeError, ReaderFormat
from readers.nmea.assembly import DecodedFile, build
from readers.nmea.lines import UNVERIFIED, UNVERIFIED_TYPE, Sentence, SentenceScan, scan_sentences, split_lines
from readers.nmea.proprietary import decode_variant, family_of, not_read_reason, sentence_name
from readers.nmea.sentences import WANTED, Decoded, ParseErrors, decode, forget_parsed, is_empty
from readers.protocols import standard_address
from spooflens.epoch_table import EpochTable, Skipped
from spooflens.errors import ReaderError

Progress = Callable[[int, int], None]

# scan counts of lines that are sentences, but broken ones
_BROKEN_SENTENCES = (
    "sentences with a bad checksum",
    "sentences with a broken checksum field",
    "sentences without a checksum (cut short?)",
)
# scan counts that mean the file is damaged (listed as "lost"), the others are routine skips
_LOST = ("file cut inside its last sentence", *_BROKEN_SENTENCES, "binary garbage (not text)")


EMPTY = "empty sentences (no data in their fields)"
UNDECODABLE = "sentences pynmeagps cannot decode"


def decode_scan(scan: SentenceScan, label: str) -> DecodedFile:
    """Decode the sentences spooflens uses; count every other one by type and every failure."""
    name = label or scan.path.name
    skipped = [
        Skipped(
            name,
            reason,
            n,
            "lost" if reason in _LOST else "unverified" if reason in (UNVERIFIED, UNVERIFIED_TYPE) else "skipped",
        )
        for reason, n in scan.counts.items()
        if n
    ]
    decoded: list[Decoded] = []
    unused: dict[str, int] = {}
    empty: dict[str, int] = {}
    bad: dict[str, int] = {}
    first_error = ""
    not_read: dict[tuple[str, str], int] = {}
    try:
        for s in scan.sentences:
            what = sentence_name(s)
            family = family_of(s)
            standard = s.kind in WANTED and not s.talker.startswith("P")
            if not standard and family is None:
                reason = not_read_reason(s)
                if reason is None:
                    unused[what] = unused.get(what, 0) + 1
                else:
                    not_read[(what, reason)] = not_read.get((what, reason), 0) + 1
                continue
            if is_empty(s):
                empty[what] = empty.get(what, 0) + 1
                continue
            try:
                decoded.append(decode(s) if family is None else decode_variant(s, family))
            except ParseErrors as err:
                bad[what] = bad.get(what, 0) + 1
                first_error = first_error or f"line {s.line + 1}: {err}"
    finally:
        forget_parsed()  # the sentences remembered are this file's
    skipped += [Skipped(w, "sentence type spooflens does not use", n) for w, n in sorted(unused.items())]
    skipped += [Skipped(w, reason, n) for (w, reason), n in sorted(not_read.items())]
    skipped += [Skipped(w, EMPTY, n) for w, n in sorted(empty.items())]
    skipped += [Skipped(w, f"{UNDECODABLE} ({first_error})", n, "lost") for w, n in bad.items()]
    return DecodedFile(label, scan, decoded, skipped)


def nmea_files(path: Path) -> list[Path]:
    """The NMEA files of a log: the file itself, or every file of a directory that sniffs as NMEA."""
    if not path.is_dir():
        return [path]
    files = [p for p in sorted(path.iterdir()) if p.is_file() and looks_like_nmea(_head(p))]
    if not files:
        raise ReaderError(path, "directory holds no NMEA 0183 log")
    return files


def decode_log(path: Path, progress: Progress | None = None) -> tuple[list[DecodedFile], list[Skipped]]:
    """Every NMEA file of a log scanned and decoded, with what was skipped (shared with `inject`)."""
    files = nmea_files(path)
    skipped: list[Skipped] = []
    if path.is_dir():
        others = [p.name for p in sorted(path.iterdir()) if p.is_file() and p not in files]
        if others:
            skipped.append(Skipped(path.name, f"files that are not NMEA logs: {', '.join(others[:5])}", len(others)))
    decoded = []
    for i, f in enumerate(files):
        part = decode_scan(scan_sentences(f), f.name if path.is_dir() else "")
        decoded.append(part)
        skipped.extend(part.skipped)
        if progress:
            progress(i + 1, len(files))
    if not any(p.decoded for p in decoded):
        sentences = [s for f in decoded for s in f.scan.sentences]
        if sentences:
            raise NothingToJudgeError(path, _what_it_holds(sentences, skipped), "nmea", skipped)
        raise ReaderError(path, f"no NMEA sentence in the log: {'; '.join(map(str, skipped[:6]))}", "nmea")
    return decoded, skipped


AIS_KINDS = ("VDM", "VDO")
AIS_POSITION_TYPES = {1, 2, 3, 18, 19, 27}  # ITU-R M.1371 position reports (class A, class B, long range)


def _what_it_holds(sentences: list[Sentence], skipped: list[Skipped]) -> str:
    """What a log of sentences none of which gave a position, heading or satellite holds: AIS traffic
    (other stations' reports, and how many of its own station's VDO carry a position), or its sentences
    by address, with how many of those spooflens reads were empty (a receiver without a fix) or broken."""
    if all(s.kind in AIS_KINDS for s in sentences):
        own = [s for s in sentences if s.kind == "VDO"]
        text = f"AIS messages only ({len(sentences) - len(own)} VDM: other stations' reports"
        if not own:
            return text + "; none of its own station's, VDO)"
        positions = sum(_ais_message_type(s.text) in AIS_POSITION_TYPES for s in own)
        return (
            text + f"; {len(own)} VDO sentences, its own station's, {positions} of them a position report: "
            "spooflens reads a vessel's own GNSS fixes, not AIS position reports)"
        )
    counts = Counter(f"${s.talker}{s.kind}" for s in sentences)
    kinds = [f"{name} x{n}" for name, n in counts.most_common()]
    listed = ", ".join(kinds[:6]) + (f" and {len(kinds) - 6} more kinds" if len(kinds) > 6 else "")
    empty = sum(s.count for s in skipped if s.reason == EMPTY)
    broken = sum(s.count for s in skipped if s.reason.startswith(UNDECODABLE))
    if not empty and not broken:
        return f"only sentences spooflens does not read ({listed}): no position, heading or satellite report"
    why = [f"{n} of them {what}" for n, what in ((empty, "empty: no fix"), (broken, "undecodable")) if n]
    return f"no position, heading or satellite report in its sentences ({listed}; {', '.join(why)})"


def _ais_message_type(text: bytes) -> int | None:
    """The message type of an AIS sentence's first fragment (the payload's first six-bit character),
    None for a later fragment or a sentence too short to hold one."""
    fields = text.split(b",")
    if len(fields) < 6 or fields[2] != b"1" or not fields[5]:
        return None
    value = fields[5][0] - 48
    return value - 8 if value > 40 else value


def read_nmea(path: Path, topics: Mapping[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    """Read an NMEA 0183 log (a file, or a directory of files) into an EpochTable."""
    path = Path(path)
    decoded, skipped = decode_log(path, progress)
    if topics:
        skipped.append(Skipped("<nmea>", f"--topic is not used for NMEA logs ({dict(topics)})", len(topics)))
    return build(path, decoded, skipped)


def _head(path: Path) -> bytes:
    try:
        with path.open("rb") as f:
            return f.read(4096)
    except OSError:
        return b""


def looks_like_nmea(head: bytes) -> bool:
    """Most data lines of the head are NMEA sentences (after logger prefixes) with valid checksums."""
    lines = split_lines(head)
    if len(lines) > 1 and not head.endswith((b"\n", b"\r")):
        lines = lines[:-1]  # the head may end inside a line
    text = b"".join(line + b"\n" for _, line in lines)
    result = scan_sentences(Path("<head>"), text)
    data_lines = sum(1 for _, ln in lines if ln.strip() and not ln.startswith(b"#"))
    good = len(result.sentences)  # verified, or unverified in a head where no sentence has a checksum
    attempts = good + sum(result.counts[reason] for reason in _BROKEN_SENTENCES)
    # half the lines, or a damaged log's many sentences among broken ones (gpsd's gp-320fw cold boot, a
    # research vessel's garbled serial capture: a sixth of its lines intact, most of the rest sentences
    # that fail their checksum)
    return good >= 1 and (good * 2 >= data_lines or (good >= 8 and max(good * 4, attempts * 2) >= data_lines))


def damaged_nmea(head: bytes) -> str | None:
    """Why a file of standard NMEA sentences is not read as one (too few pass their checksum: a tool that
    computes them wrongly, a garbled serial line), or None when it is no such file."""
    result = scan_sentences(Path("<head>"), head)
    attempts = len(result.sentences) + sum(result.counts[reason] for reason in _BROKEN_SENTENCES)
    if attempts * 2 < result.lines or not any(
        standard_address(m.group(1).decode()) for m in re.finditer(rb"^\$([A-Z][A-Z0-9]{4}),", head[:8192], re.M)
    ):
        return None
    what = ", ".join(f"{n} {reason}" for reason, n in result.counts.most_common())
    return (
        f"NMEA 0183 sentences, too few of them intact to read: {len(result.sentences)} of the first "
        f"{result.lines} lines pass their checksum ({what})"
    )


def _is_nmea(path: Path, head: bytes) -> bool:
    if path.is_dir():
        return not any(path.glob("*.csv")) and any(p.is_file() and looks_like_nmea(_head(p)) for p in path.iterdir())
    return looks_like_nmea(head)


FORMATS = (
    ReaderFormat(
        "nmea",
        "NMEA 0183 log (gpsd, VDR/AIS logger, Signal K, TAG-block and GnssLogger layouts) or a directory of them",
        read_nmea,
        _is_nmea,
        rewrite="spooflens.writers.nmea_rewrite:rewrite_nmea_log",
        folder_of_files=True,
        damaged=damaged_nmea,
    ),
)
