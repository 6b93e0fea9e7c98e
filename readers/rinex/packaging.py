"""RINEX as shipped: gzip, bzip2, Unix compress (.Z), zip, and Hatanaka's Compact RINEX (.crx, .YYd).

Archives and data centres ship RINEX packed: `..._MO.crx.gz` (Compact RINEX inside gzip), `.YYd.Z`,
`.rnx.gz`, a zip of a day's files. The outer layer is opened with Python's own gzip/bz2/zip support and
`ncompress` (the LZW of `.Z`), streamed so that an absurd size is refused before it is held in memory;
Compact RINEX is expanded by the `hatanaka` package (RNXCMP's crx2rnx, the format author's own tool).
Packing is recognised by content, never by name. A stream cut short keeps what came before the cut
(the loss listed), as a cut plain file does.
"""

from __future__ import annotations

import bz2
import shutil
import tempfile
import warnings
import zipfile
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path

from spooflens.errors import ReaderError

MAX_UNPACKED_BYTES = 512 * 2**20  # a day of 1 Hz multi-GNSS RINEX 3 is ~300 MB; more is no RINEX we hold
MAX_COMPACT_BYTES = MAX_UNPACKED_BYTES // 4  # Compact RINEX expands 3-4 fold
CHUNK = 1 << 20
HEAD_BYTES = 64 * 1024  # enough for any RINEX header's first lines

GZIP, BZIP2, ZIP, LZW = b"\x1f\x8b", b"BZh", b"PK\x03\x04", b"\x1f\x9d"


@dataclass
class Unpacked:
    """A file's RINEX text and what unpacking it lost or decided."""

    data: bytes
    packing: list[str] = field(default_factory=list)  # outermost first: ["gzip", "Compact RINEX"]
    losses: list[str] = field(default_factory=list)


def packing_of(head: bytes) -> str | None:
    """The outer packing a file's first bytes show, or None for plain text."""
    if head.startswith(GZIP):
        return "gzip"
    if head.startswith(BZIP2) and head[3:4].isdigit():
        return "bzip2"
    if head.startswith(ZIP):
        return "zip"
    if head.startswith(LZW):
        return "compress (.Z)"
    return None


def is_compact(text: bytes) -> bool:
    return b"COMPACT RINEX" in text[:80] and b"CRINEX VERS" in text[:80]


def _too_big(path: Path, what: str, limit: int) -> ReaderError:
    return ReaderError(
        path, f"{what} unpacks to more than {limit // 2**20} MiB: larger than any RINEX file spooflens holds in memory"
    )


def _inflate(path: Path, data: bytes, kind: str, limit: int, out: Unpacked) -> bytes:
    """A gzip (members one after another) or bzip2 stream, streamed; cut or corrupt: what came before."""
    chunks: list[bytes] = []
    size = 0
    pos = 0
    while pos < len(data):
        dec = zlib.decompressobj(16 + zlib.MAX_WBITS) if kind == "gzip" else bz2.BZ2Decompressor()
        try:
            for start in range(pos, len(data), CHUNK):
                piece = dec.decompress(data[start : start + CHUNK])
                size += len(piece)
                if size > limit:
                    raise _too_big(path, kind, limit)
                chunks.append(piece)
                if dec.eof:
                    break
        except (zlib.error, OSError, EOFError, ValueError) as err:
            out.losses.append(f"{kind} stream damaged ({err}): the text after the damage is lost")
            break
        if not dec.eof:
            out.losses.append(f"{kind} stream cut short: the text after the cut is lost")
            break
        rest = dec.unused_data
        pos = len(data) - len(rest)
        if not rest.strip(b"\0"):
            break
    return b"".join(chunks)


def zip_members(path: Path, data: bytes, limit: int, out: Unpacked) -> dict[str, bytes]:
    """Every file in a zip archive (name -> bytes); an archive cut short (no central directory) is read
    from its members' own headers, up to the cut."""
    members: dict[str, bytes] = {}
    total = 0
    try:
        with zipfile.ZipFile(BytesIO(data)) as z:
            for info in z.infolist():
                if info.is_dir():
                    continue
                if total + info.file_size > limit:
                    raise _too_big(path, f"zip member {info.filename}", limit)
                with z.open(info) as f:
                    body = f.read(limit + 1 - total)
                total += len(body)
                members[info.filename] = body
        return members
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError, NotImplementedError, ValueError) as err:
        out.losses.append(f"zip archive damaged or cut short ({err}): members read from their local headers")
    pos = 0
    while (pos := data.find(ZIP, pos)) >= 0 and len(data) >= pos + 30:
        method = int.from_bytes(data[pos + 8 : pos + 10], "little")
        name_len = int.from_bytes(data[pos + 26 : pos + 28], "little")
        extra_len = int.from_bytes(data[pos + 28 : pos + 30], "little")
        name = data[pos + 30 : pos + 30 + name_len].decode("latin-1")
        start = pos + 30 + name_len + extra_len
        pos = start
        if method == 8:
            dec = zlib.decompressobj(-zlib.MAX_WBITS)
            try:
                body = dec.decompress(data[start:], limit + 1 - total)
            except zlib.error:
                continue
        elif method == 0:
            body = data[start : start + limit + 1 - total]
        else:
            continue
        total += len(body)
        if total > limit:
            raise _too_big(path, f"zip member {name}", limit)
        if body and not name.endswith("/"):
            members[name] = body
    return members


def _rinex_member(path: Path, members: dict[str, bytes]) -> tuple[str, bytes]:
    """The RINEX observation file of an archive, else its first RINEX file."""
    rinex = {n: b for n, b in members.items() if b"RINEX VERS" in b[:240] or is_compact(b)}
    if not rinex:
        raise ReaderError(path, f"zip archive holds no RINEX file (members: {sorted(members)[:6]})")
    obs = [n for n, b in rinex.items() if b"OBSERVATION DATA" in b[:240] or is_compact(b)]
    name = (obs or sorted(rinex))[0]
    return name, rinex[name]


def _outer(path: Path, data: bytes, out: Unpacked, limit: int) -> bytes:
    kind = packing_of(data[:8])
    if kind is None:
        return data
    out.packing.append(kind)
    if kind in ("gzip", "bzip2"):
        return _inflate(path, data, kind, limit, out)
    if kind == "zip":
        name, body = _rinex_member(path, zip_members(path, data, limit, out))
        out.packing[-1] = f"zip ({name})"
        return body
    import ncompress

    try:
        body = ncompress.decompress(data)
    except (ValueError, RuntimeError, OSError) as err:
        raise ReaderError(path, f"Unix compress (.Z) stream that cannot be expanded: {err}") from err
    if len(body) > limit:
        raise _too_big(path, kind, limit)
    return bytes(body)


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
            kind = packing_of(f.read(8))
            f.seek(0)
            # a gzip or bzip2 stream starts at the start; a zip's directory and LZW's dictionary need it all
            raw = f.read(limit if kind is None else 16 * limit if kind in ("gzip", "bzip2") else MAX_COMPACT_BYTES)
    except OSError:
        return b""
    text = raw
    if kind in ("gzip", "bzip2"):
        dec = zlib.decompressobj(16 + zlib.MAX_WBITS) if kind == "gzip" else bz2.BZ2Decompressor()
        try:
            text = dec.decompress(raw, limit)
        except (zlib.error, OSError, EOFError, ValueError):
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
    out = Unpacked(b"")
    members = zip_members(path, path.read_bytes(), MAX_UNPACKED_BYTES, out)
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
