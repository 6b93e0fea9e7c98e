"""Derived GNSS measurement tables (GSDC 2021-2023, gnss_lib_py's names, smartLoc) read as raw
observations, their receiver positions as fixes, their ground truth beside them as truth; ground-truth
tables alone refused as what they are."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from paths import real_log

from readers import is_companion, read_log, sniff_format
from spooflens.cli import main
from spooflens.errors import ReaderError
from spooflens.geodesy import geodetic_to_enu
from spooflens.gnss.solved_fixes import with_solved_fixes

LIB = "corpus/gnss_lib_py"


def test_gsdc_2022_device_gnss() -> None:
    path = real_log(f"{LIB}/gsdc2022_device_gnss.csv")
    assert sniff_format(path) == "gnss_table"  # before: taken for a GnssLogger log and refused
    t = read_log(path)
    raw = pd.read_csv(path)
    assert t.time_reference == "gps" and t.absolute_iso(0.0).startswith("2021-04-29T22:35:2")
    obs = t.observations
    assert obs["t_s"].nunique() == 6 and set(obs["sv_id"].str[0]) >= {"G", "E", "C", "R"}
    # each pseudorange is the raw one less the table's inter-signal bias, the satellite states as given
    row = raw[(raw["Svid"] == 2) & (raw["ConstellationType"] == 1) & raw["RawPseudorangeMeters"].notna()].iloc[0]
    g02 = obs[obs["sv_id"] == "G02"].iloc[0]
    assert g02["pseudorange_m"] == pytest.approx(row["RawPseudorangeMeters"] - row["IsrbMeters"])
    assert g02["sv_x_m"] == pytest.approx(row["SvPositionXEcefMeters"])
    assert g02["sv_clock_bias_m"] == pytest.approx(row["SvClockBiasMeters"])
    # the table's least-squares positions are fixes; the ground truth beside it is the truth
    assert len(t.fixes) == 6 and len(t.truth) == 200
    enu = geodetic_to_enu(
        t.fixes["lat_deg"],
        t.fixes["lon_deg"],
        t.fixes["height_m"],
        *t.truth[["lat_deg", "lon_deg", "height_m"]].iloc[0],
    )
    assert np.hypot(enu[:, 0], enu[:, 1]).max() < 10.0
    # the observations mean what they say: a single-point solution from them lands beside the truth
    bare = copy.copy(t)
    bare.fixes = t.fixes.iloc[:0]
    solved = with_solved_fixes(bare).fixes
    enu = geodetic_to_enu(
        solved["lat_deg"], solved["lon_deg"], solved["height_m"], *t.truth[["lat_deg", "lon_deg", "height_m"]].iloc[0]
    )
    assert len(solved) == 6 and np.median(np.hypot(enu[:, 0], enu[:, 1])) < 30.0


def test_gsdc_2023_dual_frequency_keeps_one_l1_signal() -> None:
    t = read_log(real_log(f"{LIB}/gsdc2023_pixel7pro_device_gnss.csv"))
    obs = t.observations
    assert not obs.duplicated(["t_s", "sv_id"]).any()
    assert ((obs["carrier_freq_hz"] > 1.55e9) & (obs["carrier_freq_hz"] < 1.62e9)).all()
    assert any("outside the L1 band" in s.reason and s.count == 64 for s in t.skipped)
    assert len(t.truth) == 5 and t.absolute_iso(0.0).startswith("2023-09-07")


def test_gsdc_2021_derived_old_names_solve_in_mountain_view() -> None:
    t = read_log(real_log(f"{LIB}/gsdc2021_Pixel4XL_derived.csv"))
    assert t.observations["t_s"].nunique() == 286 and t.observations["sv_x_m"].notna().all()
    fixes = with_solved_fixes(t).fixes
    assert len(fixes) == 286
    assert fixes["lat_deg"].median() == pytest.approx(37.38, abs=0.05)
    assert fixes["lon_deg"].median() == pytest.approx(-122.07, abs=0.05)


def test_gnss_lib_py_names(tmp_path: Path) -> None:
    """The 2022 table under gnss_lib_py's names (as its AndroidDerived2022 loader renames it)."""
    src = real_log(f"{LIB}/gsdc2022_device_gnss.csv")
    raw = pd.read_csv(src)
    names = {1: "gps", 3: "glonass", 4: "qzss", 5: "beidou", 6: "galileo"}
    lib = pd.DataFrame(
        {
            "gps_millis": raw["ArrivalTimeNanosSinceGpsEpoch"] / 1e6,
            "gnss_id": raw["ConstellationType"].map(names),
            "sv_id": raw["Svid"],
            "signal_type": raw["SignalType"],
            "raw_pr_m": raw["RawPseudorangeMeters"],
            "intersignal_bias_m": raw["IsrbMeters"],
            **{f"{a}_sv_m": raw[f"SvPosition{a.upper()}EcefMeters"] for a in "xyz"},
            "b_sv_m": raw["SvClockBiasMeters"],
            "cn0_dbhz": raw["Cn0DbHz"],
            **{f"{a}_rx_wls_m": raw[f"WlsPosition{a.upper()}EcefMeters"] for a in "xyz"},
        }
    )
    path = tmp_path / "derived_navdata.csv"
    lib.to_csv(path, index=False)
    a, b = read_log(src).observations, read_log(path).observations
    a = a[a["sv_id"].isin(b["sv_id"])].reset_index(drop=True)
    np.testing.assert_array_equal(a["sv_id"], b["sv_id"])
    np.testing.assert_allclose(a["pseudorange_m"], b["pseudorange_m"])
    np.testing.assert_allclose(a["sv_x_m"], b["sv_x_m"])
    assert len(read_log(path).fixes) == 6


def test_smartloc_raw_with_its_reference_trajectory() -> None:
    t = read_log(real_log(f"{LIB}/smartloc_tu_chemnitz_berlin_1_raw.csv"))
    assert t.absolute_iso(0.0).startswith("2016-06-06") and t.observations["receiver_id"].unique().tolist() == ["ublox"]
    obs = t.observations
    assert set(obs["sv_id"].str[0]) == {"G", "R", "S"} and obs["doppler_hz"].notna().all()
    glonass = obs[obs["sv_id"].str.startswith("R")]
    assert glonass["carrier_freq_hz"].between(1598.0e6, 1606.0e6).all()  # G1 by the u-blox frequency slot
    assert obs["carrier_phase_cycles"].notna().any() and obs["cn0_dbhz"].between(10, 60).all()
    assert len(t.truth) == obs["t_s"].nunique()
    assert t.truth["lat_deg"].median() == pytest.approx(52.50, abs=0.05)  # Berlin


@pytest.mark.parametrize(
    "name", ["gsdc2021_Pixel4_ground_truth.csv", "gsdc2022_ground_truth.csv", "gsdc2023_pixel7pro_ground_truth.csv"]
)
def test_ground_truth_tables_are_companions_refused_as_logs(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    path = real_log(f"{LIB}/{name}")
    fmt = sniff_format(path)
    assert fmt == "gnss_table" and is_companion(path, fmt)
    assert main(["inspect", str(path)]) == 2
    assert "a ground-truth table (a reference trajectory), not a log" in capsys.readouterr().err


def test_another_table_is_refused_naming_what_it_lacks(tmp_path: Path) -> None:
    src = pd.read_csv(real_log(f"{LIB}/gsdc2021_Pixel4XL_derived.csv"), nrows=50)
    untimed = tmp_path / "no_time.csv"
    src.drop(columns=["millisSinceGpsEpoch", "receivedSvTimeInGpsNanos"]).to_csv(untimed, index=False)
    with pytest.raises(ReaderError, match=r"a table of GNSS measurements without a time \(columns .*gps_millis"):
        read_log(untimed)


def test_a_gnsslogger_log_takes_the_ground_truth_shipped_beside_it() -> None:
    """GSDC 2021: `gsdc2021_Pixel4_GnssLog.txt` beside `gsdc2021_Pixel4_ground_truth.csv` (GPS ms)."""
    t = read_log(real_log(f"{LIB}/gsdc2021_Pixel4_GnssLog.txt"))
    assert len(t.truth) == 199 and t.stream("truth", "truth").topic == "gsdc2021_Pixel4_ground_truth.csv"  # type: ignore[union-attr]
    enu = geodetic_to_enu(
        t.fixes["lat_deg"],
        t.fixes["lon_deg"],
        t.fixes["height_m"],
        *t.truth.iloc[0][["lat_deg", "lon_deg", "height_m"]],
    )
    assert np.median(np.hypot(enu[:, 0], enu[:, 1])) < 20.0  # the phone's own fixes beside the truth


def test_header_names_shifted_by_one_is_one_line_not_an_internal_error(tmp_path: Path) -> None:
    """Found by `bench fuzz --n 2000 --seed 40`: every time cell not a number, so no row at all (an empty
    id array became floats and failed a string test)."""
    lines = real_log(f"{LIB}/gsdc2021_Pixel4XL_derived.csv").read_text().splitlines()[:200]
    names = lines[0].split(",")
    shifted = tmp_path / "shifted.csv"
    shifted.write_text("\n".join([",".join([*names[1:], "extra"]), *lines[1:]]) + "\n")
    assert main(["inspect", str(shifted)]) == 2


def test_carriers_the_receiver_says_are_not_continuous_are_marked() -> None:
    """smartLoc's u-blox rows: a carrier only with cpValid (trkStat bit 1), and none with the half-cycle
    unresolved (bit 2 clear) or across a restarted lock time; the GSDC 2023 table's phone flags ten valid
    carriers HALF_CYCLE_REPORTED without HALF_CYCLE_RESOLVED (ADR state 17)."""
    path = real_log(f"{LIB}/smartloc_tu_chemnitz_berlin_1_raw.csv")
    raw = pd.read_csv(path, sep=";")
    trk = raw["Tracking status (trkStat) []"].fillna(0).astype(int)
    assert ((trk & 2) != 0).sum() == 277 and ((trk & 6) == 2).sum() == 128  # cpValid; of them halfCyc 0
    t = read_log(path)
    said = {s.reason.split(" (")[0]: s.count for s in t.skipped if "continuous" in s.reason}
    assert said == {"carriers across a loss of lock": 5, "carriers with an unresolved half-cycle ambiguity": 123}
    assert int((t.observations["carrier_arc_start"] == 0).sum()) == 149
    assert int(t.observations["carrier_phase_cycles"].notna().sum()) == 277  # kept as logged
    phone = read_log(real_log(f"{LIB}/gsdc2023_pixel7pro_device_gnss.csv"))
    (said_phone,) = [s for s in phone.skipped if "continuous" in s.reason]
    assert "HALF_CYCLE_REPORTED" in said_phone.reason and said_phone.count == 10
