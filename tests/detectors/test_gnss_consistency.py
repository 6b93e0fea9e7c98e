"""The GNSS-only consistency check: quiet on consistent fixes, alarms on a position-only ramp."""

from __future__ import annotations

from functools import cache

import numpy as np
import pandas as pd
import pytest
from paths import real_log
from shared_inputs import read_shared

from spooflens.attacks import apply_attack
from spooflens.attacks.spec import parse_attack
from spooflens.constants import KNOT_MPS
from spooflens.detectors.gnss_consistency import ConsistencyOptions, run_gnss_consistency
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import enu_to_geodetic
from spooflens.schema import make_frame


def _fixes(ramp_rate: float, start_s: float, with_velocity: bool = True, seed: int = 1) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 300.0, 1.0)
    v = np.c_[10 * np.cos(t / 60), 10 * np.sin(t / 60), np.zeros_like(t)]
    p = np.c_[600 * np.sin(t / 60), 600 * (1 - np.cos(t / 60)), np.zeros_like(t)]
    noise = np.cumsum(rng.normal(0, 0.3, (len(t), 3)), axis=0) * 0.2 + rng.normal(0, 0.5, (len(t), 3))
    attack = np.clip(t - start_s, 0, None)[:, None] * ramp_rate * np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    lat, lon, h = enu_to_geodetic(p + noise + attack, 45.0, 7.0, 300.0)
    cols = {
        "t_s": t,
        "receiver_id": ["rx"] * len(t),
        "lat_deg": lat,
        "lon_deg": lon,
        "height_m": h,
        "fix_type": np.full(len(t), 2),
    }
    if with_velocity:
        vn = v + rng.normal(0, 0.05, v.shape)
        cols |= {"vel_e_mps": vn[:, 0], "vel_n_mps": vn[:, 1], "vel_u_mps": vn[:, 2]}
    return make_frame("fixes", cols)


def test_consistent_fixes_raise_no_alarm() -> None:
    result = run_gnss_consistency(_fixes(0.0, 0.0))
    assert result.ran and result.alarms == []
    assert "reported velocity" in result.reason


def test_position_only_ramp_is_detected_with_onset_near_its_start() -> None:
    result = run_gnss_consistency(_fixes(2.0, 150.0))
    assert result.alarms, "a 2 m/s position-only ramp must be detected"
    first = result.alarms[0]
    assert 150.0 < first.start_s < 165.0
    assert first.onset_s is not None and abs(first.onset_s - 150.0) <= 5.0


def test_larger_ramps_are_detected_no_later() -> None:
    starts = [run_gnss_consistency(_fixes(rate, 150.0)).alarms[0].start_s for rate in (1.0, 2.0, 5.0)]
    assert starts == sorted(starts, reverse=True)


def test_without_velocity_a_position_step_is_caught_by_the_kinematic_check() -> None:
    fixes = _fixes(0.0, 0.0, with_velocity=False)
    quiet = run_gnss_consistency(fixes, ConsistencyOptions())
    assert "kinematic" in quiet.reason and quiet.alarms == []
    lat = fixes["lat_deg"].to_numpy().copy()
    lat[200:] += 100.0 / 111_000  # a 100 m jump north
    stepped = run_gnss_consistency(fixes.assign(lat_deg=lat))
    assert [round(a.peak_s) for a in stepped.alarms] in ([199], [200], [201], [199, 200], [200, 201])


def test_a_long_frozen_stretch_does_not_make_the_honest_part_anomalous() -> None:
    """A hover spoofer freezes position and zeroes velocity: no noise at all, which must not set the scale."""
    fixes = _fixes(0.0, 0.0)
    frozen = fixes["t_s"] >= 120.0  # 60% of the log
    for col in ("lat_deg", "lon_deg", "height_m"):
        fixes.loc[frozen, col] = fixes.loc[frozen, col].iloc[0]
    fixes.loc[frozen, ["vel_e_mps", "vel_n_mps", "vel_u_mps"]] = 0.0
    result = run_gnss_consistency(fixes)
    assert result.alarms, "the freeze itself (moving, then suddenly still) is inconsistent"
    assert all(a.end_s >= 120.0 for a in result.alarms)


def test_a_fast_flight_far_from_its_first_fix_keeps_its_sensitivity() -> None:
    """An aircraft at 90 m/s due north for 10 min, fixes exact but for 0.3 m of noise. 54 km on, the first
    fix's frame is tilted by 0.5 degrees: 7 m of up residual in every 900 m window, which the robust scale
    took in (6 m) and a 4 m jump then hid. In the local frame the residual is the noise and the jump
    alarms."""
    from spooflens.detectors.gnss_consistency import check_receiver
    from spooflens.geodesy import radii

    rng = np.random.default_rng(1)
    t = np.arange(0.0, 600.0, 0.1)
    step_n = 90.0 * 0.1 / radii(np.radians(47.0))[0]
    fixes = pd.DataFrame(
        {
            "t_s": t,
            "receiver_id": "gps",
            "lat_deg": 47.0 + np.degrees(step_n * np.arange(len(t))) + rng.normal(0.0, 0.3 / 111_000.0, len(t)),
            "lon_deg": 8.0,
            "height_m": 3000.0 + rng.normal(0.0, 0.3, len(t)),
            "vel_e_mps": 0.0,
            "vel_n_mps": 90.0,
            "vel_u_mps": 0.0,
        }
    )
    _, z, _, _ = check_receiver(fixes, ConsistencyOptions())
    assert np.nanmax(np.abs(z[t > 500.0])) < 6.0
    assert not run_gnss_consistency(fixes).alarms
    jumped = fixes.assign(height_m=fixes["height_m"] + 4.0 * (t >= 550.0))
    (alarm,) = run_gnss_consistency(jumped).alarms
    assert 549.0 <= alarm.start_s <= 551.0


def test_a_baseline_caps_the_scale_a_log_attacked_throughout_would_learn() -> None:
    """A position-only ramp from the first fix: the quietest quarter of the log is attacked too, so its
    scale hides the ramp; a baseline of two clean logs that agree caps it at twice theirs."""
    mode = "position change vs reported velocity"
    attacked = _fixes(ramp_rate=1.5, start_s=0.0)
    assert not run_gnss_consistency(attacked).alarms
    caps = {"rx": (mode, np.array([1.2, 1.2, 2.0]))}
    result = run_gnss_consistency(attacked, scale_caps=caps)
    assert result.alarms and result.alarms[0].start_s < 30.0
    assert "residual scale at most the baseline's allowance" in str(result.extras["from_baseline"])
    # a clean log of the vehicle keeps its own (smaller) scale: nothing changes
    clean = _fixes(ramp_rate=0.0, start_s=0.0)
    assert not run_gnss_consistency(clean, scale_caps=caps).alarms
    # a cap measured in the other mode (a log without velocity) is not applied
    other = {"rx": ("kinematic plausibility (no reported velocity)", np.array([0.01, 0.01, 0.01]))}
    assert not run_gnss_consistency(attacked, scale_caps=other).alarms


@cache
def _yacht() -> EpochTable:
    """A yacht's 4 h NMEA log: GLL positions at 0.001 arcmin, VTG relayed by the instrument bus."""
    return read_shared(real_log("nmea_boats/signalk_plaka.log"))


def test_a_receiver_heavier_tailed_than_gaussian_has_its_threshold_raised_from_its_own_bursts() -> None:
    """At the Gaussian threshold the clean yacht log alarms in 194 bursts where the design expects 0.07;
    from their tail the threshold is raised, and what remains is its one worst moment."""
    fixes = _yacht().fixes
    nominal = run_gnss_consistency(fixes, ConsistencyOptions(min_bursts_to_recalibrate=10**9))
    assert len(nominal.alarms) > 150
    raised = run_gnss_consistency(fixes)
    assert len(raised.alarms) <= 2 and "heavier-tailed than Gaussian, threshold raised" in raised.reason
    (series,) = [s for s in raised.series if s.name.endswith("/statistic")]
    assert series.threshold is not None and series.threshold > 50.0


@pytest.mark.parametrize(
    "attack", ["ramp:rate=0.5,axes=en,start=6000,end=6600", "step:offset=20,axes=e,start=6000,end=6600"]
)
def test_on_the_raised_threshold_a_drag_or_a_step_is_still_caught(attack: str) -> None:
    spoofed, _ = apply_attack(_yacht(), parse_attack(attack))
    alarms = run_gnss_consistency(spoofed.fixes).alarms
    assert [a for a in alarms if 6000.0 <= a.start_s <= 6020.0]


def test_a_weak_drag_over_most_of_the_log_does_not_teach_the_test_its_tail() -> None:
    """A 1 m/s ramp over the last 63 % of the yacht's log alarms in dozens of long bursts: only bursts no
    longer than the window say how the receiver's own errors behave, so the threshold stays nominal."""
    spoofed, _ = apply_attack(_yacht(), parse_attack("ramp:rate=1,axes=en,start=6000"))
    result = run_gnss_consistency(spoofed.fixes)
    assert "threshold raised" not in result.reason
    assert len([a for a in result.alarms if a.start_s >= 6000.0]) >= 10


def _moored_boat(seed: int, drag_mps: float = 0.0) -> pd.DataFrame:
    """A minute of a boat at its mooring as an RMC-only NMEA log writes it: positions to 0.0001' (18 cm
    north, 9 cm east at 60 N), speed to 0.1 kn with the course held at 188.0 (a receiver's course at rest),
    mostly 0.0 kn and now and then 0.1-0.4 kn of noise. The hull creeps 0.45 m east on its line in 7 s."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 60.0, 1.0)
    p = np.cumsum(rng.normal(0.0, 0.005, (len(t), 3)), axis=0) * np.array([1.0, 1.0, 0.0])
    p[:, 0] += 0.45 * np.clip((t - 45.0) / 7.0, 0.0, 1.0) + drag_mps * np.clip(t - 30.0, 0.0, None)
    lat, lon, _ = enu_to_geodetic(p, 60.15, 24.89, 0.0)
    creeping = (t >= 45.0) & (t < 52.0)
    knots = np.where(creeping, rng.choice([0.0, 0.2, 0.3], len(t)), rng.choice([0.0] * 12 + [0.1, 0.2, 0.4], len(t)))
    course = np.radians(188.0)
    return pd.DataFrame(
        {
            "t_s": t,
            "receiver_id": "GP",
            "lat_deg": np.round((lat - 60.0) * 60.0, 4) / 60.0 + 60.0,
            "lon_deg": np.round((lon - 24.0) * 60.0, 4) / 60.0 + 24.0,
            "height_m": 0.0,
            "vel_e_mps": knots * KNOT_MPS * np.sin(course),
            "vel_n_mps": knots * KNOT_MPS * np.cos(course),
            "vel_u_mps": np.nan,
        }
    )


@pytest.mark.parametrize("seed", [1, 4, 6, 7, 8, 10])
def test_a_moored_boat_rounded_to_its_written_resolution_is_quiet(seed: int) -> None:
    """Most windows of such a log hold no change of position and a velocity of a few mm/s east: the robust
    scale fell to its 5 cm floor on the east axis, below the 9 cm step the log writes, and the creep read as
    31-141 sigma^2 (a real moored yacht's log: 107). The scale may not fall below what the written steps
    give; the note says so."""
    result = run_gnss_consistency(_moored_boat(seed))
    assert not result.alarms
    assert "what the log's rounding of position and velocity alone gives" in result.reason


@pytest.mark.parametrize("seed", [1, 4])
def test_a_drag_of_a_moored_boat_is_still_caught_above_its_rounding(seed: int) -> None:
    (alarm,) = run_gnss_consistency(_moored_boat(seed, drag_mps=0.5)).alarms
    assert 30.0 <= alarm.start_s <= 34.0


def _braking_car(velocity_every: int = 1) -> pd.DataFrame:
    """A car at 10 m/s brakes hard to a stop at 60 s, waits two fixes, pulls away; 1 Hz fixes with 5 cm of
    noise. Stopped, its receiver writes a speed without a course: no velocity at those two fixes."""
    rng = np.random.default_rng(2)
    t = np.arange(0.0, 120.0, 0.5)
    speed = np.interp(t, [0.0, 57.0, 60.0, 62.0, 66.0, 120.0], [10.0, 10.0, 0.0, 0.0, 5.0, 5.0])
    north = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))])
    t, speed, north = t[::2], speed[::2], north[::2]
    lat, lon, h = enu_to_geodetic(np.c_[0 * t, north, 0 * t] + rng.normal(0.0, 0.05, (len(t), 3)), 59.9, 30.2, 20.0)
    v_n = np.where((t >= 60.0) & (t < 62.0), np.nan, speed)
    v_n[np.arange(len(t)) % velocity_every != 0] = np.nan
    return pd.DataFrame(
        {"t_s": t, "receiver_id": "GP", "lat_deg": lat, "lon_deg": lon, "height_m": h}
        | {"vel_e_mps": np.where(np.isfinite(v_n), 0.0, np.nan), "vel_n_mps": v_n, "vel_u_mps": np.nan}
    )


def test_a_stop_without_velocity_is_not_judged_by_a_velocity_drawn_across_it() -> None:
    """Drawn straight from the last velocity before the stop to the first after it, the car moved metres it
    never went: a real dashcam drive's braking stop read 36.7 against 25.9. A window holding a fix whose
    velocity the receiver did not give is not judged; a drag elsewhere still is."""
    assert not run_gnss_consistency(_braking_car()).alarms
    dragged = _braking_car()
    dragged["lat_deg"] += np.clip(dragged["t_s"] - 90.0, 0.0, None) * 1.0 / 111_000.0
    (alarm,) = run_gnss_consistency(dragged).alarms
    assert 90.0 <= alarm.start_s <= 95.0


def test_a_velocity_written_at_half_the_fix_rate_is_still_judged_between_its_values() -> None:
    result = run_gnss_consistency(_braking_car(velocity_every=2))
    assert np.isfinite(result.series[0].values).sum() > 80


def _hovering_copter(seed: int) -> pd.DataFrame:
    """A minute of a copter holding position at 5 Hz as a 2013 ArduPilot log writes it (1e-7 deg, 1 cm/s): it
    drifts at up to 0.3 m/s, and below 0.25 m/s its GPS holds the last course it measured, scaled by the
    speed (a real one at 127.73 deg for 8 fixes while it drifted west)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 60.0, 0.2)
    angle = np.cumsum(rng.normal(0.0, 0.15, len(t)))
    speed = 0.15 + 0.15 * np.sin(2 * np.pi * t / 17.0) ** 2
    v_true = np.c_[speed * np.sin(angle), speed * np.cos(angle)]
    p = np.concatenate([[[0.0, 0.0]], np.cumsum(0.5 * (v_true[1:] + v_true[:-1]) * 0.2, axis=0)])
    course = np.arctan2(v_true[:, 0], v_true[:, 1])
    for k in range(1, len(t)):
        if speed[k] < 0.25:
            course[k] = course[k - 1]
    reported = np.round(speed, 2)
    lat, lon, h = enu_to_geodetic(np.c_[p, 0 * t] + rng.normal(0.0, 0.02, (len(t), 3)), 44.029, -77.737, 90.0)
    return pd.DataFrame(
        {"t_s": t, "receiver_id": "GPS[0]", "lat_deg": np.round(lat, 7), "lon_deg": np.round(lon, 7), "height_m": h}
        | {"vel_e_mps": reported * np.sin(course), "vel_n_mps": reported * np.cos(course), "vel_u_mps": np.nan}
    )


@pytest.mark.parametrize("seed", [1, 2])
def test_a_course_held_at_rest_is_allowed_the_distance_travelled_on_it(seed: int) -> None:
    """The held course's direction is no measurement: each window allows the distance travelled on it (known
    in length, not in direction), and says how many fixes held it (these seeds alarmed at 24-79 before). A
    drag of 1 m/s of the same hover still alarms, within 7 s where it took 1 s."""
    result = run_gnss_consistency(_hovering_copter(seed))
    assert not result.alarms
    assert "fixes on a course held below 1 m/s (no measured direction" in result.reason
    dragged = _hovering_copter(seed)
    dragged["lat_deg"] += np.clip(dragged["t_s"] - 30.0, 0.0, None) * 1.0 / 111_000.0
    assert [a.start_s for a in run_gnss_consistency(dragged).alarms if 30.0 <= a.start_s <= 40.0]


def test_which_courses_are_held() -> None:
    from spooflens.detectors.gnss_consistency import held_course

    def velocity(course_deg: list[float], speed: list[float]) -> np.ndarray:
        c, s = np.radians(course_deg), np.asarray(speed)
        return np.c_[s * np.sin(c), s * np.cos(c), 0 * s]

    opts = ConsistencyOptions()
    speeds = [0.12, 0.18, 0.19, 0.19, 0.2, 0.1, 0.1, 0.1, 0.2, 0.3, 0.3]
    assert (
        held_course(velocity([127.73] * 8 + [251.2, 262.9, 266.0], speeds), opts).tolist() == [True] * 8 + [False] * 3
    )
    assert not held_course(velocity([90.0] * 10, [5.0] * 10), opts).any()  # a straight road at speed
    pairs = velocity([268.4, 268.4, 270.1, 271.5, 271.5, 272.0], [0.75, 0.75, 0.8, 0.8, 0.8, 0.9])
    assert not held_course(pairs, opts).any()  # a velocity repeated once (a 5 Hz log's half-rate velocity)
    assert not held_course(velocity([0.0] * 5, [0.0] * 5), opts).any()  # at rest and saying so: a measurement


def test_a_log_shorter_than_a_window_is_not_counted_as_checked() -> None:
    """Six seconds of fixes hold no 10 s window: the check judged nothing and said "NO SPOOFING DETECTED"
    with the others; it now says it could not run, and why."""
    short = _braking_car().iloc[:7]
    result = run_gnss_consistency(short)
    assert not result.ran
    assert result.reason == "no epoch to judge: no 10 s of fixes without a gap (the log spans 6.0 s)"


def test_a_receiver_with_too_few_epochs_to_learn_its_noise_is_not_judged() -> None:
    """A phone's 5 fixes over 80 s: a noise scale read off the 3 second differences they give is no scale,
    and its last fix's 5 m read 62,187 against 25.9."""
    car = _braking_car()
    few = car[car["t_s"].isin([0.0, 30.0, 79.0, 80.0, 81.0])].assign(vel_e_mps=np.nan, vel_n_mps=np.nan)
    few.loc[few.index[-1], "lat_deg"] += 5.0 / 111_000.0
    result = run_gnss_consistency(few)
    assert not result.ran and not result.alarms
    assert result.reason == (
        "GP: not judged: 3 epochs to learn its noise from (kinematic plausibility (no reported velocity)), 10 needed"
    )


def _lagging_car(lag_s: float, step_m: float = 0.0) -> pd.DataFrame:
    """A car along a straight road at 20 m/s, on an on-ramp's 0.5 m/s^2 from 100 s to 116 s and braking at
    1 m/s^2 from 200 s to 218 s, whose receiver writes the velocity of `lag_s` before each fix (a filtered or
    relayed NMEA speed: a real car's receiver read 0.75-1.25 s behind on three drives), and a position step of
    `step_m` from 150 s."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 300.0, 1.0)
    fine = np.arange(-5.0, 300.0, 0.01)
    accel = np.where((fine >= 100) & (fine < 116), 0.5, 0.0) - np.where((fine >= 200) & (fine < 218), 1.0, 0.0)
    speed = 20.0 + np.cumsum(accel) * 0.01
    along = np.interp(t, fine, np.cumsum(speed) * 0.01)
    p = np.c_[along * 0.6, along * 0.8, np.zeros_like(t)] + rng.normal(0, 0.3, (len(t), 3))
    p[t >= 150.0, :2] += step_m / np.sqrt(2)
    lat, lon, h = enu_to_geodetic(p, 45.0, 7.0, 300.0)
    v = np.interp(t - lag_s, fine, speed) + rng.normal(0, 0.05, len(t))
    cols = {"t_s": t, "receiver_id": ["rx"] * len(t), "lat_deg": lat, "lon_deg": lon, "height_m": h}
    cols |= {"fix_type": np.full(len(t), 2), "vel_e_mps": v * 0.6, "vel_n_mps": v * 0.8, "vel_u_mps": 0 * v}
    return make_frame("fixes", cols)


def test_a_velocity_behind_the_fixes_is_read_that_much_later() -> None:
    assert run_gnss_consistency(_lagging_car(1.0), ConsistencyOptions(max_velocity_lag_s=0.0)).alarms
    lagging = run_gnss_consistency(_lagging_car(1.0))
    assert not lagging.alarms and "velocity 1 s behind the fixes" in lagging.reason
    assert "behind" not in run_gnss_consistency(_lagging_car(0.0)).reason
    # the lag read off the vehicle's own accelerations absorbs no step of its position
    stepped = run_gnss_consistency(_lagging_car(1.0, step_m=50.0))
    assert "velocity 1 s behind" in stepped.reason and stepped.alarms[0].start_s == pytest.approx(150.0, abs=1.0)


def _standing_with_speed_alone(seed: int, drag_mps: float = 0.0) -> pd.DataFrame:
    """A receiver at rest writing a speed with no course (as a FLARM ground station's RMC does), its fix
    wandering by decimetres, its height by metres over tens of seconds; `drag_mps` east from 60 s."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 120.0, 1.0)
    p = np.cumsum(rng.normal(0, 0.05, (len(t), 3)), axis=0) * np.array([1.0, 1.0, 0.0])
    p[:, 2] = 3.0 * np.sin(t / 8.0) + rng.normal(0, 0.3, len(t))
    p[:, 0] += np.clip(t - 60.0, 0, None) * drag_mps
    lat, lon, h = enu_to_geodetic(p, 45.0, 7.0, 90.0)
    speed = np.abs(rng.normal(0.15, 0.1, len(t)))
    cols = {"t_s": t, "receiver_id": ["rx"] * len(t), "lat_deg": lat, "lon_deg": lon, "height_m": h}
    cols |= {"fix_type": np.full(len(t), 2), "speed_mps": speed}
    return make_frame("fixes", cols)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_speed_alone_is_the_distance_a_window_allows(seed: int) -> None:
    # without it the fixes had no velocity and the height's wander read as accelerations
    quiet = run_gnss_consistency(_standing_with_speed_alone(seed))
    assert quiet.reason.startswith("rx: position change vs reported velocity (horizontal: no vertical velocity)")
    assert "120 fixes with a speed alone" in quiet.reason and not quiet.alarms
    # a drag beyond the speeds written is still caught
    dragged = run_gnss_consistency(_standing_with_speed_alone(seed, drag_mps=1.0))
    assert dragged.alarms and 60.0 <= dragged.alarms[0].start_s <= 72.0
