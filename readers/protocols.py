"""What a file no reader reads is, so that its refusal names it ("SiRF binary: not supported").

Receivers speak many protocols besides NMEA and UBX. Each is recognised here by its framing (sync
bytes, frame trailers, checksums), counted over the file's head after any `#` comment lines (gpsd test
logs start with them): a protocol is named only when several of its frames are found, never on one
pair of bytes, so random data is still "unknown format".
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable
from pathlib import Path

from pynmeagps.nmeatypes_core import NMEA_MSGIDS, NMEA_TALKERS

HEAD = 64 * 1024
MIN_FRAMES = 3


def _data(head: bytes) -> bytes:
    """The head without leading `#` comment lines."""
    pos = 0
    while head[pos : pos + 1] == b"#":
        nl = head.find(b"\n", pos)
        if nl < 0:
            return b""
        pos = nl + 1
    return head[pos:]


def _sirf(data: bytes) -> int:
    """A0 A2, 15-bit length, payload, 15-bit checksum, B0 B3."""
    n = 0
    for m in re.finditer(rb"\xa0\xa2", data):
        p = m.start()
        length = int.from_bytes(data[p + 2 : p + 4], "big")
        end = p + 4 + length
        if length < 0x8000 and data[end + 2 : end + 4] == b"\xb0\xb3":
            n += 1
    return n


def _skytraq(data: bytes) -> int:
    """A0 A1, length, payload, XOR checksum, CR LF."""
    n = 0
    for m in re.finditer(rb"\xa0\xa1", data):
        p = m.start()
        length = int.from_bytes(data[p + 2 : p + 4], "big")
        end = p + 4 + length
        if data[end + 1 : end + 3] == b"\r\n" and len(data) > end:
            check = 0
            for b in data[p + 4 : end]:
                check ^= b
            n += check == data[end]
    return n


def _garmin(data: bytes) -> int:
    """DLE, id, size, data, checksum (the bytes sum to 0), DLE ETX (DLE stuffed inside)."""
    n = 0
    for body in re.split(rb"(?<!\x10)\x10\x03", data):
        start = body.rfind(b"\x10")
        packet = body[start + 1 :].replace(b"\x10\x10", b"\x10") if start >= 0 else b""
        if len(packet) >= 3 and packet[1] == len(packet) - 3 and sum(packet) % 256 == 0:
            n += 1
    return n


def _tsip(data: bytes) -> int:
    """DLE, id, data, DLE ETX with DLE stuffing, no length or checksum: many DLE ETX DLE junctions."""
    return len(re.findall(rb"(?<!\x10)\x10\x03\x10[^\x03\x10]", data))


def _oncore(data: bytes) -> int:
    """@@, two letters, data, XOR checksum, CR LF."""
    return len(re.findall(rb"@@[A-Z][a-zA-Z][^\n]{0,160}\r\n", data))


def _superstar2(data: bytes) -> int:
    """SOH, id, id's complement, length (NovAtel SuperStar II)."""
    return sum(
        1
        for m in re.finditer(rb"\x01", data)
        if len(data) > m.start() + 2 and data[m.start() + 1] + data[m.start() + 2] == 0xFF
    )


def _zodiac(data: bytes) -> int:
    """FF 81, id, word count, flags, then a header checksum: the five 16-bit words sum to 0."""
    n = 0
    for m in re.finditer(rb"\xff\x81", data):
        words = data[m.start() : m.start() + 10]
        if len(words) == 10:
            n += sum(int.from_bytes(words[i : i + 2], "little") for i in range(0, 10, 2)) % 65536 == 0
    return n


def _count(pattern: bytes) -> Callable[[bytes], int]:
    return lambda data: len(re.findall(pattern, data))


def _rtcm2(data: bytes) -> int:
    """RTCM SC-104 v2 in 6-of-8 bytes (bits 6-7 = 01): nearly every byte in 0x40-0x7F."""
    sample = data[:4096]
    return MIN_FRAMES if len(sample) > 200 and sum(0x40 <= b <= 0x7F for b in sample) > 0.9 * len(sample) else 0


def _rtcm3(data: bytes) -> int:
    from pyrtcm.rtcmhelpers import calc_crc24q

    n = 0
    for m in re.finditer(rb"\xd3[\x00-\x03]", data):
        p = m.start()
        length = ((data[p + 1] & 3) << 8) | data[p + 2] if len(data) > p + 2 else 0
        end = p + 6 + length
        n += end <= len(data) and calc_crc24q(data[p:end]) == 0
    return n * MIN_FRAMES  # a CRC-24Q that holds is evidence enough


# (name, frames counter) in the order they are tried; the first with MIN_FRAMES frames names the file
PROTOCOLS: tuple[tuple[str, Callable[[bytes], int]], ...] = (
    ("SiRF binary", _sirf),
    ("SkyTraq binary", _skytraq),
    ("Javad GREIS", _count(rb"(?:RT|~~|PV|SI|EL|AZ|SG|DP|EC|SS|ET|UO|GT|RD|::)[0-9A-F]{3}")),
    ("Motorola Oncore binary", _oncore),
    ("Garmin binary", _garmin),
    ("Trimble TSIP", _tsip),
    ("Hemisphere/Crescent binary ($BIN)", _count(rb"\$BIN[\x01-\x80]")),
    ("NovAtel OEM binary", _count(rb"\xaa\x44\x12\x1c")),
    ("NovAtel SuperStar II binary", _superstar2),
    ("NavCom binary", _count(rb"\x02\x99\x66")),
    ("Rockwell Zodiac binary", _zodiac),
    ("GeoStar binary", _count(rb"PSGG")),
    ("Fastrax iTalk binary", _count(rb"<![\x00-\xff]")),
    ("CASIC binary", _count(rb"\xba\xce")),
    ("RTCM 3", _rtcm3),
    ("RTCM 2 (6-of-8 bytes)", _rtcm2),
)
TEXT_PROTOCOLS: tuple[tuple[str, re.Pattern[bytes]], ...] = (
    (
        "an NTRIP source table or request (a caster's list of streams, no GNSS data)",
        re.compile(rb"^(SOURCETABLE|GET /|STR;)", re.M),
    ),
    # a file of gpsd JSON reports is read (readers.gpsd_json); a few of them before data in no protocol
    # spooflens reads (a gpsd test log's preamble) are not
    ("gpsd JSON reports as a preamble to data in another protocol", re.compile(rb'^\{"class":', re.M)),
)


def identify(path: Path, head: bytes) -> str | None:
    """The protocol a file's content is in, when it is one of `PROTOCOLS` (None: not recognised)."""
    if path.is_file() and len(head) < HEAD:
        try:
            with path.open("rb") as f:
                head = f.read(HEAD)
        except OSError:
            return None
    data = _data(head)
    if not data:
        return None
    for name, frames in PROTOCOLS:
        if frames(data) >= MIN_FRAMES:
            return name
    for name, pattern in TEXT_PROTOCOLS:
        if pattern.search(data[:4096]):
            return name
    return _proprietary_sentences(data)


def _proprietary_sentences(data: bytes) -> str | None:
    """NMEA-style lines whose addresses are no standard sentence ($PQTMVER, $PTNTHTM, $STI...)."""
    lines = [ln.strip() for ln in data[:8192].splitlines() if ln.strip()]
    addresses = [m.group(1).decode() for ln in lines if (m := re.match(rb"^\$([A-Z][A-Z0-9]{2,15}),", ln))]
    if not lines or len(addresses) * 2 < len(lines):
        return None
    if any(standard_address(a) for a in addresses):
        return None  # standard sentences too damaged to read: the NMEA reader says how (`damaged_nmea`)
    return f"proprietary NMEA-style sentences only ({_first_names(dict.fromkeys(addresses))}), no standard sentence"


def standard_address(address: str) -> bool:
    """A standard talker and sentence ($GPRMC, $SDDBT), not a maker's own ($PUBX, $PQTMVER, $STI)."""
    return (
        len(address) == 5 and address[:2] in NMEA_TALKERS and address[2:] in NMEA_MSGIDS and not address.startswith("P")
    )


def _first_names(addresses: Iterable[str], width: int = 80) -> str:
    """'$A, $B, ...' as far as `width` characters go, then how many more (never a name cut in two)."""
    names = [f"${a}" for a in addresses]
    shown: list[str] = []
    for name in names:
        if shown and len(", ".join([*shown, name])) > width:
            break
        shown.append(name)
    rest = len(names) - len(shown)
    return ", ".join(shown) + (f" and {rest} more" if rest else "")
