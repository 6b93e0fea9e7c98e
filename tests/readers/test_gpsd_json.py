"""gpsd JSON reports (gpspipe -w): logs built here from a known drive (300 s north at 10 m/s, 1 Hz TPV and
SKY with 10 satellites), and gpsd's own passthrough test log from ../shared/real."""

from __future__ import annotations

import json
import math
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from paths import real_log

from readers import read_log, sniff_format
from spooflens.cli import main
from spooflens.errors import UnsupportedFormatError
from spooflens.schema import FixType

T0 = datetime(2024, 5, 1, 12, 0, 0, tzinfo=UTC)
LAT0, LON0 = 48.1, 11.5
EARTH_M = 6_371_000.0
# (gnssid, svid, elevation, azimuth, C/N0); the last one low, weak and not used
SATS = [(0, 2, 20, 0, 30), (0, 5, 25, 37, 31), (2, 7, 30, 74, 32), (6, 12, 35, 111, 33), (0, 15, 40, 148, 34)]
SATS += [(0, 18, 45, 185, 35), (3, 21, 50, 222, 36), (0, 24, 55, 259, 37), (1, 123, 60, 296, 38), (0, 30, 6, 333, 21)]
SV_IDS = ["G02", "G05", "E07", "R12", "G15", "G18", "C21", "G24", "S23", "G30"]


def _line(obj: dict[str, Any]) -> str:
    return json.dumps(obj, separators=(",", ":"))


def preamble(device: str = "/dev/ttyACM0") -> list[str]:
    dev = {"class": "DEVICE", "path": device, "driver": "u-blox", "subtype": "SW ROM CORE 3.01,HW 00080000"}
    return [
        _line({"class": "VERSION", "release": "3.25", "rev": "3.25", "proto_major": 3, "proto_minor": 15}),
        _line({"class": "DEVICES", "devices": [dev]}),
        _line({"class": "WATCH", "enable": True, "json": True}),
    ]


def tpv(i: int, device: str = "/dev/ttyACM0", **fields: Any) -> dict[str, Any]:
    t = T0 + timedelta(seconds=i)
    out: dict[str, Any] = {
        "class": "TPV",
        "device": device,
        "mode": 3,
        "time": t.strftime("%Y-%m-%dT%H:%M:%S.000Z"),
        "lat": round(LAT0 + math.degrees(10.0 * i / EARTH_M), 9),
        "lon": LON0,
        "altHAE": 600.0,
        "altMSL": 552.5,
        "geoidSep": 47.5,
        "epx": 3.1,
        "epy": 3.1,
        "epv": 5.0,
        "eph": 4.0,
        "track": 0.0,
        "speed": 10.0,
        "climb": 0.0,
        "velN": 10.0,
        "velE": 0.0,
        "velD": 0.0,
        "eps": 0.5,
        "leapseconds": 18,
    }
    out.update(fields)
    return {k: v for k, v in out.items() if v is not None}


def sky(i: int, device: str = "/dev/ttyACM0") -> dict[str, Any]:
    sats = [
        {"PRN": s, "gnssid": g, "svid": s, "el": el, "az": az, "ss": ss, "used": k < 9, "health": 1}
        for k, (g, s, el, az, ss) in enumerate(SATS)
    ]
    t = (T0 + timedelta(seconds=i)).strftime("%Y-%m-%dT%H:%M:%S.000Z")
    return {"class": "SKY", "device": device, "time": t, "hdop": 0.9, "vdop": 1.2, "uSat": 9, "satellites": sats}


def drive(n: int = 300, device: str = "/dev/ttyACM0") -> list[str]:
    lines = preamble(device)
    for i in range(n):
        lines += [_line(tpv(i, device)), _line(sky(i, device))]
    return lines


def write(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_drive_is_read_whole(tmp_path: Path) -> None:
    table = read_log(write(tmp_path / "drive.json", drive()))
    assert table.format == "gpsd_json" and table.time_reference == "unix"
    fixes = table.fixes
    assert len(fixes) == 300 and table.receivers() == ["/dev/ttyACM0"]
    assert table.absolute_iso(0.0).startswith("2024-05-01T12:00:00")
    assert np.allclose(fixes["t_s"], np.arange(300.0))
    north = np.radians(fixes["lat_deg"] - LAT0) * EARTH_M
    assert np.allclose(north, 10.0 * np.arange(300), atol=1e-3) and np.allclose(fixes["lon_deg"], LON0)
    assert np.allclose(fixes["height_m"], 600.0)  # altHAE
    assert np.allclose(fixes["vel_n_mps"], 10.0) and np.allclose(fixes[["vel_e_mps", "vel_u_mps"]], 0.0)
    assert np.allclose(fixes["h_acc_m"], 4.0) and np.allclose(fixes["v_acc_m"], 5.0)
    assert np.allclose(fixes["vel_acc_mps"], 0.5)
    assert (fixes["fix_type"] == FixType.FIX_3D).all()
    assert np.allclose(fixes["hdop"], 0.9) and np.allclose(fixes["vdop"], 1.2) and np.allclose(fixes["sats_used"], 9)
    assert np.allclose(fixes["cn0_mean_dbhz"], np.mean([s[4] for s in SATS]))
    sats = table.satellites
    assert len(sats) == 3000
    first = sats[sats["t_s"] == 0.0].set_index("sv_id")
    assert list(first.index) == SV_IDS
    assert first.loc["R12", "elevation_deg"] == 35 and first.loc["R12", "azimuth_deg"] == 111
    assert first.loc["G30", "cn0_dbhz"] == 21 and first.loc["G30", "used"] == 0 and first.loc["G02", "used"] == 1
    assert (first["healthy"] == 1).all()
    meta = table.metadata
    assert meta["gpsd.release"] == "3.25" and meta["receiver./dev/ttyACM0"].startswith("u-blox SW ROM CORE 3.01")
    assert "certainty" in meta["accuracy"] and "not scaled" in meta["accuracy"]
    assert meta["time_source"] == "gnss" and "no other clock" in meta["clock"]
    assert meta["height"].startswith("altHAE")
    assert not [s for s in table.skipped if s.action == "lost"]


def test_heights_and_velocities_from_older_fields(tmp_path: Path) -> None:
    lines = preamble()
    for i in range(20):  # gpsd before 3.20: alt (MSL), no velN/E/D: speed, track, climb
        lines.append(
            _line(tpv(i, altHAE=None, altMSL=None, alt=552.5, velN=None, velE=None, velD=None, track=90.0, climb=1.0))
        )
    for i in range(20, 30):  # and no geoidSep at all
        lines.append(_line(tpv(i, altHAE=None, altMSL=520.0, geoidSep=None, eph=None, epx=3.0, epy=4.0)))
    table = read_log(write(tmp_path / "old.json", lines))
    f = table.fixes
    assert np.allclose(f["height_m"][:20], 600.0) and np.allclose(f["height_m"][20:], 520.0)
    assert np.allclose(f["vel_e_mps"][:20], 10.0) and np.allclose(f["vel_n_mps"][:20], 0.0, atol=1e-9)
    assert np.allclose(f["vel_u_mps"][:20], 1.0)
    assert np.allclose(f["h_acc_m"][20:], math.sqrt(12.5))
    assert "altMSL + geoidSep" in table.metadata["height"]
    assert any(s.action == "repaired" and "MSL altitude taken" in s.reason and s.count == 10 for s in table.skipped)


def test_fix_status_and_no_fix(tmp_path: Path) -> None:
    lines = [*preamble(), _line(tpv(0, mode=1)), _line(tpv(1, status=2)), _line(tpv(2, status=3))]
    lines += [_line(tpv(3, status=4)), _line(tpv(4, mode=2, altHAE=None, altMSL=None)), _line(tpv(5, status=8))]
    table = read_log(write(tmp_path / "status.json", lines))
    kinds = list(table.fixes["fix_type"])
    assert kinds == [FixType.DGNSS, FixType.RTK_FIXED, FixType.RTK_FLOAT, FixType.FIX_2D, FixType.UNKNOWN]
    assert np.allclose(table.fixes["height_m"], 600.0)  # the 2D fix: the last known height, listed
    assert any("mode 0/1" in s.reason and s.count == 1 for s in table.skipped)
    assert any("last known height" in s.reason for s in table.skipped)


def test_two_devices_are_two_receivers(tmp_path: Path) -> None:
    a, b = "/dev/ttyACM0", "/dev/ttyUSB1"
    lines = preamble(a) + preamble(b)[1:2]
    for i in range(60):
        lines += [_line(tpv(i, a)), _line(tpv(i, b, lon=LON0 + 1e-5)), _line(sky(i, a)), _line(sky(i, b))]
    table = read_log(write(tmp_path / "two.json", lines))
    assert table.receivers() == [a, b]
    assert len(table.fixes_of(a)) == 60 and len(table.fixes_of(b)) == 60
    assert np.allclose(table.fixes_of(b)["lon_deg"], LON0 + 1e-5)
    assert set(table.satellites["receiver_id"]) == {a, b}
    assert "receiver./dev/ttyUSB1" in table.metadata


@pytest.mark.parametrize("style", ["u", "uu", "Z"])
def test_host_time_prefixes_are_the_logger_clock(tmp_path: Path, style: str) -> None:
    lines = preamble()
    for i in range(60):
        late = 0.2 + (5.0 if i >= 30 else 0.0)  # the receiver's time steps 5 s back against the host at 30 s
        host = T0 + timedelta(seconds=i + late)
        stamp = {
            "u": host.strftime("%Y-%m-%d %H:%M:%S.%f"),
            "uu": f"{host.timestamp():.6f}",
            "Z": host.strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z",
        }[style]
        lines += [f"{stamp}: {_line(tpv(i))}", f"{stamp}: {_line(sky(i))}"]
    table = read_log(write(tmp_path / f"{style}.json", lines))
    assert table.metadata["time_source"] == "logger" and table.metadata["time_offset.monotonic"] == "no"
    assert table.absolute_iso(0.0).startswith("2024-05-01T12:00:00.2")
    offset = table.fixes["time_offset_s"].to_numpy()
    assert np.allclose(offset[:30] - offset[0], 0.0, atol=1e-5)
    assert np.allclose(offset[30:] - offset[0], -5.0, atol=1e-5)
    assert len(table.satellites) == 600


def test_damaged_lines_are_counted_never_a_traceback(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    lines = drive(60)
    lines[10] = "this is no JSON at all"  # a SKY line (TPV lines are 3 + 2i)
    lines[11] = '{"class":"TPV","device":"/dev/ttyACM0","mode":3,"time":"2024-05-01T12:00:04.000Z","lat":'  # cut
    lines[21] = _line(tpv(9, lat="48.1"))  # wrong type
    lines[31] = json.dumps(tpv(14, lon=float("nan")), separators=(",", ":"))  # NaN (Python's json writes it)
    lines[41] = _line(tpv(19, time="yesterday"))
    lines.insert(50, _line(tpv(3)))  # time going backwards: a fix already read, again
    lines.append(_line({"class": "PPS", "device": "/dev/ttyACM0", "real_sec": 1}))
    lines.append(_line({"class": "XYZ"}))
    path = tmp_path / "damaged.json"
    path.write_text("\n".join(lines) + '\n{"class":"TPV","mode":3,"ti')  # cut last line
    table = read_log(path)
    reasons = {s.reason: s for s in table.skipped}
    assert reasons["lines that are not valid JSON"].count == 1
    assert reasons["file cut inside its last report"].action == "lost"
    assert reasons["lines that are not gpsd JSON reports"].count == 1
    assert reasons["TPV fixes without a usable lat/lon"].count == 2
    assert any(s.stream == "TPV lat" and s.action == "lost" for s in table.skipped)
    assert any(s.stream == "TPV lon" and s.action == "lost" for s in table.skipped)
    assert reasons["TPV fixes with a time that is no ISO 8601 date"].count == 1
    assert any("time went backwards" in s.reason or "duplicate" in s.reason for s in table.skipped)
    assert any(s.stream == "PPS" for s in table.skipped) and any(s.stream == "XYZ" for s in table.skipped)
    assert len(table.fixes) == 60 - 4  # cut, lat, lon, time; the repeated fix dropped as a duplicate
    assert main(["inspect", str(path)]) == 3  # read, and said to be damaged (lines lost)
    assert "Traceback" not in capsys.readouterr().err


def test_sniffing_claims_gpsd_json_only(tmp_path: Path) -> None:
    path = write(tmp_path / "drive.log", ["# gpsd test log", "#", *drive(3)])
    assert sniff_format(path) == "gpsd_json"
    body = "GPGGA,120000.00,4806.000,N,01130.000,E,1,09,0.9,552.5,M,47.5,M,,"
    check = 0
    for c in body.encode():
        check ^= c
    nmea = write(tmp_path / "nmea.log", [f"${body}*{check:02X}"] * 5)
    assert sniff_format(nmea) == "nmea"
    text = write(tmp_path / "notes.txt", ["drive of 1 May", "{not json}", "lat 48.1 lon 11.5"])
    with pytest.raises(UnsupportedFormatError, match="unknown format"):
        sniff_format(text)
    # a gpsd preamble before data in another protocol (gpsd's test logs of binary receivers) is not this format
    mixed = tmp_path / "mixed.log"
    mixed.write_bytes(("\n".join(preamble()) + "\n").encode() + b"\xa0\xa2\x00\x02\x29\x00\xb0\xb3" * 400)
    with pytest.raises(UnsupportedFormatError, match="gpsd JSON reports as a preamble"):
        sniff_format(mixed)


def test_reports_without_fix_or_sky_are_nothing_to_judge(tmp_path: Path) -> None:
    # gpsd's JSON passthrough test log: three reports of classes no receiver sends
    table = read_log(real_log("corpus/gpsd/passthrough.log"))
    assert table.format == "gpsd_json" and not len(table.fixes)
    assert "XXX x1" in table.metadata["holds"] and "no" not in table.metadata["holds"].split(":")[0][:3]
    assert {s.stream for s in table.skipped} >= {"XXX", "YYY", "ZZZ"}
    idle = write(tmp_path / "idle.json", [*preamble(), *[_line(tpv(i, mode=1)) for i in range(5)]])
    table = read_log(idle)
    # a TPV without a fix is a TPV all the same: "without a fix (TPV)" beside "TPV x5" read as a contradiction
    assert table.metadata["holds"].startswith("gpsd JSON reports without a fix (TPV mode 2 or 3) or sky view")
    assert "TPV x5" in table.metadata["holds"]
    assert any("mode 0/1" in s.reason and s.count == 5 for s in table.skipped)


def test_cli_inspect_analyze_inject(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    clean = write(tmp_path / "drive.json", drive())
    assert main(["inspect", str(clean)]) == 0
    summary = tmp_path / "clean.summary.json"
    assert main(["analyze", str(clean), "-o", str(tmp_path / "clean.rrd"), "--json", str(summary)]) == 0
    verdict = json.loads(summary.read_text())["verdict"]
    assert not verdict["spoofed"] and not verdict["incidents"], verdict["headline"]
    spoofed = tmp_path / "spoofed.json"
    assert main(["inject", str(clean), "--attack", "step:offset=50,start=100", "-o", str(spoofed)]) == 0
    before, after = clean.read_bytes().splitlines(), spoofed.read_bytes().splitlines()
    assert len(before) == len(after)
    changed = [i for i, (x, y) in enumerate(zip(before, after, strict=True)) if x != y]
    assert len(changed) == 200 and all(b'"class":"TPV"' in before[i] for i in changed)
    old, new = json.loads(before[changed[0]]), json.loads(after[changed[0]])
    moved = math.hypot(
        math.radians(new["lat"] - old["lat"]) * EARTH_M,
        math.radians(new["lon"] - old["lon"]) * EARTH_M * math.cos(math.radians(old["lat"])),
    )
    assert moved == pytest.approx(50.0, abs=0.1)
    assert {k: v for k, v in new.items() if k not in ("lat", "lon")} == {
        k: v for k, v in old.items() if k not in ("lat", "lon")
    }
    summary = tmp_path / "spoofed.summary.json"
    assert main(["analyze", str(spoofed), "-o", str(tmp_path / "spoofed.rrd"), "--json", str(summary)]) == 0
    incidents = json.loads(summary.read_text())["verdict"]["incidents"]
    # one receiver, no IMU: the step is an anomaly of GNSS-only consistency from 100 s, not confirmed spoofing
    assert any("gnss_consistency" in i["detectors"] and abs(i["start_s"] - 100.0) <= 2.0 for i in incidents)
    assert "Traceback" not in capsys.readouterr().err


def _sky_of(i: int, sats: list[dict[str, Any]], device: str = "/dev/ttyAMA0", **fields: Any) -> str:
    """A gpsd 3.16 SKY (PRN only, no gnssid/svid), as `gpspipe -w` wrote it from a u-blox on a Raspberry Pi."""
    obj: dict[str, Any] = {"class": "SKY", "device": device, "xdop": 1.31, "ydop": 1.62, "vdop": 2.78}
    if i >= 0:
        obj["time"] = (T0 + timedelta(seconds=i)).strftime("%Y-%m-%dT%H:%M:%S.000Z")
    obj |= fields
    obj["satellites"] = sats
    return _line(obj)


def _pi_capture(n: int = 60) -> list[str]:
    """A static u-blox behind gpsd 3.16 (a real `gpspipe -w` capture's shape): two TPV without a fix and two SKY
    with no time before the first fix, then 1 Hz TPV and SKY. From 20 s on the receiver tracks G07 and an
    unidentified GLONASS signal (PRN 255) it has no almanac position for: gpsd writes `el:-91, az:0`."""
    dev = "/dev/ttyAMA0"
    lines = [
        _line({"class": "VERSION", "release": "3.16", "rev": "3.16-4", "proto_major": 3, "proto_minor": 11}),
        _line({"class": "DEVICE", "path": dev, "driver": "u-blox", "native": 1, "bps": 9600}),
        _line({"class": "TPV", "device": dev, "mode": 1}),
        _line({"class": "TPV", "device": dev, "mode": 1}),
    ]
    known = [
        {"PRN": 2, "el": 57, "az": 146, "ss": 30, "used": True},
        {"PRN": 5, "el": 66, "az": 20, "ss": 34, "used": True},
        {"PRN": 30, "el": 30, "az": 76, "ss": 28, "used": True},
        {"PRN": 129, "el": 45, "az": 159, "ss": 29, "used": False},
        {"PRN": 80, "el": 18, "az": 66, "ss": 31, "used": True},
    ]
    lines += [_sky_of(-1, known[:3]), _sky_of(-1, known)]  # before the first fix: no time, no TPV to join
    for i in range(n):
        fix = tpv(i, dev, mode=2, lat=36.622516, lon=127.348676, altHAE=None, altMSL=None, geoidSep=None)
        unknown = [{"PRN": 7, "el": -91, "az": 0, "ss": 20, "used": False}]
        unknown += [{"PRN": 255, "el": -91, "az": 0, "ss": 18, "used": False}]
        lines += [_line(fix), _sky_of(-1, known + (unknown if i >= 20 else []))]
    return lines


def test_unknown_elevation_is_no_measurement(tmp_path: Path) -> None:
    """gpsd (and u-blox under it) writes elevation -91 for a satellite tracked with no position known (u-blox:
    "elevation range +/-90, unknown if out of range; azimuth unknown if elevation is out of range"). Read as
    a measurement it was G07 "tracked 91 deg below the horizon" (a real gpsd 3.16 capture, an anomaly)."""
    table = read_log(write(tmp_path / "pi.json", _pi_capture()))
    g07 = table.satellites[table.satellites["sv_id"] == "G07"]
    assert len(g07) == 40 and g07["elevation_deg"].isna().all() and g07["azimuth_deg"].isna().all()
    assert (g07["cn0_dbhz"] == 20).all()  # the signal itself is still read
    assert table.satellites["elevation_deg"].between(-90, 90).sum() == 5 * 60
    (note,) = [s for s in table.skipped if "elevation" in s.reason]
    assert note.count == int(table.satellites["elevation_deg"].isna().sum()) >= 40 and note.action != "lost"


def test_prn_255_is_no_satellite_named(tmp_path: Path) -> None:
    """PRN 255 is u-blox's GLONASS signal whose slot is not known yet (gpsd passes it through; newer gpsd
    drops it): it was named BeiDou "C55" (no such satellite). Skipped and counted, saying why; PRNs
    outside gpsd's numbering are not named either."""
    lines = _pi_capture()
    # 40: SBAS in NMEA numbering, BeiDou in u-blox's (was "G40"); 100: no system; 263: past BeiDou (was "C63")
    weird = [{"PRN": p, "el": 10, "az": 10, "ss": 30, "used": False} for p in (40, 100, 263)]
    weird += [{"gnssid": 6, "svid": 255, "PRN": 255, "el": 5, "az": 5, "ss": 25, "used": False}]
    lines.append(_sky_of(60, [*weird, {"PRN": 2, "el": 57, "az": 146, "ss": 30, "used": True}]))
    table = read_log(write(tmp_path / "pi.json", lines))
    ids = set(table.satellites["sv_id"])
    assert ids == {"G02", "G05", "G30", "S29", "R16", "G07"}, ids
    assert not any(i.startswith("C") for i in ids)
    reasons = {s.reason: s for s in table.skipped if "SKY satellites" in s.reason}
    (slot,) = [s for r, s in reasons.items() if "255" in r]
    assert slot.count == 40 + 1 and "GLONASS" in slot.reason and slot.action == "skipped"
    (ambiguous,) = [s for r, s in reasons.items() if "33-64" in r]
    assert ambiguous.count == 1 and "SBAS" in ambiguous.reason and "BeiDou" in ambiguous.reason
    (other,) = [s for r, s in reasons.items() if "255" not in r and "33-64" not in r]
    assert other.count == 2 and other.action == "skipped"


def test_sky_before_the_first_fix_is_no_damage(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """gpspipe -w writes the sky gpsd has before the receiver's first fix, with no `time`: nothing places
    those reports in time. A real intact capture was said to be damaged (exit 3) for its first two SKY."""
    path = write(tmp_path / "pi.json", _pi_capture())
    table = read_log(path)
    (early,) = [s for s in table.skipped if "SKY" in s.reason and "before" in s.reason]
    assert early.count == 2 and early.action == "skipped"
    assert not [s for s in table.skipped if s.action == "lost"]
    assert main(["inspect", str(path)]) == 0
    # a cut line stays damage
    cut = tmp_path / "cut.json"
    cut.write_text(path.read_text() + '{"class":"SKY","device":"/dev/ttyAMA0","satel')
    assert main(["inspect", str(cut)]) == 3
    assert "Traceback" not in capsys.readouterr().err
