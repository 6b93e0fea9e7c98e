"""Mutations of logs, as a new user's damaged files would be: every one seeded and described.

A mutant is a copy of a seed log (a file, or a directory of files, with the files that belong beside
it: a truth file, a RINEX navigation file) with one to three mutations applied to one of its files:

- bytes: truncation, byte flips, an integer field overwritten with an extreme value (a length, a count,
  an offset), a block zeroed, deleted or repeated, garbage inserted, the text inside a binary record
  (schema text, message definitions, format strings) overwritten;
- text: a numeric value replaced by an extreme one (1e300, +-1e308, NaN, Inf, 999, -1, 2^63), a CSV
  column in the wrong unit (radians, millimetres, deg/s, g, milliseconds) or zeroed, header names
  shifted by one, a `# t0_ns:` too large or negative, a row cut in the middle, a huge garbage line,
  non-ASCII bytes, lines deleted, repeated or swapped;
- structure: the schema text or protobuf descriptor of an MCAP rewritten, a ULog format declaring
  huge arrays, ULog message sizes overwritten, ROS1 bag record lengths overwritten, a ROS2 sqlite3 bag
  with messages deleted or its serialization format changed;
- packed files (gzip, zip: RINEX as archives ship it): any of the above inside the packing, the
  file packed again, so the damage reaches the reader behind the unpacking;
- and the extension swapped for another format's.
"""

from __future__ import annotations

import random
import re
import shutil
import sqlite3
import struct
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

EXTREMES = (
    "1e300",
    "-1e300",
    "1e308",
    "-1e308",
    "1.7976931348623157e308",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "0",
    "999",
    "-999",
    "99999999",
    "-1",
    "9223372036854775808",
    "-9223372036854775809",
    "1e20",
    "",
    "abc",
)
EXTENSIONS = (".mcap", ".bag", ".ulg", ".csv", ".txt", ".bin", ".log", ".nmea", ".ubx", ".tlog", ".05o", ".rnx", "")
# CSV unit mistakes: (factor, what)
UNIT_ERRORS = (
    (1000.0, "x1000 (mm for m, ms for s)"),
    (0.001, "/1000"),
    (0.017453292519943295, "degrees read as radians"),
    (57.29577951308232, "radians as degrees (deg/s for rad/s)"),
    (1 / 9.80665, "m/s^2 as g"),
    (0.0, "zeroed"),
    (-1.0, "sign flipped"),
)
_NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


@dataclass(frozen=True)
class SeedLog:
    """A log to mutate: a file or a directory, with the files that belong beside it."""

    path: Path
    companions: tuple[Path, ...] = ()

    @property
    def name(self) -> str:
        return self.path.name


@dataclass(frozen=True)
class Mutant:
    seed: SeedLog
    path: Path  # the mutated log to run the command on
    description: str


Data = bytearray
ByteMutation = Callable[[random.Random, Data], str]


def _is_text(data: bytes) -> bool:
    head = data[:4096]
    if not head:
        return False
    printable = sum(32 <= b < 127 or b in (9, 10, 13) for b in head)
    return printable / len(head) > 0.97


# --- byte-level -------------------------------------------------------------------------------------


def truncate(rng: random.Random, data: Data) -> str:
    n = len(data)
    cut = rng.choice([rng.randrange(0, max(n, 1)), int(n * rng.uniform(0.9, 1.0)), rng.randrange(0, min(n, 512) + 1)])
    del data[cut:]
    return f"truncated at byte {cut} of {n}"


def flip_bytes(rng: random.Random, data: Data) -> str:
    if not data:
        return "flip: empty"
    k = rng.choice([1, 2, 4, 16, 64])
    for _ in range(k):
        i = rng.randrange(len(data))
        data[i] ^= rng.randrange(1, 256)
    return f"{k} byte(s) flipped"


def _extreme_int(rng: random.Random, width: int) -> bytes:
    bits = 8 * width
    value = rng.choice([0, 1, (1 << bits) - 1, (1 << (bits - 1)) - 1, 1 << (bits - 1), rng.getrandbits(bits)])
    return value.to_bytes(width, "little")


def overwrite_int(rng: random.Random, data: Data, at: int | None = None, width: int | None = None) -> str:
    if len(data) < 8:
        return "overwrite: too short"
    width = width or rng.choice([1, 2, 4, 8])
    if at is None:  # headers and length fields sit near the start more often than not
        at = rng.randrange(min(len(data) - width, 256)) if rng.random() < 0.4 else rng.randrange(len(data) - width)
    data[at : at + width] = _extreme_int(rng, width)
    return f"{width}-byte integer at {at} overwritten with 0x{data[at : at + width][::-1].hex()}"


def block(rng: random.Random, data: Data) -> str:
    if len(data) < 16:
        return "block: too short"
    size = min(rng.choice([8, 64, 512, 4096, 65536]), len(data) // 2)
    at = rng.randrange(len(data) - size)
    what = rng.choice(["zeroed", "deleted", "repeated", "0xff"])
    if what == "zeroed":
        data[at : at + size] = bytes(size)
    elif what == "0xff":
        data[at : at + size] = b"\xff" * size
    elif what == "deleted":
        del data[at : at + size]
    else:
        data[at:at] = data[at : at + size]
    return f"{size} bytes at {at} {what}"


def insert_garbage(rng: random.Random, data: Data) -> str:
    size = rng.choice([1, 16, 1000, 100_000])
    at = rng.randrange(len(data) + 1)
    data[at:at] = rng.randbytes(size)
    return f"{size} random bytes inserted at {at}"


def text_in_binary(rng: random.Random, data: Data) -> str:
    """Overwrite characters of a printable run (schema text, message definition, format string)."""
    runs = [m.span() for m in re.finditer(rb"[ -~\n]{24,}", data[:4_000_000])]
    if not runs:
        return flip_bytes(rng, data)
    a, b = rng.choice(runs)
    k = rng.choice([1, 3, 10])
    for _ in range(k):
        i = rng.randrange(a, b)
        data[i] = rng.choice(b"[]#:;= \n0123456789xyzABC\x00\xff")
    return f"{k} character(s) of the text at {a}-{b} overwritten"


BYTE_MUTATIONS: tuple[ByteMutation, ...] = (truncate, flip_bytes, overwrite_int, block, insert_garbage, text_in_binary)


# --- text -------------------------------------------------------------------------------------------


def _lines(data: Data) -> list[bytes]:
    return bytes(data).split(b"\n")


def _set_lines(data: Data, lines: list[bytes]) -> None:
    data[:] = b"\n".join(lines)


def _data_rows(lines: list[bytes]) -> list[int]:
    """Indices of the non-empty, non-comment lines after a header line (one that does not start with a number)."""
    rows = [i for i, line in enumerate(lines) if line.strip() and not line.startswith(b"#")]
    if rows and not _NUMBER.match(lines[rows[0]].lstrip()):
        return rows[1:]
    return rows


def value(rng: random.Random, data: Data) -> str:
    lines = _lines(data)
    rows = [i for i in _data_rows(lines) if _NUMBER.search(lines[i])]
    if not rows:
        return truncate(rng, data)
    k = rng.choice([1, 5, 50])
    new = rng.choice(EXTREMES)
    for _ in range(k):
        i = rng.choice(rows)
        numbers = list(_NUMBER.finditer(lines[i]))
        if not numbers:  # an earlier replacement took this line's last number
            continue
        m = rng.choice(numbers)
        lines[i] = lines[i][: m.start()] + new.encode() + lines[i][m.end() :]
    _set_lines(data, lines)
    return f"{k} value(s) replaced by {new!r}"


def _csv_header(lines: list[bytes]) -> int | None:
    for i, line in enumerate(lines):
        if line.strip() and not line.startswith(b"#"):
            return i if b"," in line and not _NUMBER.match(line.lstrip()) else None
    return None


def csv_column(rng: random.Random, data: Data) -> str:
    """One column of a CSV in a wrong unit, zeroed, a sentinel, or NaN: every row."""
    lines = _lines(data)
    h = _csv_header(lines)
    if h is None:
        return value(rng, data)
    names = lines[h].split(b",")
    col = rng.randrange(len(names))
    factor, what = rng.choice([*UNIT_ERRORS, (None, "999 sentinel"), (None, "NaN")])
    for i in range(h + 1, len(lines)):
        cells = lines[i].split(b",")
        if col >= len(cells):
            continue
        try:
            v = float(cells[col])
        except ValueError:
            continue
        if factor is not None:
            cells[col] = repr(v * factor).encode()
        else:
            cells[col] = b"999" if what.startswith("999") else b"nan"
        lines[i] = b",".join(cells)
    _set_lines(data, lines)
    return f"column {names[col].decode(errors='replace')!r}: {what}"


def csv_header_shift(rng: random.Random, data: Data) -> str:
    lines = _lines(data)
    h = _csv_header(lines)
    if h is None:
        return value(rng, data)
    names = lines[h].split(b",")
    lines[h] = b",".join([*names[1:], b"extra"]) if rng.random() < 0.5 else b",".join([b"extra", *names[:-1]])
    _set_lines(data, lines)
    return "header names shifted by one"


def csv_time(rng: random.Random, data: Data) -> str:
    """The clock: `# t0_ns:` too large, negative or garbage; or the time column in milliseconds."""
    lines = _lines(data)
    bad = rng.choice([b"99999999999999999999999999", b"-1700000000000000000", b"-5", b"1e30", b"nan", b"0x10"])
    for i, line in enumerate(lines):
        if line.startswith(b"# t0_ns:"):
            lines[i] = b"# t0_ns: " + bad
            _set_lines(data, lines)
            return f"# t0_ns: {bad.decode()}"
    if rng.random() < 0.5:
        lines.insert(0, b"# t0_ns: " + bad)
        _set_lines(data, lines)
        return f"# t0_ns: {bad.decode()} added"
    h = _csv_header(lines)
    if h is None:
        return value(rng, data)
    _set_lines(data, lines)
    return csv_column(random.Random(rng.random()), data)


def cut_row(rng: random.Random, data: Data) -> str:
    lines = _lines(data)
    rows = _data_rows(lines)
    if not rows:
        return truncate(rng, data)
    i = rng.choice(rows[-3:] if rng.random() < 0.5 else rows)
    cut = rng.randrange(max(len(lines[i]), 1))
    if i == rows[-1] or rng.random() < 0.5:  # the file ends in the middle of a row
        lines = [*lines[:i], lines[i][:cut]]
        _set_lines(data, lines)
        return f"file cut in the middle of line {i + 1}"
    lines[i] = lines[i][:cut]
    _set_lines(data, lines)
    return f"line {i + 1} cut in the middle"


def garbage_line(rng: random.Random, data: Data) -> str:
    lines = _lines(data)
    size = rng.choice([100, 10_000, 1_000_000, 5_000_000])
    kind = rng.choice(["random bytes", "commas", "digits"])
    if kind == "random bytes":
        junk = bytes(b for b in rng.randbytes(size) if b != 10)
    elif kind == "commas":
        junk = b"1," * (size // 2)
    else:
        junk = b"7" * size
    at = rng.randrange(len(lines) + 1)
    lines.insert(at, junk)
    _set_lines(data, lines)
    return f"{len(junk)}-byte line of {kind} at line {at + 1}"


def non_ascii(rng: random.Random, data: Data) -> str:
    if not data:
        return "non-ascii: empty"
    k = rng.choice([1, 5, 50])
    for _ in range(k):
        at = rng.randrange(len(data))
        data[at:at] = rng.choice([b"\xe9", b"\xff\xfe", b"\xc3", "é".encode(), "\u2028".encode(), b"\x00"])
    return f"{k} non-ASCII byte(s) inserted"


def lines_op(rng: random.Random, data: Data) -> str:
    lines = _lines(data)
    rows = _data_rows(lines)
    if len(rows) < 4:
        return value(rng, data)
    a = rng.choice(rows)
    b = min(a + rng.choice([1, 10, 100]), rows[-1])
    what = rng.choice(["deleted", "repeated", "swapped", "reversed"])
    if what == "deleted":
        del lines[a:b]
    elif what == "repeated":
        lines[b:b] = lines[a:b]
    elif what == "swapped":
        lines[a], lines[b] = lines[b], lines[a]
    else:
        lines[a:b] = lines[a:b][::-1]
    _set_lines(data, lines)
    return f"lines {a + 1}-{b + 1} {what}"


TEXT_MUTATIONS: tuple[ByteMutation, ...] = (
    value,
    value,
    csv_column,
    csv_header_shift,
    csv_time,
    cut_row,
    garbage_line,
    non_ascii,
    lines_op,
)


# --- structure-aware --------------------------------------------------------------------------------


def ulog_messages(data: bytes) -> list[tuple[int, int, int]]:
    """(offset, size, type) of each ULog message after the 16-byte header, as far as they parse."""
    out: list[tuple[int, int, int]] = []
    pos = 16
    while pos + 3 <= len(data) and len(out) < 200_000:
        size, kind = struct.unpack_from("<HB", data, pos)
        out.append((pos, size, kind))
        pos += 3 + size
    return out


def ulog_structure(rng: random.Random, data: Data) -> str:
    if not data.startswith(b"ULog"):
        return overwrite_int(rng, data)
    messages = ulog_messages(bytes(data))
    formats = [m for m in messages if m[2] == ord("F")]
    if formats and rng.random() < 0.5:
        pos, size, _ = rng.choice(formats)
        text = bytes(data[pos + 3 : pos + 3 + size])
        fields = text.split(b";")
        i = rng.randrange(len(fields))
        what = rng.choice(["huge array", "unknown type", "renamed", "dropped", "first field huge array"])
        if what in ("huge array", "first field huge array"):
            i = 0 if what.startswith("first") else i
            name_type = fields[i].split(b" ")
            fields[i] = re.sub(rb"(\[\d+\])?$", b"[99999999]", name_type[0]) + b" " + b" ".join(name_type[1:])
            if b":" in name_type[0]:  # the topic name sits before the first field
                head, _, first = name_type[0].partition(b":")
                fields[i] = head + b":" + first.split(b"[")[0] + b"[99999999] " + b" ".join(name_type[1:])
        elif what == "unknown type":
            fields[i] = re.sub(rb"^([^:]*:)?[a-z0-9_]+", rb"\1quaternion_t", fields[i])
        elif what == "renamed":
            fields[i] = fields[i] + b"_x"
        else:
            del fields[i]
        new = b";".join(fields)
        data[pos : pos + 3 + size] = struct.pack("<HB", len(new), ord("F")) + new
        return f"ULog format message at {pos}: {what} (field {i})"
    if not messages:
        return overwrite_int(rng, data)
    pos, _, _ = rng.choice(messages)
    return "ULog message size: " + overwrite_int(rng, data, at=pos, width=2)


def bag_structure(rng: random.Random, data: Data) -> str:
    """ROS1 bag v2.0: records are header_len(4) header data_len(4) data."""
    start = data.find(b"\n") + 1
    records: list[tuple[int, int]] = []
    pos = start
    while pos + 8 <= len(data) and len(records) < 100_000:
        (hlen,) = struct.unpack_from("<I", data, pos)
        if pos + 4 + hlen + 4 > len(data):
            break
        (dlen,) = struct.unpack_from("<I", data, pos + 4 + hlen)
        records.append((pos, hlen))
        pos += 8 + hlen + dlen
    if not records:
        return overwrite_int(rng, data)
    pos, hlen = rng.choice(records)
    at = pos if rng.random() < 0.5 else pos + 4 + hlen
    return "bag record length: " + overwrite_int(rng, data, at=at, width=4)


def mcap_schema(rng: random.Random, path: Path) -> str:
    """Rewrite an MCAP with one schema's text (or protobuf descriptor bytes) overwritten."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    src = path.with_name(path.name + ".orig")
    path.rename(src)
    try:
        with src.open("rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is None or not summary.schemas:
                raise ValueError("no summary")
            victim = rng.choice(sorted(summary.schemas))
            schema = summary.schemas[victim]
            text = bytearray(schema.data)
            what = text_in_binary(rng, text) if _is_text(bytes(text)) else flip_bytes(rng, text)
            if rng.random() < 0.3 and _is_text(bytes(text)):
                lines = _lines(text)
                del lines[rng.randrange(len(lines))]
                _set_lines(text, lines)
                what += ", a line deleted"
            with path.open("wb") as out:
                w = Writer(out)
                w.start(profile=reader.get_header().profile, library="spooflens fuzz")
                ids = {
                    sid: w.register_schema(s.name, s.encoding, bytes(text) if sid == victim else s.data)
                    for sid, s in summary.schemas.items()
                }
                chans = {
                    cid: w.register_channel(c.topic, c.message_encoding, ids.get(c.schema_id, 0), dict(c.metadata))
                    for cid, c in summary.channels.items()
                }
                for _, channel, message in reader.iter_messages(log_time_order=False):
                    w.add_message(chans[channel.id], message.log_time, message.data, message.publish_time)
                w.finish()
        return f"MCAP schema {schema.name!r} ({schema.encoding}): {what}"
    except Exception:  # noqa: BLE001 - an MCAP the library cannot rewrite gets a byte mutation instead
        shutil.copyfile(src, path)
        data = bytearray(path.read_bytes())
        what = text_in_binary(rng, data)
        path.write_bytes(bytes(data))
        return what
    finally:
        src.unlink(missing_ok=True)


def sqlite_bag(rng: random.Random, directory: Path) -> str:
    """A ROS2 sqlite3 bag: messages deleted, serialization format changed, blobs damaged, a table dropped."""
    db = next(directory.glob("*.db3"), None)
    if db is None:
        return "no db3"
    what = rng.choice(["delete all", "delete some", "delete topic", "format", "yaml format", "blob", "drop"])
    con = sqlite3.connect(db)
    try:
        if what == "delete all":
            con.execute("DELETE FROM messages")
        elif what == "delete some":
            con.execute("DELETE FROM messages WHERE id % ? = 0", (rng.choice([2, 3, 10]),))
        elif what == "delete topic":
            con.execute("DELETE FROM topics WHERE id = (SELECT min(id) FROM topics)")
        elif what == "format":
            con.execute("UPDATE topics SET serialization_format = ?", (rng.choice(["ros1", "", "json", "cdr2"]),))
        elif what == "blob":
            con.execute("UPDATE messages SET data = substr(data, 1, ?) WHERE id % 7 = 0", (rng.choice([0, 4, 12]),))
        elif what == "drop":
            con.execute(f"DROP TABLE {rng.choice(['messages', 'topics'])}")
        con.commit()
    finally:
        con.close()
    if what == "yaml format":
        meta = directory / "metadata.yaml"
        if meta.exists():
            text = meta.read_text(encoding="utf-8", errors="replace")
            meta.write_text(re.sub(r"serialization_format: \w+", "serialization_format: ros1", text))
    return f"sqlite3 bag: {what}"


# --- mutants ----------------------------------------------------------------------------------------


def _target_files(log: Path) -> list[Path]:
    if log.is_file():
        return [log]
    return sorted(p for p in log.iterdir() if p.is_file())


def packed_content(rng: random.Random, data: Data) -> str:
    """A file shipped packed (gzip, one-member zip: compressed RINEX) mutated inside its packing, so the
    damage reaches the reader behind the unpacking, not only the compressed stream."""
    import gzip
    import io
    import zipfile

    raw = bytes(data)
    if raw[:2] == b"\x1f\x8b":
        inner = bytearray(gzip.decompress(raw))
        what = _mutate_bytes(rng, inner)
        data[:] = gzip.compress(bytes(inner), compresslevel=1)
        return f"inside gzip: {what}"
    with zipfile.ZipFile(io.BytesIO(raw)) as z:
        name = rng.choice(z.namelist())
        inner = bytearray(z.read(name))
    what = _mutate_bytes(rng, inner)
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr(name, bytes(inner))
    data[:] = out.getvalue()
    return f"inside zip member {name}: {what}"


def _mutate_bytes(rng: random.Random, data: Data) -> str:
    op = rng.choice(TEXT_MUTATIONS + BYTE_MUTATIONS[:4]) if _is_text(bytes(data)) else rng.choice(BYTE_MUTATIONS)
    return op(rng, data)


def _mutate_file(rng: random.Random, path: Path) -> str:
    data = bytearray(path.read_bytes())
    if (data[:2] == b"\x1f\x8b" or data[:4] == b"PK\x03\x04") and rng.random() < 0.6:
        try:
            what = packed_content(rng, data)
        except (OSError, EOFError, ValueError, zipfile.BadZipFile, zlib.error) as err:
            what = f"packed content not reached ({type(err).__name__}); bytes flipped: {flip_bytes(rng, data)}"
        path.write_bytes(bytes(data))
        return what
    if _is_text(bytes(data)):
        op = rng.choice(TEXT_MUTATIONS + BYTE_MUTATIONS[:4])
    elif data.startswith(b"\x89MCAP") and rng.random() < 0.35:
        return mcap_schema(rng, path)
    elif data.startswith(b"ULog") and rng.random() < 0.5:
        op = ulog_structure
    elif data.startswith(b"#ROSBAG") and rng.random() < 0.4:
        op = bag_structure
    else:
        op = rng.choice(BYTE_MUTATIONS)
    what = op(rng, data)
    path.write_bytes(bytes(data))
    return what


def make_mutant(seed: SeedLog, index: int, base_seed: int, workdir: Path) -> Mutant:
    """Mutant `index` of `seed` in `workdir` (same seed and index, same bytes)."""
    rng = random.Random(f"{base_seed}:{index}:{seed.name}")
    workdir.mkdir(parents=True, exist_ok=True)
    log = workdir / seed.name
    if seed.path.is_dir():
        shutil.copytree(seed.path, log)
    else:
        shutil.copyfile(seed.path, log)
    for c in seed.companions:
        shutil.copyfile(c, workdir / c.name)
    notes = []
    for _ in range(rng.choice([1, 1, 1, 2, 3])):
        targets = _target_files(log)
        companions = [workdir / c.name for c in seed.companions]
        try:
            if log.is_dir() and any(log.glob("*.db3")) and rng.random() < 0.5:
                notes.append(sqlite_bag(rng, log))
                continue
            victim = rng.choice(companions) if companions and rng.random() < 0.1 else rng.choice(targets)
            notes.append(f"{victim.name}: {_mutate_file(rng, victim)}")
        except (OSError, ValueError, IndexError, sqlite3.Error) as err:  # a second mutation may find nothing to hold
            notes.append(f"(a mutation did not apply: {type(err).__name__})")
    if log.is_file() and rng.random() < 0.15:
        ext = rng.choice([e for e in EXTENSIONS if e != log.suffix])
        renamed = log.with_name(log.stem + ext if ext else log.stem + "_noext")
        log.rename(renamed)
        notes.append(f"renamed to {renamed.name}")
        log = renamed
    return Mutant(seed, log, "; ".join(notes))
