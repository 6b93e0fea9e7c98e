"""Proprietary and variant NMEA sentences (pynmeagps' test snippets): each family's values read equal the
sentence as pynmeagps decodes it, and land in the table where the schema has a place for them."""

from __future__ import annotations

import datetime as dt
import math
from pathlib import Path
from typing import Any

import pytest
from paths import real_log
from pynmeagps import NMEAReader
from pynmeagps.nmeatypes_core import VALNONE

from readers import read_log
from readers.nmea import decode_log
from readers.nmea.assembly import assemble, nmea_sv_id
from readers.nmea.sentences import Decoded, with_checksum
from spooflens.cli import main
from spooflens.constants import NMEA_GNSS_TALKERS
from spooflens.epoch_table import EpochTable
from spooflens.schema import FixType

UNICORE = "corpus/pynmeagps/unicore_nmea.log"
TRIMBLE = "corpus/pynmeagps/trimble_nmea.log"
SEPTENTRIO = "corpus/pynmeagps/septentriox5_nmea.log"
FEYMAN = "corpus/pynmeagps/feyman_nmea.log"


def _lines(relative: str, start: str) -> list[bytes]:
    """The log's lines that start with `start`, as written."""
    return [ln.strip() for ln in real_log(relative).read_bytes().splitlines() if ln.startswith(start.encode())]


def _parsed(line: bytes) -> Any:
    return NMEAReader.parse(line, validate=VALNONE)


def _decoded(relative: str, name: str) -> list[Decoded]:
    files, _ = decode_log(real_log(relative))
    return [d for f in files for d in f.decoded if d.name == name]


@pytest.fixture(scope="module")
def trimble() -> EpochTable:
    return read_log(real_log(TRIMBLE))


def _heading(table: EpochTable, hid: str) -> tuple[float, str]:
    rows = table.headings[table.headings["heading_id"] == hid]
    assert len(rows) >= 1, f"no {hid} heading in {sorted(set(table.headings['heading_id']))}"
    return float(rows["heading_deg"].iloc[0]), str(rows["talker"].iloc[0])


def test_unicore_secondary_antenna_gga_is_a_receiver_of_its_own() -> None:
    """GNGGAH is GGA's content (pynmeagps: the secondary antenna): its fix row carries GGA's values, under a
    receiver GNH that is not the primary antenna's GN."""
    msg = _parsed(_lines(UNICORE, "$GNGGAH")[0])
    (d,) = _decoded(UNICORE, "GNGGAH")
    assert (d.kind, d.receiver, d.antenna) == ("GGA", "GNH", "H")
    files, skipped = decode_log(real_log(UNICORE))
    fixes = assemble(files, skipped).fixes
    assert fixes is not None
    row = fixes[(fixes["receiver_id"] == "GNH") & (fixes["lat_deg"] == msg.lat)]
    assert len(row) == 1
    assert row["lon_deg"].iloc[0] == msg.lon
    assert row["height_m"].iloc[0] == pytest.approx(msg.alt + msg.sep)
    assert row["sats_used"].iloc[0] == msg.numSV
    assert row["fix_type"].iloc[0] == FixType.FIX_3D  # GGA quality 1
    assert "GN" not in set(fixes["receiver_id"])


def test_unicore_gsvh_sky_is_the_secondary_antennas() -> None:
    """Every GSVH satellite's elevation, azimuth and strongest C/N0 over its signals, as pynmeagps decodes them."""
    expected: dict[str, tuple[float, float, float]] = {}
    for line in _lines(UNICORE, "$G"):
        if line[3:8] != b"GSVH,":
            continue
        msg = _parsed(line)
        for i in range(1, 5):
            svid = getattr(msg, f"svid_{i:02d}", "")
            if not isinstance(svid, int):
                continue
            sv = nmea_sv_id(msg.talker, svid)
            assert sv is not None
            cn0 = float(getattr(msg, f"cno_{i:02d}"))
            old = expected.get(sv, (0.0, 0.0, 0.0))[2]
            expected[sv] = (float(getattr(msg, f"elv_{i:02d}")), float(getattr(msg, f"az_{i:02d}")), max(cn0, old))
    sats = read_log(real_log(UNICORE)).satellites
    assert set(sats["receiver_id"]) == {"GNH"}
    got = {r.sv_id: (r.elevation_deg, r.azimuth_deg, r.cn0_dbhz) for r in sats.itertuples()}
    assert got == expected
    assert got["G32"][2] == 45.0  # signal 1 at 45 dB-Hz beside signal 4 at 41: the strongest
    # the GSAH lists say which are used: 26 is in one, 25 in none
    used = dict(zip(sats["sv_id"], sats["used"], strict=True))
    assert used["G26"] == 1.0 and used["G25"] == 0.0


def test_unicore_hpd_position_on_gps_week_time() -> None:
    line = _lines(UNICORE, "$GPHPD")[0]
    msg = _parsed(line)
    (d,) = _decoded(UNICORE, "GPHPD")
    assert (d.lat, d.lon, d.alt_msl_m) == (msg.lat, msg.lon, msg.alt)
    # GPS week 2319, 462170 s: UTC 18 leap seconds behind GPS time
    utc = dt.datetime(1980, 1, 6, tzinfo=dt.UTC) + dt.timedelta(weeks=msg.wno, seconds=msg.tow - 18)
    assert d.day is not None
    assert d.day * 86_400 + d.tod_s == pytest.approx(utc.timestamp())
    fixes = read_log(real_log(UNICORE)).fixes
    row = fixes[fixes["receiver_id"] == "GPHPD"]
    assert row["lat_deg"].iloc[0] == msg.lat and row["vel_e_mps"].iloc[0] == pytest.approx(msg.velE)


def test_unicore_attitude_headings() -> None:
    table = read_log(real_log(UNICORE))
    assert _heading(table, "GNTHS2") == (_parsed(_lines(UNICORE, "$GNTHS2")[0]).headt, "GN")
    assert _heading(table, "GNHPR") == (_parsed(_lines(UNICORE, "$GNHPR,")[0]).heading, "GN")
    assert _heading(table, "GNTRA2")[0] == _parsed(_lines(UNICORE, "$GNTRA2")[0]).heading
    reasons = {s.stream: s.reason for s in table.skipped}
    assert "range residuals" in reasons["GNGRSH"] and "rate of turn" in reasons["GNROT2"]


def test_trimble_ggk_fix_with_its_own_quality_codes(trimble: EpochTable) -> None:
    msg = _parsed(_lines(TRIMBLE, "$PTNL,GGK")[0])
    row = trimble.fixes[trimble.fixes["receiver_id"] == "PTNL"]
    assert len(row) == 1
    assert (row["lat_deg"].iloc[0], row["lon_deg"].iloc[0]) == (msg.lat, msg.lon)
    assert msg.height == "EHT150.790" and row["height_m"].iloc[0] == 150.790  # ellipsoidal: no separation added
    assert row["sats_used"].iloc[0] == msg.sip == 9
    # Trimble's 5 is SBAS, where GGA's 5 would be RTK float
    assert msg.gpsQual == 5 and row["fix_type"].iloc[0] == FixType.SBAS


def test_trimble_pashr_and_avr_headings_are_gnss_headings(trimble: EpochTable) -> None:
    pashr = _parsed(_lines(TRIMBLE, "$PASHR,1")[0])
    avr = _parsed(_lines(TRIMBLE, "$PTNL,AVR")[0])
    assert _heading(trimble, "PASHR") == (pashr.trueHdg, "GN")
    assert _heading(trimble, "PTNLAVR")[0] == avr.yaw
    assert set(trimble.headings["talker"]) <= NMEA_GNSS_TALKERS  # never the heading reference's compass


def test_trimble_fugro_position_and_what_is_not_read(trimble: EpochTable) -> None:
    msg = _parsed(_lines(TRIMBLE, "$PFUGDP")[0])
    row = trimble.fixes[trimble.fixes["receiver_id"] == "PFUGDP"]
    assert (row["lat_deg"].iloc[0], row["lon_deg"].iloc[0]) == (msg.lat, msg.lon)
    assert row["fix_type"].iloc[0] == FixType.UNKNOWN
    reasons = {s.stream: s.reason for s in trimble.skipped}
    assert "local grid" in reasons["GPLLQ"] and "local grid" in reasons["PTNLPJK"]
    assert "base station" in reasons["PTNLBPQ"]
    assert set(trimble.fixes["receiver_id"]) == {"PTNL", "PFUGDP"}  # no PJK, LLQ or BPQ position


def test_septentrio_hrp_heading_only(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The log holds headings only: inspect reads it, analyze says there is no GNSS data to judge."""
    path = real_log(SEPTENTRIO)
    msg = _parsed(_lines(SEPTENTRIO, "$PSSN,HRP")[0])
    table = read_log(path)
    assert _heading(table, "PSSNHRP") == (msg.hdg, "GN")
    assert table.fixes.empty
    assert main(["inspect", str(path)]) == 0
    capsys.readouterr()
    assert main(["analyze", str(path), "-o", str(tmp_path / "x.rrd"), "--quiet"]) == 0
    assert "NO VERDICT: no GNSS data to judge: the log holds heading PSSNHRP (1)" in capsys.readouterr().out


def test_feyman_fmi_position_and_its_placeholder() -> None:
    lines = _lines(FEYMAN, "$GPFMI")
    first_fix = _parsed(lines[2])  # the first two are at 0 deg, 0 deg: no solution yet
    assert (_parsed(lines[0]).lat, _parsed(lines[0]).lon) == (0.0, 0.0)
    table = read_log(real_log(FEYMAN))
    row = table.fixes[table.fixes["receiver_id"] == "GPFMI"]
    assert len(row) == 1  # the 20 others share one time: one epoch, its first sentence
    assert (row["lat_deg"].iloc[0], row["lon_deg"].iloc[0]) == (first_fix.lat, first_fix.lon)
    assert row["height_m"].iloc[0] == first_fix.alt and row["sats_used"].iloc[0] == first_fix.numSV
    invalid = [s for s in table.skipped if s.stream == "GPFMI" and "without a valid position" in s.reason]
    assert invalid and invalid[0].count == 2


def test_secondary_antenna_sentences_never_join_the_primary(tmp_path: Path) -> None:
    """A GGA and a GGAH of one time are two antennas: two receivers, each with its own position."""
    bodies = [
        "$GNGGA,073346.00,4004.70000000,N,11614.10000000,E,1,28,0.6,64.2,M,8.5,M,,",
        "$GNGGAH,073346.00,4004.73874301,N,11614.19077585,E,1,28,0.6,64.2831,M,8.4925,M,,",
        "$GPGSVH,1,1,01,16,28,217,38,1",
    ]
    path = tmp_path / "two_antennas.log"
    path.write_bytes(b"\n".join(with_checksum(b.encode()) for b in bodies) + b"\n")
    table = read_log(path)
    lat = dict(zip(table.fixes["receiver_id"], table.fixes["lat_deg"], strict=True))
    assert lat["GN"] == pytest.approx(40 + 4.7 / 60)
    assert lat["GNH"] == pytest.approx(40 + 4.73874301 / 60)
    assert set(table.satellites["receiver_id"]) == {"GNH"}
    assert math.isnan(table.fixes.set_index("receiver_id").loc["GN", "cn0_mean_dbhz"])


def test_trimble_location_rtk_is_an_rtk_float_fix(tmp_path: Path) -> None:
    """GGK quality 12 ("Location RTK") is the epochs a Trimble R2's GGA calls RTK float (quality 5): its switch to
    DGPS (4) is a mode switch the explanations can name, not an unknown fix type."""
    bodies = [
        "PTNL,GGK,235654.00,122017,3403.47163916,N,11711.80927277,W,12,10,2.9,EHT371.392,M",
        "PTNL,GGK,235655.00,122017,3403.47141462,N,11711.80952375,W,4,10,2.5,EHT371.078,M",
    ]
    path = tmp_path / "r2.nmea"
    path.write_bytes(b"".join(with_checksum(b"$" + b.encode()) + b"\r\n" for b in bodies))
    assert read_log(path).fixes["fix_type"].tolist() == [FixType.RTK_FLOAT, FixType.DGNSS]
