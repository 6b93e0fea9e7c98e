"""A receiver's reported fixes against the solution of its own pseudoranges (RAIM's), on a real phone."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
from paths import real_log

from readers import read_log
from spooflens.detectors.raim import run_raim
from spooflens.pipeline.registry import AnalysisContext, AnalyzeOptions

LOG = "android_gnsslogger/gps-measurement-tools/pseudoranges_log_2016_06_30_21_26_07.txt"
NAV = "android_gnsslogger/gps-measurement-tools/hour1820.16n"


def _own_fix_findings(table) -> list[str]:
    result = run_raim(AnalysisContext(table, AnalyzeOptions()))
    return [f.text for f in result.findings if "its reported fixes" in f.text]


def test_a_phone_whose_fixes_leave_its_own_pseudoranges_is_a_finding_and_a_clean_one_is_not() -> None:
    table = read_log(real_log(LOG), {"nav": str(real_log(NAV))})
    # clean: the phone's fixes lie a median 13 m, at most 53 m, from its own pseudoranges' solution
    assert _own_fix_findings(table) == []
    raim = run_raim(AnalysisContext(table, AnalyzeOptions()))
    distance = next(s for s in raim.series if s.name == "phone/fix_from_own_solution").values
    assert 5.0 < np.nanmedian(distance) < 20.0 and np.nanmax(distance) < 60.0
    # the fixes moved 300 m north from 100 s, the raw measurements left as they were (the position
    # output falsified: what `spooflens inject` makes of a GnssLogger log, or a mock location)
    fixes = table.fixes.copy()
    late = fixes["t_s"].to_numpy() >= 100.0
    fixes.loc[late, "lat_deg"] += np.degrees(300.0 / 6_371_000.0)
    (text,) = _own_fix_findings(replace(table, fixes=fixes))
    found = re.search(r"up to (\d+) m from the position its own pseudoranges give .*?, ([\d.]+)-([\d.]+) s", text)
    assert found, text
    peak, start = float(found.group(1)), float(found.group(2))
    assert 280.0 <= peak <= 360.0 and 100.0 <= start <= 101.0


def test_each_alarm_carries_the_size_of_its_own_run_of_exclusions() -> None:
    # the real Pixel 4 XL drive (GSDC 2021, 5 s epochs) with G09 a counterfeit 2 km late over 200-300 s and
    # 300 m late over 600-800 s: two alarms, each with its own run's median and largest inconsistency (the
    # verdict weighs that size against a reflection's), not the satellite's over the whole log
    import pytest
    from paths import REAL

    from spooflens.attacks import apply_attack, parse_attack

    log = REAL / "corpus/gnss_lib_py/gsdc2021_Pixel4XL_derived.csv"
    if not log.exists():
        pytest.skip(f"real log absent: {log}")
    table = read_log(log)
    for spec in ("pr_delay:svs=G09,delay=2000,start=200,end=300", "pr_delay:svs=G09,delay=300,start=600,end=800"):
        table, _ = apply_attack(table, parse_attack(spec))
    alarms = [a for a in run_raim(AnalysisContext(table, AnalyzeOptions())).alarms if a.satellites == ("G09",)]
    assert len(alarms) == 2, alarms
    for a, (start, end) in zip(alarms, ((200.0, 300.0), (600.0, 800.0)), strict=True):
        assert start <= a.start_s <= start + 10.0 and end - 15.0 <= a.end_s <= end  # 5 s epochs, some missing
    first, second = alarms
    assert first.range_error_m is not None and 1900.0 < first.range_error_m < 2100.0
    assert second.range_error_m is not None and 250.0 < second.range_error_m < 350.0
    assert second.peak_statistic < 400.0 < first.peak_statistic


def test_as_many_satellites_as_unknowns_is_no_test() -> None:
    """A reference station's file with 4 satellites with orbits at each epoch: the residuals are zero whatever
    the ranges, and RAIM was counted among the detectors behind "NO SPOOFING"."""
    table = read_log(real_log(LOG), {"nav": str(real_log(NAV))})
    obs = table.observations
    with_orbit = obs[np.isfinite(obs["sv_x_m"].to_numpy(dtype=float))]
    four = with_orbit.groupby("t_s", group_keys=False).head(4)
    result = run_raim(AnalysisContext(replace(table, observations=four.reset_index(drop=True)), AnalyzeOptions()))
    assert not result.ran
    assert result.reason == "phone: not judged, no epoch with a satellite more than the position and clock it solves"
