"""RINEX: real observation and navigation files (recorded by others), bad input, and spoofed copies.

The strongest check ties everything together: on the GSI pair, pseudorange minus the geometric range
from the broadcast orbit to the surveyed site, plus the satellite clock, is the same for every
satellite of an epoch (the receiver clock) up to the atmosphere. Times, clocks, orbits and the
reader's field positions must all be right for that to hold.
"""

from __future__ import annotations

import itertools
import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from paths import REAL, real_log

from readers import read_log, sniff_format
from readers.rinex import (
    TextLines,
    parse_fixed,
    read_rinex,
    read_rinex_nav,
    read_rinex_nav_file,
    rinex_approx_position,
)
from spooflens.cli import main
from spooflens.epoch_table import EpochTable
from spooflens.errors import ReaderError, UnsupportedFormatError, WriterError
from spooflens.gnss.ephemeris import C_MPS, GM_GPS, OMEGA_E_GPS, satellite_states
from spooflens.pipeline.registry import REQUIREMENTS
from spooflens.writers.rinex_rewrite import COMMENT, rewrite_rinex

GSI = REAL / "rinex_gsi_pair"
OBS_0759, NAV_0759 = GSI / "07590920.05o", GSI / "07590920.05n"
PIXEL = REAL / "android_gnsslogger" / "gnss_lib_py" / "pixel6.23o"
L1, L2, L5 = 1575.42e6, 1227.60e6, 1176.45e6
GPS_2005_04_02_NS = (1316 * 7 + 6) * 86400 * 1_000_000_000  # GPS ns since 1980-01-06 of 2005-04-02 00:00 GPST


def _need(path: Path) -> Path:
    return real_log(str(path.relative_to(REAL)))


@pytest.fixture(scope="module")
def gsi() -> EpochTable:
    return read_log(_need(GSI))


@pytest.fixture(scope="module")
def pixel() -> EpochTable:
    return read_log(_need(PIXEL))


# --- the GSI pair: RINEX 2.10, two receivers -------------------------------------------------------


def test_gsi_pair_reads_as_two_receivers(gsi: EpochTable) -> None:
    obs = gsi.observations
    assert gsi.format == "rinex" and gsi.time_reference == "gps"
    assert gsi.t0_ns == GPS_2005_04_02_NS
    assert gsi.absolute_iso(0.0).startswith("2005-04-01T23:59:47")  # GPS - UTC was 13 s in 2005
    streams = {s.stream_id: s for s in gsi.streams if s.role == "observations"}
    assert set(streams) == {"0759", "3040"}
    assert {s.topic for s in streams.values()} == {"07590920.05o", "30400920.05o"}
    for s in streams.values():
        assert s.count == 120 and s.msgtype == "RINEX 2.10 obs"
        assert s.first_s == 0.0 and s.last_s == pytest.approx(3570.0, abs=0.01)  # 00:59:30
        assert s.rate_hz == pytest.approx(1 / 30, rel=1e-3)
    nav = {s.stream_id: s.count for s in gsi.streams if s.role == "nav"}
    assert nav == {"07590920.05n": 162, "30400920.05n": 164}
    per_epoch = obs.groupby(["receiver_id", "t_s"]).size()
    assert per_epoch.min() >= 7 and per_epoch.max() <= 10 and 7.5 < per_epoch.mean() < 9.5
    assert set(obs["sv_id"].str[0]) == {"G"}
    assert (obs["carrier_freq_hz"] == L1).all()
    assert obs["doppler_hz"].isna().all() and obs["cn0_dbhz"].isna().all()  # C1 L1 L2 P2 only
    assert np.isfinite(obs[["sv_x_m", "sv_clock_bias_m"]].to_numpy()).all()
    events = [s for s in gsi.skipped if s.reason.startswith("event records")]
    assert [(s.stream, s.count) for s in events] == [("07590920.05o", 3), ("30400920.05o", 1)]
    # the receivers' own loss-of-lock flags (LLI 1 on the L1 phase): those carriers are not taken as continuous
    lost = {s.stream: s.count for s in gsi.skipped if s.reason.startswith("carriers across a loss of lock")}
    assert lost == {"0759": 10, "3040": 6}
    assert len(gsi.skipped) == 4


def test_gsi_values_are_the_files_fields(gsi: EpochTable) -> None:
    first = gsi.observations.query("receiver_id == '0759' and t_s == 0").set_index("sv_id")
    assert list(first.index) == ["G03", "G07", "G08", "G11", "G19", "G20", "G24", "G28"]
    assert first.loc["G03", "pseudorange_m"] == 24767686.375
    assert first.loc["G03", "carrier_phase_cycles"] == 55923622.160
    assert first.loc["G07", "carrier_phase_cycles"] == -691177.898
    assert rinex_approx_position(OBS_0759) == (-3976219.5082, 3382372.5671, 3652512.9849)


def test_gsi_orbits_have_gps_radius_and_inertial_speed(gsi: EpochTable) -> None:
    obs = gsi.observations
    r = obs[["sv_x_m", "sv_y_m", "sv_z_m"]].to_numpy()
    v = obs[["sv_vx_mps", "sv_vy_mps", "sv_vz_mps"]].to_numpy()
    radius = np.linalg.norm(r, axis=1)
    assert radius.min() > 26.0e6 and radius.max() < 27.0e6
    speed_ecef = np.linalg.norm(v, axis=1)
    assert speed_ecef.min() > 2.5e3 and speed_ecef.max() < 3.9e3
    inertial = v + np.cross([0.0, 0.0, OMEGA_E_GPS], r)
    speed = np.linalg.norm(inertial, axis=1)
    vis_viva = np.sqrt(GM_GPS * (2 / radius - 1 / 26_560e3))  # e < 0.02: a ~ 26,560 km
    assert np.abs(speed - vis_viva).max() < 40.0  # m/s
    assert np.abs(obs["sv_clock_drift_mps"]).max() < 1.0


def _klobuchar_m(iono, lat: float, lon: float, az: np.ndarray, el: np.ndarray, tow: np.ndarray) -> np.ndarray:
    """IS-GPS-200 20.3.3.5.2.5 ionospheric L1 delay (m), angles in radians."""
    e_sc = el / np.pi
    psi = 0.0137 / (e_sc + 0.11) - 0.022
    phi_i = np.clip(lat / np.pi + psi * np.cos(az), -0.416, 0.416)
    lam_i = lon / np.pi + psi * np.sin(az) / np.cos(phi_i * np.pi)
    phi_m = phi_i + 0.064 * np.cos((lam_i - 1.617) * np.pi)
    t = (43200 * lam_i + tow) % 86400
    amp = np.maximum(sum(a * phi_m**k for k, a in enumerate(iono.alpha)), 0.0)
    per = np.maximum(sum(b * phi_m**k for k, b in enumerate(iono.beta)), 72000.0)
    x = 2 * np.pi * (t - 50400) / per
    slant = 1.0 + 16.0 * (0.53 - e_sc) ** 3
    return C_MPS * slant * np.where(np.abs(x) < 1.57, 5e-9 + amp * (1 - x**2 / 2 + x**4 / 24), 5e-9)


@pytest.mark.parametrize(("rid", "obs_name"), [("0759", "07590920.05o"), ("3040", "30400920.05o")])
def test_gsi_pseudoranges_fit_orbits_clocks_and_the_surveyed_site(gsi: EpochTable, rid: str, obs_name: str) -> None:
    """pr - range + sv clock = receiver clock (+ atmosphere): one value for every satellite of an epoch."""
    site = np.array(rinex_approx_position(GSI / obs_name))
    obs = gsi.observations[gsi.observations["receiver_id"] == rid]
    sv = obs[["sv_x_m", "sv_y_m", "sv_z_m"]].to_numpy()
    los = sv - site
    sagnac = OMEGA_E_GPS * (sv[:, 0] * site[1] - sv[:, 1] * site[0]) / C_MPS
    clock = obs["pseudorange_m"].to_numpy() - (np.linalg.norm(los, axis=1) + sagnac) + obs["sv_clock_bias_m"].to_numpy()
    spread = pd.Series(clock).groupby(obs["t_s"].to_numpy()).agg(lambda x: x.max() - x.min())
    assert spread.max() < 30.0
    # with a plain troposphere and the file's own Klobuchar coefficients the spread is a few metres
    lat = math.atan2(site[2], math.hypot(site[0], site[1]) * (1 - 0.00669438))
    lon = math.atan2(site[1], site[0])
    east = np.array([-math.sin(lon), math.cos(lon), 0.0])
    north = np.array([-math.sin(lat) * math.cos(lon), -math.sin(lat) * math.sin(lon), math.cos(lat)])
    up = np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])
    el = np.arcsin(los @ up / np.linalg.norm(los, axis=1))
    az = np.arctan2(los @ east, los @ north)
    tow = (gsi.t0_ns / 1e9 + obs["t_s"].to_numpy()) % 604800
    iono = read_rinex_nav(NAV_0759).iono
    assert iono is not None and iono.alpha[0] == pytest.approx(1.118e-8) and iono.beta[3] == pytest.approx(-1.311e5)
    corrected = clock - 2.47 / (np.sin(el) + 0.0121) - _klobuchar_m(iono, lat, lon, az, el, tow)
    spread = pd.Series(corrected).groupby(obs["t_s"].to_numpy()).agg(lambda x: x.max() - x.min())
    assert spread.max() < 8.0 and spread.median() < 5.0


# --- navigation files ---------------------------------------------------------------------------------


def _textbook_position(rec: dict[str, float], t: float) -> np.ndarray:
    """IS-GPS-200 Table 20-IV, scalar and written out once more, for one record at GPS time t."""
    a = rec["sqrt_a"] ** 2
    tk = t - (rec["week"] * 604800 + rec["toe_sow"])
    mk = rec["m0"] + (math.sqrt(GM_GPS / a**3) + rec["delta_n"]) * tk
    ek = mk
    for _ in range(30):
        ek = mk + rec["e"] * math.sin(ek)
    vk = math.atan2(math.sqrt(1 - rec["e"] ** 2) * math.sin(ek), math.cos(ek) - rec["e"])
    phi = vk + rec["omega"]
    du = rec["cus"] * math.sin(2 * phi) + rec["cuc"] * math.cos(2 * phi)
    dr = rec["crs"] * math.sin(2 * phi) + rec["crc"] * math.cos(2 * phi)
    di = rec["cis"] * math.sin(2 * phi) + rec["cic"] * math.cos(2 * phi)
    u, r, i = phi + du, a * (1 - rec["e"] * math.cos(ek)) + dr, rec["i0"] + di + rec["idot"] * tk
    om = rec["omega0"] + (rec["omega_dot"] - OMEGA_E_GPS) * tk - OMEGA_E_GPS * rec["toe_sow"]
    x, y = r * math.cos(u), r * math.sin(u)
    return np.array(
        [
            x * math.cos(om) - y * math.cos(i) * math.sin(om),
            x * math.sin(om) + y * math.cos(i) * math.cos(om),
            y * math.sin(i),
        ]
    )


def test_gsi_nav_matches_a_textbook_orbit_and_the_file_text() -> None:
    eph = read_rinex_nav(_need(NAV_0759))
    k = int(np.flatnonzero(eph.sv_id == "G01")[0])
    # the first record of the file, field by field (D exponents, fixed width, adjacent minus signs)
    assert (eph.af0[k], eph.af1[k], eph.crs[k], eph.m0[k]) == (
        3.966595977540e-04,
        1.705302565820e-12,
        -5.21875e1,
        2.871534990340,
    )
    assert (eph.week[k], eph.toe_sow[k], eph.iode[k], eph.health[k]) == (1316, 525600.0, 140, 0)
    assert eph.tgd[k] == -3.259629011150e-09 and eph.sqrt_a[k] == 5.153636478420e03
    assert eph.toc_s[k] == (1316 * 7 + 6) * 86400 + 2 * 3600
    rec = {
        f: float(getattr(eph, f)[k])
        for f in (
            "sqrt_a",
            "week",
            "toe_sow",
            "m0",
            "delta_n",
            "e",
            "omega",
            "cus",
            "cuc",
            "crs",
            "crc",
            "cis",
            "cic",
            "i0",
            "idot",
            "omega0",
            "omega_dot",
        )
    }
    t = eph.toe_s[k] + 900.0
    got = satellite_states(eph, ["G01"], np.array([t]))
    assert got.record[0] == k
    assert np.linalg.norm(got.pos_m[0] - _textbook_position(rec, t)) < 1e-3


def test_consecutive_broadcast_records_agree_between_their_toes() -> None:
    eph = read_rinex_nav(_need(NAV_0759))
    pairs = 0
    for sv in eph.satellites():
        idx = np.flatnonzero((eph.sv_id == sv) & (eph.health == 0))
        for a, b in itertools.pairwise(idx):
            if not 0 < eph.toe_s[b] - eph.toe_s[a] <= 4 * 3600:
                continue
            t = np.array([(eph.toe_s[a] + eph.toe_s[b]) / 2])
            one, two = (satellite_states(eph.take(np.array([r])), [sv], t) for r in (a, b))
            assert np.linalg.norm(one.pos_m - two.pos_m) < 10.0
            assert abs(one.clock_bias_m[0] - two.clock_bias_m[0]) < 10.0
            pairs += 1
    assert pairs > 100


def _nav_v3(v2_path: Path) -> str:
    """The GSI RINEX 2 navigation file rewritten as a RINEX 3.04 mixed file, plus a GLONASS and a Galileo record."""
    lines = v2_path.read_text().splitlines()
    end = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
    alpha = next(ln for ln in lines if "ION ALPHA" in ln)[2:50]
    beta = next(ln for ln in lines if "ION BETA" in ln)[2:50]
    out = [
        f"{'     3.04':<20}{'N: GNSS NAV DATA':<20}{'M: MIXED':<20}RINEX VERSION / TYPE",
        f"{'GPSA ' + alpha:<60}IONOSPHERIC CORR",
        f"{'GPSB ' + beta:<60}IONOSPHERIC CORR",
        f"{'':60}END OF HEADER",
    ]
    for ln in lines[end + 1 :]:
        if ln[:2].strip():
            prn, yy, mo, d, h, mi, sec = (float(v) for v in ln[:22].split())
            out.append(
                f"G{int(prn):02d} {2000 + int(yy):4d} {int(mo):02d} {int(d):02d} {int(h):02d} {int(mi):02d} "
                f"{int(sec):02d}" + ln[22:]
            )
        else:
            out.append(" " + ln)
    field = " 1.000000000000E+00"
    out += ["R07 2005 04 02 00 15 00" + field * 3] + ["    " + field * 4] * 3
    out += ["E11 2005 04 02 00 00 00" + field * 3] + ["    " + field * 4] * 7
    return "\n".join(out) + "\n"


def test_rinex3_mixed_nav_gives_the_same_gps_records(tmp_path: Path) -> None:
    v2 = read_rinex_nav_file(_need(NAV_0759))
    path = tmp_path / "BRDC00XXX_R_20050920000_01D_MN.rnx"
    path.write_text(_nav_v3(NAV_0759))
    v3 = read_rinex_nav_file(path)
    assert v3.version == 3.04 and v3.records == v2.records == 162
    for name in ("sv_id", "week", "toe_sow", "toc_s", "af0", "sqrt_a", "m0", "omega_dot", "tgd", "health", "iode"):
        assert np.array_equal(getattr(v3.ephemerides, name), getattr(v2.ephemerides, name)), name
    assert v3.ephemerides.iono == v2.ephemerides.iono
    # the GLONASS record is another system's; the Galileo one (every field 1.0) is read and refused
    (galileo, glonass) = v3.skipped
    assert (glonass.reason, glonass.count) == (
        "navigation records of GLONASS, QZSS, ... (GPS, Galileo, BeiDou orbits are used)",
        1,
    )
    assert galileo.reason.endswith("implausible orbit (sqrt(A) or e out of range))") and galileo.count == 1


def test_a_nav_file_written_with_one_digit_exponents_reads_the_same(tmp_path: Path) -> None:
    """goGPS writes `4.800000000000D+1`: 18 columns where the format has 19, the fields of a line shifted.
    Cut at the format's columns, an intact file was "unreadable or cut navigation records" (exit 3, then "no
    navigation file found"); split at its numbers, it gives the standard file's records."""
    import re

    text = _need(NAV_0759).read_text()
    head, body = text.split("END OF HEADER", 1)
    narrow = tmp_path / "gogps.05n"
    narrow.write_text(head + "END OF HEADER" + re.sub(r"([DE][+-])0(\d)", r"\1\2", body))
    standard, written = read_rinex_nav_file(_need(NAV_0759)), read_rinex_nav_file(narrow)
    assert written.records == standard.records == 162 and not written.skipped
    for name in ("sv_id", "week", "toe_sow", "toc_s", "af0", "af1", "sqrt_a", "m0", "omega_dot", "tgd", "iode"):
        assert np.array_equal(getattr(written.ephemerides, name), getattr(standard.ephemerides, name)), name


def test_bad_and_cut_nav_records_are_counted(tmp_path: Path) -> None:
    text = _need(NAV_0759).read_text()
    lines = text.splitlines()
    bad = tmp_path / "bad.05n"
    lines[12] = lines[12][:30] + "x" + lines[12][31:]  # a garbage digit in the first record
    bad.write_text("\n".join(lines[:-3]) + "\n")  # and the last record cut short
    nav = read_rinex_nav_file(bad)
    assert nav.records == 162 - 2
    assert [(s.count, s.action) for s in nav.skipped] == [(2, "lost")]
    assert "first at line 13" in nav.skipped[0].reason
    cut = tmp_path / "cut.05n"
    cut.write_text(text[:2000])  # the second record ends inside its seventh line
    assert read_rinex_nav_file(cut).records == 1
    header_only = tmp_path / "empty.05n"
    header_only.write_text("\n".join(lines[:12]) + "\n")
    with pytest.raises(ReaderError, match=r"empty.05n: no usable GPS, Galileo or BeiDou navigation record"):
        read_rinex_nav(header_only)


# --- RINEX 3: the Pixel phone (mixed GNSS, CRLF) -----------------------------------------------------------


def test_android_rinex3_mixed_constellations(pixel: EpochTable) -> None:
    obs = pixel.observations
    assert set(obs["sv_id"].str[0]) == {"G", "R", "E"}
    (stream,) = [s for s in pixel.streams if s.role == "observations"]
    assert (stream.stream_id, stream.msgtype, stream.count) == ("Google GnssLogger", "RINEX 3.03 obs", 48)
    assert pixel.absolute_iso(0.0).startswith("2023-11-07T23:42:57")  # 23:43:15 GPST minus 18 leap seconds
    first = obs[obs["t_s"] == 0].set_index("sv_id")
    assert len(first) == 19
    assert first.loc["G04", "pseudorange_m"] == 23440243.757 and first.loc["G04", "cn0_dbhz"] == 29.972
    assert first.loc["G04", "doppler_hz"] == -3537.656 and first.loc["G04", "carrier_phase_cycles"] == 150559.526
    # the phone flags every phase LLI 2, half-cycle ambiguity possible: no carrier is taken as continuous
    assert (obs["carrier_arc_start"].dropna() == 1).all()
    (half,) = [s for s in pixel.skipped if "half-cycle" in s.reason]
    assert half.count == len(obs) and half.action == "flagged" and "every carrier the receiver gave" in half.reason
    # GLONASS G1 from the header's slot/channel table (R01 +1, R02 -4)
    assert first.loc["R01", "carrier_freq_hz"] == 1602e6 + 0.5625e6
    assert first.loc["R02", "carrier_freq_hz"] == 1602e6 - 4 * 0.5625e6
    assert (first.loc[["E07", "E27", "G08"], "carrier_freq_hz"] == L1).all()
    rate = -first["doppler_hz"] * C_MPS / first["carrier_freq_hz"]
    assert np.allclose(first["pseudorange_rate_mps"], rate)
    assert obs["sv_x_m"].isna().all()
    reasons = {s.reason.split(" (")[0]: s for s in pixel.skipped}
    assert reasons["no navigation file found for pixel6.23o"].count == int(obs["sv_id"].str[0].isin(["G", "E"]).sum())
    assert reasons["rows of systems R: no satellite states"].count == int((obs["sv_id"].str[0] == "R").sum())


def test_nav_topic_overrides_the_search(tmp_path: Path) -> None:
    obs = tmp_path / "alone.05o"
    shutil.copyfile(_need(OBS_0759), obs)
    without = read_log(obs)
    assert without.observations["sv_x_m"].isna().all()
    assert any("no navigation file found for alone.05o" in s.reason for s in without.skipped)
    with_nav = read_log(obs, topics={"nav": str(NAV_0759)})
    assert np.isfinite(with_nav.observations["sv_x_m"]).all()
    assert [s.stream_id for s in with_nav.streams if s.role == "nav"] == ["07590920.05n"]
    with pytest.raises(ReaderError, match=r"nope.05n \[nav\]: navigation file given with --topic nav= does not exist"):
        read_log(obs, topics={"nav": str(tmp_path / "nope.05n")})
    # a broken nav file beside the observations costs the satellite states only
    (tmp_path / "alone.05n").write_text(NAV_0759.read_text()[:1200])
    broken = read_log(obs)
    assert broken.observations["sv_x_m"].isna().all() and len(broken.observations) == 948
    assert any(s.stream == "alone.05n" and s.reason.startswith("navigation file unusable") for s in broken.skipped)
    # and says the file was found, not "no navigation file found"
    assert any(
        "the navigation file found for alone.05o (alone.05n) could not be read" in s.reason for s in broken.skipped
    )
    # a nav file of another day: every GPS row counted, none dropped, and the two spans named
    stale = read_log(_need(PIXEL), topics={"nav": str(NAV_0759)})
    (miss,) = [s for s in stale.skipped if s.reason.startswith("GPS rows without satellite states")]
    assert miss.action == "no ephemeris" and miss.count == int((stale.observations["sv_id"].str[0] == "G").sum())
    assert "the navigation data's GPS orbits are for 2005-04-01 23:59 to 2005-04-03 00:00" in miss.reason
    assert "the observations 2023-" in miss.reason
    assert "no orbit of the navigation data given is of the observations' time" in str(
        REQUIREMENTS["satellite_states"].missing(stale)
    )
    # a nav file of the same hours but of other satellites (a static base's nav cut to its first records, whose
    # one GPS orbit was of a satellite it never saw, was said to be "of another day or hour?")
    head, body = NAV_0759.read_text().split("END OF HEADER\n", 1)
    lines = body.splitlines(keepends=True)
    records = ["".join(lines[i : i + 8]) for i in range(0, len(lines) - 7, 8)]
    seen = {int(sv[1:]) for sv in with_nav.observations["sv_id"].unique()}
    unseen = [r for r in records if int(r[:2]) not in seen]
    assert unseen and len(unseen) < len(records)
    (tmp_path / "other.05n").write_text(head + "END OF HEADER\n" + "".join(unseen))
    others = read_log(obs, topics={"nav": str(tmp_path / "other.05n")})
    (miss,) = [s for s in others.skipped if s.reason.startswith("GPS rows without satellite states")]
    assert "are of the observations' hours (2005-04-02" in miss.reason
    assert "but none is of a satellite observed (G" in miss.reason and "another day" not in miss.reason


# --- directories and sniffing -----------------------------------------------------------------------------


def test_sniff_format_files_and_directories(tmp_path: Path) -> None:
    assert sniff_format(_need(OBS_0759)) == "rinex"
    assert sniff_format(GSI) == "rinex"
    assert sniff_format(_need(PIXEL)) == "rinex"
    # the phone's folder holds its GnssLogger and NMEA logs beside the RINEX: three logs, not one
    with pytest.raises(UnsupportedFormatError, match=r"folder of separate logs.*pixel6\.nmea \(nmea\), pixel6\.txt"):
        sniff_format(PIXEL.parent)
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    shutil.copyfile(OBS_0759, mixed / "a.05o")
    assert sniff_format(mixed) == "rinex"
    (mixed / "fixes.csv").write_text("t_s,lat,lon,alt\n0,1,2,3\n")
    # CSV detection comes first, and the CSV reader never reads the RINEX file beside: two logs, not one
    with pytest.raises(UnsupportedFormatError, match=r"not one csv log: it also holds a\.05o \(rinex\)"):
        sniff_format(mixed)
    (mixed / "fixes.csv").unlink()
    (mixed / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    assert sniff_format(mixed) == "ros2bag"
    nav_only = tmp_path / "nav_only"
    nav_only.mkdir()
    shutil.copyfile(NAV_0759, nav_only / "x.05n")
    with pytest.raises(ReaderError, match="directory holds no log this tool reads"):
        sniff_format(nav_only)


def test_directory_with_duplicate_marker_names(tmp_path: Path) -> None:
    for name in ("a.05o", "b.05o"):
        shutil.copyfile(_need(OBS_0759), tmp_path / name)
    shutil.copyfile(NAV_0759, tmp_path / "a.05n")
    table = read_log(tmp_path)
    ids = sorted(s.stream_id for s in table.streams if s.role == "observations")
    assert ids == ["0759_a.05o", "0759_b.05o"]
    a, b = (table.observations[table.observations["receiver_id"] == i] for i in ids)
    assert len(a) == len(b) == 948
    assert np.isfinite(b["sv_x_m"]).all()  # b.05o has no namesake: the directory's nav file is used


# --- bad input --------------------------------------------------------------------------------------------


def _cli(path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, list[str]]:
    code = main(["inspect", str(path)])
    return code, capsys.readouterr().err.strip().splitlines()


def test_empty_and_headless_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    empty = tmp_path / "empty.05o"
    empty.write_bytes(b"")
    with pytest.raises(ReaderError, match=r"empty.05o: file is empty"):
        read_rinex(empty)
    assert _cli(empty, capsys) == (2, [f"spooflens: error: {empty}: file is empty (0 bytes)"])
    cut_header = tmp_path / "cut_header.05o"
    cut_header.write_text("\n".join(_need(OBS_0759).read_text().splitlines()[:6]) + "\n")
    with pytest.raises(ReaderError, match=r"cut_header.05o: no END OF HEADER line"):
        read_log(cut_header)
    header_only = tmp_path / "header_only.05o"
    header_only.write_text("\n".join(OBS_0759.read_text().splitlines()[:17]) + "\n")
    with pytest.raises(ReaderError, match=r"header_only.05o \[observations\]: no usable observation"):
        read_log(header_only)
    code, err = _cli(header_only, capsys)
    assert code == 2 and len(err) == 1


def test_unknown_version_and_nav_file_given_as_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    future = tmp_path / "future.05o"
    future.write_text(_need(OBS_0759).read_text().replace("     2.10 ", "     9.99 ", 1))
    with pytest.raises(ReaderError, match=r"future.05o: unsupported RINEX version 9.99; supported: 2.10, 2.11"):
        read_log(future)
    code, err = _cli(future, capsys)
    assert code == 2 and len(err) == 1 and "unsupported RINEX version 9.99" in err[0]
    garbled = tmp_path / "garbled.05o"
    garbled.write_text(OBS_0759.read_text().replace("     2.10 ", "     2.x0 ", 1))
    with pytest.raises(ReaderError, match=r"RINEX version '2.x0' is not a number"):
        read_log(garbled)
    code, err = _cli(NAV_0759, capsys)
    assert code == 2 and len(err) == 1 and "a RINEX navigation file, not observations" in err[0]


def test_file_cut_mid_epoch_keeps_what_came_before(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = _need(OBS_0759).read_bytes()
    cut = tmp_path / "cut.05o"
    cut.write_bytes(data[: len(data) // 2])
    table = read_log(cut)
    (lost,) = [s for s in table.skipped if s.action == "lost"]
    assert lost.reason.startswith("file cut mid-epoch") and lost.count == 1
    whole = read_rinex(OBS_0759, {"nav": str(NAV_0759)})
    part = table.observations
    assert 40 < part["t_s"].nunique() < 80
    ref = whole.observations.iloc[: len(part)]
    assert np.array_equal(part["pseudorange_m"].to_numpy(), ref["pseudorange_m"].to_numpy())
    code, err = _cli(cut, capsys)
    assert code == 3 and err == []
    # cut exactly at a line end inside an epoch's satellite lines
    lines = data.decode().splitlines(keepends=True)
    at_line = tmp_path / "cut_at_line.05o"
    at_line.write_text("".join(lines[:21]))  # header (17) + epoch line + 3 of its 8 satellites
    with pytest.raises(ReaderError, match="file cut mid-epoch"):
        read_log(at_line)


def test_garbage_numbers_skip_only_their_satellite_row(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = _need(OBS_0759).read_text()
    bad = tmp_path / "garbage.05o"
    bad.write_text(text.replace("24767686.375", "2476x686.375", 1).replace("55923622.160", "  559236**.16", 1))
    table = read_log(bad)
    (lost,) = [s for s in table.skipped if s.action == "lost"]
    assert (lost.stream, lost.count) == ("0759", 1) and "not a number" in lost.reason
    first = table.observations[table.observations["t_s"] == 0]
    assert "G03" not in set(first["sv_id"]) and len(first) == 7
    assert len(table.observations) == 948 - 1
    assert _cli(bad, capsys)[0] == 3
    sats = tmp_path / "bad_sat.05o"
    sats.write_text(text.replace("8G 3G 7G 8G11", "8G 3G 7Gx8G11", 1))
    table = read_log(sats)
    assert any("unreadable id" in s.reason for s in table.skipped)
    assert len(table.observations) == 948 - 1


def test_epoch_with_missing_satellite_lines_and_time_going_back(tmp_path: Path) -> None:
    lines = _need(OBS_0759).read_text().splitlines(keepends=True)
    short = tmp_path / "short.05o"
    short.write_text("".join(lines[:20] + lines[21:]))  # epoch 1 lists 8 satellites, 7 lines follow
    table = read_log(short)
    (lost,) = [s for s in table.skipped if s.action == "lost"]
    assert lost.reason.startswith("epochs with fewer satellite lines") and lost.count == 1
    assert table.observations["t_s"].nunique() == 119 and table.t0_ns == GPS_2005_04_02_NS + 30 * 1_000_000_000
    back = tmp_path / "back.05o"
    back.write_text("".join(lines[:17] + lines[26:35] + lines[17:26] + lines[35:]))  # epochs 0 and 1 swapped
    table = read_log(back)
    assert any(s.action == "repaired" and "time went backwards" in s.reason for s in table.skipped)
    assert table.observations["t_s"].is_monotonic_increasing and table.observations["t_s"].nunique() == 120


# --- synthetic files: RINEX 2 with > 12 satellites and a mid-file event, time systems, RINEX 3 cuts --------


SATS14 = [f"G{k:02d}" for k in range(1, 13)] + ["R05", "E11"]
TYPES6 = ("C1", "L1", "D1", "S1", "P2", "L2")


def _v2_obs(epochs: int, time_system: str = "GPS", event_after: int | None = None) -> str:
    """A RINEX 2.11 mixed file: 14 satellites (two epoch-header lines), 6 types (two lines per satellite).

    With `event_after`, a flag-4 event after that epoch redefines the types to C1 L1 P2 L2 (one line).
    """

    def hdr(text: str, label: str) -> str:
        return f"{text:<60}{label}"

    def types_line(types: tuple[str, ...]) -> str:
        return hdr(f"{len(types):6d}" + "".join(f"{t:>6}" for t in types), "# / TYPES OF OBSERV")

    out = [
        hdr(f"{'2.11':>9}{'':11}{'OBSERVATION DATA':<20}{'M (MIXED)':<20}", "RINEX VERSION / TYPE"),
        hdr("SYN", "MARKER NAME"),
        hdr(f"{1e6:14.4f}{2e6:14.4f}{3e6:14.4f}", "APPROX POSITION XYZ"),
        types_line(TYPES6),
        hdr(f"{2005:6d}{4:6d}{2:6d}{3:6d}{0:6d}{0.0:13.7f}     {time_system}", "TIME OF FIRST OBS"),
        hdr("", "END OF HEADER"),
    ]
    types: tuple[str, ...] = TYPES6
    for e in range(epochs):
        sec = 10.0 * e
        out.append(f" 05  4  2  3 {int(sec // 60):2d}{sec % 60:11.7f}  0{len(SATS14):3d}" + "".join(SATS14[:12]))
        out.append(" " * 32 + "".join(SATS14[12:]))
        for k, _ in enumerate(SATS14):
            pr = 2.0e7 + 1e5 * k + 100.0 * e
            values = {
                "C1": pr,
                "L1": pr / (C_MPS / L1),
                "D1": -1000.0 - k,
                "S1": 45.0,
                "P2": pr + 3.0,
                "L2": pr / (C_MPS / L2),
            }
            fields = [f"{values[t]:14.3f}  " for t in types]
            out += ["".join(fields[i : i + 5]).rstrip() for i in range(0, len(fields), 5)]
        if event_after is not None and e == event_after:
            types = ("C1", "L1", "P2", "L2")
            out += [f"{'':26}  4  2", types_line(types), hdr("types changed", "COMMENT")]
    return "\n".join(out) + "\n"


def test_rinex2_continuation_lines_multi_line_satellites_and_an_event(tmp_path: Path) -> None:
    path = tmp_path / "syn.05o"
    path.write_text(_v2_obs(6, event_after=2))
    table = read_log(path)
    obs = table.observations
    assert len(obs) == 6 * 14 and obs.groupby("t_s").size().eq(14).all()
    assert list(obs["sv_id"].iloc[:14]) == SATS14
    g05 = obs[obs["sv_id"] == "G05"].reset_index(drop=True)
    assert np.allclose(g05["pseudorange_m"], 2.0e7 + 4e5 + 100.0 * np.arange(6), atol=1e-3)
    assert g05["doppler_hz"].iloc[:3].eq(-1004.0).all() and g05["doppler_hz"].iloc[3:].isna().all()
    assert g05["cn0_dbhz"].iloc[:3].eq(45.0).all()
    assert np.allclose(g05["pseudorange_rate_mps"].iloc[:3], 1004.0 * C_MPS / L1)
    r05 = obs[obs["sv_id"] == "R05"]
    assert r05["carrier_freq_hz"].isna().all() and r05["pseudorange_rate_mps"].isna().all()  # no channel in v2
    assert any("event records" in s.reason for s in table.skipped)
    assert rinex_approx_position(path) == (1e6, 2e6, 3e6)


def test_time_systems(tmp_path: Path) -> None:
    gps = tmp_path / "gps.05o"
    gps.write_text(_v2_obs(2))
    glo = tmp_path / "glo.05o"
    glo.write_text(_v2_obs(2, time_system="GLO"))
    t_gps, t_glo = read_log(gps).t0_ns, read_log(glo).t0_ns
    assert t_gps == GPS_2005_04_02_NS + 3 * 3600 * 1_000_000_000
    assert t_glo == t_gps - 3 * 3600 * 1_000_000_000 + 13 * 1_000_000_000  # UTC(SU) + 3 h, GPS - UTC = 13 s
    odd = tmp_path / "odd.05o"
    odd.write_text(_v2_obs(2, time_system="XYZ"))
    with pytest.raises(ReaderError, match=r"time system 'XYZ' \(TIME OF FIRST OBS\) is not supported"):
        read_log(odd)


def _v3_obs(epochs: int, sats: int = 10, crlf: bool = False) -> str:
    """A RINEX 3.04 GPS + Galileo file, 4 types, one line per satellite."""
    out = [
        f"{'     3.04':<20}{'OBSERVATION DATA':<20}{'M':<20}RINEX VERSION / TYPE",
        f"{'V3SYN':<60}MARKER NAME",
        f"{'G    4 C1C L1C D1C S1C':<60}SYS / # / OBS TYPES",
        f"{'E    4 C1X L1X D1X S1X':<60}SYS / # / OBS TYPES",
        f"{'  2024     1     1     0     0    0.0000000     GPS':<60}TIME OF FIRST OBS",
        f"{'':<60}END OF HEADER",
    ]
    names = [f"G{k + 1:02d}" if k % 2 == 0 else f"E{k + 1:02d}" for k in range(sats)]
    rows = np.arange(epochs)
    for e in rows.tolist():
        h, rest = divmod(e, 3600)
        out.append(f"> 2024 01 01 {h:02d} {rest // 60:02d}{rest % 60:11.7f}  0{sats:3d}")
        out += [
            f"{sv}{2.1e7 + 1e3 * k + e:14.3f}  {1.1e8 + e:14.3f}  {-500.25:14.3f}  {40.0:14.3f}  "
            for k, sv in enumerate(names)
        ]
    return ("\r\n" if crlf else "\n").join(out) + ("\r\n" if crlf else "\n")


def test_rinex3_cut_short_epochs_and_garbage(tmp_path: Path) -> None:
    text = _v3_obs(5)
    lines = text.splitlines(keepends=True)
    path = tmp_path / "short.rnx"
    path.write_text("".join(lines[: 6 + 11 + 3] + lines[6 + 11 + 4 :]))  # epoch 1: header says 10, 9 follow
    table = read_log(path)
    (fix,) = [s for s in table.skipped if s.action != "no ephemeris"]
    assert fix.action == "repaired" and "satellite count differs" in fix.reason
    assert len(table.observations) == 49
    cut = tmp_path / "cut.rnx"
    cut.write_bytes(text.encode()[:-30])
    table = read_log(cut)
    assert [s.reason for s in table.skipped if s.action == "lost"] == ["file cut mid-epoch; kept every epoch before"]
    assert table.observations["t_s"].nunique() == 4
    bad = tmp_path / "bad.rnx"
    bad.write_text(text.replace("  40.000  \n", "  4O.000  \n", 1))
    table = read_log(bad)
    assert len(table.observations) == 49 and any("not a number" in s.reason for s in table.skipped)


def test_a_long_observation_file_is_read_whole(tmp_path: Path) -> None:
    """200,000 satellite rows, every one kept (how fast: `spooflens bench read`, not a timing assertion)."""
    path = tmp_path / "big.rnx"
    path.write_text(_v3_obs(20_000, sats=10))
    table = read_log(path)
    assert len(table.observations) == 200_000
    assert table.observations["t_s"].nunique() == 20_000


def test_parse_fixed_accepts_numbers_and_flags_garbage() -> None:
    fields = [
        b"  123.456     ",
        b"              ",
        b" 12 3.4       ",
        b"   1.2.3      ",
        b"  -12-3       ",
        b"    +7        ",
        b"   -.25       ",
        b"      12345678",
        b"   -12.3456789",
        b"**************",
    ]
    values, blank, bad = parse_fixed(np.frombuffer(b"".join(fields), dtype=np.uint8).reshape(-1, 14))
    assert list(blank) == [False, True] + [False] * 8
    assert list(bad) == [False, False, True, True, True, False, False, False, False, True]
    ok = ~blank & ~bad
    assert values[ok].tolist() == [123.456, 7.0, -0.25, 12345678.0, -12.3456789]


def test_text_lines_handle_crlf_and_a_missing_last_newline(tmp_path: Path) -> None:
    path = tmp_path / "t.txt"
    path.write_bytes(b"abc\r\nde\nf")
    text = TextLines.load(path)
    assert [text.line(i) for i in range(len(text))] == ["abc", "de", "f"] and not text.terminated
    assert text.field(np.array([0, 1, 2]), 1, 3).tobytes() == b"bc " + b"e  " + b"   "


# --- spoofed copies ----------------------------------------------------------------------------------------


def _fields_v2(line: str) -> list[float | None]:
    out: list[float | None] = []
    for k in range(5):
        f = line[16 * k : 16 * k + 14]
        out.append(float(f) if f.strip() else None)
    return out


def _gsi_blocks(text: str) -> dict[tuple[str, str], str]:
    """(epoch line, satellite) -> its data line, for the GSI files (4 types: one line per satellite)."""
    lines = text.splitlines()
    end = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
    out, i = {}, end + 1
    while i < len(lines):
        ln = lines[i]
        if ln[28:29] != "0":
            i += 1 + int(ln[29:32])
            continue
        n = int(ln[29:32])
        sats = [ln[32 + 3 * k : 35 + 3 * k] for k in range(n)]
        for k, sv in enumerate(sats):
            out[(ln[:26], sv)] = lines[i + 1 + k]
        i += 1 + n
    return out


def test_rewrite_round_trip_on_the_gsi_pair(gsi: EpochTable, tmp_path: Path) -> None:
    obs = gsi.observations.copy()
    moved = (obs["sv_id"] == "G07") & (obs["t_s"] >= 600.0)
    obs.loc[moved, "pseudorange_m"] += 100.0
    obs.loc[moved, "carrier_phase_cycles"] += 100.0 / (C_MPS / L1)
    gone = (obs["receiver_id"] == "0759") & (obs["sv_id"] == "G11") & (obs["t_s"] == 300.0)
    spoofed = obs[~gone]
    dst = tmp_path / "spoofed"
    note = rewrite_rinex(GSI, dst, gsi, spoofed)
    assert note == f"{int(moved.sum()):,} observations changed, 1 removed in 2 files"
    assert sorted(p.name for p in dst.iterdir()) == sorted(p.name for p in GSI.iterdir())
    assert (dst / "07590920.05n").read_bytes() == NAV_0759.read_bytes()
    again = read_log(dst)
    a = spoofed.reset_index(drop=True)
    b = again.observations
    assert len(b) == len(a) == len(gsi.observations) - 1
    assert (a[["receiver_id", "sv_id"]].to_numpy() == b[["receiver_id", "sv_id"]].to_numpy()).all()
    assert np.abs(a["t_s"] - b["t_s"]).max() == 0.0
    assert np.abs(a["pseudorange_m"] - b["pseudorange_m"]).max() < 1e-3
    assert np.abs(a["carrier_phase_cycles"] - b["carrier_phase_cycles"]).max() < 1.5e-3
    assert np.array_equal(
        gsi.observations.loc[~moved & ~gone, "sv_x_m"].to_numpy(),
        again.observations.loc[~moved[~gone].to_numpy(), "sv_x_m"].to_numpy(),
    )
    # byte level: the comment line, the one shortened epoch, and the moved satellite's lines differ; nothing else
    for name in ("07590920.05o", "30400920.05o"):
        src_text = (GSI / name).read_text()
        out_text = (dst / name).read_text()
        assert out_text.count(COMMENT) == 1
        src_lines = src_text.splitlines()
        out_lines = [ln for ln in out_text.splitlines() if COMMENT not in ln]
        src_blocks, out_blocks = _gsi_blocks(src_text), _gsi_blocks(out_text)
        removed = {k for k in src_blocks if k not in out_blocks}
        assert len(removed) == (1 if name.startswith("0759") else 0)
        changed = {k for k in out_blocks if out_blocks[k] != src_blocks[k]}
        assert {sv for _, sv in changed} == {"G 7"} and len(changed) > 50
        for key in changed:
            old, new = _fields_v2(src_blocks[key]), _fields_v2(out_blocks[key])
            l1, c1, l2, p2 = (n - o for n, o in zip(new[:4], old[:4], strict=True))  # type: ignore[operator]
            assert c1 == pytest.approx(100.0, abs=1e-6) and p2 == pytest.approx(100.0, abs=1e-6)
            assert l1 == pytest.approx(100.0 / (C_MPS / L1), abs=1e-3)
            assert l2 == pytest.approx(100.0 / (C_MPS / L2), abs=1e-3)
            assert src_blocks[key][14:16] == out_blocks[key][14:16]  # LLI/SSI kept
        if name.startswith("3040"):
            assert len(src_lines) == len(out_lines)
            assert sum(x != y for x, y in zip(src_lines, out_lines, strict=True)) == len(changed)
        else:
            assert len(out_lines) == len(src_lines) - 1
            epoch = " 05  4  2  0  5  0.0000000  0  7G 3G 7G 8G19G20G24G28"
            assert epoch in out_lines and " 05  4  2  0  5  0.0000000  0  8G 3G 7G 8G11G19G20G24G28" in src_lines


def test_rewrite_a_single_file_brings_its_nav_along(gsi: EpochTable, tmp_path: Path) -> None:
    table = read_log(_need(OBS_0759))
    obs = table.observations.copy()
    obs.loc[obs["sv_id"] == "G28", "pseudorange_m"] -= 25.0
    dst = tmp_path / "spoofed.05o"
    note = rewrite_rinex(OBS_0759, dst, table, obs)
    assert note.startswith("120 observations changed, 0 removed in 1 file") and "spoofed.05n" in note
    again = read_log(dst)
    assert np.abs(again.observations["pseudorange_m"] - obs["pseudorange_m"]).max() < 1e-3
    assert np.isfinite(again.observations["sv_x_m"]).all()


def test_rewrite_rinex2_epoch_headers_with_continuation_lines(tmp_path: Path) -> None:
    src = tmp_path / "syn.05o"
    src.write_text(_v2_obs(4, event_after=1))
    table = read_log(src)
    obs = table.observations.copy()
    e0, e1 = (obs["t_s"] == 0.0), (obs["t_s"] == 10.0)
    drop = (e0 & obs["sv_id"].isin(["G02", "E11"])) | (e1 & obs["sv_id"].isin(["G01", "G02", "R05"]))
    shift = (obs["sv_id"] == "G03") & (obs["t_s"] <= 10.0)
    obs.loc[shift, "pseudorange_m"] += 7.0
    obs.loc[shift, "pseudorange_rate_mps"] += 2.0
    dst = tmp_path / "out.05o"
    assert rewrite_rinex(src, dst, table, obs[~drop]).startswith("2 observations changed, 5 removed in 1 file")
    lines = dst.read_text().splitlines()
    head = [ln for ln in lines if ln.startswith(" 05  4  2  3")]
    assert head[0].endswith(" 12G01G03G04G05G06G07G08G09G10G11G12R05")  # 14 - 2: no continuation line
    assert head[1].endswith(" 11G03G04G05G06G07G08G09G10G11G12E11")
    assert lines[lines.index(head[0]) + 1].startswith("G") is False  # a data line, not a continuation
    again = read_log(dst).observations
    kept = obs[~drop].reset_index(drop=True)
    assert (again["sv_id"].to_numpy() == kept["sv_id"].to_numpy()).all()
    assert np.abs(again["pseudorange_m"] - kept["pseudorange_m"]).max() < 1e-3
    g03 = again[again["sv_id"] == "G03"].iloc[0]
    assert g03["doppler_hz"] == pytest.approx(-1002.0 - 2.0 / (C_MPS / L1), abs=1e-3)
    assert g03["carrier_phase_cycles"] == pytest.approx(
        kept.loc[1, "carrier_phase_cycles"] + 7.0 / (C_MPS / L1), abs=2e-3
    )


def test_rewrite_rinex3_keeps_crlf_and_shifts_every_signal(pixel: EpochTable, tmp_path: Path) -> None:
    obs = pixel.observations.copy()
    g08 = (obs["sv_id"] == "G08") & (obs["t_s"] >= 100.0)
    obs.loc[g08, "pseudorange_m"] += 50.0
    obs.loc[g08, "pseudorange_rate_mps"] += 1.0
    gone = (obs["sv_id"] == "R02") & (obs["t_s"] == 0.0)
    dst = tmp_path / "pixel_spoofed.23o"
    rewrite_rinex(PIXEL, dst, pixel, obs[~gone])
    src_raw, out_raw = PIXEL.read_bytes(), dst.read_bytes()
    assert out_raw.count(b"\n") == out_raw.count(b"\r\n") and out_raw.count(b"\n") == src_raw.count(b"\n")
    src_lines, out_lines = src_raw.decode().splitlines(), out_raw.decode().splitlines()
    assert "> 2023 11 07 23 43 15.0002755  0 18" in out_lines[21]
    pairs = [
        (a, b)
        for a, b in zip(
            [ln for ln in src_lines if ln.startswith("G08")],
            [ln for ln in out_lines if ln.startswith("G08")],
            strict=True,
        )
        if a != b
    ]
    assert len(pairs) == int(g08.sum())
    with_l5 = 0
    for a, b in pairs:
        old = [float(a[3 + 16 * k : 17 + 16 * k].strip() or "nan") for k in range(8)]  # C1C L1C D1C S1C C5Q L5Q D5Q S5Q
        new = [float(b[3 + 16 * k : 17 + 16 * k].strip() or "nan") for k in range(8)]
        assert np.array_equal(np.isnan(old), np.isnan(new))
        if np.isnan(old[4]):
            old[4:], new[4:] = [0.0] * 4, [50.0, 50.0 * L5 / C_MPS, -L5 / C_MPS, 0.0]
        else:
            with_l5 += 1
        d = np.subtract(new, old)
        assert d[0] == pytest.approx(50.0, abs=1e-6) and d[4] == pytest.approx(50.0, abs=1e-6)
        assert d[1] == pytest.approx(50.0 * L1 / C_MPS, abs=1e-3) and d[5] == pytest.approx(50.0 * L5 / C_MPS, abs=1e-3)
        assert d[2] == pytest.approx(-L1 / C_MPS, abs=1e-3) and d[6] == pytest.approx(-L5 / C_MPS, abs=1e-3)
        assert d[3] == 0.0 and d[7] == 0.0
    assert with_l5 > 10
    again = read_log(dst).observations
    kept = obs[~gone].reset_index(drop=True)
    assert len(again) == len(kept)
    assert np.abs(again["pseudorange_rate_mps"] - kept["pseudorange_rate_mps"]).max() < 1e-3


def test_rewrite_drops_emptied_epochs_and_refuses_a_foreign_table(tmp_path: Path) -> None:
    # one epoch is 2 header lines + 14 satellites x 2 lines (RINEX 2 example), or 1 + 10 lines (RINEX 3 example)
    for name, text, epoch_lines in (("v2.05o", _v2_obs(4), 2 + 14 * 2), ("v3.rnx", _v3_obs(4), 1 + 10)):
        src = tmp_path / name
        src.write_text(text)
        table = read_log(src)
        obs = table.observations
        times = list(obs["t_s"].unique())
        dst = tmp_path / f"out_{name}"
        assert rewrite_rinex(src, dst, table, obs[obs["t_s"] != times[1]]).startswith("0 observations changed")
        again = read_log(dst)
        assert list(again.observations["t_s"].unique()) == [times[0], *times[2:]]
        assert len(dst.read_text().splitlines()) == len(text.splitlines()) + 1 - epoch_lines
    foreign = read_log(tmp_path / "v2.05o")
    with pytest.raises(WriterError, match=r"receivers \['SYN'\] are not in this RINEX log"):
        rewrite_rinex(tmp_path / "v3.rnx", tmp_path / "x.rnx", foreign, foreign.observations)
    with pytest.raises(WriterError, match="must not overwrite its source"):
        rewrite_rinex(tmp_path / "v2.05o", tmp_path / "v2.05o", foreign, foreign.observations)


def test_rows_of_a_satellite_the_broadcast_flags_unhealthy_are_said_so(tmp_path: Path) -> None:
    """A real F9P file's G07 carried SV health 63 in its navigation record: its rows were reported as "without a
    valid broadcast ephemeris", which reads as a missing or broken record, not the broadcast's own flag."""
    obs = tmp_path / "flagged.05o"
    shutil.copyfile(_need(OBS_0759), obs)
    lines = NAV_0759.read_text().splitlines()
    end = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
    sick = read_log(obs, topics={"nav": str(NAV_0759)}).observations["sv_id"].value_counts().index[0]
    for i in range(end + 1, len(lines), 8):  # RINEX 2 GPS records: 8 lines, health in line 6's second field
        if int(lines[i][:2]) == int(sick[1:]):
            lines[i + 6] = lines[i + 6][:22] + " 6.300000000000D+01" + lines[i + 6][41:]
    (tmp_path / "flagged.05n").write_text("\n".join(lines) + "\n")
    table = read_log(obs)
    (flag,) = [s for s in table.skipped if s.action == "unhealthy"]
    assert f"GPS rows of satellites the broadcast flags unhealthy ({sick})" in flag.reason
    assert flag.count == int((table.observations["sv_id"] == sick).sum())
    assert table.observations.loc[table.observations["sv_id"] == sick, "sv_x_m"].isna().all()
    assert not any("without a valid broadcast ephemeris" in s.reason for s in table.skipped)


def test_a_time_system_pushed_right_by_a_wider_seconds_field_is_read(tmp_path: Path) -> None:
    """A Hatanaka sample file writes TIME OF FIRST OBS's seconds one character wider than the format: its time
    system sat at columns 50-52, was read as 'GP', and the intact file was refused."""
    lines = _need(OBS_0759).read_text().splitlines()
    k = next(i for i, ln in enumerate(lines) if ln[60:].strip() == "TIME OF FIRST OBS")
    lines[k] = f"{'  2005     4     2     0     0     0.0000000     GPS':<60}TIME OF FIRST OBS"
    (tmp_path / "wide.05o").write_text("\n".join(lines) + "\n")
    wide, plain = read_log(tmp_path / "wide.05o"), read_log(OBS_0759)
    assert wide.t0_ns == plain.t0_ns and wide.observations["t_s"].equals(plain.observations["t_s"])


def _with_lli(text: str, edits: dict[tuple[int, str], str], field: int, first_col: int) -> str:
    """`text` with the LLI digit (column 15 of observation field `field`) set at (epoch, satellite)."""
    epoch, out = -1, []
    for line in text.splitlines(keepends=True):
        if line.startswith(">"):
            epoch += 1
        elif (epoch, line[:3]) in edits:
            col = first_col + 16 * field + 14
            line = line[:col] + edits[(epoch, line[:3])] + line[col + 1 :]
        out.append(line)
    return "".join(out)


def test_carriers_the_receiver_flags_lost_lock_or_half_cycle_are_not_taken_as_continuous(tmp_path: Path) -> None:
    """LLI bit 0 (lost lock since the previous epoch) and bit 1 (half-cycle ambiguity possible) clear the
    carrier: a half-cycle slip (0.095 m on L1) passes the Doppler screen and would read as a rate error.
    Bit 2 (BOC tracking) is no slip; epoch flag 1 (power failure) restarts every carrier."""
    edits = {(1, "G01"): "1", (2, "E02"): "2", (2, "G03"): "4", (3, "G05"): "3"}
    text = _with_lli(_v3_obs(6), edits, field=1, first_col=3)
    lines = text.splitlines(keepends=True)
    k = [i for i, line in enumerate(lines) if line.startswith(">")][4]
    lines[k] = lines[k][:31] + "1" + lines[k][32:]  # epoch 4: power failure since epoch 3
    path = tmp_path / "flags.rnx"
    path.write_text("".join(lines))
    table = read_log(path)
    obs = table.observations.set_index(["t_s", "sv_id"])["carrier_arc_start"]
    cleared = set(obs[obs == 1].index)
    power = {(4.0, sv) for sv in obs.loc[4.0].index}
    assert cleared == {(1.0, "G01"), (2.0, "E02"), (3.0, "G05")} | power
    assert obs.loc[(2.0, "G03")] == 0  # BOC tracking: no slip
    assert table.observations["carrier_phase_cycles"].notna().all()  # every carrier kept as logged
    said = {s.reason.split(" (")[0]: (s.count, s.action) for s in table.skipped if "continuous" in s.reason}
    assert said == {
        "carriers across a loss of lock": (1 + 1 + 10, "flagged"),
        "carriers with a half-cycle ambiguity or slip possible": (1, "flagged"),
    }


def test_rinex2_lli_digits_clear_carriers(tmp_path: Path) -> None:
    text = _v2_obs(3)
    lines = text.splitlines(keepends=True)
    data = [i for i, line in enumerate(lines) if line.startswith(" 05  4  2")]
    g05 = data[1] + 2 + 2 * 4  # epoch 1: two epoch-header lines, then two lines per satellite; G05 is the 5th
    lines[g05] = lines[g05][:30] + "1" + lines[g05][31:]  # L1 is the 2nd field: LLI at column 31
    path = tmp_path / "lli.05o"
    path.write_text("".join(lines))
    obs = read_log(path).observations.set_index(["t_s", "sv_id"])["carrier_arc_start"]
    assert list(obs[obs == 1].index) == [(10.0, "G05")]
