"""Attack injection: exact offsets per kind, window respected, spoofed copies in every format."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pipeline_support import circling_table
from shared_inputs import read_shared

from readers import read_log
from spooflens.attacks import AttackError, AttackTruth, apply_attack, parse_attack, sidecar_path
from spooflens.cli import SIMULATE_FORMATS, main
from spooflens.geodesy import geodetic_to_enu
from spooflens.simulation.simulate import simulate
from spooflens.writers import SUFFIX, write_log


def _enu_shift(before: pd.DataFrame, after: pd.DataFrame) -> np.ndarray:
    """Each spoofed fix relative to its original, in the original's own local ENU frame."""
    return np.array(
        [
            geodetic_to_enu(a.lat_deg, a.lon_deg, a.height_m, b.lat_deg, b.lon_deg, b.height_m)
            for a, b in zip(after.itertuples(), before.itertuples(), strict=True)
        ]
    )


@pytest.mark.parametrize(
    ("text", "expect"),
    [
        ("ramp:rate=2,axes=en,start=100", lambda tau: np.c_[2 * tau, 2 * tau, 0 * tau]),
        ("step:offset=30,axes=u,start=100", lambda tau: np.c_[0 * tau, 0 * tau, 30 + 0 * tau]),
        ("velocity_pull:dv=0.1,axes=n,start=100", lambda tau: np.c_[0 * tau, 0.1 * tau, 0 * tau]),
        (
            "position_pull:offset=100,axes=e,ramp=50,start=100",
            lambda tau: np.c_[100 * np.minimum(tau / 50, 1), 0 * tau, 0 * tau],
        ),
    ],
)
def test_offsets_are_exact_and_only_inside_the_window(text: str, expect) -> None:
    table = circling_table(seconds=300.0)
    spoofed, truth = apply_attack(table, parse_attack(text + ",end=250"))
    shift = _enu_shift(table.fixes, spoofed.fixes)
    t = table.fixes["t_s"].to_numpy()
    inside = (t >= 100) & (t <= 250)
    # offsets are along the ellipsoid; the tangent-plane check differs by curvature (~d^2 / 2R)
    np.testing.assert_allclose(shift[inside], expect(t[inside] - 100), rtol=1e-4, atol=2e-2)
    np.testing.assert_allclose(shift[~inside], 0.0, atol=1e-9)
    assert (truth.start_s, truth.end_s, truth.receivers) == (100.0, 250.0, ["/gps/fix"])


def test_position_attacks_leave_velocity_alone_unless_asked() -> None:
    table = circling_table(seconds=120.0)
    untouched, _ = apply_attack(table, parse_attack("ramp:rate=3,start=10"))
    pd.testing.assert_frame_equal(untouched.fixes[["vel_e_mps", "vel_n_mps"]], table.fixes[["vel_e_mps", "vel_n_mps"]])
    moved, _ = apply_attack(table, parse_attack("ramp:rate=3,start=10,vel=1"))
    dv = moved.fixes["vel_e_mps"].to_numpy() - table.fixes["vel_e_mps"].to_numpy()
    assert np.allclose(dv[table.fixes["t_s"] >= 10], 3.0)


def test_hover_freezes_position_and_zeroes_velocity() -> None:
    table = circling_table(seconds=120.0)
    spoofed, _ = apply_attack(table, parse_attack("hover:start=40,end=80"))
    window = spoofed.fixes[(spoofed.fixes["t_s"] >= 40) & (spoofed.fixes["t_s"] <= 80)]
    assert window["lat_deg"].nunique() == 1 and window["lon_deg"].nunique() == 1
    assert np.allclose(window[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy(), 0.0)


def test_single_antenna_spoofer_collapses_the_baseline() -> None:
    sim = simulate("dual_receiver", seed=2, duration_s=120.0)
    spoofed, truth = apply_attack(sim.table, parse_attack("single_antenna:rate=1,start=60"))
    a, b = spoofed.fixes_of("/gps/fix"), spoofed.fixes_of("/gps2/fix")
    ref = a.iloc[0]
    pa = geodetic_to_enu(a["lat_deg"], a["lon_deg"], a["height_m"], ref.lat_deg, ref.lon_deg, ref.height_m)
    pb = geodetic_to_enu(b["lat_deg"], b["lon_deg"], b["height_m"], ref.lat_deg, ref.lon_deg, ref.height_m)
    baseline = np.linalg.norm(pa - pb, axis=1)
    t = a["t_s"].to_numpy()
    assert np.median(baseline[t < 55]) > 0.5  # 1.2 m lever arm plus noise before
    assert np.all(baseline[t >= 60] < 1e-6)  # identical positions after
    assert sorted(truth.receivers) == ["/gps/fix", "/gps2/fix"]


def test_parse_errors_name_kinds_and_parameters() -> None:
    with pytest.raises(AttackError, match=r"unknown attack kind 'rmap'.*ramp"):
        parse_attack("rmap:rate=2")
    with pytest.raises(AttackError, match=r"ramp: bad parameter 'speed=2'; parameters are"):
        parse_attack("ramp:speed=2")
    with pytest.raises(AttackError, match="axes='ex'"):
        parse_attack("ramp:axes=ex")
    with pytest.raises(AttackError, match="not after start"):
        parse_attack("step:start=50,end=10")


@settings(max_examples=25, deadline=None)
@given(st.floats(0.1, 20.0), st.floats(0.0, 200.0), st.sampled_from(["e", "n", "u", "en", "enu"]))
def test_attack_truth_round_trips_and_nothing_changes_before_start(rate: float, start: float, axes: str) -> None:
    table = circling_table(seconds=60.0)
    spec = parse_attack(f"ramp:rate={rate},axes={axes},start={start}")
    if start > table.fixes["t_s"].max():  # a window after the log's end is refused, never an empty attack
        with pytest.raises(AttackError, match="after the end of the log's fixes"):
            apply_attack(table, spec)
        return
    spoofed, truth = apply_attack(table, spec)
    assert AttackTruth.from_json(truth.to_json()) == truth
    before = table.fixes["t_s"].to_numpy() < start
    pd.testing.assert_frame_equal(spoofed.fixes[before], table.fixes[before])


@pytest.mark.parametrize("fmt", [f for f in SIMULATE_FORMATS if f != "rinex"])  # RINEX: observations only
def test_inject_writes_a_spoofed_copy_in_the_same_format(fmt: str, tmp_path: Path) -> None:
    sim = simulate("ground", seed=1, duration_s=40.0)
    src = tmp_path / f"log{SUFFIX[fmt]}"
    write_log(sim.table, src, fmt)
    out = tmp_path / f"spoofed{SUFFIX[fmt]}"
    assert main(["inject", str(src), "--attack", "ramp:rate=2,start=20", "-o", str(out)]) == 0
    original, spoofed = read_log(src), read_log(out)
    expected, _ = apply_attack(original, parse_attack("ramp:rate=2,start=20"))
    cols = ["lat_deg", "lon_deg", "height_m"]
    np.testing.assert_allclose(spoofed.fixes[cols].to_numpy(), expected.fixes[cols].to_numpy(), rtol=0, atol=1e-9)
    pd.testing.assert_frame_equal(spoofed.imu, original.imu)
    truth = AttackTruth.read(sidecar_path(out))
    assert truth.kind == "ramp" and truth.start_s == 20.0


def test_inject_into_the_real_husky_bag(husky_bag: Path, tmp_path: Path) -> None:
    out = tmp_path / "husky_spoofed.bag"
    assert main(["inject", str(husky_bag), "--attack", "ramp:rate=2,start=200", "-o", str(out)]) == 0
    original, spoofed = read_shared(husky_bag), read_log(out)
    pd.testing.assert_frame_equal(spoofed.imu, original.imu)
    pd.testing.assert_frame_equal(spoofed.odometry, original.odometry)
    shift = _enu_shift(original.fixes, spoofed.fixes)
    t = original.fixes["t_s"].to_numpy()
    late = t > 250
    np.testing.assert_allclose(shift[late, :2], np.c_[2 * (t[late] - 200), 2 * (t[late] - 200)], rtol=1e-4, atol=2e-2)
