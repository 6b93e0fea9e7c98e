"""A u-blox receiver capture split into its frames: UBX, NMEA, RTCM3, text comments and garbage.

Captures interleave UBX with NMEA (the receiver's own text output) and RTCM3 (corrections fed to it),
and gpsd test logs start with `#` text lines. Every frame's checksum is verified (UBX Fletcher-8,
NMEA XOR, RTCM3 CRC-24Q); a candidate that fails is not a frame: the scan moves on by one byte and
re-synchronises, so a corrupt length field costs only the bytes it covers, never the frames after it.
A frame cut by the end of the file is counted as lost.
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from pyrtcm.rtcmhelpers import calc_crc24q

from readers.rtcm_ephemeris import RTCM_EPHEMERIS

UBX_SYNC = b"\xb5\x62"
MAX_NMEA = 120  # longest NMEA sentence accepted (the standard's limit is 82 characters)
_CANDIDATE = re.compile(rb"[\xb5$!\xd3#]")


@dataclass(frozen=True)
class UbxFrame:
    offset: int
    msg_class: int
    msg_id: int
    payload: bytes

    @property
    def raw_length(self) -> int:
        return len(self.payload) + 8


@dataclass(frozen=True)
class NmeaLine:
    offset: int
    text: bytes  # "$...*hh", line ending removed


@dataclass
class Frames:
    ubx: list[UbxFrame] = field(default_factory=list)
    nmea: list[NmeaLine] = field(default_factory=list)
    comments: list[str] = field(default_factory=list)
    rtcm: Counter[int] = field(default_factory=Counter)  # message number -> count
    rtcm_ephemerides: list[bytes] = field(default_factory=list)  # whole frames of RTCM_EPHEMERIS messages
    garbage_bytes: int = 0
    bad: Counter[str] = field(default_factory=Counter)  # damaged or cut frames, by kind
    order: list[tuple[str, int]] = field(default_factory=list)  # ("ubx" | "nmea", index) in file order


def fletcher(data: bytes) -> bytes:
    """UBX checksum (8-bit Fletcher over class, id, length and payload), vectorised."""
    b = np.frombuffer(data, dtype=np.uint8).astype(np.int64)
    n = len(b)
    ck_a = int(b.sum()) & 0xFF
    ck_b = int(((n - np.arange(n)) * b).sum()) & 0xFF
    return bytes((ck_a, ck_b))


def _nmea_at(data: bytes, pos: int) -> int:
    """End (after the line break) of a valid NMEA sentence starting at `pos`, or -1."""
    end = data.find(b"\n", pos, pos + MAX_NMEA + 2)
    if end < 0:
        return -1
    line = data[pos:end].rstrip(b"\r")
    star = line.rfind(b"*")
    if star < 0 or len(line) != star + 3:
        return -1
    check = 0
    for c in line[1:star]:
        if c < 32 or c > 126:
            return -1
        check ^= c
    try:
        return end + 1 if int(line[star + 1 :], 16) == check else -1
    except ValueError:
        return -1


def split_frames(data: bytes) -> Frames:
    """Every frame of a capture, in file order, with what could not be framed counted."""
    out = Frames()
    pos, n = 0, len(data)
    while pos < n:
        b = data[pos]
        if b == 0xB5 and data[pos + 1 : pos + 2] == b"\x62":
            if pos + 6 > n:
                out.bad["UBX message cut by the end of the file"] += 1
                break
            length = data[pos + 4] | (data[pos + 5] << 8)
            end = pos + 8 + length
            if end > n:
                # a cut frame or a corrupt length: only a frame can tell; look for one further on
                nxt = data.find(UBX_SYNC, pos + 2)
                if nxt < 0:
                    out.bad["UBX message cut by the end of the file"] += 1
                    break
                out.bad["UBX headers with an impossible length"] += 1
                out.garbage_bytes += nxt - pos
                pos = nxt
                continue
            if fletcher(data[pos + 2 : end - 2]) == data[end - 2 : end]:
                out.order.append(("ubx", len(out.ubx)))
                out.ubx.append(UbxFrame(pos, data[pos + 2], data[pos + 3], data[pos + 6 : end - 2]))
                pos = end
                continue
            out.bad["UBX messages with a bad checksum"] += 1
        elif b in (0x24, 0x21):  # '$', '!'
            end = _nmea_at(data, pos)
            if end > 0:
                out.order.append(("nmea", len(out.nmea)))
                out.nmea.append(NmeaLine(pos, data[pos:end].rstrip(b"\r\n")))
                pos = end
                continue
        elif b == 0xD3 and pos + 3 <= n and data[pos + 1] & 0xFC == 0:
            length = ((data[pos + 1] & 0x03) << 8) | data[pos + 2]
            end = pos + 6 + length
            if end <= n and calc_crc24q(data[pos:end]) == 0:
                number = (data[pos + 3] << 4) | (data[pos + 4] >> 4) if length >= 2 else 0
                out.rtcm[number] += 1
                if number in RTCM_EPHEMERIS:
                    out.rtcm_ephemerides.append(data[pos:end])
                pos = end
                continue
        elif b == 0x23 and (pos == 0 or data[pos - 1] == 0x0A):  # '#' at a line start: a text comment
            end = data.find(b"\n", pos)
            end = n if end < 0 else end + 1
            out.comments.append(data[pos + 1 : end].decode("utf-8", errors="replace").strip())
            pos = end
            continue
        m = _CANDIDATE.search(data, pos + 1)
        nxt = m.start() if m else n
        out.garbage_bytes += nxt - pos
        pos = nxt
    return out
