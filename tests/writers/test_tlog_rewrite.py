"""Attacked copies of MAVLink telemetry logs: the vehicle's GPS packets re-encoded in their own framing (v1 or
v2, same sequence number and ids, valid CRC), every other record byte for byte; a step moves the fixes read
back, a jammer's lost fixes are no fix and its inflated accuracies and lost satellites are in the packets;
signed packets and packets that fail their CRC are copied as they are. No real tlog with a clear licence
exists: the logs are written with pymavlink's encoder (`mavlink_support.write_tlog`)."""

from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mavlink_support import msgid, tlog_records, write_tlog

from readers import read_log
from spooflens.attacks import apply_attack, parse_attack
from spooflens.cli import main
from spooflens.geodesy import geodetic_to_enu
from spooflens.writers.rewrite import unwritten_changes
from spooflens.writers.tlog_rewrite import rewrite_tlog

GPS_IDS = {24, 124}  # GPS_RAW_INT, GPS2_RAW


def _mavlink() -> Any:
    from pymavlink.dialects.v20 import ardupilotmega

    return ardupilotmega


def decoded(packet: bytes) -> Any:
    """The message of a packet, its CRC checked (pymavlink raises on a bad one)."""
    return _mavlink().MAVLink(None).decode(bytearray(packet))


def _crc_ok(packet: bytes) -> bool:
    try:
        decoded(packet)
    except _mavlink().MAVError:
        return False
    return True


def inject(src: Path, attack: str, dst: Path, capsys: pytest.CaptureFixture[str]) -> str:
    assert main(["inject", str(src), "--attack", attack, "-o", str(dst)]) == 0
    return capsys.readouterr().out


def assert_only_gps_packets_differ(src: Path, copy: Path) -> list[tuple[bytes, bytes]]:
    """Every record of `copy` has the receive time of `src`'s; every record that is no GPS packet is the
    same bytes, and so is a GPS packet that fails its CRC; a GPS packet keeps its framing, sequence number,
    ids and (v1) length. Returns the GPS packets (source, copy)."""
    a, b = tlog_records(src.read_bytes()), tlog_records(copy.read_bytes())
    assert len(a) == len(b)
    gps = []
    for (t0, p0), (t1, p1) in zip(a, b, strict=True):
        assert t0 == t1
        if msgid(p0) in GPS_IDS:
            gps.append((p0, p1))
        if msgid(p0) not in GPS_IDS or not _crc_ok(p0):
            assert p0 == p1
            continue
        assert p1[0] == p0[0] and msgid(p1) == msgid(p0)
        m0, m1 = decoded(p0), decoded(p1)
        assert (m1.get_seq(), m1.get_srcSystem(), m1.get_srcComponent()) == (
            m0.get_seq(),
            m0.get_srcSystem(),
            m0.get_srcComponent(),
        )
        if p0[0] == 0xFE:
            assert len(p1) == len(p0)
    return gps


@pytest.mark.parametrize(("v1", "gps2"), [(False, False), (True, False), (False, True)], ids=["v2", "v1", "gps2"])
def test_a_step_moves_the_fixes_read_back_and_nothing_else(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], v1: bool, gps2: bool
) -> None:
    src, dst = tmp_path / "flight.tlog", tmp_path / "step.tlog"
    write_tlog(src, seconds=60.0, v1=v1, gps2=gps2)
    receivers = 2 if gps2 else 1
    out = inject(src, "step:offset=50,start=30", dst, capsys)
    assert f"{150 * receivers} GPS packets rewritten ({300 * receivers} fixes in the table)" in out
    gps = assert_only_gps_packets_differ(src, dst)
    assert sum(p0 != p1 for p0, p1 in gps) == 150 * receivers
    clean, copy = read_log(src), read_log(dst)
    assert len(copy.fixes) == len(clean.fixes) and copy.t0_ns == clean.t0_ns
    np.testing.assert_array_equal(copy.fixes["t_s"], clean.fixes["t_s"])
    f0, f1 = clean.fixes, copy.fixes
    moved = geodetic_to_enu(f1["lat_deg"], f1["lon_deg"], f1["height_m"], f0["lat_deg"], f0["lon_deg"], f0["height_m"])
    on = f0["t_s"].to_numpy() >= 30.0
    np.testing.assert_allclose(moved[on, :2], 50.0, atol=0.012)  # 1e-7 deg is 1.1 cm
    np.testing.assert_allclose(moved[~on], 0.0, atol=1e-9)
    np.testing.assert_allclose(moved[:, 2], 0.0, atol=1e-3)  # mm
    np.testing.assert_array_equal(f1["vel_n_mps"], f0["vel_n_mps"])  # a step has no velocity
    if v1:  # a MAVLink1 sender's packet: its 30 bytes of payload, no extension fields added
        assert all(len(p1) == 6 + 30 + 2 for _, p1 in gps)


def test_a_jammer_writes_lost_fixes_inflated_accuracies_and_fewer_satellites(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src, dst = tmp_path / "flight.tlog", tmp_path / "jam.tlog"
    write_tlog(src, seconds=120.0)
    clean = read_log(src)
    # 12 satellites: 5 lost leave a fix, 9 do not
    out = inject(src, "jam:start=40,end=60,lost=5", tmp_path / "jam5.tlog", capsys)
    assert "not in the copy" not in out and "no C/N0, AGC, noise or jamming indicator" in out
    kept = read_log(tmp_path / "jam5.tlog").fixes
    on = kept["t_s"].between(42.0, 58.0).to_numpy()
    assert (kept["sats_used"][on] == 7).all() and (kept["sats_used"][~kept["t_s"].between(39.0, 61.0)] == 12).all()
    assert (kept["h_acc_m"][on] > 3 * 0.8).all() and (kept["hdop"][on] > 0.9).all()
    assert (kept["v_acc_m"][on] > 1.5).all() and (kept["vel_acc_mps"][on] > 0.3).all()

    out = inject(src, "jam:start=40,end=60,lost=9", dst, capsys)
    truth = json.loads((tmp_path / "jam.tlog.attack.json").read_text())
    (lost_s,) = truth["phases"][0]["fix_lost_s"]
    assert "lost: fix_type 1, no fix" in out and "not in the copy" not in out
    gps = assert_only_gps_packets_differ(src, dst)
    written = [decoded(p1) for _, p1 in gps]
    no_fix = [m for m in written if m.fix_type <= 1]
    assert len(no_fix) == round((lost_s[1] - lost_s[0]) * 5) + 1
    copy = read_log(dst)
    gone = clean.fixes["t_s"].between(lost_s[0], lost_s[1])
    np.testing.assert_array_equal(copy.fixes["t_s"], clean.fixes["t_s"][~gone])
    assert any(s.reason == "fix_type 0-1 (no fix)" and s.count == len(no_fix) for s in copy.skipped)
    # what the receiver said as the jammer rose and fell, before and after its fix was lost
    ramp = copy.fixes["t_s"].between(40.1, 42.0).to_numpy()
    assert ramp.any() and (copy.fixes["h_acc_m"][ramp] > 0.8).all()
    assert unwritten_changes(clean, apply_attack(clean, parse_attack("jam:start=40,end=60,lost=9"))[0], copy) == []


def test_the_receivers_unix_time_moves_with_a_spoofers_clock(tmp_path: Path) -> None:
    src, dst = tmp_path / "ardupilot.tlog", tmp_path / "capture.tlog"
    write_tlog(src, seconds=120.0, gps_unix_from_s=1e9)  # ArduPilot's GPS_RAW_INT: the receiver's UNIX time
    clean = read_log(src)
    spoofed, _ = apply_attack(clean, parse_attack("capture:start=70,clock=2.5"))
    rewrite_tlog(src, dst, clean, spoofed, True)
    copy = read_log(dst)
    key = ["receiver_id", "t_s"]
    both = copy.fixes.merge(spoofed.fixes, on=key, suffixes=("", "_attacked"))
    assert len(both) == len(spoofed.fixes) == len(copy.fixes)
    x, y = both["time_offset_s"].to_numpy(), both["time_offset_s_attacked"].to_numpy()
    np.testing.assert_allclose(x - x[0], y - y[0], atol=1e-6)  # whole microseconds
    assert np.ptp(x) == pytest.approx(2.5, abs=1e-6)
    np.testing.assert_allclose(both["vel_e_mps"], both["vel_e_mps_attacked"], atol=0.006)  # cm/s, cdeg
    np.testing.assert_allclose(both["vel_n_mps"], both["vel_n_mps_attacked"], atol=0.006)
    np.testing.assert_allclose(both["h_acc_m"], both["h_acc_m_attacked"], atol=5e-4)


def _resigned(packet: bytes) -> bytes:
    """The packet signed (MAVLink 2 signing, a made-up key), its sequence number and ids kept."""
    m = decoded(packet)
    mav = _mavlink().MAVLink(None, srcSystem=m.get_srcSystem(), srcComponent=m.get_srcComponent())
    mav.seq = m.get_seq()
    mav.signing.secret_key = bytes(32)
    mav.signing.sign_outgoing = True
    mav.signing.timestamp = 1
    return bytes(m.pack(mav))


def _with_gps_packets(src: Path, dst: Path, change: Any, from_s: float) -> int:
    """`src` with `change` applied to the GPS packets received from `from_s` s on; how many were changed."""
    records = tlog_records(src.read_bytes())
    t0 = struct.unpack(">Q", records[0][0])[0]
    out, n = bytearray(), 0
    for t, packet in records:
        late = (struct.unpack(">Q", t)[0] - t0) / 1e6 >= from_s
        if late and msgid(packet) in GPS_IDS:
            packet, n = change(packet), n + 1
        out += t + packet
    dst.write_bytes(bytes(out))
    return n


def test_signed_packets_are_copied_and_the_note_says_what_the_copy_lacks(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plain, src = tmp_path / "plain.tlog", tmp_path / "signed.tlog"
    write_tlog(plain, seconds=60.0)
    _with_gps_packets(plain, src, _resigned, 20.0)
    clean = read_log(src)
    assert len(clean.fixes) == 300  # read: a signature is not checked without the key
    out = inject(src, "jam:start=30,end=50,lost=9", tmp_path / "jam.tlog", capsys)
    jammer_on = int(clean.fixes["t_s"].between(30.0, 50.0, inclusive="neither").sum())  # every fix it moved
    assert f"0 GPS packets rewritten (209 fixes in the table; 91 lost: fix_type 1, no fix), {jammer_on} attacked" in out
    assert "packets copied unchanged: signed" in out
    assert "not in the copy (the format or its writer has no place for them): reported accuracies" in out
    assert "the lost fixes" in out
    assert (tmp_path / "jam.tlog").read_bytes() == src.read_bytes()


def test_a_packet_that_fails_its_crc_is_copied_as_it_is(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    plain, src, dst = tmp_path / "plain.tlog", tmp_path / "damaged.tlog", tmp_path / "step.tlog"
    write_tlog(plain, seconds=60.0)
    damaged = _with_gps_packets(plain, src, lambda p: p[:-1] + bytes([p[-1] ^ 0xFF]), 50.0)
    clean = read_log(src)
    assert len(clean.fixes) == 300 - damaged and any(s.action == "lost" for s in clean.skipped)
    inject(src, "step:offset=50,start=30", dst, capsys)
    gps = assert_only_gps_packets_differ(src, dst)
    bad = [(p0, p1) for p0, p1 in gps if not _crc_ok(p0)]
    assert len(bad) == damaged and all(p0 == p1 for p0, p1 in bad)
    assert sum(p0 != p1 for p0, p1 in gps) == 150 - damaged
    assert len(read_log(dst).fixes) == 300 - damaged


def analyze_json(path: Path, tmp_path: Path) -> dict[str, Any]:
    report = tmp_path / f"{path.name}.json"
    assert main(["analyze", str(path), "-o", str(tmp_path / "x.rrd"), "--json", str(report), "--quiet"]) == 0
    summary: dict[str, Any] = json.loads(report.read_text())
    return summary


@pytest.mark.slow
def test_analyze_finds_the_step_and_sees_the_jammer_only_as_degradation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A tlog carries no C/N0, AGC, noise or jamming indicator: the interference detector cannot run on the
    jammed copy, and the satellites lost with the accuracies grown read as a degradation, not spoofing."""
    src = tmp_path / "flight.tlog"
    write_tlog(src, seconds=90.0)
    inject(src, "step:offset=50,start=50", tmp_path / "step.tlog", capsys)
    (spoofing,) = analyze_json(tmp_path / "step.tlog", tmp_path)["verdict"]["events"]
    assert spoofing["kind"] == "spoofing" and 49.0 <= spoofing["onset_s"] <= 50.5

    inject(src, "jam:start=40,end=80,lost=5", tmp_path / "jam.tlog", capsys)
    summary = analyze_json(tmp_path / "jam.tlog", tmp_path)
    assert not summary["verdict"]["spoofed"]
    (degradation,) = summary["verdict"]["events"]
    assert degradation["kind"] == "degradation" and degradation["start_s"] <= 42.0 and degradation["end_s"] >= 79.0
    (interference,) = [a for a in summary["analyses"] if a["name"] == "interference"]
    assert not interference["ran"] and interference["reason"].startswith("no C/N0 (per satellite or mean), AGC")


@pytest.mark.slow
def test_fixes_back_after_a_long_outage_are_no_departure_of_the_ins_that_coasted_through_it(tmp_path: Path) -> None:
    """A jammer that costs the fix for 38 s: when the fixes come back, the INS has drifted over the outage
    (this writer's IMU reads a constant gyro rate its attitude never shows). The coast from the returning
    fixes' alarm began where the INS was last aided: it was "SPOOFING from 79.20 s" (an inertial departure
    confirmed at the first returning fix); the reference is now re-converging there and confirms nothing."""
    src = tmp_path / "flight.tlog"
    write_tlog(src, seconds=120.0)
    assert main(["inject", str(src), "--attack", "jam:start=40,end=80,lost=9", "-o", str(tmp_path / "j.tlog")]) == 0
    summary = analyze_json(tmp_path / "j.tlog", tmp_path)
    assert not summary["verdict"]["spoofed"], summary["verdict"]["headline"]
    assert not [e for e in summary["verdict"]["events"] if e["kind"] == "spoofing"]
    assert any(e["start_s"] <= 79.2 <= e["end_s"] for e in summary["verdict"]["events"])  # still an event there
