"""What each detector's model requires of the data, checked before it runs, on real logs (and real logs
made to break one precondition: decimated, cut short, relayed, a station dragged away)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from paths import HUSKY_BAG, SAMPLE_LOGS, real_log

from spooflens.epoch_table import EpochTable
from spooflens.gnss.same_receiver import group_receivers
from spooflens.gnss.stations import surveyed_station
from spooflens.output.summary import build_summary
from spooflens.pipeline import preconditions as pc
from spooflens.pipeline.registry import REQUIREMENTS, AnalysisContext, AnalyzeOptions, run_analyses
from spooflens.pipeline.verdict import decide
from spooflens.service import read_table


def _ctx(table: EpochTable, **extra: object) -> AnalysisContext:
    return AnalysisContext(table, AnalyzeOptions(extra=dict(extra)))


def _check(name: str, table: EpochTable, **extra: object):  # type: ignore[no-untyped-def]
    return pc.PRECONDITIONS[name].check(_ctx(table, **extra))


@pytest.fixture(scope="module")
def husky() -> EpochTable:
    return read_table(HUSKY_BAG, {}, show_progress=False)


def _first(table: EpochTable, seconds: float) -> EpochTable:
    """The table's first `seconds` of every frame (a shorter real log)."""
    cut = {n: getattr(table, n)[getattr(table, n)["t_s"] <= seconds].reset_index(drop=True) for n in ("imu", "fixes")}
    return replace(table, **cut)


# --- the INS -------------------------------------------------------------------------------------------


def test_the_husky_imu_at_30_hz_is_fit_for_strapdown_and_its_395_s_for_noise_learning(husky: EpochTable) -> None:
    for name in (pc.STRAPDOWN_IMU, pc.INERTIAL_SPAN, pc.NOISE_LEARNING):
        assert _check(name, husky) is None, name


def test_an_imu_decimated_to_telemetry_rate_is_not_mechanised(husky: EpochTable) -> None:
    # a MAVLink telemetry log carries SCALED_IMU at about 0.7 Hz: the husky's 30 Hz IMU, every 43rd sample
    slow = replace(husky, imu=husky.imu.iloc[::43].reset_index(drop=True))
    unmet = _check(pc.STRAPDOWN_IMU, slow)
    assert unmet is not None and unmet.stops
    assert unmet.text == "IMU /imu/data at 0.7 Hz: strapdown needs >= 20 Hz"
    assert unmet.values["rate_hz"] == pytest.approx(30.0 / 43, rel=0.01)


def test_a_long_gap_in_the_imu_is_named_with_its_time_and_navigated_around(husky: EpochTable) -> None:
    t = husky.imu["t_s"].to_numpy(float)
    holed = replace(husky, imu=husky.imu[(t < 100.0) | (t > 102.0)].reset_index(drop=True))
    unmet = _check(pc.STRAPDOWN_IMU, holed)
    assert unmet is not None and not unmet.stops  # limits: the navigation runs on each side of the gap
    assert unmet.found.startswith("IMU /imu/data stops for 2.0") and "at 100.0 s" in unmet.found
    assert "no gap over 0.5 s" in unmet.requires
    assert "navigated anew on each stretch between the gaps, on 0.0-100.0 s, 102.0-" in unmet.requires
    assert "not navigated on 100.0-102.0 s (the IMU stopped for 2.0" in unmet.requires
    assert unmet.values["gaps"] == 1


def test_an_imu_whose_stretches_between_gaps_are_all_too_short_is_not_mechanised(husky: EpochTable) -> None:
    # a 1 s gap every 40 s: no stretch holds the 50 fixes over 30 s after the filter's 20 s the noise needs
    t = husky.imu["t_s"].to_numpy(float)
    holed = replace(husky, imu=husky.imu[(t - t[0]) % 40.0 < 39.0].reset_index(drop=True))
    unmet = _check(pc.STRAPDOWN_IMU, holed)
    assert unmet is not None and unmet.stops
    assert "no stretch between its gaps is long enough to navigate" in unmet.found
    assert unmet.values["navigated_s"] == 0.0


def test_detectors_on_a_slow_imu_do_not_run_and_say_why_in_the_json(husky: EpochTable) -> None:
    slow = replace(husky, imu=husky.imu.iloc[::43].reset_index(drop=True))
    results = run_analyses(slow)
    by = {r.name: r for r in results}
    for name in ("navigation", "kf_innovation", "glrt", "mlrt_calibrated"):
        assert not by[name].ran, name
        assert by[name].reason == "IMU /imu/data at 0.7 Hz: strapdown needs >= 20 Hz"
    assert by["gnss_consistency"].ran
    summary = build_summary(slow, results, decide(results))
    kf = next(a for a in summary["analyses"] if a["name"] == "kf_innovation")
    assert kf["precondition"]["name"] == "strapdown_imu"
    assert kf["precondition"]["values"]["longest_gap_s"] > 1.0
    assert "kf_innovation" in summary["verdict"]["detectors_not_run"]


def test_a_log_shorter_than_the_filter_settles_runs_no_inertial_test(husky: EpochTable) -> None:
    short = _first(husky, 15.0)
    unmet = _check(pc.INERTIAL_SPAN, short)
    assert unmet is not None and unmet.found.startswith("GNSS with the IMU for 1")
    assert "20 s the filter settles in" in unmet.requires


def test_noise_learning_says_what_a_short_log_cannot_learn_and_does_not_stop(husky: EpochTable) -> None:
    minutes = _check(pc.NOISE_LEARNING, _first(husky, 120.0))
    assert minutes is not None and not minutes.stops
    assert "slow wander" in minutes.requires and "poorly determined" in minutes.requires
    seconds = _check(pc.NOISE_LEARNING, _first(husky, 40.0))
    assert seconds is not None and not seconds.stops
    assert "nothing was learned, the prior stands" in seconds.requires


# --- two receivers -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("log", "receivers"),
    [("corpus/gpsd/sirfstarv-nmea.log", ("GP", "GL", "GN")), ("corpus/gpsd/quectel-eg25-g.log", ("GN", "GP"))],
)
def test_nmea_talkers_of_one_receiver_are_one_receiver(log: str, receivers: tuple[str, ...]) -> None:
    table = read_table(real_log(log), {}, show_progress=False)
    (group,) = group_receivers(table)
    assert group.receivers == receivers
    assert (
        group.describe()
        == f"receivers {', '.join(receivers)} are one receiver: NMEA talkers of one stream ({log.split('/')[-1]})"
    )
    unmet = _check(pc.INDEPENDENT_RECEIVERS, table)
    assert unmet is not None and "need two receivers with independent errors" in unmet.requires


def _relayed_copy(table: EpochTable, rid: str, delay_s: float, decimals_of_minutes: int) -> EpochTable:
    """The receiver's fixes once more under a second source, as a multiplexer or an instrument bus passes
    them on: later by a constant delay, written with fewer decimals of minutes."""
    fx = table.fixes_of(rid).copy()

    def rounded(deg: np.ndarray) -> np.ndarray:
        whole = np.trunc(deg)
        return whole + np.round((deg - whole) * 60.0, decimals_of_minutes) / 60.0

    fx = fx.assign(
        receiver_id="mux/GP",
        t_s=fx["t_s"] + delay_s,
        lat_deg=rounded(fx["lat_deg"].to_numpy(float)),
        lon_deg=rounded(fx["lon_deg"].to_numpy(float)),
    )
    fixes = pd.concat([table.fixes, fx], ignore_index=True).sort_values("t_s", kind="stable")
    return replace(table, fixes=fixes.reset_index(drop=True))


def test_one_receiver_relayed_under_a_second_source_with_a_delay_and_coarser_rounding_is_one_receiver() -> None:
    table = read_table(real_log("nmea_boats/gpsd_bundg_zeus_9.log"), {}, show_progress=False)
    (rid,) = table.receivers()
    relayed = _relayed_copy(table, rid, delay_s=1.0, decimals_of_minutes=3)
    (group,) = group_receivers(relayed)
    assert group.receivers == (rid, "mux/GP")
    assert "mux/GP repeats " in group.why[0] and "1.00 s later: one receiver relayed twice" in group.why[0]
    assert _check(pc.INDEPENDENT_RECEIVERS, relayed) is not None
    # at the same time tags nothing says which one relays the other (a yacht's GP and its instrument bus's II)
    (same,) = group_receivers(_relayed_copy(table, rid, delay_s=0.0, decimals_of_minutes=3))
    assert f"{rid} and mux/GP write the same fixes at " in same.why[0] and "at the same times" in same.why[0]


def test_two_real_receivers_and_two_under_one_spoofer_antenna_stay_two() -> None:
    gsi = read_table(real_log("rinex_gsi_pair"), {}, show_progress=False)
    assert [g.receivers for g in group_receivers(gsi)] == [("0759",), ("3040",)]
    # the sample's second receiver is taken over by the first's single-antenna spoofer from 60 s: the
    # baseline collapses, yet each receiver keeps its own noise, so the pair is not called one receiver
    sample = read_table(SAMPLE_LOGS / "dual_receiver.mcap", {}, show_progress=False)
    assert len(group_receivers(sample)) == 2
    assert _check(pc.INDEPENDENT_RECEIVERS, sample) is None


# --- raw observations and stations --------------------------------------------------------------------


def test_three_epochs_of_raw_observations_teach_no_noise_scale() -> None:
    table = read_table(real_log("corpus/georinex/14601736.18o"), {}, show_progress=False)
    # the receiver flags 13 of its 37 phases lost lock (LLI 1): no carrier rate into those, and still two
    # epochs have carrier rates of 5 satellites (the arcs continue from the flagged phases)
    for name, epochs in ((pc.CARRIER_CONTINUITY, 2), (pc.PSEUDORANGE_ARCS, 2)):
        unmet = _check(name, table)
        assert unmet is not None and unmet.values == {"epochs/st": epochs}, name
        assert "20 epochs needed" in unmet.requires


def test_carrier_rates_need_epochs_at_most_a_minute_apart_pseudorange_changes_two() -> None:
    table = read_table(real_log("rinex_gsi_pair/07590920.05o"), {}, show_progress=False)
    assert _check(pc.CARRIER_CONTINUITY, table) is None and _check(pc.PSEUDORANGE_ARCS, table) is None
    epochs = np.unique(table.observations["t_s"].to_numpy(float))[::3]  # 90 s apart; this log has no Doppler
    sparse = replace(table, observations=table.observations[table.observations["t_s"].isin(epochs)])
    unmet = _check(pc.CARRIER_CONTINUITY, sparse)
    assert unmet is not None and unmet.found.startswith("carrier-phase rates (or Doppler) of 5 or more satellites at 0")
    assert _check(pc.PSEUDORANGE_ARCS, sparse) is None


def _dragged(table: EpochTable, rid: str, from_s: float, mps: float) -> EpochTable:
    """The receiver's fixes moved north at `mps` from `from_s` on (what a spoofer does to a station)."""
    fx = table.fixes
    t = fx["t_s"].to_numpy(float)
    moved = (fx["receiver_id"] == rid).to_numpy() & (t >= from_s)
    lat = fx["lat_deg"].to_numpy(float).copy()
    lat[moved] += mps * (t[moved] - from_s) / 111_320.0
    return replace(table, fixes=fx.assign(lat_deg=lat))


def test_a_station_whose_fixes_a_spoofer_drags_away_later_stays_a_known_station() -> None:
    table = read_table(real_log("rinex_gsi_pair/07590920.05o"), {}, show_progress=False)
    assert _check(pc.INDEPENDENT_REFERENCE, table) is None
    # dragged at 2 m/s from 10 minutes on, for the 50 minutes left: over the whole log most 30 s spans
    # move, but its first minutes stayed put, and the header is where those began
    late = _dragged(table, "0759", 600.0, 2.0)
    found, _ = pc.known_stations(_ctx(late))
    assert "0759" in found and "first 5 min" in found["0759"].source  # type: ignore[attr-defined]
    # a log shorter than those minutes says how much of it was judged, not "its first 5 min"
    short = replace(table, fixes=table.fixes[table.fixes["t_s"] <= 240.0].reset_index(drop=True))
    found, _ = pc.known_stations(_ctx(short))
    assert "0% of 30 s spans of its 240 s" in found["0759"].source  # type: ignore[attr-defined]
    # shorter than a span (a 24 s static u-blox was said to have "0% of 30 s spans of its 24 s"): first to last fix
    first = table.fixes[table.fixes["receiver_id"] == "0759"].iloc[:25].reset_index(drop=True)
    brief = replace(table, fixes=first.assign(t_s=np.arange(25.0)))  # its first 25 fixes taken 1 s apart
    found, _ = pc.known_stations(_ctx(brief))
    assert "from its first fix to its last, 24 s later (no 30 s span in it), within 0.5 m/s" in found["0759"].source  # type: ignore[attr-defined]
    # a station logging every 5 min has 2 fixes in those minutes: judged on its first 10, and with fewer than 3
    # fixes not judged at all (it was said to move)
    fx = table.fixes[table.fixes["receiver_id"] == "0759"]
    sparse = replace(table, fixes=fx.iloc[::10].reset_index(drop=True))
    found, _ = pc.known_stations(_ctx(sparse))
    assert "0% of spans between fixes of its first 10 fixes (45 min)" in found["0759"].source  # type: ignore[attr-defined]
    two = replace(sparse, fixes=sparse.fixes.iloc[:2])
    reason = "2 fix(es), too few to tell whether it stayed put: its RINEX header position is not used as a station"
    assert surveyed_station(two, "0759") == (None, reason)
    # moving from the start, it is no station: its header is only where it started
    early = _dragged(table, "0759", 0.0, 2.0)
    unmet = _check(pc.INDEPENDENT_REFERENCE, early)
    assert unmet is not None and "the receiver moves" in unmet.found


def test_the_baseline_error_keeps_running_when_a_spoofer_moves_one_station_of_the_pair() -> None:
    gsi = read_table(real_log("rinex_gsi_pair"), {}, show_progress=False)
    assert _check(pc.SURVEYED_SITES, gsi) is None
    moved = _dragged(gsi, "3040", 1200.0, 1.0)
    assert _check(pc.SURVEYED_SITES, moved) is None
    by = {r.name: r for r in run_analyses(moved) if r.name.startswith("baseline")}
    assert by["baseline_error"].ran and by["baseline_error"].alarms


def test_a_receiver_time_not_beside_the_log_clock_says_how_many_fixes_had_both() -> None:
    # a GnssLogger v1.4 log's Fix lines carry no elapsedRealtimeNanos: "0 fixes" beside 8 fixes read
    table = read_table(real_log("rinex_gsi_pair/07590920.05o"), {}, show_progress=False)
    n = len(table.fixes)
    missing = REQUIREMENTS["time_offset"].missing(table)
    assert missing is not None and missing.endswith(f"; 0 of {n} fixes have both, 20 needed)")
