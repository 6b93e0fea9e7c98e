"""RINEX 4 (2021-): observation files keep 3.x's records; navigation files put each record behind a
`> EPH sv TYPE` line, add STO/EOP/ION records and move the ionosphere terms out of the header. No RINEX 4
file is in the corpus: these are the corpus's 3.x files written as 4.00 (the converters below follow the
RINEX 4.00 format's record layout), read back to what the 3.x file gives."""

from __future__ import annotations

import gzip
import re
from pathlib import Path

import numpy as np
import pytest
from paths import REAL

from readers import read_log
from readers.rinex import read_rinex_nav_file

NAV3 = REAL / "corpus" / "georinex" / "VILL00ESP_R_20181700000_01D_MN.rnx.gz"  # G, E, C, R and S records
OBS3 = REAL / "corpus" / "gnss_lib_py" / "z_tracking.rnx"
V4_TYPE = {"G": "LNAV", "E": "INAV", "C": "D1", "R": "FDMA", "J": "LNAV", "S": "SBAS", "I": "LNAV"}


def _as_v4_nav(text: str) -> str:
    """A RINEX 3 navigation file as 4.00: each record behind its `> EPH` line, the GPS ionosphere terms in an
    `> ION G01 LNAV` record, with a system time offset (STO) and an Earth orientation (EOP) record among them."""
    lines = text.splitlines()
    end = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
    head = [ln for ln in lines[: end + 1] if "IONOSPHERIC CORR" not in ln]
    head[0] = "     4.00" + head[0][9:]
    iono = {
        ln[:4]: [float(ln[5 + 12 * k : 17 + 12 * k]) for k in range(4)]
        for ln in lines[:end]
        if "IONOSPHERIC CORR" in ln
    }
    a, b = iono["GPSA"], iono["GPSB"]
    body = [
        "> ION G01 LNAV",
        "    2018 07 29 00 00 00" + "".join(f"{v:19.12E}" for v in a[:3]),
        "    " + "".join(f"{v:19.12E}" for v in [a[3], *b[:3]]),
        "    " + f"{b[3]:19.12E}" + f"{0.0:19.12E}",
        "> STO G01 LNAV",
        "    2018 07 29 00 00 00 GPUT  UTC(USNO)",
        "     5.040000000000E+05 1.862645149231E-09 8.881784197001E-16 0.000000000000E+00",
        "> EOP G01 CNVX",
        "    2018 07 29 00 00 00 0.000000000000E+00 0.000000000000E+00 0.000000000000E+00",
    ]
    for ln in lines[end + 1 :]:
        if ln[:1].strip():
            body.append(f"> EPH {ln[:3]} {V4_TYPE[ln[0]]}")
        body.append(ln)
    return "\n".join(head + body) + "\n"


def test_a_rinex4_navigation_file_gives_the_records_and_ionosphere_of_its_3x_original(tmp_path: Path) -> None:
    v3 = read_rinex_nav_file(NAV3)
    path = tmp_path / "VILL00ESP_R_20181700000_01D_MN.rnx"
    path.write_text(_as_v4_nav(gzip.decompress(NAV3.read_bytes()).decode()))
    v4 = read_rinex_nav_file(path)
    assert v4.version == 4.0 and v4.records == v3.records > 0
    for key in ("toe_sow", "sqrt_a", "e", "af0", "week"):
        np.testing.assert_array_equal(getattr(v4.ephemerides, key), getattr(v3.ephemerides, key))
    assert v4.ephemerides.iono == v3.ephemerides.iono and v3.ephemerides.iono is not None  # from > ION, not the header
    said = {s.reason for s in v4.skipped}
    assert any("RINEX 4 records not read (STO G LNAV" in r for r in said)
    assert any("RINEX 4 records not read (EOP G CNVX" in r for r in said)
    assert any("RINEX 4 records not read (EPH S SBAS" in r for r in said)
    assert any("RINEX 4 records not read (EPH R FDMA" in r for r in said)


def test_a_rinex4_nav_record_of_a_message_type_not_read_is_counted_not_misread(tmp_path: Path) -> None:
    """GPS CNAV records have more lines and other fields: passed over, counted; LNAV beside them read."""
    text = _as_v4_nav(gzip.decompress(NAV3.read_bytes()).decode())
    sv = re.search(r"> EPH (G\d\d) LNAV", text)
    assert sv is not None
    text = text.replace(sv.group(0), f"> EPH {sv.group(1)} CNAV", 1)
    path = tmp_path / "cnav.rnx"
    path.write_text(text)
    nav = read_rinex_nav_file(path)
    assert nav.records == read_rinex_nav_file(NAV3).records - 1
    assert any(s.reason.startswith("RINEX 4 records not read (EPH G CNAV") and s.count == 1 for s in nav.skipped)


def test_a_rinex4_observation_file_reads_as_its_3x_original(tmp_path: Path) -> None:
    v4 = tmp_path / "z_tracking_v4.rnx"
    text = OBS3.read_text()
    assert text.startswith("     3.04")
    v4.write_text("     4.00" + text[9:])
    a, b = read_log(OBS3), read_log(v4)
    assert len(b.observations) == len(a.observations) > 0
    np.testing.assert_array_equal(
        b.observations["pseudorange_m"].to_numpy(), a.observations["pseudorange_m"].to_numpy()
    )
    assert b.t0_ns == a.t0_ns


def test_a_rinex5_file_is_still_refused(tmp_path: Path) -> None:
    future = tmp_path / "future.rnx"
    future.write_text("     5.00" + OBS3.read_text()[9:])
    with pytest.raises(Exception, match=r"unsupported RINEX version 5; supported: .*4.00-4.02"):
        read_log(future)
