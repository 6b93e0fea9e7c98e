"""u-blox captures of every generation: fixes from the messages before NAV-PVT, dating the capture from
its own messages, timing receivers, and MON-VER polls. Every capture is a real one from the corpus;
where a case needs a message removed or a flag cleared, the real capture is re-framed with exactly that
change (checksums recomputed)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from paths import real_log
from pyubx2 import UBXReader

from readers import read_log
from readers.ubx import messages as m
from readers.ubx.frames import UbxFrame, fletcher, split_frames
from spooflens.cli import main
from spooflens.epoch_table import HOLDS
from spooflens.schema import FixType

Edit = Callable[[str, UbxFrame], bytes | None]  # (message name, frame) -> payload to write, None to drop


def _name(frame: UbxFrame) -> str:
    return m.MSG.get((frame.msg_class, frame.msg_id), f"{frame.msg_class:02x}-{frame.msg_id:02x}")


def _reframed(path: Path, out: Path, edit: Edit) -> Path:
    """The capture's UBX frames and NMEA lines in file order, each UBX payload passed through `edit`."""
    frames = split_frames(path.read_bytes())
    parts = []
    for kind, i in frames.order:
        if kind == "nmea":
            parts.append(frames.nmea[i].text + b"\r\n")
            continue
        f = frames.ubx[i]
        payload = edit(_name(f), f)
        if payload is None:
            continue
        head = bytes((f.msg_class, f.msg_id)) + len(payload).to_bytes(2, "little") + payload
        parts.append(b"\xb5\x62" + head + fletcher(head))
    out.write_bytes(b"".join(parts))
    return out


def test_nav_sol_fixes_of_a_receiver_without_nav_pvt() -> None:
    """navisys GR-701W (2024): NAV-SOL (ECEF position and velocity, fix, week) and NAV-SVINFO only.
    Before: refused as holding no fix."""
    t = read_log(real_log("corpus/gpsd/navisys-gr701w.log"))
    assert t.time_reference == "gps" and t.absolute_iso(0.0).startswith("2024-03-28") and not t.segments
    fx = t.fixes
    assert len(fx) > 40 and set(fx["fix_type"]) <= {FixType.FIX_2D, FixType.FIX_3D, FixType.DGNSS}
    # the header's surveyed place: Lewiston ID, 46.4045 N 117.0207 W, 253.8 m MSL
    assert np.median(fx["lat_deg"]) == pytest.approx(46.4045, abs=2e-4)
    assert np.median(fx["lon_deg"]) == pytest.approx(-117.0207, abs=2e-4)
    assert np.nanmax(np.hypot(fx["vel_e_mps"], fx["vel_n_mps"])) < 2.0  # a stationary receiver
    # NAV-SVINFO (u-blox's single satellite numbering) is the satellites frame
    sats = t.satellites
    assert len(sats) and sats["sv_id"].str.match(r"^[GRSECJ]\d\d$").all()
    assert t.stream("satellites", "ubx").msgtype == "UBX NAV-SVINFO"  # type: ignore[union-attr]
    assert fx["sats_used"].notna().all()


def test_posllh_and_velned_give_the_fix_nav_pvt_gives(tmp_path: Path) -> None:
    """The ZED-X20P capture (2025) logs NAV-PVT and NAV-POSLLH/VELNED/STATUS at the same epochs: without
    its NAV-PVT the legacy messages must give the same position and velocity."""
    src = real_log("corpus/pyubx2/pygpsdata-NAV-ZED-X20P.log")
    full = read_log(src)
    legacy = read_log(_reframed(src, tmp_path / "no_pvt.ubx", lambda n, f: None if n == "NAV-PVT" else f.payload))
    assert "NAV-POSLLH" in legacy.stream("fix", "ubx").msgtype  # type: ignore[union-attr]
    a, b = full.fixes, legacy.fixes
    assert len(a) == len(b) == 2 and np.array_equal(a["t_s"], b["t_s"])
    np.testing.assert_allclose(b[["lat_deg", "lon_deg"]], a[["lat_deg", "lon_deg"]], atol=1e-7)
    np.testing.assert_allclose(b["height_m"], a["height_m"], atol=1e-3)
    velocity = ["vel_e_mps", "vel_n_mps", "vel_u_mps"]
    np.testing.assert_allclose(b[velocity], a[velocity], atol=0.011)  # cm/s against mm/s
    np.testing.assert_allclose(b[["h_acc_m", "v_acc_m"]], a[["h_acc_m", "v_acc_m"]], atol=1e-3)
    # the first epoch's NAV-STATUS gives its fix type; the capture ends before the second epoch's
    assert b["fix_type"].iloc[0] == a["fix_type"].iloc[0] == FixType.FIX_3D
    assert b["fix_type"].iloc[1] == FixType.UNKNOWN
    assert full.absolute_iso(0.0) == legacy.absolute_iso(0.0)  # dated by NAV-TIMEGPS/TIMEUTC without NAV-PVT


def test_antaris_4_timing_kit_of_2007_is_dated_and_read() -> None:
    """AEK-4T (2007): NAV-SOL, NAV-STATUS, NAV-TIMEUTC, TIM-TP; before: refused."""
    t = read_log(real_log("corpus/gpsd/ublox-aek-4t.log"))
    assert t.time_reference == "gps" and t.absolute_iso(0.0).startswith("2007-12-23")
    assert len(t.fixes) == 4 and not t.segments
    # Playa del Carmen, 20.63 N 87.07 W
    assert t.fixes["lat_deg"].median() == pytest.approx(20.63, abs=0.01)
    assert t.fixes["lon_deg"].median() == pytest.approx(-87.07, abs=0.01)


def test_a_timing_receiver_says_it_holds_time_only(tmp_path: Path) -> None:
    """u-blox M8T in surveyed-in timing mode: every epoch a time-only fix (gpsFix 5). With its NAV-SAT the
    satellites are read and the time-only epochs listed; without it, a NO VERDICT that says so."""
    src = real_log("corpus/gpsd/u-blox-m8t-time.log")
    t = read_log(src)
    assert not len(t.fixes) and len(t.satellites)
    assert any("time-only fix" in s.reason and s.count == 151 for s in t.skipped)
    timing = _reframed(src, tmp_path / "timing.ubx", lambda n, f: None if n == "NAV-SAT" else f.payload)
    holds = read_log(timing).metadata[HOLDS]
    assert holds.startswith("this capture holds time only: no position, velocity or raw observations")
    assert main(["inspect", str(timing)]) == 0


def test_mon_ver_polls_and_a_sensor_fusion_drive(tmp_path: Path) -> None:
    """pyubx2's calibration drive (2026): NAV-PVAT fixes, and MON-VER polls (empty payloads) that made
    an internal error ('UBXMessage' object has no attribute 'hwVersion')."""
    src = real_log("corpus/pyubx2/pygpsdata-SF-calibration.log")
    t = read_log(src)
    assert len(t.fixes) == 527 and t.time_reference == "gps" and t.absolute_iso(0.0).startswith("2026-04-20")
    speed = np.hypot(t.fixes["vel_e_mps"], t.fixes["vel_n_mps"])
    assert 10 < speed.max() < 20  # a car, up to 15 m/s
    assert any(s.stream == "MON-VER" and "poll" in s.reason for s in t.skipped)
    assert main(["inspect", str(real_log("corpus/pyubx2/ucenter-ZEDF9P-configdebug.log"))]) in (0, 3)


def _undated(name: str, frame: UbxFrame, keep_dates_after: int | None) -> bytes | None:
    """A payload with the message's date taken away (NAV-PVT's validDate/validTime cleared, the
    time messages dropped), for frames before byte `keep_dates_after` (None: everywhere)."""
    if keep_dates_after is not None and frame.offset >= keep_dates_after:
        return frame.payload
    if name in ("NAV-TIMEGPS", "NAV-TIMEUTC", "NAV-SOL", "RXM-RAWX", "TIM-TP"):
        return None
    if name == "NAV-PVT":
        p = bytearray(frame.payload)
        p[11] &= ~0x03  # valid: validDate, validTime
        return bytes(p)
    return frame.payload


def test_a_date_learned_partway_dates_the_whole_capture_as_one_recording(tmp_path: Path) -> None:
    """navisys GR-8013 (2024), its first half stripped of every date: the week learned halfway dates the
    fixes before it too, one recording, the same times as the intact capture."""
    src = real_log("corpus/gpsd/navisys-gr8013.log")
    whole = read_log(src)
    half = src.stat().st_size // 2
    late = read_log(_reframed(src, tmp_path / "late.ubx", lambda n, f: _undated(n, f, half)))
    assert late.time_reference == "gps" and not late.segments
    assert late.absolute_iso(0.0) == whole.absolute_iso(0.0)
    np.testing.assert_array_equal(late.fixes["t_s"], whole.fixes["t_s"])
    undated = read_log(_reframed(src, tmp_path / "undated.ubx", lambda n, f: _undated(n, f, None)))
    assert undated.time_reference == "relative" and not undated.segments
    assert any(s.action == "undated" and "no date anywhere" in s.reason for s in undated.skipped)
    assert "no date anywhere" in undated.metadata["clock"]
    assert len(undated.fixes) == len(whole.fixes)


def test_nmea_fixes_and_ubx_satellite_reports_share_one_clock(tmp_path: Path) -> None:
    """A u-blox 8 capture whose fixes come from its NMEA (NAV-PVT, NAV-SOL... removed) and whose NAV-SAT
    has only iTOW: before, the NMEA dates and the undated iTOW made two recordings."""
    src = real_log("corpus/gpsd/ublox8-uniqid-monhw.log")
    drop = {"NAV-PVT", "NAV-SOL", "NAV-POSECEF", "NAV-VELECEF", "NAV-TIMEGPS"}
    t = read_log(_reframed(src, tmp_path / "nmea_fixes.ubx", lambda n, f: None if n in drop else f.payload))
    assert t.time_reference == "gps" and not t.segments
    assert len(t.fixes) and len(t.satellites)
    span_fix = (t.fixes["t_s"].min(), t.fixes["t_s"].max())
    assert t.satellites["t_s"].min() < span_fix[1] + 2 and t.satellites["t_s"].max() > span_fix[0] - 2
    assert "NMEA dates" in t.metadata["clock"]


def test_mon_ver_payload_pyubx2_parses_as_a_poll() -> None:
    """pyubx2 gives an empty MON-VER no hwVersion; mon_ver says nothing rather than failing."""
    poll = UBXReader.parse(b"\xb5\x62\x0a\x04\x00\x00\x0e\x34")
    assert m.mon_ver(poll) == {}
