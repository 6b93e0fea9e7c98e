"""RINEX observation files (2.10/2.11, 3.02-3.05, 4.00-4.02) to an EpochTable, RINEX navigation files to GPS orbits.

A log is one observation file or a directory holding several (one receiver per file: MARKER NAME, else
the file stem; duplicates get the file name appended). Each satellite of each epoch becomes one row of
the `observations` frame, on the GPS time scale (`time_reference` "gps").

**Which observable.** One L1-band signal per satellite and epoch, the first present (not blank, not
0.0, which RINEX uses for "missing") of a priority list; phase, Doppler and C/N0 come from that same
signal (`L`, `D`, `S` with the code's band and attribute), never mixed across signals:

- RINEX 2: `C1`, then `P1`; with `L1`, `D1`, `S1` (a blank system letter is GPS).
- RINEX 3, per system (`CODE_PRIORITY`): GPS `C1C C1W C1P C1Y C1X C1S C1L C1M`; GLONASS `C1C C1P`;
  Galileo `C1C C1X C1B C1A C1Z`; QZSS `C1C C1X C1L C1S C1Z C1E C1B`; SBAS `C1C`; BeiDou B1I
  `C2I C2X C2Q` (3.03+) or `C1I C1Q` (3.02), then B1C `C1P C1X C1D`; NavIC `C5A C5X C5B C5C` (L5).

**Carrier continuity.** A phase whose loss-of-lock indicator (the digit after the F14.3 value) has bit 0
set (lock lost since the previous epoch), or bit 1 (half-cycle ambiguity or slip possible), and every
phase of an epoch with flag 1 (power failure since the previous epoch), is marked (`carrier_arc_start`),
counted as flagged: the range-rate detector then takes no carrier difference into it (`readers.carrier_arcs`).
Bit 2 (BOC tracking; anti-spoofing in 2.x) is no slip.

Carrier frequency: 1575.42 MHz for GPS/Galileo/QZSS/SBAS L1/E1 and BeiDou B1C, 1561.098 MHz for
B1I, 1176.45 MHz for NavIC L5; GLONASS G1 from the header's GLONASS SLOT / FRQ # (NaN without it).
`pseudorange_rate_mps = -doppler_hz * c / carrier_freq_hz`.

**Satellite states.** GPS rows get the satellite's position, velocity and clock at the signal's
transmission time (`t_rx - pr/c`, corrected once by the satellite clock), in the ECEF frame of that
instant (no Earth-rotation correction: the receiver side applies it). The navigation file is found
beside the observation file: the same name with the extension's last letter `o` -> `n`/`p`
(`07590920.05o` -> `07590920.05n`), a RINEX 3 long name `..._MO.rnx` -> `..._GN.rnx`/`..._MN.rnx`,
`.obs` -> `.nav`; else every GPS/mixed navigation file in the directory (found by content). The topic
`nav` overrides this: `read_log(path, topics={"nav": "/path/brdc0920.05n"})`, on the command line
`--topic nav=/path/brdc0920.05n`. Rows without a valid broadcast record keep NaN states and are
counted under "no ephemeris"; non-GPS satellites get no states (only GPS orbits are modelled).

**Time.** Epochs are taken in the file's time system (TIME OF FIRST OBS): GPS (and QZSS/Galileo,
aligned with GPS to nanoseconds) as they are; BeiDou time + 14 s; GLONASS time (UTC(SU) + 3 h) is
converted to GPS with the leap-second table. Other systems are refused. The receiver clock offset
field is ignored. Epoch flags 0 and 1 are data; 2-5 are events whose header records are skipped (a
flag-4 record that redefines the observation types is honoured); 6 (cycle-slip records) is skipped.

**Bad input.** A file cut mid-epoch keeps every complete epoch before the cut; a satellite row with a
field that is not a number is skipped; an epoch whose header lists more satellites than lines follow
is skipped (RINEX 2) or read from the lines present (RINEX 3); every such loss is listed in
`table.skipped`. An unknown version, a navigation file given as a log, or a file without END OF
HEADER is one ReaderError.

Parsing is vectorised: a file is read once as bytes and every fixed-width field of every line is cut
out with numpy, so a 1 Hz day (86,400 epochs, ~1M satellite rows) reads in a few seconds.
"""

from __future__ import annotations

from pathlib import Path

from readers import ReaderFormat
from readers.compression import packing_of
from readers.rinex.assembly import APPROX_POSITION_KEY, obs_files, read_rinex
from readers.rinex.navigation import NavFile, find_nav_files, is_broadcast_nav, read_rinex_nav, read_rinex_nav_file
from readers.rinex.observation import (
    BAND_HZ,
    CODE_PRIORITY,
    CODE_PRIORITY_V2,
    GLONASS_FDMA,
    ObsHeader,
    ObsScan,
    carrier_frequency_hz,
    is_rinex_obs,
    read_obs_header,
    rinex_approx_position,
    scan_obs,
)
from readers.rinex.packaging import is_compact
from readers.rinex.text import GPS_EPOCH, OBSERVATION_VERSIONS, SUPPORTED_VERSIONS, TextLines, first_line, parse_fixed

__all__ = [
    "APPROX_POSITION_KEY",
    "BAND_HZ",
    "CODE_PRIORITY",
    "CODE_PRIORITY_V2",
    "FORMATS",
    "GLONASS_FDMA",
    "GPS_EPOCH",
    "SUPPORTED_VERSIONS",
    "NavFile",
    "ObsHeader",
    "ObsScan",
    "TextLines",
    "carrier_frequency_hz",
    "find_nav_files",
    "is_broadcast_nav",
    "is_rinex_obs",
    "obs_files",
    "parse_fixed",
    "read_obs_header",
    "read_rinex",
    "read_rinex_nav",
    "read_rinex_nav_file",
    "rinex_approx_position",
    "scan_obs",
]


def _is_rinex(path: Path, head: bytes) -> bool:
    if path.is_dir():
        # a directory with CSV files is a CSV log, even when RINEX files lie beside them
        return not any(path.glob("*.csv")) and any(p.is_file() and is_rinex_obs(p) for p in sorted(path.iterdir()))
    if packing_of(head) is not None or is_compact(head):  # shipped packed: the RINEX line is inside
        first = first_line(path)
    else:
        first = head.split(b"\n", 1)[0].decode("latin-1")
    return "RINEX VERSION / TYPE" in first


FORMATS = (
    ReaderFormat(
        "rinex",
        f"RINEX observation file ({OBSERVATION_VERSIONS}; plain, gzip, bzip2, .Z, zip or Hatanaka .crx) or a "
        "directory of them, navigation file beside",
        read_rinex,
        _is_rinex,
        rewrite="spooflens.writers.rinex_rewrite:rewrite_rinex_log",
        folder_of_files=True,
        companion=lambda path: path.is_file() and not is_rinex_obs(path),  # a navigation file
    ),
)
