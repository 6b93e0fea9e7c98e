"""Per-satellite evidence: a counterfeit satellite among real ones, in a receiver's own NAV-SAT reports
(captures built with pyubx2) and in raw observations with broadcast orbits (the real GSI RINEX pair)."""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from paths import REAL
from pyubx2 import GET, UBXMessage

from readers import read_log
from spooflens.detectors.base import DetectorResult
from spooflens.detectors.satellite_signals import (
    HORIZON,
    SIGNALS,
    horizon_dip_deg,
    run_satellite_signals,
    satellites_heard_text,
)
from spooflens.epoch_table import EpochTable
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.registry import AnalysisContext, AnalyzeOptions
from spooflens.pipeline.run import analyze_table

GSI = REAL / "rinex_gsi_pair" / "07590920.05o"
F9R = REAL / "ubx_receivers" / "gpsd_ublox-zed-f9r.log"
ITOW0 = 186_400_000
# (svId, elevation deg, azimuth deg, C/N0 dB-Hz) of a static receiver's GPS sky
SKY = [(2, 62, 40, 44), (5, 35, 120, 41), (7, 48, 200, 43), (12, 20, 300, 36), (15, 28, 80, 38), (20, 70, 250, 45),
       (25, 15, 170, 34), (29, 40, 330, 42)]  # fmt: skip
Sat = tuple[int, int, int, int, int, int]  # svId, elev, azim, C/N0, used, health


def _nav_sat(itow: int, sats: list[Sat]) -> bytes:
    body = b""
    for sv, elev, azim, cno, used, health in sats:
        flags = 7 | (used << 3) | (health << 4) | (1 << 8)  # quality 7, orbit from ephemeris
        body += struct.pack("<BBBbhhI", 0, sv, cno, elev, azim, 5 if used else 0, flags)
    head = struct.pack("<IBB2x", itow, 1, len(sats))
    return UBXMessage("NAV", "NAV-SAT", GET, payload=head + body).serialize()


def _pvt(itow: int, s: int) -> bytes:
    return UBXMessage(
        "NAV", "NAV-PVT", GET, iTOW=itow, year=2024, month=3, day=5, hour=3, min=46 + s // 60, second=s % 60,
        validDate=1, validTime=1, fixType=3, gnssFixOk=1, numSV=8, lon=7.5, lat=45.1, height=300_000,
        hMSL=250_000, hAcc=1500, vAcc=2500, velN=0, velE=0, velD=0, sAcc=300,
    ).serialize()  # fmt: skip


def _capture(path: Path, seconds: int, change: Callable[[int, list[Sat]], list[Sat]] | None = None) -> Path:
    rng = np.random.default_rng(5)
    out = []
    for s in range(seconds):
        itow = ITOW0 + 1000 * s
        sats: list[Sat] = [(sv, el, az, cno + int(rng.integers(-1, 2)), 1, 1) for sv, el, az, cno in SKY]
        if change is not None:
            sats = change(s, sats)
        out += [_pvt(itow, s), _nav_sat(itow, sats)]
    path.write_bytes(b"".join(out))
    return path


def _run(table: EpochTable) -> dict[str, DetectorResult]:
    return {r.name: r for r in run_satellite_signals(AnalysisContext(table, AnalyzeOptions()))}


def test_a_clean_sky_raises_nothing(tmp_path: Path) -> None:
    table = read_log(_capture(tmp_path / "clean.ubx", 120))
    assert len(table.satellites) == 120 * len(SKY)
    assert any(s.role == "satellites" and s.msgtype == "UBX NAV-SAT" for s in table.streams)
    res = _run(table)
    assert res[HORIZON].ran and res[SIGNALS].ran
    assert not res[HORIZON].alarms and not res[SIGNALS].alarms


def test_a_satellite_tracked_below_the_horizon_is_named(tmp_path: Path) -> None:
    def ghost(s: int, sats: list[Sat]) -> list[Sat]:
        return [*sats, (31, -25, 10, 46, 0, 1)] if s >= 40 else sats

    res = _run(read_log(_capture(tmp_path / "ghost.ubx", 120, ghost)))
    alarms = res[HORIZON].alarms
    assert alarms and {a.satellites for a in alarms} == {("G31",)}
    assert alarms[0].start_s == pytest.approx(40.0, abs=1e-6) and alarms[0].end_s == pytest.approx(119.0, abs=1e-6)
    assert "G31 tracked 25 deg below the horizon at 46 dB-Hz" in res[HORIZON].findings[0].text
    assert res[HORIZON].evidence == Evidence.RECEIVER  # the receiver's own elevations


def test_one_satellite_stepping_above_the_others_is_named_and_a_common_change_is_not(tmp_path: Path) -> None:
    def takeover(s: int, sats: list[Sat]) -> list[Sat]:
        return [(sv, el, az, cno + 14 if sv == 12 and s >= 60 else cno, u, h) for sv, el, az, cno, u, h in sats]

    res = _run(read_log(_capture(tmp_path / "step.ubx", 120, takeover)))
    alarms = res[SIGNALS].alarms
    assert [a.satellites for a in alarms] == [("G12",)]
    assert alarms[0].onset_s == pytest.approx(60.0, abs=1.01)
    assert "G12's C/N0 rose" in res[SIGNALS].findings[0].text

    def turned(s: int, sats: list[Sat]) -> list[Sat]:
        # the antenna turned: one satellite up, two down at the same time
        bump = {12: 14, 2: -8, 20: -8}
        return [(sv, el, az, cno + (bump.get(sv, 0) if s >= 60 else 0), u, h) for sv, el, az, cno, u, h in sats]

    assert not _run(read_log(_capture(tmp_path / "turned.ubx", 120, turned)))[SIGNALS].alarms

    def rising(s: int, sats: list[Sat]) -> list[Sat]:
        # a satellite climbing into view: 15 dB over two minutes, never a step
        return [(sv, el, az, cno + (s // 8 if sv == 25 else 0), u, h) for sv, el, az, cno, u, h in sats]

    assert not _run(read_log(_capture(tmp_path / "rising.ubx", 120, rising)))[SIGNALS].alarms


def test_a_satellite_back_from_shadow_to_its_own_level_is_no_rise(tmp_path: Path) -> None:
    """A car's satellite off the roadside: at its level for 12 s, shadowed 16 dB for 14 s, back 7 s, shadowed 14 s,
    back for good (a real dashcam log's G06). Its median is the shadowed level by then, so the last return
    stood 13 dB "above its history" and, with one more class, made a medium SPOOFING incident. A satellite
    that rises above any level it held before is still named."""

    def shadowed(s: int, sats: list[Sat]) -> list[Sat]:
        # G20, the strongest, 8 dB above the others' median in the open
        bump = 4 - (16 if 12 <= s < 26 or 33 <= s < 47 else 0)
        return [(sv, el, az, cno + bump if sv == 20 else cno, u, h) for sv, el, az, cno, u, h in sats]

    assert not _run(read_log(_capture(tmp_path / "shadow.ubx", 90, shadowed)))[SIGNALS].alarms

    def shadowed_then_taken(s: int, sats: list[Sat]) -> list[Sat]:
        bump = 4 - (16 if 12 <= s < 26 or 33 <= s < 47 else 0) + (11 if s >= 60 else 0)
        return [(sv, el, az, cno + bump if sv == 20 else cno, u, h) for sv, el, az, cno, u, h in sats]

    alarms = _run(read_log(_capture(tmp_path / "taken.ubx", 90, shadowed_then_taken)))[SIGNALS].alarms
    assert [a.satellites for a in alarms] == [("G20",)] and alarms[0].onset_s == pytest.approx(60.0, abs=1.01)


def test_a_strong_healthy_satellite_the_receiver_refuses_is_named(tmp_path: Path) -> None:
    def refuse(s: int, sats: list[Sat]) -> list[Sat]:
        return [(sv, el, az, cno, 0 if sv == 7 else u, h) for sv, el, az, cno, u, h in sats]

    res = _run(read_log(_capture(tmp_path / "refused.ubx", 120, refuse)))
    assert {a.satellites for a in res[SIGNALS].alarms} == {("G07",)}
    assert "left G07 out of its solution at 100%" in res[SIGNALS].findings[0].text

    def weak_low(s: int, sats: list[Sat]) -> list[Sat]:
        # a weak, low satellite left out is ordinary
        return [(sv, el, az, cno, 0 if sv == 25 else u, h) for sv, el, az, cno, u, h in sats]

    assert not _run(read_log(_capture(tmp_path / "weak.ubx", 120, weak_low)))[SIGNALS].alarms


def test_orbits_put_every_real_satellite_above_the_horizon_and_an_invented_position_below_it() -> None:
    if not GSI.exists():
        pytest.skip("the GSI RINEX pair is not present")
    from spooflens.gnss.solved_fixes import with_solved_fixes

    table = with_solved_fixes(read_log(GSI))
    res = _run(table)
    assert res[HORIZON].ran and not res[HORIZON].alarms
    assert res[HORIZON].evidence == Evidence.RAW_MEASUREMENT
    lowest = res[HORIZON].series[0].values
    assert np.nanmin(lowest) > -1.0  # RINEX receivers track down to the horizon, never below it
    # the same signals at a position on the other side of the Earth: the sky cannot be that one
    f = table.fixes
    moved = replace(table, fixes=f.assign(lat_deg=-f["lat_deg"], lon_deg=f["lon_deg"] - 180.0))
    far = _run(moved)[HORIZON]
    assert len({a.satellites for a in far.alarms}) >= 4


def test_real_receiver_reports_raise_nothing() -> None:
    if not F9R.exists():
        pytest.skip("the u-blox F9R capture is not present")
    table = read_log(F9R)
    res = _run(table)
    assert res[HORIZON].ran and res[SIGNALS].ran
    assert not res[HORIZON].alarms and not res[SIGNALS].alarms


def test_horizon_dip() -> None:
    assert horizon_dip_deg(0.0) == 0.0
    assert horizon_dip_deg(10_000.0) == pytest.approx(3.2, abs=0.05)


def test_satellite_reports_survive_a_csv_round_trip(tmp_path: Path) -> None:
    from spooflens.writers import write_log

    table = read_log(_capture(tmp_path / "sky.ubx", 30))
    write_log(table, tmp_path / "sky_csv", "csv")
    back = read_log(tmp_path / "sky_csv")
    cols = ["t_s", "sv_id", "cn0_dbhz", "elevation_deg", "azimuth_deg", "used", "residual_m", "healthy"]
    left = table.satellites[cols].reset_index(drop=True)
    right = back.satellites[cols].reset_index(drop=True)
    assert len(left) == len(right) == 30 * len(SKY)
    assert (left["sv_id"].astype(str) == right["sv_id"].astype(str)).all()
    num = cols[2:]
    assert np.allclose(left[num].to_numpy(float), right[num].to_numpy(float), equal_nan=True)
    assert any(s.role == "satellites" for s in back.streams)


def test_the_recording_draws_every_satellites_cn0_and_elevation(tmp_path: Path) -> None:
    from rerun.chunk import RrdReader

    from spooflens.output.recording import write_recording
    from spooflens.pipeline.registry import run_analyses

    def ghost(s: int, sats: list[Sat]) -> list[Sat]:
        return [*sats, (31, -25, 10, 46, 0, 1)] if s >= 40 else sats

    table = read_log(_capture(tmp_path / "ghost.ubx", 60, ghost))
    out = tmp_path / "ghost.rrd"
    write_recording(out, table, run_analyses(table))
    rows: dict[str, int] = {}
    for chunk in RrdReader(str(out)).store().stream():
        if not chunk.is_static:
            rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    assert rows["/gnss/ubx/cn0_dbhz/G02"] == 60 and rows["/gnss/ubx/cn0_dbhz/G31"] == 20
    assert rows["/gnss/ubx/elevation_deg/G31"] == 20
    assert rows["/detectors/satellite_horizon/ubx/lowest_elevation"] == 60


def test_a_counterfeit_satellite_in_a_real_phone_log_is_found_by_two_classes(tmp_path: Path) -> None:
    """The real 2016-06-30 GnssLogger log (CSV copy, its navigation file beside it): G12 replaced from
    100 s by a counterfeit 2 km late and 12 dB stronger. RAIM (raw measurements) and the C/N0 step
    (receiver) agree in time and name G12; the clean copy stays clean."""
    import json
    import shutil

    from spooflens.cli import main
    from spooflens.writers import write_log

    phone = REAL / "android_gnsslogger" / "gps-measurement-tools"
    log = phone / "pseudoranges_log_2016_06_30_21_26_07.txt"
    if not log.exists():
        pytest.skip("the GnssLogger log is not present")
    copy = tmp_path / "phone_csv"
    write_log(read_log(log), copy, "csv")
    shutil.copy(phone / "hour1820.16n", tmp_path / "hour1820.16n")
    attacked = tmp_path / "attacked_csv"
    spec = "pr_delay:svs=G12,delay=2000,cn0=12,start=100"
    assert main(["inject", str(copy), "--attack", spec, "-o", str(attacked)]) == 0
    verdicts = {}
    for name in ("phone_csv", "attacked_csv"):
        out = tmp_path / f"{name}.json"
        main(["analyze", str(tmp_path / name), "-o", str(tmp_path / f"{name}.rrd"), "--json", str(out), "--quiet"])
        verdicts[name] = json.loads(out.read_text())["verdict"]
    assert not verdicts["phone_csv"]["spoofed"]
    spoofed = verdicts["attacked_csv"]
    assert spoofed["spoofed"]
    incident = next(i for i in spoofed["incidents"] if i["spoofing"])
    assert incident["confidence"] == "high" and incident["satellites"] == ["G12"]
    assert {"raw_measurement", "receiver"} <= set(incident["evidence"])
    assert {"raim", "satellite_signals"} <= set(incident["detectors"])
    assert 98.0 <= incident["onset_s"] <= 101.0 and incident["end_s"] >= 220.0


def test_every_satellite_at_one_cn0_is_one_transmitter(tmp_path: Path) -> None:
    rng = np.random.default_rng(9)

    def one_transmitter(s: int, sats: list[Sat]) -> list[Sat]:
        if s < 60:
            return sats
        return [(sv, el, az, 44 + int(rng.integers(-1, 2)), u, h) for sv, el, az, _, u, h in sats]

    res = _run(read_log(_capture(tmp_path / "flat.ubx", 120, one_transmitter)))
    alarms = res[SIGNALS].alarms
    assert len(alarms) == 1 and alarms[0].satellites == ()
    assert 60.0 <= alarms[0].start_s <= 64.0 and alarms[0].end_s == pytest.approx(119.0)
    assert "8 satellites at one C/N0" in res[SIGNALS].findings[0].text


def test_a_cn0_that_never_moves_is_a_placeholder_not_one_transmitter(tmp_path: Path) -> None:
    def placeholder(s: int, sats: list[Sat]) -> list[Sat]:
        return [(sv, el, az, 45, u, h) for sv, el, az, _, u, h in sats]

    res = _run(read_log(_capture(tmp_path / "constant.ubx", 120, placeholder)))
    assert res[SIGNALS].ran and not res[SIGNALS].alarms


def test_a_sky_of_fewer_epochs_than_any_test_holds_for_is_not_judged(tmp_path: Path) -> None:
    """A phone log of one epoch (every satellite at 0 dB-Hz, none used) was "NO SPOOFING DETECTED by 2
    detector(s)": both tests ran on a sky none of whose checks can hold for the 3 epochs they need."""
    results = _run(read_log(_capture(tmp_path / "two.ubx", 2)))
    for name in (HORIZON, SIGNALS):
        assert not results[name].ran, name
        assert results[name].reason.endswith("its sky at 2 epoch(s), 3 needed"), results[name].reason
    assert _run(read_log(_capture(tmp_path / "three.ubx", 3)))[SIGNALS].ran


def test_a_sky_at_one_c_n0_with_some_satellites_held_is_still_one_transmitter(tmp_path: Path) -> None:
    """A real receiver fed by a signal simulator: 4 of its 7 satellites held at 51 dB-Hz, the others moving
    by a dB around them. Fewer than half moved, so the sky was taken for a writer's placeholder and the one
    transmitter's signature was never looked at; a placeholder holds them all."""
    rng = np.random.default_rng(3)

    def simulator(s: int, sats: list[Sat]) -> list[Sat]:
        return [
            (sv, el, az, 51 + (int(rng.integers(-1, 2)) if k >= 5 else 0), u, h)
            for k, (sv, el, az, _, u, h) in enumerate(sats)
        ]

    table = read_log(_capture(tmp_path / "simulator.ubx", 120, simulator))
    res = _run(table)
    assert res[SIGNALS].alarms and res[SIGNALS].alarms[0].satellites == ()
    assert "satellites at one C/N0" in res[SIGNALS].findings[0].text
    # one evidence class: no spoofing confirmed, but the headline says the anomaly bears a spoofer's marks
    verdict = analyze_table(table).verdict
    assert not verdict.spoofed and verdict.headline.startswith("NO SPOOFING DETECTED")
    assert "(1 with a spoofer's marks: " in verdict.headline and "one transmitter" in verdict.headline
    (event,) = verdict.events
    assert any(m.text.endswith("one transmitter") and m.claim == "one transmitter" for m in event.spoofer_marks)


def test_satellites_listed_without_a_c_n0_are_counted_apart() -> None:
    """A handheld MTK receiver (mjuenema/python-gpsdshm `tests/test.nmea`) fills its GSV's last slots with
    placeholders (PRNs 33-51, elevation 0 or below, never a C/N0): "19 satellites" counted them with the sky."""
    rows = pd.DataFrame(
        {
            "sv_id": ["G09", "G07", "G23", "G05", "G44", "G45", "G09", "G07", "G23", "G05", "G44", "G45"],
            "cn0_dbhz": [19.0, 13.0, 36.0, np.nan, np.nan, np.nan, 20.0, 14.0, 35.0, np.nan, np.nan, np.nan],
        }
    )
    assert satellites_heard_text(rows) == "3 satellites with a C/N0 (3 more listed without one)"
    assert satellites_heard_text(rows.assign(cn0_dbhz=30.0)) == "6 satellites"
