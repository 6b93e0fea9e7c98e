"""RINEX as shipped: gzip, bzip2, xz, Unix compress (.Z), zip, and Hatanaka's Compact RINEX (.crx, .YYd).

Archives and data centres ship RINEX packed: `..._MO.crx.gz` (Compact RINEX inside gzip), `.YYd.Z`,
`.rnx.gz`, a zip of a day's files. The outer layer is opened with `readers.compression` (gzip, bzip2,
xz, zip) and `ncompress` (the LZW of `.Z`), streamed so that an absurd size is refused before it is held in memory;
Compact RINEX is expanded by the `hatanaka` package (RNXCMP's crx2rnx, the format author's own tool).
Packing is recognised by content, never by name. A stream cut short keeps what came before the cut
(the loss listed), as a cut plain file does.
"""

from __future__ import annotations

import lzma
import shutil
import tempfile
import warnings
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path

from readers.compression import STREAMS, decompressor, expand_lzw, inflate, packing_of, zip_members
from spooflens.errors import ReaderError

MAX_UNPACKED_BYTES = 512 * 2**20  # a day of 1 Hz multi-GNSS RINEX 3 is ~300 MB; more is no RINEX we hold
MAX_COMPACT_BYTES = MAX_UNPACKED_BYTES // 4  # Compact RINEX expands 3-4 fold
HEAD_BYTES = 64 * 1024  # enough for any RINEX header's first lines


@dataclass
class Unpacked:
    """A file's RINEX text and what unpacking it lost or decided."""

    data: bytes
    packing: list[str] = field(default_factory=list)  # outermost first: ["gzip", "Compact RINEX"]
    losses: list[str] = field(default_factory=list)


def is_compact(text: bytes) -> bool:
    return b"COMPACT RINEX" in text[:80] and b"CRINEX VERS" in text[:80]


def _too_big(path: Path, what: str, limit: int) -> ReaderError:
    return ReaderError(
        path, f"{what} unpacks to more than {limit // 2**20} MiB: larger than any RINEX file spooflens holds in memory"
    )


def _inflate(path: Path, data: bytes, kind: str, limit: int, out: Unpacked) -> bytes:
    """A gzip, bzip2 or xz stream's text; cut or corrupt: what came before, the loss listed."""
    text = BytesIO()
    _, damage = inflate(path, kind, BytesIO(data), text, limit, _too_big)
    if damage:
        out.losses.append(damage)
    return text.getvalue()


def _rinex_member(path: Path, members: dict[str, bytes]) -> tuple[str, bytes]:
    """The RINEX observation file of an archive, else its first RINEX file."""
    rinex = {n: b for n, b in members.items() if b"RINEX VERS" in b[:240] or is_compact(b)}
    if not rinex:
        raise ReaderError(path, f"zip archive holds no RINEX file (members: {sorted(members)[:6]})")
    obs = [n for n, b in rinex.items() if b"OBSERVATION DATA" in b[:240] or is_compact(b)]
    name = (obs or sorted(rinex))[0]
    return name, rinex[name]


def _outer(path: Path, data: bytes, out: Unpacked, limit: int) -> bytes:
    kind = packing_of(data[:512])
    if kind is None or kind == "tar":  # a tar of RINEX is the packed-log reader's
        return data
    out.packing.append(kind)
    if kind in STREAMS:
        return _inflate(path, data, kind, limit, out)
    if kind == "zip":
        name, body = _rinex_member(path, zip_members(path, data, limit, out.losses, _too_big))
        out.packing[-1] = f"zip ({name})"
        return body
    return expand_lzw(path, data, limit, _too_big)


def unpack(path: Path) -> Unpacked:
    """The RINEX text of a file as shipped (plain files are returned as they are)."""
    try:
        data = path.read_bytes()
    except OSError as err:
        raise ReaderError(path, f"cannot read: {err.strerror or err}") from err
    out = Unpacked(b"")
    text = _outer(path, data, out, MAX_UNPACKED_BYTES)
    if is_compact(text):
        if len(text) > MAX_COMPACT_BYTES:
            raise _too_big(path, "Compact RINEX", MAX_COMPACT_BYTES)
        text = _expand_compact(path, text, out)
    out.data = text
    return out


def _expand_compact(path: Path, text: bytes, out: Unpacked) -> bytes:
    import hatanaka

    out.packing.append("Compact RINEX (Hatanaka)")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            expanded = hatanaka.crx2rnx(text, skip_strange_epochs=True)
        except (hatanaka.HatanakaException, ValueError, OSError) as err:
            first = str(err).strip().splitlines()[0][:200] if str(err).strip() else type(err).__name__
            raise ReaderError(path, f"Compact RINEX (Hatanaka) that crx2rnx cannot expand: {first}") from err
    for w in caught:
        message = " ".join(str(w.message).split())[:200]
        out.losses.append(f"crx2rnx: {message}")
    if len(expanded) > MAX_UNPACKED_BYTES:
        raise _too_big(path, "Compact RINEX", MAX_UNPACKED_BYTES)
    return bytes(expanded)


def head_text(path: Path, limit: int = HEAD_BYTES) -> bytes:
    """The first bytes of a file's RINEX text (what sniffing and header look-ups need), unpacking only
    that much of a gzip or bzip2 stream; a Compact RINEX head with its two CRINEX lines removed (the
    RINEX header follows them as it was)."""
    try:
        with path.open("rb") as f:
            kind = packing_of(f.read(512))
            if kind == "tar":  # a tar of RINEX is the packed-log reader's
                return b""
            f.seek(0)
            # a compressed stream starts at the start; a zip's directory and LZW's dictionary need it all
            raw = f.read(limit if kind is None else 16 * limit if kind in STREAMS else MAX_COMPACT_BYTES)
    except OSError:
        return b""
    text = raw
    if kind in STREAMS:
        dec = decompressor(kind)
        try:
            text = dec.decompress(raw, limit)
        except (zlib.error, OSError, EOFError, lzma.LZMAError, ValueError):
            return b""
    elif kind is not None:
        try:
            text = _outer(path, raw, Unpacked(b""), MAX_UNPACKED_BYTES)
        except ReaderError:
            return b""
    text = text[:limit]
    if is_compact(text):
        text = text.split(b"\n", 2)[-1]
    return text


@contextmanager
def archive_folder(path: Path) -> Iterator[Path | None]:
    """A zip archive holding several RINEX files, laid out in a temporary folder (an observation file
    and the navigation file shipped beside it), or None for anything else."""
    try:
        with path.open("rb") as f:
            is_zip = packing_of(f.read(8)) == "zip"
    except OSError:
        is_zip = False
    if not is_zip:
        yield None
        return
    members = zip_members(path, path.read_bytes(), MAX_UNPACKED_BYTES, [], _too_big)
    rinex = {n: b for n, b in members.items() if b"RINEX VERS" in b[:240] or is_compact(b)}
    if len(rinex) < 2:
        yield None
        return
    folder = Path(tempfile.mkdtemp(prefix="spooflens-zip-"))
    try:
        for name, body in rinex.items():
            (folder / Path(name).name).write_bytes(body)
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)
