"""A receiver's time tags against the time its pseudoranges fit the broadcast orbits at
(`spooflens.gnss.time_tags`): simulated tags moved by a known offset, a counterfeit satellite that must not
pass for one, and the real CEDA station, whose Galileo pseudoranges fit the orbits 2.98 s after its tags."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from paths import real_log

from readers import read_log
from spooflens.detectors import raim
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import geodetic_to_ecef
from spooflens.gnss.ephemeris import states_at_transmission, synthetic_constellation
from spooflens.gnss.single_point import SinglePointOptions, ranged_by_receiver
from spooflens.gnss.time_tags import TimeTagFit, time_tag_fit
from spooflens.pipeline.preconditions import ORBIT_TIMING
from spooflens.pipeline.registry import AnalysisContext, AnalyzeOptions
from spooflens.simulation.observations import ObservationNoise, simulate_observations

T0 = 1_400_000_000.0  # GPS seconds, 2024-05
BOSTON = geodetic_to_ecef(42.37, -71.1, 30.0)
CEDA = "corpus/georinex/CEDA00USA_R_20182100000_23H_15S_MO.rnx.gz"
GSI = "rinex_gsi_pair/07590920.05o"


def _tagged(tags_behind_s: float, seed: int = 0) -> pd.DataFrame:
    """A static receiver's observations at 5 s over 10 min, its satellites put where a reader whose time tags
    are `tags_behind_s` behind the measurement times puts them."""
    rng = np.random.default_rng(seed)
    eph = synthetic_constellation(T0, rng=rng)
    t = np.arange(0.0, 600.0, 5.0)
    rx = np.repeat(BOSTON[None], len(t), axis=0)
    obs = simulate_observations("rx", t, T0 + t, rx, np.zeros_like(rx), eph, ObservationNoise(), rng)
    tags = T0 + obs["t_s"].to_numpy(float) - tags_behind_s
    states = states_at_transmission(eph, obs["sv_id"].to_numpy(), tags, obs["pseudorange_m"].to_numpy(float))
    return obs.assign(**states.columns())


def _fit(obs: pd.DataFrame) -> TimeTagFit:
    fit = time_tag_fit(obs)
    assert fit is not None
    return fit


@pytest.mark.parametrize("behind_s", [3.0, -18.0])
def test_tags_off_the_measurement_times_are_found_with_their_offset(behind_s: float) -> None:
    # 3 s as on the CEDA station; -18 s as a log written in UTC and read as GPS time
    fit = _fit(_tagged(behind_s))
    assert fit.offset_s == pytest.approx(behind_s, abs=0.01)
    assert fit.tags_off()
    assert fit.scale_logged > 100.0 and fit.scale_moved < 3.0


def test_tags_at_the_measurement_times_are_not_off() -> None:
    fit = _fit(_tagged(0.0))
    assert abs(fit.offset_s) < 0.005 and not fit.tags_off()
    assert fit.scale_logged < 3.0


def test_a_counterfeit_satellite_is_no_time_fault() -> None:
    # one satellite 300 m late throughout (what `pr_delay` injects): its residuals change with the geometry
    # from epoch to epoch, which no one offset of all satellites explains
    obs = _tagged(0.0)
    late = obs["sv_id"] == "G13"
    obs.loc[late, "pseudorange_m"] += 300.0
    fit = _fit(obs)
    assert fit.scale_logged > 10.0
    assert not fit.tags_off()


def _ceda_hour() -> tuple[EpochTable, pd.DataFrame]:
    """CEDA and its Galileo rows of 07:40-08:40 GPS time (up to five satellites with orbits per epoch)."""
    table = read_log(real_log(CEDA))
    ((_, rows, _),) = ranged_by_receiver(table)
    clock = rows["t_s"].to_numpy(float) + 15.0  # the file starts at 00:00:15
    return table, rows[(clock >= 7 * 3600 + 40 * 60) & (clock < 8 * 3600 + 40 * 60)].reset_index(drop=True)


def test_ceda_galileo_pseudoranges_fit_the_orbits_three_seconds_after_their_tags() -> None:
    # an independent computation (textbook Galileo orbits, the station's surveyed position) gives the same
    # offset, 2.94-3.07 s over the day, and so do the file's GLONASS satellites against their own orbits
    table, hour = _ceda_hour()
    fit = time_tag_fit(hour, table.gps_seconds(hour["t_s"].to_numpy(float)), SinglePointOptions(iono=table.ionosphere))
    assert fit is not None and fit.epochs >= 30
    assert fit.offset_s == pytest.approx(2.98, abs=0.01)
    assert fit.tags_off()
    # kilometres at the logged times, the metre level of a good station once the tags are moved
    assert fit.scale_logged > 100.0 and fit.scale_moved < 2.0


def test_a_station_whose_tags_are_right_is_not_off() -> None:
    table = read_log(real_log(GSI))
    ((_, rows, t_gps),) = ranged_by_receiver(table)
    fit = time_tag_fit(rows, t_gps, SinglePointOptions(iono=table.ionosphere))
    assert fit is not None and abs(fit.offset_s) < 0.005 and not fit.tags_off()


def test_raim_does_not_judge_a_receiver_whose_tags_are_off() -> None:
    # before: RAIM ran on CEDA with a residual scale 683 times its a-priori and could exclude nothing
    ceda = raim.ANALYSIS.unmet(AnalysisContext(read_log(real_log(CEDA)), AnalyzeOptions()))
    assert [u.name for u in ceda] == [ORBIT_TIMING]
    assert "2.98 s after the logged times" in ceda[0].found
    assert raim.ANALYSIS.unmet(AnalysisContext(read_log(real_log(GSI)), AnalyzeOptions())) == []
