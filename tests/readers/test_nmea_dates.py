"""NMEA dates: each stretch of a receiver's time of day takes its own RMC date, and a date that jumps while the
time of day carries on is said plainly (where, by how much, and which date the stretch is read on).

The shapes are those of a real receiver fed by a GPS simulator (AlexT2594/ml-gps-spoofing-gps-data-analysis,
static in Rome): a real-sky recording of 2019-03-20 followed in the same file by a simulator recording dated
2019-03-11 that starts 8 minutes earlier in the time of day (its first part was read on the second's date);
and a real sky of 2019-02-22 taken over by the simulator 21 s later with its date 2019-02-08 (14 days back)."""

from __future__ import annotations

from pathlib import Path

from readers import read_log
from spooflens.epoch_table import EpochTable, Skipped


def _sentence(body: str) -> str:
    check = 0
    for c in body.encode():
        check ^= c
    return f"${body}*{check:02X}"


def _epoch(hhmmss: str, date: str, fix: bool = True) -> list[str]:
    """One second of the simulator-fed receiver: GGA, GSV, GSA, RMC (its order)."""
    if not fix:
        bodies = [f"GPGGA,{hhmmss}.00,,,,,0,00,99.99,,,,,,", f"GPRMC,{hhmmss}.00,V,,,,,,,{date},,,N"]
        return [_sentence(b) for b in bodies]
    bodies = [
        f"GPGGA,{hhmmss}.00,4155.817280,N,01236.695386,E,1,08,1.6,67.3,M,45.0,M,,",
        "GPGSV,2,1,08,13,74,331,20,28,61,076,23,15,39,307,19,05,38,207,14",
        "GPGSV,2,2,08,30,36,063,37,17,13,130,37,24,13,265,20,07,06,072,40",
        "GPGSA,A,3,07,13,15,17,24,28,30,,,,,,2.2,1.5,1.6",
        f"GPRMC,{hhmmss}.00,A,4155.817280,N,01236.695386,E,000.0,,{date},,,A",
    ]
    return [_sentence(b) for b in bodies]


def _write(path: Path, epochs: list[tuple[str, str]]) -> Path:
    path.write_text("\n".join(line for hhmmss, date in epochs for line in _epoch(hhmmss, date)) + "\n")
    return path


def _seconds(hhmm: str, first: int, n: int) -> list[str]:
    return [f"{hhmm}{s:02d}" for s in range(first, first + n)]


def _dates(table: EpochTable) -> list[Skipped]:
    return [s for s in table.skipped if "date" in s.reason]


def test_each_recording_of_a_joined_file_keeps_its_own_date(tmp_path: Path) -> None:
    """02_truth_then_spoof: 18 s dated 200319 from 10:08:36, then 29 s dated 110319 from 10:00:39. The
    date most of the file has (the second's) was given to both; each now has its own, and the one date
    that jumps inside the first (a second read a day ahead) is listed in the first recording only."""
    first = [(t, "200319") for t in _seconds("1008", 36, 18)]
    first[5] = (first[5][0], "210319")
    second = [(t, "110319") for t in _seconds("1000", 39, 21) + _seconds("1001", 0, 8)]
    table = read_log(_write(tmp_path / "truth_then_spoof.nmea", first + second))
    assert len(table.segments) == 2
    one, two = table.segment(0), table.segment(1)
    assert one.absolute_iso(0.0) == "2019-03-20T10:08:36+00:00"
    assert two.absolute_iso(0.0) == "2019-03-11T10:00:39+00:00"
    assert len(one.fixes) == 18 and len(two.fixes) == 29
    (jump,) = _dates(one)
    assert jump.count == 1 and jump.action == "repaired"
    assert "at 10:08:41 RMC's date is 2019-03-21" in jump.reason and "1 day forward" in jump.reason
    assert "read as 2019-03-20 10:08:36 to 10:08:53, the date of 17 of its 18 dated sentences" in jump.reason
    assert not _dates(two)


def test_a_date_that_jumps_while_the_time_of_day_carries_on_is_said(tmp_path: Path) -> None:
    """01_true_with_spoof: real sky 11:00:18-22 dated 220219, the simulator from 11:00:43 dated 080219. One
    stretch of the time of day: read on the date most of its RMCs give, the jump said with its dates, size
    and time (it was a bare count: "dates that jump ... (not followed)")."""
    epochs = [(t, "220219") for t in _seconds("1100", 18, 5)] + [(t, "080219") for t in _seconds("1100", 43, 6)]
    table = read_log(_write(tmp_path / "true_with_spoof.nmea", epochs))
    assert not table.segments and len(table.fixes) == 11
    assert table.absolute_iso(0.0) == "2019-02-08T11:00:18+00:00"
    (jump,) = _dates(table)
    assert (jump.count, jump.action) == (5, "repaired")
    assert jump.reason == (
        "dates that jump against the continuous time of day, not followed: at 11:00:43 RMC's date is 2019-02-08 "
        "where the time of day, carried on from 2019-02-22 11:00:22, gives 2019-02-22: 14 days (2 weeks) back. "
        "The stretch is read as 2019-02-08 11:00:18 to 11:00:48, the date of 6 of its 11 dated sentences"
    )


def test_a_default_date_before_the_almanac_does_not_date_the_fixes(tmp_path: Path) -> None:
    """gpsd's MTK-3301 shape: five epochs on the receiver's default clock (1980-01-05 23:59:46-50), as many
    fixes on the real date afterwards. The tie between them dated the fixes 1980; each stretch has its own."""
    lines = [line for t in _seconds("2359", 46, 5) for line in _epoch(t, "050180", fix=False)]
    lines += [line for t in _seconds("0814", 34, 5) for line in _epoch(t, "230808")]
    path = tmp_path / "mtk.nmea"
    path.write_text("\n".join(lines) + "\n")
    table = read_log(path)
    assert table.absolute_iso(0.0) == "2008-08-23T08:14:34+00:00"
    assert not _dates(table)


def test_a_stretch_a_gps_week_rollover_off_is_read_on_the_others_date_and_said(tmp_path: Path) -> None:
    """gpsd's GP-320FW cold boot shape: fixes dated 2019-04-07, a reboot (one void second on a garbage clock,
    23:59:48 of 2006-12-16), then fixes from 00:04:10 dated 1999-08-22: 1024 weeks back, the same day to a
    10-bit week. The receiver's seconds stay on one day, the most common (as before), and the rollover is
    said beside the garbage date."""
    lines = [line for t in _seconds("0003", 43, 3) for line in _epoch(t, "070419")]
    lines += _epoch("235948", "161206", fix=False)
    lines += [line for t in _seconds("0004", 10, 10) for line in _epoch(t, "220899")]
    path = tmp_path / "rollover.nmea"
    path.write_text("\n".join(lines) + "\n")
    table = read_log(path)
    assert table.absolute_iso(0.0) == "1999-08-22T00:03:43+00:00" and len(table.fixes) == 13
    rolled, garbage = _dates(table)
    assert (rolled.count, rolled.action) == (3, "repaired")
    assert "(00:03:43 to 00:03:45) 7168 days (1024 weeks) forward" in rolled.reason
    assert "read on 1999-08-22 as the rest, not on 2019-04-07" in rolled.reason
    assert garbage.count == 1 and "at 00:04:10 RMC's date is 1999-08-22" in garbage.reason


def test_midnight_keeps_one_stretch(tmp_path: Path) -> None:
    """The date advancing exactly when the time of day wraps is no jump."""
    epochs = [(t, "311219") for t in _seconds("2359", 57, 3)] + [(t, "010120") for t in _seconds("0000", 0, 3)]
    table = read_log(_write(tmp_path / "midnight.nmea", epochs))
    assert list(table.fixes["t_s"]) == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0] and not _dates(table)
    assert table.absolute_iso(3.0) == "2020-01-01T00:00:00+00:00"
