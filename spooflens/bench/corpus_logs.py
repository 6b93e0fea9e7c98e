"""Which paths of a real-log corpus are logs, and what is known of each (`spooflens bench corpus`).

A folder with a `MANIFEST.tsv` (the corpus of `../shared/real/corpus/`) lists its data files one a row:
there each row is one log, whatever the folder around it holds (a folder of RINEX files of five stations
is five logs, not the one multi-receiver log `spooflens batch` would read it as), with the manifest's
format, vehicle and notes. Elsewhere what is a log is what `spooflens batch` says (`batch.find_logs`:
sniffed by content; a ROS2 bag, RINEX or NMEA folder is one log), with vehicle "unknown" and, when the
folder's README describes it in its table, that description as the notes.

Not logs: RINEX navigation files and other companions (`readers.is_companion`), the manifest's
`rinex-nav` rows, manifest rows whose notes say they are the ground truth of another log, and what no
reader recognises outside a manifest.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass, field
from pathlib import Path

MANIFEST = "MANIFEST.tsv"
# tags in the manifest's notes (corpus/README.md) marking a log that is not a recording of the clean sky
NOT_CLEAN_TAGS = frozenset(
    {
        "SIMULATOR-FED",
        "SYNTHETIC",
        "EDITED",
        "DEMO-MODE",
        "TEST-LOAD",
        "TEST-VECTOR",
        "NO-PVT",
        "NO-OWN-PVT",
        "NO-GNSS",
    }
)
# natural (non-attack) anomalies the README tags; such a log is still clean sky
NATURAL_FAULT_TAGS = frozenset(
    {
        "WEEK-ROLLOVER",
        "LEAP-SECONDS",
        "TIME-ERROR",
        "RECEIVER-RESET",
        "COLD-START",
        "TIME-JUMP",
        "TIME-DISORDER",
        "LOSS-OF-FIX",
        "SIGNAL-LOSS",
        "RECEIVER-FLAGGED",
    }
)
KNOWN_TAGS = NOT_CLEAN_TAGS | NATURAL_FAULT_TAGS
# a tag is a whole upper-case token: NO-GNSS must not be read out of NO-GNSS-RAW, nor TIME- of TIME-JUMP
_TOKEN = re.compile(r"(?<![A-Za-z0-9-])[A-Z][A-Z0-9]*(?:-[A-Z0-9]+)*(?![A-Za-z0-9-])")
# a manifest row that is the reference trajectory of another row ("ground truth for X", "use as ground
# truth"); "truth in X" is said of the log X is the truth of
_TRUTH_OF_ANOTHER = re.compile(r"\b(ground truth|reference trajectory)\b[^;]*\bfor\b|\buse as ground truth", re.I)
# the manifest's format names for logs found by sniffing outside it (reader name -> manifest vocabulary)
MANIFEST_FORMAT_OF_READER = {
    "ardupilot": "dataflash",
    "rinex": "rinex-obs",
    "ros1bag": "rosbag",
    "ros2bag": "rosbag",
}


@dataclass(frozen=True)
class CorpusLog:
    """One log of the corpus: `format` in the manifest's vocabulary, `reader` the format a reader sniffs
    (None when none recognises it: `analyze` will refuse it and say why)."""

    path: Path
    name: str  # the path relative to the corpus root given on the command line
    format: str
    reader: str | None
    vehicle: str = "unknown"
    notes: str = ""
    tags: tuple[str, ...] = ()
    licence: str = ""
    listed: bool = False  # a row of a MANIFEST.tsv

    @property
    def clean(self) -> bool:
        """A recording of the clean sky: a SPOOFING verdict on it is a false accusation."""
        return not NOT_CLEAN_TAGS.intersection(self.tags)


@dataclass(frozen=True)
class NotLog:
    path: Path
    name: str
    why: str


@dataclass
class Corpus:
    logs: list[CorpusLog] = field(default_factory=list)
    not_logs: list[NotLog] = field(default_factory=list)


def tags_of(notes: str) -> tuple[str, ...]:
    """The README's tags named in a manifest row's notes, in order, each once."""
    return tuple(dict.fromkeys(t for t in _TOKEN.findall(notes) if t in KNOWN_TAGS))


def is_truth_of_another(notes: str) -> bool:
    """A manifest row that is another row's ground truth (a reference trajectory), not a log to judge."""
    return _TRUTH_OF_ANOTHER.search(notes) is not None


def reader_format(path: Path) -> str | None:
    """The format a reader recognises `path` as, None when none does (or it cannot be opened)."""
    from readers import recognised_format
    from spooflens.errors import SpooflensError

    try:
        return recognised_format(path)
    except SpooflensError:
        return None


def _companion(path: Path, reader: str | None) -> bool:
    from readers import is_companion

    return reader is not None and is_companion(path, reader)


def manifest_logs(manifest: Path, root: Path) -> Corpus:
    """The rows of one MANIFEST.tsv: its logs, and its rows that are not logs (navigation, truth, missing)."""
    out = Corpus()
    with manifest.open(newline="") as f:
        rows = list(csv.DictReader(f, delimiter="\t"))
    for row in rows:
        path = manifest.parent / row["path"]
        name = str(path.relative_to(root))
        fmt, notes = row.get("format") or "other", row.get("notes") or ""
        if not path.exists():
            out.not_logs.append(NotLog(path, name, "listed in the manifest but missing"))
            continue
        reader = reader_format(path)
        if fmt == "rinex-nav" or _companion(path, reader):
            out.not_logs.append(NotLog(path, name, "navigation or companion file (data for a log)"))
            continue
        if is_truth_of_another(notes):
            out.not_logs.append(NotLog(path, name, "ground truth of another log (manifest notes)"))
            continue
        out.logs.append(
            CorpusLog(
                path,
                name,
                fmt,
                reader,
                vehicle=row.get("vehicle") or "unknown",
                notes=notes,
                tags=tags_of(notes),
                licence=row.get("licence") or "",
                listed=True,
            )
        )
    return out


def readme_descriptions(root: Path) -> dict[str, str]:
    """folder or file (relative to `root`) -> its "what it is" cell in `root/README.md`'s table."""
    readme = root / "README.md"
    if not readme.is_file():
        return {}
    out = {}
    for line in readme.read_text(errors="replace").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) >= 2 and cells[0].startswith("`") and cells[0].endswith("`"):
            out[cells[0].strip("`").rstrip("/")] = cells[1]
    return out


def _description(name: str, described: dict[str, str]) -> str:
    """The README description of the longest folder or file that `name` is or lies in."""
    keys = [k for k in described if name == k or name.startswith(k + "/")]
    return described[max(keys, key=len)] if keys else ""


def discover(root: Path) -> Corpus:
    """Every log under `root`: manifest rows where a MANIFEST.tsv lists them, `batch.find_logs` elsewhere."""
    from spooflens.batch import find_logs

    root = root.resolve()
    out = Corpus()
    manifests = sorted(root.rglob(MANIFEST))
    listed_folders = [m.parent for m in manifests]
    for manifest in manifests:
        part = manifest_logs(manifest, root)
        out.logs += part.logs
        out.not_logs += part.not_logs
    described = readme_descriptions(root)

    def in_a_manifest_folder(p: Path) -> bool:
        return any(p == d or d in p.parents for d in listed_folders)

    logs, not_logs = find_logs((str(root),))
    for p in logs:
        if in_a_manifest_folder(p):
            continue
        name = str(p.relative_to(root))
        reader = reader_format(p)
        fmt = MANIFEST_FORMAT_OF_READER.get(reader or "", reader or "other")
        out.logs.append(CorpusLog(p, name, fmt, reader, notes=_description(name, described)))
    for p in not_logs:
        if not in_a_manifest_folder(p):
            out.not_logs.append(NotLog(p, str(p.relative_to(root)), "not a log (no reader, or data for a log)"))
    out.logs.sort(key=lambda c: c.name)
    return out
