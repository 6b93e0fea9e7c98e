"""Galileo (and BeiDou) broadcast orbits: RINEX 3 records, I/NAV pages in a u-blox capture, RTCM3
orbits, the orbit with each system's own constants, checked on a real capture; and what they are for:
a GPS-only spoofer before a GPS + Galileo receiver, which RAIM sees only when the Galileo satellites
have orbits."""

from __future__ import annotations

import copy
import math
from datetime import timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from paths import real_log
from ubx_support import capture_from_rinex, inav_page, inav_words, sfrbx

from readers import read_log
from readers.inav import InavDecoder
from readers.rinex import GPS_EPOCH, read_rinex_nav_file
from readers.rtcm_ephemeris import rtcm_ephemerides
from readers.ubx.frames import split_frames
from spooflens.attacks import apply_attack, parse_attack
from spooflens.attacks.spec import AttackError
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import geodetic_to_ecef
from spooflens.gnss.ephemeris import (
    GM_GALILEO,
    GM_GPS,
    OMEGA_E_GPS,
    GpsEphemerides,
    galileo_constellation,
    satellite_states,
    synthetic_constellation,
)
from spooflens.gnss.geometry import azimuth_elevation
from spooflens.pipeline.run import analyze_table
from spooflens.simulation.observations import ObservationNoise, simulate_observations

WEEK_S = 604_800
T0 = 1_400_000_160.0  # GPS s: toe and toc are whole minutes (I/NAV) and multiples of 16 s (LNAV)
WEEK, TOE = divmod(T0, WEEK_S)
REC: dict[str, Any] = {  # an E11-like I/NAV record
    "sv_id": "E11", "week": int(WEEK), "toe_sow": TOE, "toc_s": T0, "af0": -5.123e-4, "af1": -8.1e-12,
    "af2": 0.0, "tgd": -2.3283064365e-9, "sqrt_a": 5440.6123, "e": 3.1e-4, "m0": 1.234, "delta_n": 2.9e-9,
    "omega": -0.789, "i0": 0.9775, "idot": -3.1e-10, "omega0": 2.345, "omega_dot": -5.6e-9, "cuc": -2.5e-6,
    "cus": 7.9e-6, "crc": 180.5, "crs": -48.2, "cic": 3.7e-8, "cis": -1.1e-8, "health": 0, "iode": 87,
}  # fmt: skip
BGD_E5A = -2.0954757929e-9
# half an LSB of each I/NAV field (Galileo OS SIS ICD Tables 60-62)
QUANTUM = {
    "af0": 2.0**-34, "af1": 2.0**-46, "af2": 2.0**-59, "tgd": 2.0**-32, "crs": 2.0**-5, "crc": 2.0**-5,
    "cuc": 2.0**-29, "cus": 2.0**-29, "cic": 2.0**-29, "cis": 2.0**-29, "e": 2.0**-33, "sqrt_a": 2.0**-19,
    "m0": np.pi * 2.0**-31, "omega0": np.pi * 2.0**-31, "i0": np.pi * 2.0**-31, "omega": np.pi * 2.0**-31,
    "delta_n": np.pi * 2.0**-43, "omega_dot": np.pi * 2.0**-43, "idot": np.pi * 2.0**-43,
}  # fmt: skip
ANGLES = ("m0", "omega0", "omega")
BOSTON = geodetic_to_ecef(42.37, -71.1, 30.0)


def _d19(v: float) -> str:
    return f"{v:19.12E}".replace("E", "D")


def _record_text(rec: dict[str, Any], tail: list[tuple[float, ...]]) -> str:
    """One RINEX 3.04 navigation record: the epoch line, the four orbit lines every system shares (GPS
    layout), then the system's own last lines `tail`."""
    t = GPS_EPOCH + timedelta(seconds=float(rec["toc_s"]))
    f = {k: float(v) for k, v in rec.items() if k != "sv_id"}
    rows = [
        (f["iode"], f["crs"], f["delta_n"], f["m0"]),
        (f["cuc"], f["e"], f["cus"], f["sqrt_a"]),
        (f["toe_sow"], f["cic"], f["omega0"], f["cis"]),
        (f["i0"], f["crc"], f["omega"], f["omega_dot"]),
        *tail,
    ]
    head = f"{rec['sv_id']} {t:%Y %m %d %H %M %S}" + "".join(_d19(f[k]) for k in ("af0", "af1", "af2"))
    return head + "\n" + "".join("    " + "".join(_d19(v) for v in row) + "\n" for row in rows)


def _rinex_record(rec: dict[str, Any], sources: int, health: int, bgd_e5a: float = BGD_E5A) -> str:
    """One Galileo record (Table A8): data sources, SISA, health, the two BGDs, transmission time."""
    tail = [
        (float(rec["idot"]), float(sources), float(rec["week"]), 0.0),
        (3.12, float(health), bgd_e5a, float(rec["tgd"])),
        (float(rec["toe_sow"]) - 30.0,),
    ]
    return _record_text(rec, tail)


def _nav_file(path: Path, records: list[str]) -> Path:
    header = [
        f"{'     3.04':<20}{'N: GNSS NAV DATA':<20}{'E: GALILEO':<20}RINEX VERSION / TYPE",
        f"{'':60}END OF HEADER",
    ]
    path.write_text("\n".join(header) + "\n" + "".join(records))
    return path


def test_a_rinex3_galileo_record_is_read_with_its_own_fields(tmp_path: Path) -> None:
    e12 = REC | {"sv_id": "E12", "m0": 2.0}
    e13 = REC | {"sv_id": "E13", "m0": 2.5}
    nav = read_rinex_nav_file(
        _nav_file(
            tmp_path / "BRDC_EN.rnx",
            [
                _rinex_record(REC, 517, 0b111000000),  # I/NAV E1-B + E5b, clock for E5b/E1; E5b unhealthy
                _rinex_record(REC | {"sv_id": "E11", "m0": 1.0}, 258, 0),  # F/NAV: the same orbit on E5a
                _rinex_record(e12, 513, 0b010),  # I/NAV, E1-B signal out of service
                _rinex_record(e13, 1 | 256, 0, bgd_e5a=-4e-9),  # I/NAV with the E5a/E1 clock
            ],
        )
    )
    eph = nav.ephemerides
    assert eph.sv_id.tolist() == ["E11", "E12", "E13"]
    for key, value in REC.items():
        if key == "sv_id":
            continue
        assert getattr(eph, key)[0].item() == pytest.approx(value, rel=1e-11, abs=1e-20), key
    # an E1 user corrects the I/NAV clock with BGD(E1, E5b), an E5a/E1 clock with BGD(E1, E5a)
    assert eph.tgd.tolist() == [pytest.approx(REC["tgd"]), pytest.approx(REC["tgd"]), pytest.approx(-4e-9)]
    # only the E1-B bits speak for an E1 signal: E11's E5b trouble does not count, E12's E1-B does
    assert eph.health.tolist() == [0, 0b010, 0]
    assert [(s.reason, s.count) for s in nav.skipped] == [
        ("Galileo F/NAV records (the I/NAV records carry the same orbits)", 1)
    ]
    st = satellite_states(eph, np.array(["E11", "E12", "E13"]), np.full(3, T0 + 600.0))
    assert st.valid.tolist() == [True, False, True]
    assert np.linalg.norm(st.pos_m[0]) == pytest.approx(29_600e3, rel=2e-3)


def test_galileo_orbits_move_with_galileos_gravitational_constant() -> None:
    eph = galileo_constellation(T0)
    sv = np.array(eph.satellites())
    assert len(sv) == 24 and sv[0] == "E01"
    st = satellite_states(eph, sv, np.full(len(sv), T0 + 7200.0))
    r = st.pos_m
    speed = np.linalg.norm(st.vel_mps + np.cross([0.0, 0.0, OMEGA_E_GPS], r), axis=1)
    a = float(eph.sqrt_a[0] ** 2)
    np.testing.assert_allclose(np.linalg.norm(r, axis=1), a, rtol=1e-9)
    np.testing.assert_allclose(speed, np.sqrt(GM_GALILEO / a), rtol=1e-9)
    # GPS's constant would put them 0.27 mm/s faster: far above what the check resolves
    assert np.all(np.abs(speed / np.sqrt(GM_GPS / a) - 1.0) > 5e-8)


def _records(eph: GpsEphemerides) -> list[dict[str, Any]]:
    return [{k: r[k] for k in ("sv_id", "week", "toe_sow", "toc_s", "health", "iode", *QUANTUM)} for r in eph.records()]


def _payload(sv: int, words: list[int]) -> bytes:
    return sfrbx(sv, words, 2)[6:-2]


def test_inav_pages_decode_to_the_broadcast_record() -> None:
    records = [REC | {"sv_id": "E30"}, *_records(galileo_constellation(T0, rng=np.random.default_rng(4)))]
    decoder = InavDecoder()
    for rec in records:
        sv = int(str(rec["sv_id"])[1:])
        for word in inav_words(rec, T0 - 600.0):
            decoder.add(_payload(sv, inav_page(word)), T0 - 597.0)
    got = {r["sv_id"]: r for r in decoder.records()}
    assert sorted(got) == sorted(str(r["sv_id"]) for r in records)
    for rec in records:
        out = got[rec["sv_id"]]
        assert (out["week"], out["toe_sow"], out["toc_s"], out["iode"], out["health"]) == (
            rec["week"], rec["toe_sow"], rec["toc_s"], rec["iode"], 0
        )  # fmt: skip
        for key, q in QUANTUM.items():
            error = float(out[key]) - float(rec[key])
            if key in ANGLES:  # sent in semicircles, [-1, 1): the synthetic orbits' nodes are not wrapped
                error = (error + np.pi) % (2 * np.pi) - np.pi
            assert abs(error) <= 0.51 * q, key
        # the page came 2 s after its time of week began, the receiver logged it 3 s after
        assert float(out["message_offset_s"]) == pytest.approx(-1.0)
        assert float(out["received_s"]) == T0 - 597.0
    decoded = GpsEphemerides.from_records(decoder.records())
    truth = GpsEphemerides.from_records([r | {"max_age_s": 7200.0} for r in records])
    names = np.array(decoded.satellites())
    a = satellite_states(decoded, names, np.full(len(names), T0 + 900.0))
    b = satellite_states(truth, names, np.full(len(names), T0 + 900.0))
    assert np.max(np.linalg.norm(a.pos_m - b.pos_m, axis=1)) < 0.3  # the fields' own quantisation
    assert np.max(np.abs(a.clock_bias_m - b.clock_bias_m)) < 0.01


def _android_page(page_words: list[int]) -> bytes:
    """The same page as Android's TYPE_GAL_I carries it: both 114-bit parts, MSB first, in 29 bytes."""
    page = 0
    for w in page_words:
        page = (page << 32) | w
    even, odd = page >> (128 + 14), (page >> 14) & ((1 << 114) - 1)
    return (((even << 114) | odd) << 4).to_bytes(29, "big")


def test_android_gal_i_messages_decode_to_the_same_record() -> None:
    via_ubx, via_android = InavDecoder(), InavDecoder()
    for word in inav_words(REC, T0):
        via_ubx.add(_payload(11, inav_page(word)), T0 + 3.0)
        via_android.add_android(11, _android_page(inav_page(word)), T0 + 3.0)
    assert via_android.records() == via_ubx.records() and len(via_ubx.records()) == 1
    via_android.add_android(11, b"\x00" * 28, T0)
    assert via_android.counts["not Galileo I/NAV"] == 1


def test_a_damaged_page_fails_its_crc_and_never_becomes_an_orbit() -> None:
    decoder = InavDecoder()
    words = inav_words(REC, T0)
    pages = [inav_page(w) for w in words]
    damaged = list(pages[1])
    damaged[2] ^= 1 << 7  # one bit of word 2's orbit
    for page in (pages[0], damaged, *pages[2:]):
        decoder.add(_payload(11, page), T0)
    decoder.add(_payload(11, inav_page(words[0], alert=True)), T0)
    decoder.add(_payload(12, pages[3]), T0)  # word 4 names E11: not E12's
    assert decoder.records() == []
    assert decoder.counts["CRC failed"] == 1 and decoder.counts["alert page"] == 1
    assert decoder.counts["word 4 of another satellite"] == 1
    assert [s.reason for s in decoder.dropped("RXM-SFRBX")] == [
        "Galileo I/NAV pages dropped: CRC failed",
        "Galileo I/NAV pages dropped: word 4 of another satellite",
    ]
    decoder.add(_payload(11, pages[1]), T0)  # the page again, undamaged
    assert len(decoder.records()) == 1


def _static_capture(tmp_path: Path, galileo_orbits: bool = True) -> Path:
    """A static GPS + Galileo u-blox capture of 300 s (RAWX and SFRBX), simulated from the two
    constellations; without `galileo_orbits` its Galileo I/NAV pages are left out."""
    rng = np.random.default_rng(7)
    gps = synthetic_constellation(T0, rng=rng)
    gal = galileo_constellation(T0, rng=rng)
    eph = GpsEphemerides.combined([gps, gal])
    t = np.arange(300.0)
    rx = np.repeat(BOSTON[None], len(t), axis=0)
    obs = simulate_observations("ubx", t, T0 + t, rx, np.zeros_like(rx), eph, ObservationNoise(), rng)
    assert {"G", "E"} <= set(obs["sv_id"].str[0])
    records = _records(gps) + (_records(gal) if galileo_orbits else [])
    path = tmp_path / ("gps_galileo.ubx" if galileo_orbits else "gps_only_orbits.ubx")
    path.write_bytes(capture_from_rinex(obs, T0, [r | {"max_age_s": math.inf} for r in records], None))
    return path


def test_a_capture_gives_its_galileo_satellites_their_orbits(tmp_path: Path) -> None:
    table = read_log(_static_capture(tmp_path))
    obs = table.observations
    gal = obs[obs["sv_id"].str.startswith("E")]
    assert len(gal) > 1000 and np.isfinite(gal["sv_x_m"].to_numpy(float)).all()
    assert not [s for s in table.skipped if "Galileo" in s.reason]
    radius = np.linalg.norm(gal[["sv_x_m", "sv_y_m", "sv_z_m"]].to_numpy(float), axis=1)
    np.testing.assert_allclose(radius, 29_600_318.0, rtol=1e-6)
    eph = table.ephemerides
    assert eph is not None and {s[0] for s in eph.satellites()} == {"G", "E"}


def _raim_alarms(table: EpochTable) -> list[tuple[float, float]]:
    analysis = analyze_table(table)
    (raim,) = [r for r in analysis.results if r.name == "raim"]
    assert raim.ran and not raim.advisory
    return [(a.start_s, a.end_s) for a in raim.alarms]


def test_a_gps_only_spoofer_is_seen_by_raim_only_with_the_galileo_orbits(tmp_path: Path) -> None:
    """The open SDR spoofers transmit GPS alone: every GPS pseudorange says the receiver is elsewhere,
    consistently, so GPS-only RAIM has nothing to find; the real Galileo satellites disagree with them."""
    attack = parse_attack("ramp:rate=3,systems=G,start=150")
    with_galileo = read_log(_static_capture(tmp_path))
    assert _raim_alarms(with_galileo) == []
    spoofed, truth = apply_attack(with_galileo, attack)
    assert truth.satellites and all(s.startswith("G") for s in truth.satellites)
    alarms = _raim_alarms(spoofed)
    assert alarms and 150.0 <= alarms[0][0] <= 160.0 and alarms[-1][1] >= 290.0
    gps_orbits_only, _ = apply_attack(read_log(_static_capture(tmp_path, galileo_orbits=False)), attack)
    assert _raim_alarms(gps_orbits_only) == []


def test_systems_needs_pseudoranges_of_that_system(tmp_path: Path) -> None:
    table = read_log(_static_capture(tmp_path))
    with pytest.raises(AttackError, match="no satellite of systems 'C'"):
        apply_attack(table, parse_attack("step:offset=100,systems=C,start=10"))
    no_raw = copy.copy(table)
    no_raw.observations = table.observations.iloc[:0]
    with pytest.raises(AttackError, match="acts on raw pseudoranges"):
        apply_attack(no_raw, parse_attack("step:offset=100,systems=G,start=10"))


# --- real data: a u-blox ZED-F9R fed RTCM3 corrections (gpsd's regression capture, Turin 2025) ---------------


def test_real_rtcm_orbits_put_the_satellites_where_the_receiver_saw_them() -> None:
    """The base station's GPS (1019), BeiDou (1042) and Galileo I/NAV (1046) orbits in a real capture,
    through our orbit model, against the elevation and azimuth the receiver reported for each satellite
    (NAV-SAT, whole degrees) from its own decoding: within a degree and a half. A week off, a wrong
    constant, the GPS scale on Galileo's angles, BeiDou's 14 s or its geostationary frame (C02, C05)
    wrong would put them degrees to tens of degrees away."""
    path = real_log("ubx_receivers/gpsd_ublox-zed-f9r.log")
    table = read_log(path)
    origin = float(np.asarray(table.gps_seconds(0.0)).reshape(-1)[0])
    frames = split_frames(path.read_bytes())
    records, skipped = rtcm_ephemerides(frames.rtcm_ephemerides, origin)
    assert [(s.reason.split(":")[0], s.count) for s in skipped] == [("1045", 15)]
    eph = GpsEphemerides.from_records(records)
    assert {s[0] for s in eph.satellites()} == {"G", "E", "C"} and len(eph.satellites()) == 53
    sat = table.satellites[table.satellites["sv_id"].str[0].isin(["G", "E", "C"])]
    fix = table.fixes.iloc[0]
    rx = geodetic_to_ecef(float(fix["lat_deg"]), float(fix["lon_deg"]), float(fix["height_m"]))
    st = satellite_states(eph, sat["sv_id"].to_numpy(str), origin + sat["t_s"].to_numpy(float))
    # every GPS and Galileo satellite it saw has an orbit in the stream, every BeiDou one but C60
    assert set(sat["sv_id"][~st.valid]) == {"C60"}
    seen = sat[st.valid]
    assert {"C02", "C05"} <= set(seen["sv_id"]) and len(set(seen["sv_id"])) == 36
    az, el = azimuth_elevation(st.pos_m[st.valid], np.broadcast_to(rx, (int(st.valid.sum()), 3)))
    reported_el = seen["elevation_deg"].to_numpy(float)
    d_el = np.degrees(el) - reported_el
    d_az = (np.degrees(az) - seen["azimuth_deg"].to_numpy(float) + 180.0) % 360.0 - 180.0
    assert np.abs(d_el).max() < 1.5
    assert np.abs(d_az[reported_el < 70.0]).max() < 1.5  # near the zenith a degree of azimuth is nothing


def test_a_rinex_beidou_record_and_the_rtcm_one_give_the_same_orbit(tmp_path: Path) -> None:
    """A real BeiDou record (the geostationary C02, from the capture's RTCM3 1042) written as RINEX 3
    (BDT calendar and week, as RINEX holds them) reads back as the same orbit on the GPS time scale."""
    path = real_log("ubx_receivers/gpsd_ublox-zed-f9r.log")
    origin = float(np.asarray(read_log(path).gps_seconds(0.0)).reshape(-1)[0])
    records, _ = rtcm_ephemerides(split_frames(path.read_bytes()).rtcm_ephemerides, origin)
    rec = next(r for r in records if r["sv_id"] == "C02")
    bdt = dict(rec)  # back to BeiDou time, as RINEX writes it
    bdt["toc_s"] = float(rec["toc_s"]) - 14.0
    bdt["toe_sow"] = float(rec["toe_sow"]) - 14.0
    bdt["week"] = int(rec["week"]) - 1356
    tail = [
        (float(bdt["idot"]), 0.0, float(bdt["week"]), 0.0),
        (2.0, float(bdt["health"]), float(bdt["tgd"]), -1.38e-8),  # SatH1, TGD1, TGD2
        (float(bdt["toe_sow"]) - 60.0, 1.0),  # transmission time, AODC
    ]
    text = _record_text(bdt, tail)
    header = f"{'     3.04':<20}{'N: GNSS NAV DATA':<20}{'C: BDS':<20}RINEX VERSION / TYPE\n{'':60}END OF HEADER\n"
    (tmp_path / "BRDC_CN.rnx").write_text(header + text)
    nav = read_rinex_nav_file(tmp_path / "BRDC_CN.rnx").ephemerides
    assert (nav.week[0], nav.toe_sow[0], nav.toc_s[0]) == (rec["week"], rec["toe_sow"], rec["toc_s"])
    rtcm = GpsEphemerides.from_records([rec])
    when = np.full(1, origin + 20.0)
    a, b = satellite_states(nav, ["C02"], when), satellite_states(rtcm, ["C02"], when)
    assert np.linalg.norm(a.pos_m - b.pos_m) < 1e-3 and abs(a.clock_bias_m[0] - b.clock_bias_m[0]) < 1e-3
    assert 42_000e3 < np.linalg.norm(a.pos_m) < 42_300e3  # geostationary


def test_a_capture_with_rtcm_orbits_gives_its_raw_observations_satellite_states(tmp_path: Path) -> None:
    """RAWX and the RTCM3 1019/1042/1046 messages a rover was fed, no subframes: its GPS, Galileo and
    BeiDou rows get satellite states from the correction stream's orbits."""
    real = real_log("ubx_receivers/gpsd_ublox-zed-f9r.log")
    rtcm = b"".join(split_frames(real.read_bytes()).rtcm_ephemerides)
    origin = float(np.asarray(read_log(real).gps_seconds(0.0)).reshape(-1)[0])
    rng = np.random.default_rng(2)
    records, _ = rtcm_ephemerides(split_frames(rtcm).rtcm_ephemerides, origin)
    eph = GpsEphemerides.from_records(records)
    t = np.arange(60.0)
    turin = geodetic_to_ecef(45.0658, 7.6591, 304.6)
    rx = np.repeat(turin[None], len(t), axis=0)
    obs = simulate_observations("ubx", t, origin + t, rx, np.zeros_like(rx), eph, ObservationNoise(), rng)
    path = tmp_path / "rover.ubx"
    path.write_bytes(rtcm + capture_from_rinex(obs, origin, [], None))
    table = read_log(path)
    got = table.observations
    assert {"G", "E", "C"} <= set(got["sv_id"].str[0])
    assert np.isfinite(got["sv_x_m"].to_numpy(float)).all()
    (nav,) = [s for s in table.streams if s.role == "nav"]
    assert nav.msgtype == "RTCM3 1019/1042/1046 (GPS, Galileo, BeiDou)"
    assert table.ephemerides is not None and np.isnan(table.ephemerides.received_s).all()
