"""Compressed streams and zip archives as the readers that take logs as shipped need them
(`readers.packed` for every format, `readers.rinex.packaging` for RINEX): the packing recognised by
content, a stream inflated a bounded piece at a time, a zip's members read even when its directory is lost.
What came before a cut or damage is always kept; the damage is returned to be listed, never raised.
"""

from __future__ import annotations

import bz2
import lzma
import zipfile
import zlib
from collections.abc import Callable
from io import BytesIO
from pathlib import Path
from typing import IO, Any

from spooflens.errors import ReaderError

CHUNK = 1 << 20
LZW_PACKING = "compress (.Z)"
GZIP, BZIP2, ZIP, LZW, XZ = b"\x1f\x8b", b"BZh", b"PK\x03\x04", b"\x1f\x9d", b"\xfd7zXZ\x00"
STREAMS = ("gzip", "bzip2", "xz")  # the packings `inflate` takes off

# (file, what unpacks, the limit it passed) -> the error that refuses it: each caller says why its limit is
TooBig = Callable[[Path, str, int], ReaderError]
Decompressor = Any  # zlib's, bz2's or lzma's decompressor object


def packing_of(head: bytes) -> str | None:
    """The outer packing a file's first bytes (512 for a tar) show, or None for none."""
    if head.startswith(GZIP):
        return "gzip"
    if head.startswith(BZIP2) and head[3:4].isdigit():
        return "bzip2"
    if head.startswith(ZIP):
        return "zip"
    if head.startswith(LZW):
        return LZW_PACKING
    if head.startswith(XZ):
        return "xz"
    if head[257:262] == b"ustar":
        return "tar"
    return None


def decompressor(packing: str) -> Decompressor:
    """A fresh decompressor of one gzip, bzip2 or xz member."""
    if packing == "gzip":
        return zlib.decompressobj(16 + zlib.MAX_WBITS)
    return bz2.BZ2Decompressor() if packing == "bzip2" else lzma.LZMADecompressor()


def inflate(
    path: Path, packing: str, source: IO[bytes], target: IO[bytes], limit: int, too_big: TooBig
) -> tuple[int, str | None]:
    """A gzip, bzip2 or xz stream (members one after another) written out a bounded piece at a time;
    (bytes written, the damage or cut that ended it, None when whole). A stream cut or damaged keeps
    every byte decoded before the cut, not only whole pieces (Python's GzipFile loses what it decoded in
    the read that meets the cut). More than `limit` bytes: `too_big`'s error."""
    written = 0
    dec = decompressor(packing)
    pending = b""  # input read and not yet taken by the decompressor
    while True:
        more_output = not getattr(dec, "needs_input", not getattr(dec, "unconsumed_tail", b""))
        if not pending and not more_output:
            pending = source.read(CHUNK)
            if not pending:
                break
        try:
            out = dec.decompress(pending, CHUNK)
        except (zlib.error, OSError, EOFError, lzma.LZMAError, ValueError) as err:
            return written, f"{packing} stream damaged ({err}): what came after the damage is lost"
        pending = getattr(dec, "unconsumed_tail", b"")
        written += len(out)
        if written > limit:
            raise too_big(path, packing, limit)
        target.write(out)
        if dec.eof:  # a member ended: another may follow (gzip -c a >> b), else only padding
            rest = dec.unused_data + pending + source.read(CHUNK)
            if not rest.strip(b"\0"):
                return written, None
            dec, pending = decompressor(packing), rest
    if isinstance(dec, type(zlib.decompressobj())):
        tail = dec.flush()
        written += len(tail)
        target.write(tail)
    return written, f"{packing} stream cut short: what came after the cut is lost"


def expand_lzw(path: Path, data: bytes, limit: int, too_big: TooBig) -> bytes:
    """A Unix compress (.Z) stream expanded whole by `ncompress` (LZW has no member boundaries to stream
    by); one that cannot be expanded is refused, one larger than `limit` is `too_big`'s error."""
    import ncompress

    try:
        body = ncompress.decompress(data)
    except (ValueError, RuntimeError, OSError) as err:
        raise ReaderError(path, f"Unix compress (.Z) stream that cannot be expanded: {err}") from err
    if len(body) > limit:
        raise too_big(path, LZW_PACKING, limit)
    return bytes(body)


def zip_members(path: Path, data: bytes, limit: int, losses: list[str], too_big: TooBig) -> dict[str, bytes]:
    """Every file in a zip archive (name -> bytes); an archive cut short (no central directory) is read
    from its members' own headers, up to the cut (said in `losses`)."""
    members: dict[str, bytes] = {}
    total = 0
    try:
        with zipfile.ZipFile(BytesIO(data)) as z:
            for info in z.infolist():
                if info.is_dir():
                    continue
                if total + info.file_size > limit:
                    raise too_big(path, f"zip member {info.filename}", limit)
                with z.open(info) as f:
                    body = f.read(limit + 1 - total)
                total += len(body)
                members[info.filename] = body
        return members
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError, NotImplementedError, ValueError) as err:
        losses.append(f"zip archive damaged or cut short ({err}): members read from their local headers")
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
            raise too_big(path, f"zip member {name}", limit)
        if body and not name.endswith("/"):
            members[name] = body
    return members
