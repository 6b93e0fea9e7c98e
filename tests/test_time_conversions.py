"""Every time conversion round-trips, and leap seconds are applied by the right clock.

The expected values come from an independent source: the dates of the 18 leap seconds (IERS
Bulletin C, 1981-07-01 to 2017-01-01) and Python's `datetime`, never the lookup table under test.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from readers.rinex.text import calendar_ns
from readers.ubx import _gps_of_itow
from spooflens.epoch_table import (
    GPS_EPOCH_UNIX_NS,
    EpochTable,
    gps_ns_of_unix_ns,
    gps_seconds_of_unix_ns,
    unix_ns_of_gps_ns,
    unix_ns_of_gps_seconds,
    utc_gps_offset_ns,
)

NS = 1_000_000_000
# the days a leap second ended (UTC midnight after 23:59:60): GPS - UTC became 1, 2, ... 18 s
LEAP_MIDNIGHTS = [
    "1981-07-01", "1982-07-01", "1983-07-01", "1985-07-01", "1988-01-01", "1990-01-01", "1991-01-01",
    "1992-07-01", "1993-07-01", "1994-07-01", "1996-01-01", "1997-07-01", "1999-01-01", "2006-01-01",
    "2009-01-01", "2012-07-01", "2015-07-01", "2017-01-01",
]  # fmt: skip
UNIX_1980 = GPS_EPOCH_UNIX_NS
UNIX_2100 = 4_102_444_800 * NS


def _unix_ns(day: str, seconds: int = 0) -> int:
    t = dt.datetime.fromisoformat(day).replace(tzinfo=dt.UTC) + dt.timedelta(seconds=seconds)
    return int(t.timestamp()) * NS


def _expected_leaps(unix_ns: int) -> int:
    return sum(unix_ns >= _unix_ns(day) for day in LEAP_MIDNIGHTS)


@pytest.mark.parametrize("k", range(len(LEAP_MIDNIGHTS)))
def test_gps_of_utc_around_each_leap_second(k: int) -> None:
    midnight = _unix_ns(LEAP_MIDNIGHTS[k])
    # the second before midnight still has k leap seconds, midnight and the 17 s after it k + 1: the
    # old lookup (UTC looked up in a GPS-keyed table) was one second short exactly there
    for offset_s, leaps in [(-1, k), *((s, k + 1) for s in range(0, 18))]:
        unix = midnight + offset_s * NS
        assert gps_seconds_of_unix_ns(unix) == (unix - UNIX_1980) / NS + leaps
        assert unix_ns_of_gps_seconds(gps_seconds_of_unix_ns(unix)) == unix


def test_known_instants() -> None:
    assert gps_seconds_of_unix_ns(_unix_ns("2017-01-01")) == 1167264018.0
    assert gps_seconds_of_unix_ns(_unix_ns("2016-12-31", 86399)) == 1167264016.0
    assert gps_seconds_of_unix_ns(UNIX_1980) == 0.0
    # the leap second itself (GPS 1167264017) reads as a second 23:59:59, as a UNIX clock shows it
    assert unix_ns_of_gps_seconds(1167264017.0) == _unix_ns("2016-12-31", 86399)


@settings(max_examples=300, deadline=None)
@given(st.integers(UNIX_1980, UNIX_2100))
def test_utc_to_gps_to_utc_is_identity(unix_ns: int) -> None:
    gps = gps_ns_of_unix_ns(unix_ns)
    assert int(gps) == unix_ns - UNIX_1980 + _expected_leaps(unix_ns) * NS
    assert int(unix_ns_of_gps_ns(gps)) == unix_ns
    assert int(utc_gps_offset_ns(unix_ns - UNIX_1980)) == _expected_leaps(unix_ns) * NS


@settings(max_examples=300, deadline=None)
@given(st.integers(0, UNIX_2100 - UNIX_1980))
def test_gps_to_utc_to_gps_is_identity_outside_leap_seconds(gps_ns: int) -> None:
    unix = int(unix_ns_of_gps_ns(gps_ns))
    back = int(gps_ns_of_unix_ns(unix))
    leap_seconds = [(_unix_ns(d) - UNIX_1980) + k * NS for k, d in enumerate(LEAP_MIDNIGHTS)]  # GPS of 23:59:60
    inside = any(start <= gps_ns < start + NS for start in leap_seconds)
    assert back == (gps_ns - NS if inside else gps_ns)


def test_conversions_are_monotonic_and_vectorised() -> None:
    unix = np.arange(_unix_ns("2016-12-31", 86390), _unix_ns("2017-01-01", 10), NS // 4)
    gps = gps_ns_of_unix_ns(unix)
    assert np.all(np.diff(gps) > 0)
    np.testing.assert_array_equal(unix_ns_of_gps_ns(gps), unix)


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 10**7), st.sampled_from(["gps", "unix"]), st.floats(0.0, 1e5, allow_nan=False))
def test_epoch_table_clocks_agree(t0_s: int, reference: str, t_s: float) -> None:
    """A table's times as UTC and as GPS seconds describe one instant, whichever clock the log keeps."""
    t0_ns = (1_400_000_000 if reference == "unix" else 1_000_000_000) * NS + t0_s * NS
    table = EpochTable(Path("x"), "test", t0_ns, reference)
    unix, gps = table.unix_ns(t_s), table.gps_seconds(t_s)
    assert unix is not None and gps is not None
    gps_ns = int(gps_ns_of_unix_ns(unix))
    leap_second = reference == "gps" and abs(float(gps) * NS - gps_ns - NS) < 1e4  # 23:59:60 reads as 23:59:59
    assert abs(gps_ns / NS - float(gps)) < 2e-6 or leap_second
    assert abs(int(table.absolute_ns(t_s)) - t0_ns - round(t_s * 1e9)) <= 1


@settings(max_examples=200, deadline=None)
@given(st.datetimes(dt.datetime(1980, 1, 6), dt.datetime(2199, 12, 31)))
def test_rinex_calendar_matches_datetime(when: dt.datetime) -> None:
    """RINEX epoch fields (year ... seconds with 7 decimals) -> ns on the file's own scale."""

    def col(v: int) -> np.ndarray:
        return np.array([v], dtype=np.int64)

    micro = when.second * 10_000_000 + when.microsecond * 10
    ns, ok = calendar_ns(
        col(when.year), col(when.month), col(when.day), col(when.hour), col(when.minute), col(micro), col(7)
    )
    assert ok[0]
    assert int(ns[0]) == int(when.replace(tzinfo=dt.UTC).timestamp()) * NS + when.microsecond * 1000


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 4_000_000_000_000), st.integers(-302_000_000, 302_000_000))
def test_ubx_itow_is_put_in_the_week_of_its_reference(gps_ms: int, ref_offset_ms: int) -> None:
    """iTOW (ms of the GPS week) back to GPS seconds, with a reference within half a week."""
    itow = gps_ms % 604_800_000
    out = _gps_of_itow(np.array([itow], dtype=np.int64), (gps_ms + ref_offset_ms) / 1000.0)
    assert out[0] == pytest.approx(gps_ms / 1000.0, abs=1e-6)
