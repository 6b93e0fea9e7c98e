"""NMEA 2000 logs (canboat's plain, FAST and PLAIN_MIX_FAST text) read as fixes and headings, on the real
captures of the corpus; fast-packet frames split over lines reassembled."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from paths import real_log

from readers import read_log, sniff_format
from spooflens.cli import main
from spooflens.schema import FixType

AAVA = "corpus/signalk/aava-n2k.data"


def test_aava_gnss_position_data_heading_and_time() -> None:
    """Sailing yacht Aava (2014): 129029 at 1 Hz with 129026 COG/SOG, 127250 heading, 126992 time."""
    path = real_log(AAVA)
    assert sniff_format(path) == "n2k"  # before: "unknown format"
    t = read_log(path)
    assert t.time_reference == "unix" and t.absolute_iso(0.0).startswith("2014-08-15T19:00:00")
    fx = t.fixes
    assert t.receivers() == ["N2K/160"] and len(fx) == 597
    assert fx["lat_deg"].median() == pytest.approx(59.72, abs=0.05)  # the Gulf of Finland
    assert fx["lon_deg"].median() == pytest.approx(24.74, abs=0.05)
    assert (fx["fix_type"] == FixType.FIX_3D).all() and fx["sats_used"].between(9, 12).all()
    assert fx["hdop"].median() == pytest.approx(0.8)
    speed = np.hypot(fx["vel_e_mps"], fx["vel_n_mps"])
    assert 2.0 < np.nanmedian(speed) < 5.0  # 3.47 m/s over ground in the first 129026
    # the receiver's own date and time (129029) against the logger's: constant to within the logging
    assert np.nanmax(np.abs(fx["time_offset_s"])) < 1.0
    hd = t.headings
    assert set(hd["heading_id"]) == {"N2K/160/127250"} and set(hd["talker"]) == {"GN"}  # sent by the GNSS source
    first = hd.iloc[0]
    assert first["heading_deg"] == pytest.approx(np.degrees(3.475) % 360, abs=0.01)


def test_furuno_fast_format_rapid_positions() -> None:
    """A FAST-format capture (fast-packet PGNs on one line) with 129025/129026 only: rapid positions as
    fixes, without altitude (0 m, listed), velocity from COG/SOG."""
    t = read_log(real_log("corpus/canboat/furuno-130842-figure8-fast.raw"))
    assert set(t.receivers()) == {"N2K/25", "N2K/52"}
    assert any(s.action == "repaired" and "height set to 0 m" in s.reason for s in t.skipped)
    assert t.fixes["vel_e_mps"].notna().mean() > 0.9
    assert np.hypot(t.fixes["vel_e_mps"], t.fixes["vel_n_mps"]).max() > 3.0  # figure-8s at speed


def test_plain_mix_fast_and_the_speed_log() -> None:
    """Suster Anna (2020, PLAIN_MIX_FAST): two GNSS sources, compasses and speed logs (128259) whose
    speed through the water joins the compass heading, as NMEA 0183 VHW does."""
    t = read_log(real_log("corpus/canboat/susteranna2020.raw"))
    assert set(t.receivers()) == {"N2K/127", "N2K/18"}
    water = t.headings[t.headings["water_speed_mps"].notna()]
    assert len(water) > 40 and set(water["talker"]) <= {"HC", "II"}
    assert main(["inspect", str(real_log("corpus/canboat/susteranna2020.raw"))]) == 3  # two unreadable lines


def test_dirona_old_time_layout_and_several_sources() -> None:
    t = read_log(real_log("corpus/canboat/dirona-actisense-serial.raw"))
    assert set(t.receivers()) == {"N2K/7", "N2K/33"} and t.duration_s > 180
    assert not [s for s in t.skipped if s.action == "lost"]  # `2016-02-28-19:56:59` lines read too


def test_fast_packet_frames_split_over_lines_are_reassembled(tmp_path: Path) -> None:
    """Aava's 129029 lines (43 bytes) written as canboat's plain format writes a fast packet: a first
    frame (sequence, length, 6 bytes), then frames of 7 bytes, each on its own line."""
    lines = real_log(AAVA).read_text().splitlines()
    out = []
    for line in lines[:3000]:
        ts, pri, pgn, src, dst, _length, *data = line.split(",")
        if pgn != "129029":
            out.append(line)
            continue
        frames = [["a0", f"{len(data):02x}", *data[:6]]]
        rest, k = data[6:], 1
        while rest:
            frames.append([f"{0xA0 + k:02x}", *rest[:7], *["ff"] * (7 - len(rest[:7]))])
            rest, k = rest[7:], k + 1
        out += [",".join([ts, pri, pgn, src, dst, "8", *f]) for f in frames]
    split = tmp_path / "plain.raw"
    split.write_text("\n".join(out) + "\n")
    whole = tmp_path / "whole.raw"
    whole.write_text("\n".join(lines[:3000]) + "\n")
    a, b = read_log(whole).fixes, read_log(split).fixes
    assert len(a) == len(b) > 50
    np.testing.assert_allclose(a[["lat_deg", "lon_deg", "height_m"]], b[["lat_deg", "lon_deg", "height_m"]])


def test_actisense_a_text(tmp_path: Path) -> None:
    """The same messages in Actisense's `A` text (time of day, source/destination/priority, PGN, bytes):
    the same fixes, on a relative clock (the format has no date)."""
    lines = real_log(AAVA).read_text().splitlines()[:2000]
    out = []
    for line in lines:
        ts, pri, pgn, src, dst, _length, *data = line.split(",")
        stamp = ts[11:23].replace(":", "")
        out.append(f"A{stamp} {int(src):02X}{int(dst):02X}{int(pri):1X} {int(pgn):05X} {''.join(data).upper()}")
    plain, actisense = tmp_path / "plain.raw", tmp_path / "actisense.log"
    plain.write_text("\n".join(lines) + "\n")
    actisense.write_text("\n".join(out) + "\n")
    assert sniff_format(actisense) == "n2k"
    a, b = read_log(plain), read_log(actisense)
    assert b.time_reference == "relative" and len(a.fixes) == len(b.fixes) > 50
    np.testing.assert_allclose(a.fixes[["lat_deg", "lon_deg"]], b.fixes[["lat_deg", "lon_deg"]])
    np.testing.assert_allclose(np.diff(a.fixes["t_s"]), np.diff(b.fixes["t_s"]), atol=1e-6)
