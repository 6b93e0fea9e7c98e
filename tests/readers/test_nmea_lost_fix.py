"""An NMEA receiver that loses its fix partway keeps the sky of its fix-less epochs: their GSV (C/N0 per
satellite) is in the satellites frame, so the interference detector sees the C/N0 collapse that lost the fix,
and a jammer injected over those epochs is written into their GSV. The sky before the first fix (a cold
start's acquisition) and the sky on another clock (a receiver's default time) are not placed."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from readers import read_log
from spooflens.cli import main
from spooflens.detectors.interference import run_interference
from spooflens.epoch_table import EpochTable
from spooflens.pipeline.run import analyze_table

# (PRN, elevation, azimuth) of the eight GPS satellites in view
SKY = (
    (5, 62, 40),
    (12, 45, 110),
    (15, 30, 200),
    (18, 70, 300),
    (21, 20, 60),
    (24, 55, 250),
    (25, 15, 150),
    (29, 35, 330),
)
# 1 Hz from 12:00:00: acquiring until the first fix at 12:00:05; no fix from 12:01:00 to 12:01:19, the C/N0
# 20 dB down; fixes again to 12:02:29
SECONDS, FIRST_FIX, LOST, DROP_DB = 150, 5, range(60, 80), 20
DEFAULT_CLOCK = "235948.00"  # one epoch before all that on the receiver's clock before it knew the time


def _sentence(body: str) -> str:
    check = 0
    for c in body.encode():
        check ^= c
    return f"${body}*{check:02X}"


def _epoch(hhmmss: str, date: str, fix: bool, drop: int, s: int) -> list[str]:
    if fix:
        bodies = [
            f"GPRMC,{hhmmss},A,4807.0380,N,01131.0000,E,0.0,0.0,{date},,,A",
            f"GPGGA,{hhmmss},4807.0380,N,01131.0000,E,1,08,0.9,545.4,M,46.9,M,,",
        ]
    else:
        bodies = [f"GPRMC,{hhmmss},V,,,,,,,{date},,,N", f"GPGGA,{hhmmss},,,,,0,00,99.99,,,,,,"]
    # each satellite's C/N0 moves a little from epoch to epoch (38-45 dB-Hz), as a receiver's does
    cells = [
        f"{prn:02d},{el:02d},{az:03d},{38 + (k * 7 + s * 3) % 8 - drop:02d}" for k, (prn, el, az) in enumerate(SKY)
    ]
    bodies += [f"GPGSV,2,{m + 1},08," + ",".join(cells[4 * m : 4 * m + 4]) for m in range(2)]
    return [_sentence(b) for b in bodies]


def _log() -> list[str]:
    lines = _epoch(DEFAULT_CLOCK, "050180", False, 10, 0)
    for s in range(SECONDS):
        acquiring, lost = s < FIRST_FIX, s in LOST
        drop = DROP_DB if lost else 10 if acquiring else 0
        lines += _epoch(f"12{s // 60:02d}{s % 60:02d}.00", "050324", not (acquiring or lost), drop, s)
    return lines


@pytest.fixture()
def lost_fix(tmp_path: Path) -> Path:
    path = tmp_path / "lost_fix.nmea"
    path.write_text("\n".join(_log()) + "\n")
    return path


def t_of(s: int) -> float:
    """Table time of second `s` after 12:00:00: the log starts at the first fix."""
    return float(s - FIRST_FIX)


def _fixless_sky(table: EpochTable) -> pd.DataFrame:
    sats = table.satellites
    return sats[sats["t_s"].between(t_of(LOST[0]), t_of(LOST[-1]))]


def test_the_fixless_epochs_keep_their_sky(lost_fix: Path) -> None:
    table = read_log(lost_fix)
    t_fix = table.fixes["t_s"].to_numpy(float)
    assert len(t_fix) == SECONDS - FIRST_FIX - len(LOST)
    assert not ((t_fix >= t_of(LOST[0])) & (t_fix <= t_of(LOST[-1]))).any()
    fixless = 1 + FIRST_FIX + len(LOST)
    assert any(s.count == fixless and "without a valid position" in s.reason for s in table.skipped)
    sky = _fixless_sky(table)
    assert sorted(sky["t_s"].unique()) == [t_of(s) for s in LOST]
    assert (sky.groupby("t_s")["sv_id"].nunique() == len(SKY)).all()
    assert sky["cn0_dbhz"].between(18.0, 25.0).all()  # 38-45 dB-Hz less the 20 dB
    # every epoch from the first fix on has its sky; none before it, none on the default clock
    assert sorted(table.satellites["t_s"].unique()) == [t_of(s) for s in range(FIRST_FIX, SECONDS)]
    (astray,) = [s for s in table.skipped if "of epochs without a fix, an hour or more from any fix (" in s.reason]
    assert astray.count == 1


def test_the_interference_detector_sees_the_collapse_that_lost_the_fix(lost_fix: Path) -> None:
    table = read_log(lost_fix)
    result = run_interference(table)
    (alarm,) = result.alarms
    assert (alarm.start_s, alarm.end_s) == (t_of(LOST[0]), t_of(LOST[-1]))
    (finding,) = result.findings
    assert "all 8 GPS L1 satellites fell by 19-21 dB together" in finding.text and "fix lost" in finding.text
    verdict = analyze_table(table).verdict
    assert not verdict.spoofed and "JAMMING / INTERFERENCE from 55.00 s to 74.00 s" in verdict.headline


def test_a_jammer_injected_over_the_fixless_epochs_is_written_into_their_gsv(lost_fix: Path, tmp_path: Path) -> None:
    jammed = tmp_path / "jammed.nmea"
    assert main(["inject", str(lost_fix), "--attack", "jam:start=45,end=95,cn0=10", "-o", str(jammed)]) == 0
    before, after = _fixless_sky(read_log(lost_fix)), _fixless_sky(read_log(jammed))
    assert len(before) == len(after) == len(LOST) * len(SKY)
    # 10 dB more on 18-25 dB-Hz: below what the receiver tracks, every satellite reported without a C/N0
    assert after["cn0_dbhz"].isna().all()
