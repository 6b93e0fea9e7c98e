"""u-blox UBX: the real captures read right, messages the captures lack (built with pyubx2), bad input."""

from __future__ import annotations

import json
import math
import re
import struct
from pathlib import Path

import numpy as np
import pandas as pd
import pymap3d
import pytest
from paths import REAL, real_log
from pyubx2 import GET, UBXMessage, UBXReader
from ubx_support import rawx as rawx_message

from readers import read_log, sniff_format
from readers.ubx.frames import split_frames
from readers.ubx.messages import RAWX_MEAS, rawx
from spooflens.cli import main
from spooflens.epoch_table import HOLDS, EpochTable
from spooflens.schema import FixType, SpoofingFlag

UBX_LOGS = REAL / "ubx_receivers"
F9R, F9P = UBX_LOGS / "gpsd_ublox-zed-f9r.log", UBX_LOGS / "gpsd_ublox-zed-f9p_hpg1.11.log"


def _need(path: Path) -> Path:
    return real_log(str(path.relative_to(REAL)))


@pytest.fixture(scope="module")
def f9r() -> EpochTable:
    return read_log(_need(F9R))


@pytest.fixture(scope="module")
def f9p() -> EpochTable:
    return read_log(_need(F9P))


def _gga(path: Path) -> dict[str, tuple[float, float, float]]:
    """GGA sentences of the capture by UTC second, split by hand: (lat, lon, MSL + separation)."""
    out = {}
    for m in re.finditer(rb"\$G[NP]GGA,([^*\r\n]*)\*", path.read_bytes()):
        f = m.group(1).decode().split(",")
        lat = (float(f[1][:2]) + float(f[1][2:]) / 60) * (-1 if f[2] == "S" else 1)
        lon = (float(f[3][:3]) + float(f[3][3:]) / 60) * (-1 if f[4] == "W" else 1)
        out[f[0][:6]] = (lat, lon, float(f[8]) + float(f[10]))
    return out


def test_f9r_nav_pvt_fixes(f9r: EpochTable) -> None:
    assert sniff_format(F9R) == "ubx"
    assert f9r.time_reference == "gps" and f9r.absolute_iso(0.0).startswith("2025-04-11T23:14:08")
    fixes = f9r.fixes
    assert len(fixes) == 30 and np.all(np.diff(fixes["t_s"]) == 1.0)
    first = fixes.iloc[0]
    assert (first["lat_deg"], first["lon_deg"]) == (45.065772, 7.6590613)
    assert first["height_m"] == pytest.approx(304.639)  # mm -> m, above the ellipsoid
    assert (first["h_acc_m"], first["v_acc_m"], first["vel_acc_mps"]) == pytest.approx((0.092, 0.088, 0.196))
    assert first["vel_u_mps"] == pytest.approx(-0.033)  # velD 33 mm/s down
    assert first["sats_used"] == 25 and first["fix_type"] == FixType.RTK_FLOAT  # carrSoln 1
    assert (first["hdop"], first["vdop"]) == (0.82, 1.17)  # NAV-DOP
    assert 20 < first["cn0_mean_dbhz"] < 45  # NAV-SAT
    assert set(fixes["spoofing_flag"]) == {SpoofingFlag.UNKNOWN}  # no NAV-STATUS in this capture
    rf = fixes.dropna(subset=["agc"])
    assert len(rf) == 7  # MON-RF, block 0 (its "compact" second block is cut short)
    assert set(rf["agc"]) == {4914} and set(rf["noise_per_ms"]) == {69} and set(rf["jamming_state"]) == {1}
    assert rf["jamming_indicator"].between(10, 30).all()


def test_f9r_nav_pvt_against_the_nmea_gga_of_the_same_capture(f9r: EpochTable) -> None:
    gga = _gga(F9R)
    checked = 0
    for _, row in f9r.fixes.iterrows():
        stamp = f9r.absolute_iso(row["t_s"])[11:19].replace(":", "")
        lat, lon, h = gga[stamp]
        e, n, u = pymap3d.geodetic2enu(lat, lon, h, row["lat_deg"], row["lon_deg"], row["height_m"])
        assert math.hypot(e, n) < 0.02 and abs(u) < 0.11  # GGA: 1e-5 minutes, altitude and separation to 0.1 m
        checked += 1
    assert checked == 30


def test_f9r_mixed_stream_is_counted(f9r: EpochTable) -> None:
    counts = {s.stream: s.count for s in f9r.skipped}
    assert sum(n for k, n in counts.items() if k.startswith("RTCM3")) == 224
    assert counts["RTCM3 1075"] == 30 and counts["NAV-SIG"] == 30
    assert counts["NMEA"] == 841  # GGA, RMC, VTG, GSA, GSV, GST, ZDA: the same solution again
    assert "FWVER=HPS 1.30" in f9r.metadata["receiver.gpsd_device"]
    assert "ntrip" not in json.dumps(f9r.metadata)  # the header's corrections URL (with a password) stays out
    assert "spoofDetState" in f9r.metadata["enum.spoofing_state"]


def test_f9p_rawx_observations(f9p: EpochTable) -> None:
    obs = f9p.observations
    assert f9p.time_reference == "gps" and f9p.absolute_iso(1.0).startswith("2019-04-12T01:19:0")
    assert obs["t_s"].nunique() == 654
    assert set(obs["sv_id"].str[0]) == {"G", "R", "E", "C"}
    assert obs["pseudorange_m"].between(1.8e7, 4.3e7).all()  # MEO to BeiDou GEO/IGSO
    assert obs[["sv_x_m", "sv_clock_bias_m"]].isna().all().all()
    # no RXM-SFRBX in this capture and no navigation file beside it: every row is counted, GPS with the way out
    assert sum(s.count for s in f9p.skipped if s.action == "no ephemeris") == len(obs)
    assert any("RXM-SFRBX" in s.reason and "--topic nav=" in s.reason for s in f9p.skipped)
    glo = obs[obs["sv_id"].str.startswith("R")]
    k = np.round((glo["carrier_freq_hz"] - 1602e6) / 0.5625e6)
    assert k.between(-7, 6).all()
    # the rate from Doppler against the pseudorange's own change: equal up to the receiver clock drift,
    # which is common to every satellite of an epoch (so removed by the epoch's median)
    wide = obs.pivot_table(index="t_s", columns="sv_id", values=["pseudorange_m", "pseudorange_rate_mps"])
    t = wide.index.to_numpy()
    dpr = np.diff(wide["pseudorange_m"].to_numpy(), axis=0) / np.diff(t)[:, None]
    rate = 0.5 * (wide["pseudorange_rate_mps"].to_numpy()[1:] + wide["pseudorange_rate_mps"].to_numpy()[:-1])
    resid = dpr - rate
    resid -= np.nanmedian(resid, axis=1, keepdims=True)
    assert np.nanmedian(np.abs(resid)) < 0.5  # m/s; a sign or wavelength error would be hundreds


def test_rawx_numpy_decode_equals_pyubx2() -> None:
    frames = [f for f in split_frames(_need(F9P).read_bytes()).ubx if (f.msg_class, f.msg_id) == (2, 0x15)]
    for frame in frames[::60]:
        epoch = rawx(frame)
        head = bytes((2, 0x15)) + len(frame.payload).to_bytes(2, "little") + frame.payload
        ck_a = ck_b = 0
        for b in head:
            ck_a = (ck_a + b) & 0xFF
            ck_b = (ck_b + ck_a) & 0xFF
        msg = UBXReader.parse(b"\xb5\x62" + head + bytes((ck_a, ck_b)))
        assert epoch.gps_s == msg.week * 604800 + msg.rcvTow
        for i, meas in enumerate(epoch.meas, start=1):
            assert meas["prMes"] == getattr(msg, f"prMes_{i:02d}")
            assert meas["cpMes"] == getattr(msg, f"cpMes_{i:02d}")
            assert meas["doMes"] == pytest.approx(getattr(msg, f"doMes_{i:02d}"), rel=1e-7)
            assert (meas["svId"], meas["cno"]) == (getattr(msg, f"svId_{i:02d}"), getattr(msg, f"cno_{i:02d}"))
            assert meas["trkStat"] & 1 == getattr(msg, f"prValid_{i:02d}")


def test_f9p_fixes_come_from_its_nmea(f9p: EpochTable) -> None:
    fixes = f9p.fixes
    assert f9p.receivers() == ["ubx"] and len(fixes) == 655
    first = fixes.iloc[0]
    lat, lon, h = _gga(F9P)["011903"]
    assert (first["lat_deg"], first["lon_deg"], first["height_m"]) == pytest.approx((lat, lon, h))
    # its own description: 45.877591500S 170.500124833E
    e, n, _ = pymap3d.geodetic2enu(first["lat_deg"], first["lon_deg"], 0, -45.8775915, 170.500124833, 0)
    assert math.hypot(e, n) < 1.0


# --- messages the real captures lack, written with pyubx2's own generator --------------------------


def _esf_raw(tag: int, gyro_dps: tuple[float, float, float], accel: tuple[float, float, float]) -> bytes:
    words = []
    raw = (*(g * 4096 for g in gyro_dps), *(a * 1024 for a in accel))  # deg/s * 2^-12, m/s^2 * 2^-10
    for kind, value in zip((14, 13, 5, 16, 17, 18), raw, strict=True):
        words.append(struct.pack("<II", (kind << 24) | (round(value) & 0xFFFFFF), tag))
    return UBXMessage("ESF", "ESF-RAW", GET, payload=b"\x00" * 4 + b"".join(words)).serialize()


def _capture(seconds: int = 6) -> bytes:
    out = [b"# Name: built with pyubx2 for spooflens tests\n"]
    sw, hw = b"EXT CORE 1.00 (test)".ljust(30, b"\0"), b"00190000".ljust(10, b"\0")
    ver = UBXMessage("MON", "MON-VER", GET, swVersion=sw, hwVersion=hw)
    out.append(ver.serialize())
    tick = 39.0625e-6
    for s in range(seconds):
        itow = 186_400_000 + 1000 * s  # Tuesday 2024-03-05 03:46:22 UTC = GPS 03:46:40
        out.append(
            UBXMessage(
                "NAV", "NAV-PVT", GET, iTOW=itow, year=2024, month=3, day=5, hour=3, min=46, second=22 + s,
                validDate=1, validTime=1, fixType=3, gnssFixOk=1, numSV=14, lon=7.5, lat=45.1 + 1e-5 * s,
                height=300_000, hMSL=250_000, hAcc=1500, vAcc=2500, velN=1100, velE=0, velD=0, sAcc=300,
            ).serialize()
        )  # fmt: skip
        status = 1 if s < 3 else 2
        out += [
            UBXMessage("NAV", "NAV-DOP", GET, iTOW=itow, hDOP=0.8, vDOP=1.2).serialize(),
            UBXMessage("NAV", "NAV-STATUS", GET, iTOW=itow, gpsFix=3, gpsFixOk=1, spoofDetState=status).serialize(),
            UBXMessage(
                "SEC", "SEC-SIG", GET, version=1, jamDetEnabled=1, jammingState=2, spfDetEnabled=1, spoofingState=1
            ).serialize(),
            UBXMessage("MON", "MON-HW", GET, noisePerMS=80, agcCnt=5000, jammingState=1, jamInd=12).serialize(),
        ]
        out.append(b"$GNTXT,01,01,02,spooflens test*00\r\n")  # a bad checksum: counted, not NMEA
        for k in range(10):  # 10 Hz IMU, tagged in sensor ticks
            tag = round((100.0 + s + 0.1 * k) / tick)
            out.append(_esf_raw(tag, (0.0, 0.0, 5.0), (0.1, 0.0, -9.81)))
    return b"".join(out)


def test_generated_capture_status_security_hw_version_and_imu(tmp_path: Path) -> None:
    path = tmp_path / "generated.ubx"
    path.write_bytes(_capture())
    table = read_log(path)
    assert table.time_reference == "gps" and table.absolute_iso(0.0).startswith("2024-03-05T03:46:22")
    f = table.fixes
    assert len(f) == 6
    assert list(f["spoofing_state"]) == [1, 1, 1, 2, 2, 2]
    assert list(f["spoofing_flag"]) == [SpoofingFlag.CLEAR] * 3 + [SpoofingFlag.INDICATED] * 3
    assert set(f["jamming_state"]) == {2}  # SEC-SIG wins over MON-HW
    assert set(f["agc"]) == {5000} and set(f["noise_per_ms"]) == {80} and set(f["jamming_indicator"]) == {12}
    assert (f["hdop"].iloc[0], f["vdop"].iloc[0]) == (0.8, 1.2)
    assert f["vel_n_mps"].iloc[0] == pytest.approx(1.1)
    assert table.metadata["receiver.sw_version"] == "EXT CORE 1.00 (test)"
    assert table.metadata["receiver.hw_version"] == "00190000"
    imu = table.imu
    esf = table.stream("imu", "ubx_esf")
    assert len(imu) == 60 and esf is not None and esf.body_frame == "FRD"
    assert table.metadata["imu.time_tag_unit_s"] == "3.90625e-05"  # fitted from the stream
    assert np.allclose(np.diff(imu["t_s"]), 0.1)
    assert imu["wz_radps"].iloc[0] == pytest.approx(math.radians(5.0))
    assert imu["az_mps2"].iloc[0] == pytest.approx(-9.81, abs=1e-3)


def test_corrupt_and_cut_captures_keep_what_they_can(tmp_path: Path) -> None:
    data = bytearray(_capture())
    frames = split_frames(bytes(data))
    victim = [f for f in frames.ubx if (f.msg_class, f.msg_id) == (1, 4)][1]  # the second epoch's NAV-DOP
    data[victim.offset + 9] ^= 0xFF
    data[victim.offset + 4 : victim.offset + 6] = b"\xff\xff"  # and a length running past the end of the file
    data += b"\xb5\x62\x01\x07\x5c\x00" + b"\x00" * 20  # cut inside a last NAV-PVT
    path = tmp_path / "damaged.ubx"
    path.write_bytes(bytes(data) + bytes(range(256)))
    table = read_log(path)
    assert len(table.fixes) == 6 and len(table.imu) == 60  # only the damaged NAV-DOP is gone
    assert np.isnan(table.fixes["hdop"].iloc[1]) and table.fixes["hdop"].iloc[2] == 0.8
    lost = {s.reason for s in table.skipped if s.action == "lost"}
    assert "UBX headers with an impossible length" in lost
    assert any(s.stream == "bytes" for s in table.skipped)


def test_bad_input_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    only_version = tmp_path / "version.ubx"
    only_version.write_bytes(_capture(0))
    # a sound capture of the receiver's version alone: nothing to judge, said (not a refusal)
    assert read_log(only_version).metadata[HOLDS].startswith("no fix, raw observation or IMU sample in the capture")
    assert main(["inspect", str(only_version)]) == 0
    assert "no GNSS data to judge: no fix, raw observation" in capsys.readouterr().out
    cut = tmp_path / "cut.ubx"
    cut.write_bytes(_need(F9R).read_bytes()[:60_000])
    table = read_log(cut)
    assert 0 < len(table.fixes) < 30


def test_inspect_and_analyze_real_captures(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(_need(F9P))]) == 0
    out = capsys.readouterr().out
    assert "RXM-RAWX" in out and "observations" in out
    summary = tmp_path / "f9r.json"
    assert main(["analyze", str(_need(F9R)), "-o", str(tmp_path / "f9r.rrd"), "--json", str(summary), "--quiet"]) == 0
    assert json.loads(summary.read_text())["verdict"]["spoofed"] is False
    assert RAWX_MEAS.itemsize == 32


def test_a_capture_whose_fixes_come_from_its_nmea_lists_one_fix_stream_the_nmeas() -> None:
    """The ZED-F9P capture carries RXM-RAWX and no UBX position message: its fixes are its NMEA's, and the
    streams say so once (no second, empty UBX fix stream counting the same fixes)."""
    table = read_log(_need(F9P))
    fix_streams = [s for s in table.streams if s.role == "fix"]
    assert [(s.topic, s.count) for s in fix_streams] == [("NMEA in the UBX stream", len(table.fixes))]


def test_rawx_carriers_the_receiver_says_are_not_continuous_are_cleared(tmp_path: Path) -> None:
    """trkStat halfCyc 0 (half-cycle unresolved), subHalfCyc toggling (half a cycle taken off the phase)
    and a lock time that restarted: the carrier is not taken as continuous with the previous epoch. A
    half-cycle slip on L1 (0.095 m) passes the Doppler screen and would read as a 0.095 m/s rate error."""
    week_s = 2304 * 604_800 + 186_400  # the NAV-PVT epochs of _capture(): 2024-03-05
    trk = {"G01": [7] * 5, "G02": [7, 3, 7, 7, 7], "G03": [7, 7, 15, 15, 15], "G04": [7] * 5}
    lock = {"G04": [64500, 64500, 64500, 300, 1300]}
    raw = b""
    for s in range(5):
        rows = pd.DataFrame(
            {
                "sv_id": list(trk),
                "pseudorange_m": [2.1e7 + 1e5 * k for k in range(4)],
                "carrier_phase_cycles": [1.1e8 + 10.0 * s + k for k in range(4)],
                "doppler_hz": -500.0,
                "cn0_dbhz": 40.0,
                "trk_stat": [trk[sv][s] for sv in trk],
                "locktime_ms": [lock.get(sv, [64500] * 5)[s] for sv in trk],
            }
        )
        raw += rawx_message(week_s + s, rows)
    path = tmp_path / "slips.ubx"
    path.write_bytes(_capture(5) + raw)
    table = read_log(path)
    obs = table.observations.set_index(["t_s", "sv_id"])["carrier_arc_start"]
    assert len(obs) == 20
    assert set(obs[obs == 1].index) == {(1.0, "G02"), (2.0, "G03"), (3.0, "G04")}
    said = {s.reason.split(" (")[0]: s.count for s in table.skipped if "continuous" in s.reason}
    assert said == {
        "carriers across a loss of lock": 1,
        "carriers with an unresolved half-cycle ambiguity": 1,
        "carriers whose half-cycle correction changed since the previous epoch": 1,
    }
    assert all(s.action == "flagged" for s in table.skipped if "continuous" in s.reason)
