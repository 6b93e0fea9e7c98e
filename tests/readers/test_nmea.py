"""NMEA 0183: the real boat logs read right, logger layouts, bad input, and inject's in-place round trip."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from paths import REAL, real_log
from shared_inputs import read_shared

from readers import read_log, sniff_format
from spooflens.cli import main
from spooflens.constants import KNOT_MPS
from spooflens.epoch_table import HOLDS, EpochTable
from spooflens.errors import ReaderError
from spooflens.schema import FixType

BOATS = REAL / "nmea_boats"
BUNDG, SAAB, PLAKA = BOATS / "gpsd_bundg_zeus_9.log", BOATS / "gpsd_saab-r4.log", BOATS / "signalk_plaka.log"
PIXEL_NMEA = REAL / "android_gnsslogger" / "gnss_lib_py" / "pixel6.nmea"
KNOT = 1852 / 3600


def _need(path: Path) -> Path:
    return real_log(str(path.relative_to(REAL)))


@pytest.fixture(scope="module")
def bundg() -> EpochTable:
    return read_log(_need(BUNDG))


@pytest.fixture(scope="module")
def plaka() -> EpochTable:
    return read_shared(_need(PLAKA))


def _write(path: Path, bodies: list[str]) -> Path:
    path.write_text("\n".join(_sentence(b) for b in bodies) + "\n")
    return path


def _sentence(body: str) -> str:
    check = 0
    for c in body.encode():
        check ^= c
    return f"${body}*{check:02X}"


def _field_degrees(text: str, hemi: str, digits: int) -> float:
    v = float(text[:digits]) + float(text[digits:]) / 60
    return -v if hemi in "SW" else v


def _raw(path: Path, kind: str) -> dict[str, list[str]]:
    """Sentences of one kind by their time field, split by hand (independent of the reader)."""
    out: dict[str, list[str]] = {}
    for line in path.read_text(errors="replace").splitlines():
        if line[3:6] == kind and line.startswith("$"):
            f = line.split("*")[0].split(",")
            out[f[5] if kind == "GLL" else f[1]] = f
    return out


def _distance_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    dn = math.radians(lat2 - lat1) * 6_371_000
    de = math.radians(lon2 - lon1) * 6_371_000 * math.cos(math.radians(lat1))
    return math.hypot(dn, de)


def test_bundg_counts_rates_units(bundg: EpochTable) -> None:
    assert sniff_format(BUNDG) == "nmea"
    assert bundg.time_reference == "unix" and bundg.absolute_iso(0.5).startswith("2018-08-20T09:47:36")
    assert bundg.receivers() == ["GP"]
    fixes = bundg.fixes
    assert len(fixes) == 149  # epochs of GGA (138), RMC (146) and GLL (147) times, 09:47:36-09:50:03
    assert np.median(np.diff(fixes["t_s"])) == pytest.approx(1.0)
    first = fixes.iloc[0]
    assert first["height_m"] == pytest.approx(-4 + 46.8)  # GGA MSL altitude + geoid separation
    assert (first["sats_used"], first["hdop"], first["vdop"]) == (12, 0.60, 0.90)  # GGA numSV, GSA DOPs
    assert first["fix_type"] == FixType.FIX_3D
    # mean of the 12 C/N0 values of the first GSV group (39 35 33 37 34 39 33 38 46 32 27 31)
    assert first["cn0_mean_dbhz"] == pytest.approx(424 / 12)
    # SDHDG at ~10 Hz: magnetic 229.8 + 1.3 E variation = true 231.1
    headings = bundg.headings
    hdg = headings[headings["heading_id"] == "SDHDG"]
    assert len(hdg) == 1457 and hdg["heading_deg"].iloc[0] == pytest.approx(231.1)
    assert hdg["water_speed_mps"].isna().all()
    # SDVHW: the speed log's sentence, true heading 231.3 and 6.6 kn through the water
    vhw = headings[headings["heading_id"] == "SDVHW"]
    assert len(vhw) == 150 and set(headings["heading_id"]) == {"SDHDG", "SDVHW"}
    assert vhw["heading_deg"].iloc[0] == pytest.approx(231.3)
    assert vhw["water_speed_mps"].iloc[0] == pytest.approx(6.6 * 1852 / 3600)
    sdhdg = bundg.stream("heading", "SDHDG")
    assert sdhdg is not None and 9.0 < sdhdg.rate_hz < 10.5
    unused = {s.stream: s.count for s in bundg.skipped if "does not use" in s.reason}
    assert unused["WIMWV"] == 300 and unused["SDDPT"] == 149


def test_bundg_position_and_velocity_against_independent_values(bundg: EpochTable) -> None:
    rmc = _raw(BUNDG, "RMC")
    fixes = bundg.fixes
    utc = bundg.unix_ns(fixes["t_s"].to_numpy())
    assert utc is not None
    tod = [f"{int(u // 1e9) % 86400 // 3600:02d}{int(u // 1e9) % 3600 // 60:02d}{int(u // 1e9) % 60:02d}" for u in utc]
    checked = 0
    for (_, row), t in zip(fixes.iterrows(), tod, strict=True):
        f = rmc.get(t)
        if f is None:
            continue
        lat, lon = _field_degrees(f[3], f[4], 2), _field_degrees(f[5], f[6], 3)
        # the fix is GGA's; the chartplotter's RMC of the same second differs by its own few metres
        assert _distance_m(row["lat_deg"], row["lon_deg"], lat, lon) < 6.0
        assert math.hypot(row["vel_e_mps"], row["vel_n_mps"]) == pytest.approx(float(f[7]) * KNOT, abs=1e-9)
        checked += 1
    assert checked > 100
    # the reported speed agrees with the position change (a boat at ~3 m/s)
    lat, lon, t = (fixes[c].to_numpy() for c in ("lat_deg", "lon_deg", "t_s"))
    track = sum(_distance_m(lat[i], lon[i], lat[i + 1], lon[i + 1]) for i in range(len(lat) - 1))
    speed = np.hypot(fixes["vel_e_mps"], fixes["vel_n_mps"]).mean()
    assert track / (t[-1] - t[0]) == pytest.approx(speed, rel=0.1)


def test_saab_gyro_heading_and_dgps(tmp_path: Path) -> None:
    table = read_log(_need(SAAB))
    assert len(table.fixes) == 12 and table.absolute_iso(0).startswith("2011-06-01T13:07:11")
    assert set(table.fixes["fix_type"]) == {FixType.DGNSS}  # GGA quality 2
    gll = _raw(SAAB, "GLL")["130711"]
    first = table.fixes.iloc[0]
    lat, lon = _field_degrees(gll[1], gll[2], 2), _field_degrees(gll[3], gll[4], 3)
    assert _distance_m(first.lat_deg, first.lon_deg, lat, lon) < 0.01
    hdt = [float(ln.split(",")[1]) for ln in SAAB.read_text().splitlines() if ln.startswith("$HEHDT")]
    assert list(table.headings["heading_deg"]) == hdt and len(hdt) == 12 and set(table.headings["talker"]) == {"HE"}
    assert any("height set to 0 m" in s.reason for s in table.skipped)  # no altitude in its GGA
    assert {s.stream: s.count for s in table.skipped}["AIVDO"] == 12


def test_plaka_long_voyage_without_dates(plaka: EpochTable) -> None:
    assert plaka.time_reference == "relative"  # its ZDA sentences carry no date
    assert len(plaka.fixes) == 7250 and plaka.duration_s == pytest.approx(14845.0)
    assert np.median(np.diff(plaka.fixes["t_s"])) == pytest.approx(2.0)
    assert plaka.fixes["lat_deg"].iloc[0] == pytest.approx(60 + 5.071 / 60)
    assert len(plaka.headings) == 0
    empty = {s.stream: s.count for s in plaka.skipped if s.reason.startswith("empty")}
    assert empty == {"GPGSV": 7250, "IIHDT": 14500, "IIHDM": 7250}  # HDM is read since issue 40: these are empty
    # VTG speed against the GLL position change, epoch by epoch (independent sentences of the voyage)
    f = plaka.fixes
    lat, lon, t = (f[c].to_numpy() for c in ("lat_deg", "lon_deg", "t_s"))
    v_pos = np.array([_distance_m(lat[i], lon[i], lat[i + 1], lon[i + 1]) for i in range(len(t) - 1)]) / np.diff(t)
    v_vtg = np.hypot(f["vel_e_mps"], f["vel_n_mps"]).to_numpy()[:-1]
    assert np.nanmedian(np.abs(v_pos - v_vtg)) < 0.5


def test_gnsslogger_nmea_file_uses_its_logger_times() -> None:
    table = read_log(_need(PIXEL_NMEA))
    assert table.format == "nmea" and table.metadata["time_source"] == "logger"
    assert len(table.fixes) == 48 and table.absolute_iso(0).startswith("2023-11-07T23:42:57")
    assert abs(float(table.metadata["clock.gnss_minus_logger_s"])) < 2.0


BASE_BODIES = [
    "GPGGA,235958.00,5012.0000,N,00806.0000,W,1,08,0.9,10.0,M,50.0,M,,",
    "GPRMC,235958.00,A,5012.0000,N,00806.0000,W,10.0,90.0,311219,,,A",
    "HEHDT,91.5,T",
    "GPGGA,235959.00,5012.0000,N,00805.9914,W,1,08,0.9,10.0,M,50.0,M,,",
    "HEHDT,91.6,T",
    "GPGGA,000000.00,5012.0000,N,00805.9828,W,1,08,0.9,10.0,M,50.0,M,,",
    "GPRMC,000000.00,A,5012.0000,N,00805.9828,W,10.0,90.0,010120,,,A",
    "HEHDT,91.7,T",
    "GPGGA,000001.00,5012.0000,N,00805.9742,W,1,08,0.9,10.0,M,50.0,M,,",
]


def test_midnight_and_year_rollover(tmp_path: Path) -> None:
    path = tmp_path / "midnight.nmea"
    path.write_text("\r\n".join(_sentence(b) for b in BASE_BODIES) + "\r\n")
    table = read_log(path)
    assert table.absolute_iso(0.0) == "2019-12-31T23:59:58+00:00"
    assert list(table.fixes["t_s"]) == [0.0, 1.0, 2.0, 3.0]
    assert table.absolute_iso(3.0) == "2020-01-01T00:00:01+00:00"
    assert list(table.headings["heading_deg"]) == [91.5, 91.6, 91.7]
    assert np.all(np.diff(table.headings["t_s"]) > 0)


def test_logger_prefixes_tag_blocks_and_two_receivers(tmp_path: Path) -> None:
    start = 1577836798.0  # 2019-12-31T23:59:58Z
    lines = []
    for i, body in enumerate(BASE_BODIES):
        t = start + 0.4 * i
        if i % 3 == 0:
            lines.append(f"{t:.3f} {_sentence(body)}")
        elif i % 3 == 1:
            lines.append(f"{round(t * 1000)};N;{_sentence(body)}")
        else:
            tag = f"s:bridge,c:{round(t * 1000)}"
            check = 0
            for c in tag.encode():
                check ^= c
            lines.append(f"\\{tag}*{check:02X}\\{_sentence(body)}")
    gn = [b.replace("GPGGA", "GNGGA") for b in BASE_BODIES]
    second = [f"{start + 0.4 * i + 0.1:.3f} {_sentence(b)}" for i, b in enumerate(gn)]
    path = tmp_path / "mixed.log"
    path.write_text("# a VDR export\n" + "\n".join(lines + [s for s in second if "GNGGA" in s]) + "\n")
    table = read_log(path)
    assert table.metadata["time_source"] == "logger" and table.time_reference == "unix"
    assert sorted(table.receivers()) == ["GN", "GP", "bridge/GP"]
    assert table.absolute_iso(0.0).startswith("2019-12-31T23:59:58")
    assert table.metadata["log_header"] == "a VDR export"


def test_two_files_in_a_directory_are_two_receivers(tmp_path: Path) -> None:
    log = tmp_path / "voyage"
    log.mkdir()
    (log / "gps1.nmea").write_text("\n".join(_sentence(b) for b in BASE_BODIES) + "\n")
    moved = [b.replace("5012.0000,N", "5012.0100,N") for b in BASE_BODIES]
    (log / "gps2.nmea").write_text("\n".join(_sentence(b) for b in moved) + "\n")
    (log / "notes.txt").write_text("crew notes\n")
    table = read_log(log)
    assert sorted(table.receivers()) == ["gps1.nmea/GP", "gps2.nmea/GP"]
    a, b = table.fixes_of("gps1.nmea/GP").iloc[0], table.fixes_of("gps2.nmea/GP").iloc[0]
    assert _distance_m(a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg) == pytest.approx(18.5, abs=0.2)  # 0.01'
    assert any("notes.txt" in s.reason for s in table.skipped)


def test_bad_checksum_garbage_and_cut_last_line(tmp_path: Path) -> None:
    lines = [_sentence(b) for b in BASE_BODIES]
    lines[3] = lines[3].replace("5012.0000", "5012.9000")  # corrupt: checksum no longer matches
    data = ("\n".join(lines[:-1]) + "\n").encode() + b"\x00\xff\xfe junk\n" + lines[-1].encode()[:30]
    path = tmp_path / "damaged.log"
    path.write_bytes(data)
    table = read_log(path)
    lost = {s.reason: s.count for s in table.skipped if s.action == "lost"}
    assert lost["sentences with a bad checksum"] == 1
    assert lost["binary garbage (not text)"] == 1
    assert lost["file cut inside its last sentence"] == 1
    assert list(table.fixes["t_s"]) == [0.0, 2.0]  # the 23:59:59 GGA was the corrupt one


def test_a_zda_year_beyond_64_bits_is_no_date_not_an_overflow(tmp_path: Path) -> None:
    """The second 10^4 fuzz run wrote -9223372036854775809 into NMEA fields: a ZDA "year" that large
    overflowed the date arithmetic (OverflowError before). It is no date; the fixes stay."""
    bodies = [*BASE_BODIES[:2], "GPZDA,235958.00,31,12,-9223372036854775809,00,00", *BASE_BODIES[2:]]
    path = tmp_path / "zda.log"
    path.write_text("\n".join(_sentence(b) for b in bodies) + "\n")
    table = read_log(path)
    assert len(table.fixes) == len(read_log(_write(tmp_path / "base.log", BASE_BODIES)).fixes)


def test_sentences_of_nothing_to_judge_say_what_they_are(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    only_unused = tmp_path / "wind.log"
    only_unused.write_text(_sentence("WIMWV,57.5,R,13.0,N,A") + "\n")
    # sound sentences of a wind instrument: nothing to judge, said (not a refusal)
    assert read_log(only_unused).metadata[HOLDS] == (
        "only sentences spooflens does not read ($WIMWV x1): no position, heading or satellite report"
    )
    empty = tmp_path / "empty.log"  # a receiver without a fix: its position sentence empty
    empty.write_text(_sentence("GPGGA,,,,,,,,,,,,,,") + "\n" + _sentence("WIMWV,57.5,R,13.0,N,A") + "\n")
    assert read_log(empty).metadata[HOLDS] == (
        "no position, heading or satellite report in its sentences ($GPGGA x1, $WIMWV x1; 1 of them empty: no fix)"
    )
    assert main(["inspect", str(empty)]) == 0
    assert "no GNSS data to judge: no position" in capsys.readouterr().out


def test_inspect_and_analyze_real_logs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(_need(SAAB))]) == 0
    out = capsys.readouterr().out
    assert "HEHDT" in out and "heading" in out
    summary = tmp_path / "bundg.json"
    assert main(["analyze", str(_need(BUNDG)), "-o", str(tmp_path / "b.rrd"), "--json", str(summary), "--quiet"]) == 0
    verdict = json.loads(summary.read_text())["verdict"]
    assert verdict["spoofed"] is False  # a clean real voyage


def test_inject_round_trip_edits_positions_in_place(bundg: EpochTable, tmp_path: Path) -> None:
    out = tmp_path / "spoofed.log"
    assert main(["inject", str(BUNDG), "--attack", "step:start=60,offset=200", "-o", str(out)]) == 0
    before, after = BUNDG.read_bytes().split(b"\n"), out.read_bytes().split(b"\n")
    assert len(before) == len(after)
    changed = [(a, b) for a, b in zip(before, after, strict=True) if a != b]
    assert changed and all(a[3:6] in (b"GGA", b"RMC", b"GLL") for a, _ in changed)
    spoofed = read_log(out)
    assert not [s for s in spoofed.skipped if s.action == "lost"]  # every rewritten checksum is valid
    truth = json.loads(out.with_name(out.name + ".attack.json").read_text())
    assert truth["kind"] == "step"
    t = bundg.fixes["t_s"].to_numpy()
    a, b = bundg.fixes, spoofed.fixes
    e, n, _ = pymap3d.geodetic2enu(b.lat_deg, b.lon_deg, b.height_m, a.lat_deg, a.lon_deg, a.height_m)
    # 200 m east and north, to the 0.0001' (0.19 m east, 0.11 m north) the sentences carry
    assert np.all(np.hypot(e, n)[t < 60] == 0)
    assert np.allclose(e[t >= 60], 200, atol=0.15) and np.allclose(n[t >= 60], 200, atol=0.15)
    assert np.array_equal(a["height_m"], b["height_m"])
    assert spoofed.headings.equals(bundg.headings)


def test_bundg_satellites_from_gsv_and_gsa_agree_with_the_sentences(bundg: EpochTable) -> None:
    sats = bundg.satellites
    assert any(s.role == "satellites" and s.msgtype == "NMEA GSV/GSA" for s in bundg.streams)
    assert set(sats["sv_id"].str[0]) == {"G", "R"}  # GPGSV and GLGSV (GLONASS numbered 65-96)
    assert sats["elevation_deg"].between(0, 90).all() and sats["azimuth_deg"].between(0, 360).all()
    assert sats.groupby("t_s")["sv_id"].apply(lambda s: s.is_unique).all()
    # every satellite a GPGSV sentence lists is in the frame, with its elevation and C/N0
    lines = (BOATS / "gpsd_bundg_zeus_9.log").read_text(errors="replace").splitlines()
    first_gsv = next(ln.split("*")[0].split(",") for ln in lines if ln.startswith("$GPGSV,") and ln.split(",")[7])
    sv, el, cn0 = int(first_gsv[4]), float(first_gsv[5]), float(first_gsv[7])
    rows = sats[sats["sv_id"] == f"G{sv:02d}"]
    assert ((rows["elevation_deg"] == el) & (rows["cn0_dbhz"] == cn0)).any()
    # the epochs' mean C/N0 in the fixes is the mean of the satellites' C/N0
    mean = sats.groupby("t_s")["cn0_dbhz"].mean()
    fixes = bundg.fixes.set_index("t_s")["cn0_mean_dbhz"]
    common = mean.index.intersection(fixes.index)
    assert len(common) > 100
    assert np.allclose(mean[common], fixes[common], equal_nan=True)


@pytest.mark.parametrize(
    ("talker", "svid", "expected"),
    [
        ("GP", 5, "G05"), ("GP", 46, "S33"), ("GN", 70, "R06"), ("GL", 70, "R06"), ("GA", 11, "E11"),
        ("GB", 21, "C21"), ("BD", 221, "C21"), ("GP", 195, "J03"), ("GQ", 2, "J02"), ("GP", 120, None),
    ],
)  # fmt: skip
def test_nmea_satellite_numbers(talker: str, svid: int, expected: str | None) -> None:
    from readers.nmea.assembly import nmea_sv_id

    assert nmea_sv_id(talker, svid) == expected


def test_a_talker_that_sends_no_checksums_is_read_unverified() -> None:
    # an HP 58534A timing receiver (2010): no sentence has a checksum; pynmeagps decodes none without one
    table = read_log(real_log("corpus/gpsd/hp58534a.log"))
    assert len(table.fixes) == 2
    lat, lon = table.fixes["lat_deg"].to_numpy(float), table.fixes["lon_deg"].to_numpy(float)
    assert np.allclose(lat, -33.8172283, atol=1e-6) and np.allclose(lon, 18.7321367, atol=1e-6)
    assert set(table.satellites["cn0_dbhz"].dropna().astype(int)) >= {31, 35, 46}
    assert any(s.action == "unverified" and "without a checksum" in s.reason for s in table.skipped)


def test_a_sentence_is_checksummed_as_its_talker_would() -> None:
    from readers.nmea.sentences import with_checksum

    for sent in (b"$GPGSV,1,1,00*79", b"$GPRMC,001902.00,V,,,,,,,020211,,,N*77"):
        assert with_checksum(sent[:-3]) == sent and with_checksum(sent) == sent


def test_a_gn_talkers_gsa_lists_are_of_the_system_their_id_names() -> None:
    """NMEA 4.10 `GNGSA,...,3` lists Galileo satellites by Galileo numbers: E01, E11, E12, E24, E31, E33 used,
    not the GPS satellites of those numbers (the ZED-F9K drive's first epoch; BeiDou's list is system 4)."""
    t = read_log(real_log("corpus/gps-measurement-tools/MTV.Local1.ublox-F9K.20200206-181434.nmea"))
    first = t.satellites[t.satellites["t_s"] == t.satellites["t_s"].min()].set_index("sv_id")["used"]
    galileo = {sv for sv in first.index if sv.startswith("E") and first[sv] == 1.0}
    assert galileo == {"E01", "E11", "E12", "E24", "E31", "E33"}
    assert {sv for sv in first.index if sv.startswith("C") and first[sv] == 1.0} == {"C27", "C28", "C30", "C36", "C37"}
    assert first["G30"] == 0.0 and first["E05"] == 0.0


@pytest.mark.parametrize(
    ("layout", "sep"),
    [("bare CR (classic Mac OS, serial loggers)", b"\r"), ("no line break at all", b""), ("CR LF", b"\r\n")],
)
def test_lines_ending_in_a_bare_cr_or_in_nothing_read_as_the_same_log(
    bundg: EpochTable, tmp_path: Path, layout: str, sep: bytes
) -> None:
    """A real u-blox M8 log kept with CR-only line ends (and stored with none) was read as one sentence and
    judged NO VERDICT: no GNSS data. Its sentences are the same whatever ends its lines."""
    path = tmp_path / "relaid.log"
    path.write_bytes(sep.join(BUNDG.read_bytes().splitlines()) + sep)
    assert sniff_format(path) == "nmea", layout
    table = read_log(path)
    assert table.fixes.equals(bundg.fixes), layout
    assert table.satellites.equals(bundg.satellites), layout
    assert table.headings.equals(bundg.headings), layout
    assert not [s for s in table.skipped if s.action == "lost"], layout
    out = tmp_path / "spoofed.log"  # inject rewrites in place: every line end kept as it was
    assert main(["inject", str(path), "--attack", "step:start=60,offset=200", "-o", str(out)]) == 0
    assert out.read_bytes().count(b"\r") == path.read_bytes().count(b"\r")
    assert out.read_bytes().count(b"\n") == path.read_bytes().count(b"\n")
    assert not [s for s in read_log(out).skipped if s.action == "lost"]


def test_standard_sentences_whose_checksums_all_fail_are_refused_saying_so(tmp_path: Path) -> None:
    """A bus-route simulator wrote every checksum wrong: it was refused as "proprietary NMEA-style
    sentences only ($GPRMC, $GPGGA)", which hid the cause."""
    path = tmp_path / "wrong_sums.nmea"
    path.write_text("".join(_sentence(b)[:-2] + "00\n" for b in BASE_BODIES if b.startswith("GP")))
    expected = (
        r"NMEA 0183 sentences, too few of them intact to read: 0 of the first 6 lines pass their checksum "
        r"\(6 sentences with a bad checksum\)"
    )
    with pytest.raises(ReaderError, match=expected):
        sniff_format(path)


def test_a_garbled_serial_capture_is_read_as_a_damaged_nmea_log(tmp_path: Path) -> None:
    """A research vessel's capture over a noisy serial line: a fifth of the lines intact, most others sentences
    that fail their checksum or lost their `$`. It was refused as proprietary sentences; what is intact is
    read and the rest counted as lost."""
    lines = []
    for body in BASE_BODIES:
        intact = _sentence(body)
        lines += [intact, intact.replace(",", "", 1), intact.replace(",", ";", 1), intact[1:], intact[1:-3]]
    path = tmp_path / "garbled.log"
    path.write_text("\n".join(lines) + "\n")
    assert sniff_format(path) == "nmea"
    table = read_log(path)
    lost = {s.reason: s.count for s in table.skipped if s.action == "lost"}
    assert lost["sentences with a bad checksum"] == 2 * len(BASE_BODIES)
    assert list(table.fixes["t_s"]) == [0.0, 1.0, 2.0, 3.0]


def test_lines_stamped_in_milliseconds_keep_their_own_stamps(tmp_path: Path) -> None:
    """GnssLogger stamps each NMEA line in ms when it came. A burst's GGA after its GSA and VTG lines was
    spread toward the next burst as if the stamps were whole seconds: its fixes came 0.7 s late and the
    receiver's clock offset was read as -1.27 s where its lines say -0.59 s."""
    t0_ms = 1699400577000  # 2023-11-07 23:42:57 UTC
    lines = []
    for k in range(12):
        hhmmss = f"2342{57 + k:02d}" if 57 + k < 60 else f"2343{57 + k - 60:02d}"
        sky, fix = t0_ms + 1000 * k + 554, t0_ms + 1000 * k + 591
        lines += [f"NMEA,{_sentence('GPGSV,1,1,01,08,12,287,24')},{sky}"]
        lines += [f"NMEA,{_sentence('GNGSA,A,3,08,18,23,25,27,,,,,,,,1.0,0.7,0.8')},{fix}"]
        lines += [f"NMEA,{_sentence('GNVTG,,T,,M,0.0,N,0.0,K,A')},{fix}"]
        lines += [
            f"NMEA,{_sentence(f'GNGGA,{hhmmss}.00,3725.590397,N,12210.422534,W,1,12,0.7,51.9,M,-28.4,M,,')},{fix}"
        ]
        lines += [f"NMEA,{_sentence(f'GNRMC,{hhmmss}.00,A,3725.590397,N,12210.422534,W,0.0,,071123,,,A')},{fix}"]
    path = tmp_path / "gnss_log.nmea"
    path.write_text("\n".join(lines) + "\n")
    table = read_log(path)
    assert table.metadata["time_source"] == "logger"
    assert float(table.metadata["clock.gnss_minus_logger_s"]) == pytest.approx(-0.591, abs=0.002)
    assert table.absolute_iso(0).startswith("2023-11-07T23:42:57.591")


def test_a_routers_bracketed_logger_time_is_read(tmp_path: Path) -> None:
    """A boat's NMEA router logs `[1494938987296][**] $GPRMC,...`: it was refused as an unknown format."""
    lines = [f"[{1577836798000 + 500 * k}][**] {_sentence(b)}" for k, b in enumerate(BASE_BODIES)]
    path = tmp_path / "router.log"
    path.write_text("\n".join(lines) + "\n")
    table = read_log(path)
    assert table.metadata["time_source"] == "logger"  # the bracketed time is the logger's clock
    assert len(table.fixes) == 4 and table.absolute_iso(0).startswith("2019-12-31T23:59:58")
    assert not [s for s in table.skipped if s.action in ("lost", "unverified")]


@pytest.mark.parametrize("mark", ["$ADPMB,5,0", "$GSENSORD,-0.120,-0.060,0.060"])
def test_a_loggers_own_marks_without_checksums_are_no_damage(mark: str, tmp_path: Path) -> None:
    """An AMOD 3080 logger writes `$ADPMB,5,0` button marks without a checksum among its receiver's checksummed
    sentences, a dashcam its accelerometer as `$GSENSORD` (an address of 8 letters): they were counted as
    sentences cut short and the log called damaged. A type that never carries one is whole; a GGA without
    one where other GGAs have theirs is still cut short."""
    lines = [_sentence(b) for b in BASE_BODIES]
    lines.insert(2, mark)
    lines.insert(6, mark)
    lines.insert(8, "$" + BASE_BODIES[0])  # a GGA without its checksum
    path = tmp_path / "amod.log"
    path.write_text("\n".join(lines) + "\n")
    table = read_log(path)
    by_action = {(s.action, s.reason): s.count for s in table.skipped if s.action in ("lost", "unverified")}
    assert by_action == {
        ("unverified", "sentences of a type that never carries a checksum in this file, taken unverified"): 2,
        ("lost", "sentences without a checksum (cut short?)"): 1,
    }


def test_a_receivers_per_system_lines_without_a_position_are_no_receivers_of_their_own(tmp_path: Path) -> None:
    """A Trimble R2 writes $GNGNS with the fix and, NMEA 4.11, $GPGNS and $GLGNS with each system's count and no
    position: they became receivers GP and GL, which took the GPS and GLONASS sky away from GN (left with
    Galileo's 3 satellites while its fix used 10)."""
    bodies = []
    for k in range(5):
        tod = f"2356{47 + k:02d}.00"
        bodies += [
            f"GNGNS,{tod},3403.47162394,N,11711.80927093,W,FFNNN,10,1.2,403.600,-32.133,,",
            f"GPGNS,{tod},,,,,,6,,,,1.0,0",
            f"GLGNS,{tod},,,,,,4,,,,1.0,0",
            "GPGSV,1,1,02,26,33,050,38,09,40,314,43",
            "GLGSV,1,1,02,73,52,022,52,74,62,247,50",
            "GAGSV,1,1,01,19,82,349,44",
            f"GNRMC,{tod},A,3403.47162394,N,11711.80927093,W,0.003,0.000,201217,12.0194,E,D",
        ]
    table = read_log(_write(tmp_path / "trimble.log", bodies))
    assert table.receivers() == ["GN"]
    assert set(table.satellites["sv_id"]) == {"G26", "G09", "R09", "R10", "E19"}
    per_system = {s.stream: s.reason for s in table.skipped if s.stream in ("GP", "GL")}
    assert per_system == {"GP": "position sentences without a position, read as GN's"} | {
        "GL": "position sentences without a position, read as GN's"
    }


def test_a_relay_repeating_a_stale_fix_is_not_read_as_one(tmp_path: Path) -> None:
    """A boat's autopilot re-sends one `$APGLL` taken six minutes before the capture, under that old time, with
    every second of the GPS's own sentences: read as a fix, the 43 s capture became 402 s starting at
    05:52:10. The stale epoch is dropped and said; a receiver repeating its fix a few times is read."""
    bodies = []
    for k in range(20):
        hhmmss = f"0558{10 + k:02d}"
        bodies += [
            f"GPGGA,{hhmmss},3806.969,N,12137.458,W,1,10,1.7,0,M,,M,,",
            f"GPRMC,{hhmmss},A,3806.969,N,12137.458,W,0.1,191.5,130504,15.1,E",
            "APGLL,3806.9680,N,12137.4580,W,055210.00,A",
        ]
    table = read_log(_write(tmp_path / "relay.nmea", bodies))
    assert set(table.fixes["receiver_id"]) == {"GP"} and len(table.fixes) == 20
    assert table.duration_s == pytest.approx(19.0)
    (said,) = [s for s in table.skipped if "stale" in s.reason]
    assert said.stream == "AP" and "GLL repeating one fix at 05:52:10.0 (its time of day) 20 times" in said.reason
    # the same GLL twice within one second of the GPS: a repeat, not a stale relay
    twice = read_log(_write(tmp_path / "twice.nmea", bodies[:3] + bodies[2:4] + bodies[5:9]))
    assert not [s for s in twice.skipped if "stale" in s.reason] and "AP" in set(twice.fixes["receiver_id"])


def test_a_type_whose_checksums_take_in_the_dollar_is_whole(tmp_path: Path) -> None:
    """An LG phone's own `$GPGLG` computes its checksum with the leading `$` taken in: every one of them
    "failed" and an intact log was called damaged. A type all of whose checksums are that XOR is whole; a
    standard sentence with such a checksum among right ones is still a bad checksum."""

    def dollar_sum(body: str) -> str:
        check = ord("$")
        for c in body.encode():
            check ^= c
        return f"${body}*{check:02X}"

    lines = [_sentence(b) for b in BASE_BODIES]
    lines.insert(1, dollar_sum("GPGLG,1,2,3"))
    lines.insert(4, dollar_sum("GPGLG,4,5,6"))
    path = tmp_path / "lg.nmea"
    path.write_text("\n".join(lines) + "\n")
    table = read_log(path)
    assert not [s for s in table.skipped if s.action == "lost"]
    assert any("checksums take in the '$'" in s.reason and s.count == 2 for s in table.skipped)
    lines.insert(2, dollar_sum(BASE_BODIES[0]))  # a GGA whose checksum took the '$' in, among right GGAs
    path.write_text("\n".join(lines) + "\n")
    lost = {s.reason: s.count for s in read_log(path).skipped if s.action == "lost"}
    assert lost == {"sentences with a bad checksum": 1}


def test_a_phones_burst_ending_with_its_fix_keeps_its_sky_with_that_fix(tmp_path: Path) -> None:
    """GnssLogger's NMEA writes each second as GSV, GSA, VTG, then RMC and GGA, every line stamped in ms: in
    file order the sky joined the previous second's fix (every C/N0 a second early, the first fix two
    seconds of sky, the last none). The logger's stamps place each line with the fix stamped nearest it;
    whole-second stamps, which cannot tell bursts apart, leave file order."""
    lines = []
    for k in range(6):
        ms = 1701381316874 + 1000 * k
        hhmmss = f"2155{16 + k:02d}.00"
        lines += [
            f"NMEA,{_sentence(f'GPGSV,1,1,01,09,61,139,{20 + k}')},{ms}",
            f"NMEA,{_sentence('GNGSA,A,3,09,,,,,,,,,,,,1.0,0.6,0.7')},{ms + 3}",
            f"NMEA,{_sentence(f'GNRMC,{hhmmss},A,3725.345973,N,12214.745114,W,0.0,,301123,15.0,E,A')},{ms + 4}",
            f"NMEA,{_sentence(f'GNGGA,{hhmmss},3725.345973,N,12214.745114,W,1,12,0.6,107.3,M,-28.0,M,,')},{ms + 4}",
        ]
    path = tmp_path / "gnss_log.nmea"
    path.write_text("\n".join(lines) + "\n")
    sky = read_log(path).satellites
    assert sky["cn0_dbhz"].tolist() == [20.0, 21.0, 22.0, 23.0, 24.0, 25.0]
    np.testing.assert_allclose(sky["t_s"], np.arange(6.0), atol=0.01)


def test_a_speed_written_without_a_course_is_kept_as_a_speed(tmp_path: Path) -> None:
    """A FLARM ground station's u-blox writes RMC's speed (0.045-0.7 kn) with a blank course while it barely
    moves: the speed is a measurement, its direction unknown; a course gives the velocity as before."""
    bodies = [
        "GPRMC,120000.00,A,4807.0380,N,01131.0000,E,0.045,,230394,,,A",
        "GPGGA,120000.00,4807.0380,N,01131.0000,E,1,08,0.9,545.4,M,46.9,M,,",
        "GPRMC,120001.00,A,4807.0381,N,01131.0000,E,0.694,,230394,,,A",
        "GPGGA,120001.00,4807.0381,N,01131.0000,E,1,08,0.9,545.6,M,46.9,M,,",
        "GPRMC,120002.00,A,4807.0382,N,01131.0000,E,0.700,90.0,230394,,,A",
        "GPGGA,120002.00,4807.0382,N,01131.0000,E,1,08,0.9,545.5,M,46.9,M,,",
    ]
    fixes = read_log(_write(tmp_path / "flarm.nmea", bodies)).fixes
    assert fixes["speed_mps"].iloc[:2].tolist() == pytest.approx([0.045 * KNOT_MPS, 0.694 * KNOT_MPS])
    assert fixes[["vel_e_mps", "vel_n_mps"]].iloc[:2].isna().all().all()
    assert np.isnan(fixes["speed_mps"].iloc[2]) and fixes["vel_e_mps"].iloc[2] == pytest.approx(0.7 * KNOT_MPS)


def test_gsv_elevation_or_azimuth_out_of_range_is_no_measurement(tmp_path: Path) -> None:
    """NMEA GSV elevation is 00-90 and azimuth 000-359: a receiver's 95 or -91 elevation (a "not known"), or
    an azimuth beyond 360 (north, to receivers that write 0-360), is no satellite position: NaN, counted,
    never a satellite below the horizon (gpsd's -91 made a real capture's G07 "tracked 91 deg below the horizon")."""
    bodies = []
    for k in range(10):
        hhmmss = f"1200{k:02d}"
        bodies += [
            f"GPGGA,{hhmmss},4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
            "GPGSV,2,1,05,02,57,146,30,05,66,020,34,07,95,000,20,09,-91,000,21",
            "GPGSV,2,2,05,12,40,400,33",
            f"GPRMC,{hhmmss},A,4807.038,N,01131.000,E,0.0,0.0,010524,,",
        ]
    table = read_log(_write(tmp_path / "gsv.nmea", bodies))
    sats = table.satellites.set_index(["t_s", "sv_id"]).loc[0.0]
    assert sats.loc["G02", "elevation_deg"] == 57 and sats.loc["G05", "azimuth_deg"] == 20
    assert np.isnan(sats.loc["G07", ["elevation_deg", "azimuth_deg"]].astype(float)).all()
    assert sats.loc["G07", "cn0_dbhz"] == 20  # the signal is still read
    assert np.isnan(float(sats.loc["G12", "azimuth_deg"])) and sats.loc["G12", "elevation_deg"] == 40
    assert not (table.satellites["elevation_deg"].abs() > 90).any()
    assert not (table.satellites["azimuth_deg"] > 360).any()
    notes = [s for s in table.skipped if "elevation" in s.reason or "azimuth" in s.reason]
    assert notes and all(s.action != "lost" for s in notes)


def test_a_speed_logs_magnetic_heading_keeps_its_water_speed(tmp_path: Path) -> None:
    """A yacht's instrument bus writes VHW with the magnetic heading only (`$IIVHW,,T,15.0,M,3.3,N,6.0,K`): its
    86 water speeds were dropped as "headings without a value" and the heading test said "no speed log"."""
    bodies = []
    for k in range(5):
        hhmmss = f"1200{k:02d}"
        bodies += [
            f"GPRMC,{hhmmss},A,5752.000,N,01148.000,E,3.3,15.0,010615,,",
            f"GPGGA,{hhmmss},5752.000,N,01148.000,E,1,08,0.9,5.0,M,30.0,M,,",
            "IIVHW,,T,15.0,M,3.3,N,6.1,K",
        ]
    table = read_log(_write(tmp_path / "vhw.nmea", bodies))
    vhw = table.headings[table.headings["heading_id"] == "IIVHW"]
    assert len(vhw) == 5 and (vhw["heading_deg"] == 15.0).all()
    assert vhw["water_speed_mps"].to_numpy() == pytest.approx(3.3 * KNOT_MPS)
    (note,) = [s for s in table.skipped if s.stream == "IIVHW"]
    assert note.action == "repaired" and "magnetic headings without a variation (HDM, HDG, VHW)" in note.reason


def test_an_epoch_before_the_first_altitude_is_said_to_take_the_first_not_the_last(tmp_path: Path) -> None:
    """A handheld MTK receiver's log (mjuenema/python-gpsdshm `tests/test.nmea`) opens with an RMC whose GGA is
    not in the file: that epoch took the next height and was said to take "the receiver's last known height",
    which it had none of yet."""
    log = tmp_path / "mtk.nmea"
    log.write_text(
        "$GPRMC,185132.000,A,3745.5274,S,14459.9666,E,1.28,124.66,280116,,,A*7C\n"
        "$GPGGA,185133.000,3745.5270,S,14459.9662,E,1,5,1.70,85.7,M,-3.9,M,,*61\n"
        "$GPRMC,185133.000,A,3745.5270,S,14459.9662,E,1.26,122.38,280116,,,A*7E\n"
        "$GPGGA,185134.000,3745.5274,S,14459.9658,E,1,5,1.70,85.7,M,-3.9,M,,*6B\n"
        "$GPRMC,185134.000,A,3745.5274,S,14459.9658,E,1.06,163.52,280116,,,A*7F\n"
    )
    table = read_log(log)
    assert np.allclose(table.fixes["height_m"], 85.7 - 3.9)
    (filled,) = [s for s in table.skipped if s.reason.startswith("epochs without altitude")]
    assert filled.count == 1
    assert filled.reason.endswith("last known height (the 1 before its first: that first height)")
