"""Where a report's numbers came from: the input's identity (size, SHA-256) and what ran on it."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

CHUNK = 1 << 20


@dataclass(frozen=True)
class InputIdentity:
    name: str
    size_bytes: int
    sha256: str
    how: str  # what the hash covers


def _hash_file(path: Path, h: hashlib._Hash) -> int:
    size = 0
    with path.open("rb") as f:
        while chunk := f.read(CHUNK):
            h.update(chunk)
            size += len(chunk)
    return size


def identify(path: Path) -> InputIdentity:
    """SHA-256 of a file, or of a directory log (ROS2 bag, CSV or RINEX folder): every file's relative
    path and bytes, in path order, so the same folder always gives the same digest."""
    path = Path(path)
    h = hashlib.sha256()
    if path.is_dir():
        files = sorted(p for p in path.rglob("*") if p.is_file())
        size = 0
        for p in files:
            h.update(str(p.relative_to(path)).encode() + b"\0")
            size += _hash_file(p, h)
        return InputIdentity(path.name, size, h.hexdigest(), f"directory: {len(files)} files, names and bytes")
    return InputIdentity(path.name, _hash_file(path, h), h.hexdigest(), "file bytes")
