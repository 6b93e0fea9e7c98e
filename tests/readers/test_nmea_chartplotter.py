"""A sailboat's chartplotter (rob42/freeboard-server's test log, PacCup 2008, at ~8 kn): talker EC writes GGA, GLL
and RMC every ~2 s, but its time field moves in 10 s steps, five fixes under each time; its RMC carries the
magnetic variation (15.0 E) that the instruments' HDM and VHW headings (talker II) need to be true. The lines
are the log's own, shortened to ten cycles."""

from __future__ import annotations

from pathlib import Path

import pytest

from readers import read_log
from spooflens.epoch_table import EpochTable

CYCLES = [  # GGA, GLL, RMC of each fix, as the chartplotter wrote them
    (
        "$ECGGA,194320,3748.789,N,12226.838,W,1,06,2.0,-18.0,M,0.0,M,0.0,*4A",
        "$ECGLL,3748.791,N,12226.840,W,194320,A,A*47",
        "$ECRMC,194320,A,3748.791,N,12226.840,W,8.4,314.0,140708,015.0,E,A*1F",
    ),
    (
        "$ECGGA,194320,3748.794,N,12226.844,W,1,06,2.0,-17.0,M,0.0,M,0.0,*42",
        "$ECGLL,3748.794,N,12226.844,W,194320,A,A*46",
        "$ECRMC,194320,A,3748.794,N,12226.844,W,8.5,314.0,140708,015.0,E,A*1F",
    ),
    (
        "$ECGGA,194320,3748.798,N,12226.848,W,1,06,2.0,-17.0,M,0.0,M,0.0,*42",
        "$ECGLL,3748.798,N,12226.848,W,194320,A,A*46",
        "$ECRMC,194320,A,3748.798,N,12226.848,W,8.4,315.0,140708,015.0,E,A*1F",
    ),
    (
        "$ECGGA,194320,3748.802,N,12226.851,W,1,06,2.0,-17.0,M,0.0,M,0.0,*46",
        "$ECGLL,3748.802,N,12226.851,W,194320,A,A*42",
        "$ECRMC,194320,A,3748.802,N,12226.851,W,8.4,318.0,140708,015.0,E,A*16",
    ),
    (
        "$ECGGA,194320,3748.806,N,12226.855,W,1,06,2.0,-17.0,M,0.0,M,0.0,*46",
        "$ECGLL,3748.806,N,12226.855,W,194320,A,A*42",
        "$ECRMC,194320,A,3748.806,N,12226.855,W,8.4,322.0,140708,015.0,E,A*1F",
    ),
    (
        "$ECGGA,194330,3748.810,N,12226.858,W,1,06,2.0,-17.0,M,0.0,M,0.0,*4D",
        "$ECGLL,3748.810,N,12226.858,W,194330,A,A*49",
        "$ECRMC,194330,A,3748.810,N,12226.858,W,8.3,323.0,140708,015.0,E,A*12",
    ),
    (
        "$ECGGA,194330,3748.813,N,12226.862,W,1,06,2.0,-17.0,M,0.0,M,0.0,*47",
        "$ECGLL,3748.813,N,12226.862,W,194330,A,A*43",
        "$ECRMC,194330,A,3748.813,N,12226.862,W,8.2,323.0,140708,015.0,E,A*19",
    ),
    (
        "$ECGGA,194330,3748.816,N,12226.866,W,1,06,2.0,-17.0,M,0.0,M,0.0,*46",
        "$ECGLL,3748.816,N,12226.866,W,194330,A,A*42",
        "$ECRMC,194330,A,3748.816,N,12226.866,W,8.1,321.0,140708,015.0,E,A*19",
    ),
    (
        "$ECGGA,194330,3748.820,N,12226.869,W,1,06,2.0,-17.0,M,0.0,M,0.0,*4C",
        "$ECGLL,3748.820,N,12226.869,W,194330,A,A*48",
        "$ECRMC,194330,A,3748.820,N,12226.869,W,8.0,319.0,140708,015.0,E,A*19",
    ),
    (
        "$ECGGA,194330,3748.824,N,12226.873,W,1,06,2.0,-17.0,M,0.0,M,0.0,*43",
        "$ECGLL,3748.824,N,12226.873,W,194330,A,A*47",
        "$ECRMC,194330,A,3748.824,N,12226.873,W,7.9,319.0,140708,015.0,E,A*10",
    ),
]
# between two fixes: the sky's GSA (12 GPS satellites), the instruments' magnetic heading and speed log
BETWEEN = [
    "$GPGSA,A,3,32,23,25,13,08,04,06,16,07,27,20,03,1.4,0.9,1.1*35",
    "$IIHDM,306,M*39",
    "$IIVHW,,T,306,M,07.76,N,14.37,K*67",
]


def _sentence(body: str) -> str:
    check = 0
    for c in body.encode():
        check ^= c
    return f"${body}*{check:02X}"


def _read(path: Path, lines: list[str]) -> EpochTable:
    path.write_text("\n".join(lines) + "\n")
    return read_log(path)


def _log(kinds: tuple[str, ...] = ("GGA", "GLL", "RMC")) -> list[str]:
    return [line for cycle in CYCLES for line in [*cycle, *BETWEEN] if line[3:6] in kinds or not line.startswith("$EC")]


def test_fixes_under_a_time_already_used_keep_the_first_and_say_the_others(tmp_path: Path) -> None:
    """The ten fixes fell into two epochs, 19:43:20 and 19:43:30, and the first GGA of each was kept: eight
    positions were dropped without a word. Their times are not known finer than the 10 s step: still not used,
    but said, with the step and the fix interval."""
    table = _read(tmp_path / "paccup.nmea", _log())
    fixes = table.fixes
    assert len(fixes) == 2 and fixes["t_s"].tolist() == [0.0, 10.0]
    assert fixes["lat_deg"].tolist() == pytest.approx([37 + 48.789 / 60, 37 + 48.810 / 60])
    (said,) = [s for s in table.skipped if s.stream == "EC"]
    assert said.count == 8 and said.action == "skipped"
    assert "under a time of day already used" in said.reason and "their times are not known, not used" in said.reason
    assert "time moves in 10 s steps, its fixes come every ~2 s" in said.reason
    # a log of one time (pynmeagps' fixture writes twenty positions under one) says so, not "1 of its 1 times"
    (said,) = [s for s in _read(tmp_path / "one.nmea", _log()[:30]).skipped if s.stream == "EC"]
    assert said.count == 4 and "(the receiver's only time holds 5)" in said.reason


def test_a_bus_echo_of_identical_sentences_is_no_fix_of_its_own(tmp_path: Path) -> None:
    """Every sentence written twice (a multiplexer passing the bus on twice): the same two fixes, the same eight
    said, no stale relay."""
    table = _read(tmp_path / "echo.nmea", [line for line in _log() for _ in range(2)])
    assert len(table.fixes) == 2
    assert [(s.stream, s.count) for s in table.skipped if s.stream == "EC"] == [("EC", 8)]
    assert not [s for s in table.skipped if "stale" in s.reason]


def test_a_systems_gsa_repeated_in_one_epoch_is_not_summed(tmp_path: Path) -> None:
    """Without GGA the satellites used come from GSA: the five GPGSA of the five cycles under 19:43:20 were summed
    into 60 satellites; one system's list counts once."""
    fixes = _read(tmp_path / "no_gga.nmea", _log(("GLL", "RMC"))).fixes
    assert fixes["sats_used"].tolist() == [12, 12]


def test_fixes_under_one_time_beside_another_receiver_are_no_stale_relay(tmp_path: Path) -> None:
    """A second receiver at 1 Hz in the same file: five different GGA under one time across its epochs were taken
    for "a relay holding a stale fix" and the epoch dropped. A relay repeats one position; these are five."""
    lines = []
    for k, cycle in enumerate(CYCLES):
        for j in range(2):
            s = 20 + 2 * k + j
            lines.append(_sentence(f"GPGGA,1943{s:02d},3748.800,N,12226.850,W,1,09,1.0,2.0,M,-30.0,M,,"))
        lines += cycle
    table = _read(tmp_path / "two.nmea", lines)
    assert not [s for s in table.skipped if "stale" in s.reason]
    assert len(table.fixes[table.fixes["receiver_id"] == "EC"]) == 2


@pytest.mark.parametrize(("hemisphere", "true_deg"), [("E", 306.0 + 15.0), ("W", 306.0 - 15.0)])
def test_magnetic_headings_are_made_true_with_rmcs_variation(hemisphere: str, true_deg: float, tmp_path: Path) -> None:
    """HDM and VHW's magnetic heading were taken as true "without a variation" though every RMC of the log gives
    it: 15 degrees off. They are made true with the variation of the RMC nearest in time (east added, west
    taken off), and the repair says which variation."""
    lines = _log()
    if hemisphere == "W":
        lines = [_sentence(ln[1:-3].replace("015.0,E", "015.0,W")) if "RMC" in ln else ln for ln in lines]
    table = _read(tmp_path / "headings.nmea", lines)
    headings = table.headings
    assert set(headings["heading_id"]) == {"IIHDM", "IIVHW"} and len(headings) == 20
    assert headings["heading_deg"].tolist() == pytest.approx([true_deg] * 20)
    notes = {s.stream: s for s in table.skipped if s.stream.startswith("II")}
    for note in notes.values():
        assert note.action == "repaired" and note.count == 10
        assert f"made true with ECRMC's magnetic variation (15.0 deg {hemisphere})" in note.reason
