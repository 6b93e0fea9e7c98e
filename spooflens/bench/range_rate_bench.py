"""Seed 001's experiments: the rate model and the pseudorange model against a free INS, beside the paper.

In depth: docs/methods/range-rate.md."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import click
import numpy as np
import pandas as pd
from numpy.typing import NDArray
from rich.table import Table

from spooflens.detectors.references import Reference
from spooflens.detectors.statistics.pseudorange_rate import (
    fit_velocity_error,
    paper_threshold,
    position_error,
    rate_residuals,
    t_statistic,
    t_threshold,
    window_for_bias,
)
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import ecef_to_enu_vectors, enu_rotation, geodetic_to_ecef
from spooflens.gnss.ephemeris import GpsEphemerides
from spooflens.gnss.geometry import expected_range_rate, sagnac_range
from spooflens.gnss.grid import observation_grid
from spooflens.navigation.imu_models import grade
from spooflens.navigation.strapdown import NavState, free_inertial, preintegrate, propagate
from spooflens.output.console import console, progress, show_progress
from spooflens.pipeline.evidence import Evidence
from spooflens.simulation.observations import L1_WAVELENGTH_M, ObservationNoise, simulate_observations
from spooflens.simulation.sensors import ImuSamples, ideal_imu
from spooflens.simulation.trajectories import Profile, Segment, Truth, generate

FloatArray = NDArray[np.float64]
GSI = Path(__file__).resolve().parents[3] / "shared" / "real" / "rinex_gsi_pair"
NAV = GSI / "07590920.05n"
START = (34.0, 108.0, 400.0)
GRADES = ("seed001_n1", "seed001_n2")
WINDOWED = " / 5 s window"  # suffix of the variant whose INS restarts from the truth 5 s before each epoch
RX = "rx"
# Table 3: scheme -> (start s, end s, axis the paper sees it on, what)
SCHEMES: dict[str, tuple[float, float, int, str]] = {
    "2 hover": (25.0, 50.0, 0, "reported position frozen at 25 s, zero velocity"),
    "3 velocity pull": (650.0, 750.0, 1, "north velocity +0.1 m/s, position follows"),
    "4 position step": (1500.0, 1550.0, 0, "east position +100 m at once"),
    "4 position ramp": (1500.0, 1550.0, 0, "east position pulled at 2 m/s to 100 m"),
}
BINS = (0.0, 250.0, 500.0, 750.0, 1000.0, 1250.0, 1500.0)  # Fig. 11: false alarms over time, 250 s bins
PAPER: dict[str, Any] = {
    "threshold_rate_mps": {"E": 0.2071, "N": 0.1366},
    "threshold_pseudorange_m": {"E": 58.5951, "N": 58.1481},
    "false_alarms": {  # Table 5, out of 1500
        "rate": {"seed001_n1": (37, 43), "seed001_n2": (88, 94)},
        "pseudorange": {"seed001_n1": (432, 478), "seed001_n2": (617, 648)},
    },
    "denominator": 1500,
}


@dataclass(frozen=True)
class BenchOptions:
    runs: int = 100
    duration_s: float = 1750.0
    imu_hz: float = 100.0
    threshold_until_s: float = 200.0  # the paper's "first 200 s"
    count_from_s: float = 250.0  # false alarms counted over (250, 1750]: 1500 epochs
    p_false_alarm: float = 0.01
    p_detect: float = 0.9
    bias_mps: float = 0.1
    window_s: float = 5.0  # the restarted-INS variant (0: free INS only)
    product: bool = True
    real: bool = True


# --- trajectories ------------------------------------------------------------------------------------------


def paper_profile(duration_s: float = 1750.0) -> Profile:
    """A flight like the paper's Fig. 3: at rest heading east, away east from 10 s (so the 25-50 s hover
    spoof is seen on east only), climbs, turns and cruises."""
    segs = (
        Segment(10.0),
        Segment(15.0, 1.2),
        Segment(100.0, 0.0, 0.0, 2.0),
        Segment(30.0, 0.0, 3.0),
        Segment(270.0, 0.2),
        Segment(30.0, 0.0, -3.0, -1.0),
        Segment(245.0),
        Segment(60.0, 0.0, 1.5),
        Segment(300.0, -0.05),
        Segment(45.0, 0.0, -2.0, 1.0),
        Segment(645.0),
    )
    total = sum(s.duration_s for s in segs)
    segs = (*segs[:-1], replace(segs[-1], duration_s=segs[-1].duration_s + duration_s - total))
    return Profile(START[0], START[1], START[2], 0.0, 0.0, segs, banked_turns=True, blend_s=3.0)


def random_profile(rng: np.random.Generator, duration_s: float = 1750.0) -> Profile:
    """A random flight from rest: random heading, speed-up, then turns, climbs and speed changes."""
    segs = [Segment(10.0), Segment(15.0, float(rng.uniform(0.6, 2.0)))]
    total = 25.0
    while total < duration_s:
        d = float(min(rng.uniform(20.0, 200.0), duration_s - total))
        turn = float(rng.choice([0.0, 0.0, rng.uniform(-3.0, 3.0)]))
        segs.append(
            Segment(d, float(rng.uniform(-0.05, 0.05)), turn, float(rng.uniform(-2.0, 2.0)) * (rng.random() < 0.3))
        )
        total += d
    return Profile(START[0], START[1], START[2], 0.0, float(rng.uniform(0.0, 360.0)), tuple(segs), True, 3.0)


# --- the spoofer: every satellite seen from a fake trajectory ------------------------------------------------


def fake_trajectory(scheme: str, t: FloatArray, p: FloatArray, v: FloatArray, lat: FloatArray, lon: FloatArray):
    """(mask, fake ECEF position, fake ECEF velocity) at GNSS epochs for one Table 3 scheme."""
    a, b, _, _ = SCHEMES[scheme]
    on = (t >= a) & (t <= b)
    R = enu_rotation(lat, lon)  # ECEF -> ENU per epoch
    east, north = R[:, 0, :], R[:, 1, :]
    pf, vf = p.copy(), v.copy()
    if scheme.startswith("2"):
        k0 = int(np.flatnonzero(on)[0])
        pf[on], vf[on] = p[k0], 0.0
    elif scheme.startswith("3"):
        pf[on] = p[on] + 0.1 * (t[on] - a)[:, None] * north[on]
        vf[on] = v[on] + 0.1 * north[on]
    elif scheme == "4 position step":
        pf[on] = p[on] + 100.0 * east[on]
    else:
        pf[on] = p[on] + np.minimum(2.0 * (t[on] - a), 100.0)[:, None] * east[on]
        vf[on] = v[on] + np.where((t[on] - a) < 50.0, 2.0, 0.0)[:, None] * east[on]
    return on, pf, vf


def spoofed(obs: pd.DataFrame, t: FloatArray, on: NDArray[np.bool_], p, v, pf, vf) -> pd.DataFrame:
    """The observation rows as a receiver at the fake trajectory would have measured them, during `on`."""
    k = np.searchsorted(t, obs["t_s"].to_numpy(float))
    hit = on[k]
    sv = obs[["sv_x_m", "sv_y_m", "sv_z_m"]].to_numpy(float)
    sv_v = obs[["sv_vx_mps", "sv_vy_mps", "sv_vz_mps"]].to_numpy(float)
    drift = obs["sv_clock_drift_mps"].to_numpy(float)
    zero = np.zeros(len(obs))
    d_range = sagnac_range(sv, pf[k]) - sagnac_range(sv, p[k])
    d_rate = expected_range_rate(sv, sv_v, drift, pf[k], vf[k], zero) - expected_range_rate(
        sv, sv_v, drift, p[k], v[k], zero
    )
    out = obs.copy()
    out["pseudorange_m"] += np.where(hit, d_range, 0.0)
    out["carrier_phase_cycles"] += np.where(hit, d_range / L1_WAVELENGTH_M, 0.0)
    out["pseudorange_rate_mps"] += np.where(hit, d_rate, 0.0)
    out["doppler_hz"] -= np.where(hit, d_rate / L1_WAVELENGTH_M, 0.0)
    return out


# --- one trajectory ------------------------------------------------------------------------------------------


def _table(obs: pd.DataFrame, start_gps: float, eph: GpsEphemerides) -> EpochTable:
    t = EpochTable(Path("seed001-bench"), "simulation", round(start_gps * 1e9), "gps", observations=obs)
    t.ephemerides = eph
    return t


def _noisy(t: FloatArray, ideal: tuple[FloatArray, FloatArray], name: str, rng: np.random.Generator) -> ImuSamples:
    """The ideal IMU plus a grade's turn-on biases, bias random walks and white noise (as
    `spooflens.simulation.sensors.noisy_imu`, with the ideal samples computed once for both grades)."""
    gr = grade(name)
    f, w = ideal
    n, dt = len(t), float(np.median(np.diff(t)))
    bg = rng.normal(0.0, gr.gyro_bias_sigma, 3) + np.cumsum(rng.normal(0.0, gr.gyro_bias_rw * np.sqrt(dt), (n, 3)), 0)
    ba = rng.normal(0.0, gr.accel_bias_sigma, 3) + np.cumsum(rng.normal(0.0, gr.accel_bias_rw * np.sqrt(dt), (n, 3)), 0)
    w_n = w + bg + rng.normal(0.0, gr.gyro_arw / np.sqrt(dt), (n, 3))
    f_n = f + ba + rng.normal(0.0, gr.accel_vrw / np.sqrt(dt), (n, 3))
    return ImuSamples(t, f_n, w_n, bg, ba)


def free_ins_reference(truth: Truth, imu, g_idx: NDArray[np.int64]) -> Reference:
    """The INS running free from the true initial state, at the GNSS epochs (1 s blocks)."""
    pre = preintegrate(truth.t, imu.f_b, imu.w_b)
    s0 = NavState(0.0, truth.lat[0], truth.lon[0], truth.h[0], truth.v_enu[0].copy(), truth.C[0].copy())
    step = int(g_idx[1] - g_idx[0])
    states = free_inertial(pre, s0, step)[: len(g_idx)]
    lat = np.degrees([s.lat for s in states])
    lon = np.degrees([s.lon for s in states])
    pos = geodetic_to_ecef(lat, lon, np.array([s.h for s in states]))
    vel = np.einsum("eji,ej->ei", enu_rotation(lat, lon), np.array([s.v for s in states]))
    prev = np.vstack([pos[:1] * np.nan, pos[:-1]])
    return Reference("ins", "free INS from the true initial state", Evidence.INERTIAL, prev, pos, vel)


def truth_reference(truth: Truth, g_idx: NDArray[np.int64]) -> Reference:
    pos = truth.ecef()[g_idx]
    prev = np.vstack([pos[:1] * np.nan, pos[:-1]])
    return Reference("truth", "the true trajectory", Evidence.INERTIAL, prev, pos, truth.ecef_velocity()[g_idx])


def trajectory_statistics(
    profile: Profile, start_gps: float, eph: GpsEphemerides, seed: int, opts: BenchOptions
) -> dict[str, Any]:
    """dv (rate model) and dp (pseudorange model) per grade, clean and under each scheme, plus the free INS's
    velocity error."""
    rng = np.random.default_rng(seed)
    truth = generate(profile, opts.imu_hz)
    step = round(opts.imu_hz)
    g_idx = np.arange(0, len(truth.t), step)
    t = truth.t[g_idx]
    p, v = truth.ecef()[g_idx], truth.ecef_velocity()[g_idx]
    lat, lon = np.degrees(truth.lat[g_idx]), np.degrees(truth.lon[g_idx])
    obs = simulate_observations(RX, t, start_gps + t, p, v, eph, ObservationNoise(), rng)
    grids = {"clean": observation_grid(_table(obs, start_gps, eph), RX)}
    for scheme in SCHEMES:
        on, pf, vf = fake_trajectory(scheme, t, p, v, lat, lon)
        grids[scheme] = observation_grid(_table(spoofed(obs, t, on, p, v, pf, vf), start_gps, eph), RX)
    out: dict[str, Any] = {"t": grids["clean"].t_s}
    ideal = ideal_imu(truth)
    for g in GRADES:
        imu = _noisy(truth.t, ideal, g, rng)
        refs = {g: free_ins_reference(truth, imu, g_idx)}
        if opts.window_s:
            refs[f"{g}{WINDOWED}"] = windowed_reference(truth, imu, g_idx, opts.window_s)
        for key, ref in refs.items():
            out[key] = {"ins_velocity_error": ecef_to_enu_vectors(lat, lon, ref.vel - v)}
            for name, grid in grids.items():
                res = rate_residuals(grid, ref, eph.iono)
                dv = fit_velocity_error(res, grid.systems).fit.d_enu
                dp = position_error(grid, ref, eph.iono).d_enu
                out[key][name] = {"rate": dv, "pseudorange": dp}
    return out


def windowed_reference(truth: Truth, imu: ImuSamples, g_idx: NDArray[np.int64], window_s: float) -> Reference:
    """The INS restarted from the true state `window_s` before each epoch and propagated alone: what an INS
    whose aiding stopped a few seconds ago gives (ideal aiding: the restart state is exact)."""
    pre = preintegrate(truth.t, imu.f_b, imu.w_b)
    step = int(g_idx[1] - g_idx[0])
    back = round(window_s * step / (truth.t[g_idx[1]] - truth.t[g_idx[0]]))
    E = len(g_idx)
    llh_prev, llh, v_enu = (np.full((E, 3), np.nan) for _ in range(3))
    for e in range(1, E):
        i0 = max(int(g_idx[e]) - back, 0)
        i0 = min(i0, int(g_idx[e - 1]))
        s = NavState(truth.t[i0], truth.lat[i0], truth.lon[i0], truth.h[i0], truth.v_enu[i0].copy(), truth.C[i0].copy())
        i = i0
        for target, dest in ((int(g_idx[e - 1]), llh_prev), (int(g_idx[e]), llh)):
            while i < target:
                j = min(target, i + step)
                s = propagate(s, *pre.increment(i, j))
                i = j
            dest[e] = (s.lat, s.lon, s.h)
        v_enu[e] = s.v
    ok = np.isfinite(llh).all(axis=1)
    pos, prev, vel = (np.full((E, 3), np.nan) for _ in range(3))
    pos[ok] = geodetic_to_ecef(np.degrees(llh[ok, 0]), np.degrees(llh[ok, 1]), llh[ok, 2])
    prev[ok] = geodetic_to_ecef(np.degrees(llh_prev[ok, 0]), np.degrees(llh_prev[ok, 1]), llh_prev[ok, 2])
    vel[ok] = np.einsum("eji,ej->ei", enu_rotation(np.degrees(llh[ok, 0]), np.degrees(llh[ok, 1])), v_enu[ok])
    return Reference(
        "ins", f"INS restarted from the truth {window_s:g} s before each epoch", Evidence.INERTIAL, prev, pos, vel
    )


# --- the paper's rules on one run ------------------------------------------------------------------------------


def _first(t: FloatArray, alarm: NDArray[np.bool_], a: float, b: float) -> float | None:
    k = np.flatnonzero(alarm & (t >= a) & (t <= b))
    return float(t[k[0]] - a) if len(k) else None


def _keys(d: dict[str, Any]) -> list[str]:
    """The grade (and reference variant) keys of a run, evaluation or summary."""
    return [k for k in d if k.startswith("seed001")]


def evaluate(run: dict[str, Any], opts: BenchOptions) -> dict[str, Any]:
    """Thresholds from the clean run's first 200 s; false-alarm counts over (250, 1750] of the clean run;
    per scheme, the delay of the first alarm on the paper's axis within the attack (None: missed)."""
    t = run["t"]
    fit_win = (t > 0) & (t <= opts.threshold_until_s)
    count_win = t > opts.count_from_s
    out: dict[str, Any] = {"denominator": int(count_win.sum())}
    for g in _keys(run):
        r = run[g]
        gout: dict[str, Any] = {}
        for model in ("rate", "pseudorange"):
            clean = r["clean"][model]
            band = [paper_threshold(clean[fit_win, i], opts.p_false_alarm) for i in range(2)]
            fa = [int(np.sum(np.abs(clean[count_win, i] - band[i][0]) > band[i][1])) for i in range(2)]
            det = {}
            for scheme, (a, b, axis, _) in SCHEMES.items():
                x = r[scheme][model][:, axis]
                det[scheme] = _first(t, np.abs(x - band[axis][0]) > band[axis][1], a, b + 2.0)
            alarm = np.stack([np.abs(clean[:, i] - band[i][0]) > band[i][1] for i in range(2)], axis=1)
            late = alarm & count_win[:, None]
            first = [float(t[np.flatnonzero(late[:, i])[0]]) if late[:, i].any() else None for i in range(2)]
            in_bin = [(t > lo) & (t <= lo + 250.0) for lo in BINS]
            bins = [float(np.mean(alarm[m].any(axis=1))) if m.any() else float("nan") for m in in_bin]
            gout[model] = {
                "threshold": [band[0][1], band[1][1]],
                "false_alarms": fa,
                "detect_delay": det,
                "first_false_alarm_s": first,
                "false_alarm_fraction_by_time": bins,
            }
        # windowed t-test on the rate model, window sized for a 0.1 m/s bias from the 200 s scale
        clean = r["clean"]["rate"]
        sd = [float(np.std(clean[fit_win, i], ddof=1)) for i in range(2)]
        K = [window_for_bias(opts.bias_mps, s, opts.p_false_alarm, opts.p_detect)[0] for s in sd]
        fa, det = [], {}
        for i in range(2):
            T = t_statistic(clean[:, i], K[i])
            fa.append(int(np.sum(np.abs(T[count_win]) >= t_threshold(opts.p_false_alarm, K[i]))))
        for scheme, (a, b, axis, _) in SCHEMES.items():
            T = t_statistic(r[scheme]["rate"][:, axis], K[axis])
            det[scheme] = _first(t, np.abs(np.nan_to_num(T)) >= t_threshold(opts.p_false_alarm, K[axis]), a, b + 2.0)
        gout["ttest"] = {"K": K, "false_alarms": fa, "detect_delay": det}
        ve = r["ins_velocity_error"]
        gout["ins_velocity_error_200s"] = np.abs(ve[np.searchsorted(t, 200.0)]).tolist()
        gout["ins_velocity_error_end"] = np.abs(ve[-1]).tolist()
        out[g] = gout
    return out


def paper_scenario(opts: BenchOptions, report=None) -> dict[str, Any]:
    """Part 1-3: the main trajectory and `runs` random ones."""
    from readers.rinex import read_rinex_nav

    eph = read_rinex_nav(NAV)
    day = float(np.min(eph.toe_s))
    rng = np.random.default_rng(2022)
    evals = []
    main_run = None
    for i in range(opts.runs):
        profile = paper_profile(opts.duration_s) if i == 0 else random_profile(rng, opts.duration_s)
        start = day + 600.0 + float(rng.uniform(0.0, 20.0 * 3600.0)) if i else day + 3.0 * 3600.0
        run = trajectory_statistics(profile, start, eph, 1000 + i, opts)
        if i == 0:
            main_run = run
        evals.append(evaluate(run, opts))
        if report:
            report("seed001: paper scenario", i + 1, opts.runs)
    return {"evals": evals, "main": main_run}


def summarise(evals: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {"runs": len(evals), "denominator": evals[0]["denominator"]}
    for g in _keys(evals[0]):
        gout: dict[str, Any] = {}
        for model in ("rate", "pseudorange", "ttest"):
            fa = np.array([e[g][model]["false_alarms"] for e in evals], dtype=float)
            m: dict[str, Any] = {"false_alarms_mean": fa.mean(axis=0).round(1).tolist()}
            if model != "ttest":
                thr = np.array([e[g][model]["threshold"] for e in evals])
                m["threshold_median"] = np.median(thr, axis=0).tolist()
                m["threshold_main"] = evals[0][g][model]["threshold"]
                first = [
                    min((x for x in e[g][model]["first_false_alarm_s"] if x is not None), default=None) for e in evals
                ]
                known = [x for x in first if x is not None]
                m["first_false_alarm_median_s"] = float(np.median(known)) if known else None
                m["false_alarm_fraction_by_time"] = np.nanmean(
                    [e[g][model]["false_alarm_fraction_by_time"] for e in evals], axis=0
                ).tolist()
            else:
                m["K_median"] = np.median([e[g]["ttest"]["K"] for e in evals], axis=0).tolist()
            det = {}
            for scheme in SCHEMES:
                d = [e[g][model]["detect_delay"][scheme] for e in evals]
                hit = [x for x in d if x is not None]
                det[scheme] = {
                    "detected": len(hit) / len(d),
                    "median_delay_s": float(np.median(hit)) if hit else None,
                    "main": evals[0][g][model]["detect_delay"][scheme],
                }
            m["detection"] = det
            gout[model] = m
        gout["ins_velocity_error_200s_median"] = np.median([e[g]["ins_velocity_error_200s"] for e in evals], 0).tolist()
        gout["ins_velocity_error_end_median"] = np.median([e[g]["ins_velocity_error_end"] for e in evals], 0).tolist()
        out[g] = gout
    return out


# --- this implementation's rule on the main trajectory -------------------------------------------------------


def product_rule(opts: BenchOptions) -> dict[str, Any]:
    """`spooflens analyze`'s range_rate detector (default settings) on the main trajectory simulated as a full
    log (IMU, raw observations, the receiver's own fixes), clean and with all four schemes, for both grades."""
    from spooflens.detectors.range_rate import run as run_seed001
    from spooflens.gnss.single_point import solve_logged
    from spooflens.pipeline.registry import AnalysisContext, AnalyzeOptions
    from spooflens.schema import make_frame
    from spooflens.simulation.simulate import Scenario, simulate

    out: dict[str, Any] = {}
    for g in GRADES:
        sc = Scenario(
            "seed001",
            paper_profile(opts.duration_s),
            opts.imu_hz,
            1.0,
            grade(g),
            observations=ObservationNoise(),
            constellation=str(NAV),
            imu_orientation=False,
        )
        sim = simulate(sc, seed=7)
        table = sim.table
        tr = sim.truth
        obs = table.observations
        t = np.unique(obs["t_s"].to_numpy(float))
        k = np.searchsorted(tr.t, t)
        p, v = tr.ecef()[k], tr.ecef_velocity()[k]
        lat, lon = np.degrees(tr.lat[k]), np.degrees(tr.lon[k])
        gout: dict[str, Any] = {}
        for case in ("clean", *SCHEMES):
            tab = table
            if case != "clean":
                on, pf, vf = fake_trajectory(case, t, p, v, lat, lon)
                tab = _with_observations(table, spoofed(obs, t, on, p, v, pf, vf), solve_logged, make_frame)
            ctx = AnalysisContext(tab, AnalyzeOptions())  # what a user gets: the default filter settings
            res = run_seed001(ctx)[0]
            alarms = [(a.start_s, a.end_s) for a in res.alarms]
            if case == "clean":
                gout[case] = {"alarms": alarms, "epochs": len(t)}
            else:
                a, b, _, _ = SCHEMES[case]
                first = [s for s, e in alarms if e >= a and s <= b + 2.0]
                gout[case] = {"delay_s": (min(first) - a) if first else None, "alarms": alarms}
        out[g] = gout
    return out


def _with_observations(table: EpochTable, obs: pd.DataFrame, solve_logged, make_frame) -> EpochTable:
    """The table with its observations replaced and its fixes re-solved from them (a simulated receiver's
    fixes are its own single-point solution, so this is what it would have reported)."""
    import copy

    out = copy.copy(table)
    out.observations = obs
    sol = solve_logged(out, obs)
    fixes = make_frame("fixes", sol.fixes_columns())
    for c in ("h_acc_m", "v_acc_m", "vel_acc_mps"):
        fixes[c] = np.interp(fixes["t_s"], table.fixes["t_s"], table.fixes[c])
    out.fixes = fixes
    return out


# --- real data --------------------------------------------------------------------------------------------


def real_stations() -> dict[str, Any]:
    """The rate test on the GSI stations: the product rule's alarms, and the paper's per-sample rule with its
    thresholds from the first 200 s (only 7 epochs at 30 s), over the rest of the hour."""
    from readers import read_log
    from spooflens.detectors.range_rate import run as run_seed001
    from spooflens.detectors.references import station_reference
    from spooflens.gnss.solved_fixes import with_solved_fixes
    from spooflens.gnss.stations import stations
    from spooflens.pipeline.registry import AnalysisContext, AnalyzeOptions

    table = with_solved_fixes(read_log(GSI))
    res = run_seed001(AnalysisContext(table, AnalyzeOptions()))[0]
    found, _ = stations(table, {})
    out: dict[str, Any] = {"product_alarms": len(res.alarms), "receivers": {}}
    for rid, st in found.items():
        grid = observation_grid(table, rid)
        r = rate_residuals(grid, station_reference(grid, st), table.ionosphere)
        dv = fit_velocity_error(r, grid.systems).fit.d_enu
        t = grid.t_s
        fit = np.isfinite(dv).all(axis=1) & (t <= 200.0)
        rest = np.isfinite(dv).all(axis=1) & (t > 200.0)
        bands = [paper_threshold(dv[fit, i], 0.01) for i in range(2)]
        fa = [int(np.sum(np.abs(dv[rest, i] - bands[i][0]) > bands[i][1])) for i in range(2)]
        out["receivers"][rid] = {
            "epochs": int(rest.sum()),
            "paper_rule_false_alarms_EN": fa,
            "paper_thresholds_mps": [b[1] for b in bands],
            "dv_rms_enu_mps": np.sqrt(np.nanmean(dv**2, axis=0)).tolist(),
        }
    return out


# --- printing ---------------------------------------------------------------------------------------------


def _fmt(x: float | None, digits: int = 1) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


def print_report(summary: dict[str, Any], product: dict[str, Any] | None, real: dict[str, Any] | None) -> None:
    out = console()
    n = summary["denominator"]
    t5 = Table(
        "model",
        "grade",
        "false alarms E",
        "N",
        "rate E %",
        "N %",
        "paper E",
        "paper N",
        title=f"Table 5 (clean runs, {summary['runs']} trajectories, out of {n})",
    )
    keys = _keys(summary)
    for model in ("rate", "pseudorange"):
        for g in keys:
            fa = summary[g][model]["false_alarms_mean"]
            pe, pn = PAPER["false_alarms"][model][g.split(" ")[0]]
            t5.add_row(
                model,
                g,
                _fmt(fa[0]),
                _fmt(fa[1]),
                _fmt(100 * fa[0] / n, 2),
                _fmt(100 * fa[1] / n, 2),
                f"{pe} ({100 * pe / 1500:.2f}%)",
                f"{pn} ({100 * pn / 1500:.2f}%)",
            )
    for g in keys:
        fa = summary[g]["ttest"]["false_alarms_mean"]
        t5.add_row(
            "rate, t-test", g, _fmt(fa[0]), _fmt(fa[1]), _fmt(100 * fa[0] / n, 2), _fmt(100 * fa[1] / n, 2), "-", "-"
        )
    out.print(t5)
    th = Table(
        "model",
        "grade",
        "E (main run)",
        "N (main run)",
        "E (median)",
        "N (median)",
        "paper E",
        "paper N",
        title="Per-sample thresholds from the first 200 s (P_FA 0.01)",
    )
    for model, unit in (("rate", "m/s"), ("pseudorange", "m")):
        key = "threshold_rate_mps" if model == "rate" else "threshold_pseudorange_m"
        for g in keys:
            m = summary[g][model]
            th.add_row(
                f"{model} ({unit})",
                g,
                _fmt(m["threshold_main"][0], 4),
                _fmt(m["threshold_main"][1], 4),
                _fmt(m["threshold_median"][0], 4),
                _fmt(m["threshold_median"][1], 4),
                str(PAPER[key]["E"]),
                str(PAPER[key]["N"]),
            )
    out.print(th)
    det = Table(
        "scheme",
        "grade",
        "rate per-sample",
        "rate t-test",
        "pseudorange",
        "this rule (main run)",
        title="Detection: share of runs with an alarm during the attack (median delay s); paper Fig. 9/10",
    )
    for scheme in SCHEMES:
        for g in keys:
            cells = []
            for model in ("rate", "ttest", "pseudorange"):
                d = summary[g][model]["detection"][scheme]
                cells.append(f"{100 * d['detected']:.0f}% ({_fmt(d['median_delay_s'])})")
            prod = "-"
            if product is not None and g in product:
                d = product[g][scheme]["delay_s"]
                prod = "missed" if d is None else f"{d:.1f} s"
            det.add_row(scheme, g, *cells, prod)
    out.print(det)
    f11 = Table(
        "model",
        "grade",
        "first false alarm (median s)",
        *[f"{int(lo)}-{int(lo) + 250} s" for lo in BINS],
        title="Fig. 11: share of epochs with a false alarm (E or N), clean runs, over time",
    )
    for model in ("rate", "pseudorange"):
        for g in keys:
            m = summary[g][model]
            f11.add_row(
                model,
                g,
                _fmt(m["first_false_alarm_median_s"], 0),
                *[f"{100 * x:.0f}%" for x in m["false_alarm_fraction_by_time"]],
            )
    out.print(f11)
    for g in keys:
        out.print(
            f"{g}: INS velocity error (E, N, U) median over runs: at 200 s "
            + ", ".join(f"{x:.3f}" for x in summary[g]["ins_velocity_error_200s_median"])
            + " m/s; at the end "
            + ", ".join(f"{x:.2f}" for x in summary[g]["ins_velocity_error_end_median"])
            + f" m/s; t-test window K (E, N) median {summary[g]['ttest']['K_median']}"
        )
    if product:
        for g in GRADES:
            c = product[g]["clean"]
            out.print(
                f"this rule, {g}, clean main run: {len(c['alarms'])} alarm(s) over {c['epochs']} epochs {c['alarms']}"
            )
    if real:
        out.print(f"real GSI stations (zero-velocity reference): this rule raised {real['product_alarms']} alarm(s)")
        for rid, r in real["receivers"].items():
            out.print(
                f"  {rid}: {r['epochs']} epochs after 200 s; paper rule (thresholds "
                + "/".join(f"{x:.4f}" for x in r["paper_thresholds_mps"])
                + f" m/s from 7 epochs) false alarms E/N {r['paper_rule_false_alarms_EN']}; dv RMS E/N/U "
                + "/".join(f"{x:.4f}" for x in r["dv_rms_enu_mps"])
                + " m/s"
            )


def _json_ready(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _json_ready(v) for k, v in x.items() if k != "main"}
    if isinstance(x, list | tuple):
        return [_json_ready(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.floating | np.integer):
        return x.item()
    return x


def plot_main(run: dict[str, Any], opts: BenchOptions, path: Path) -> None:
    """Fig. 9/10 like: the main trajectory's rate and pseudorange statistics (E, N), N1, under every scheme."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = run["t"]
    fig, axes = plt.subplots(2, 2, figsize=(12, 7), sharex=True)
    r = run[GRADES[0]]
    ev = evaluate(run, opts)[GRADES[0]]
    for col, model, unit in ((0, "rate", "m/s"), (1, "pseudorange", "m")):
        for row, axis in enumerate(("east", "north")):
            ax = axes[row, col]
            ax.plot(t, r["clean"][model][:, row], color="0.6", lw=0.8, label="clean")
            for scheme in SCHEMES:
                a, b, _, _ = SCHEMES[scheme]
                sel = (t >= a - 5) & (t <= b + 5)
                ax.plot(t[sel], r[scheme][model][sel, row], lw=1.0, label=f"scheme {scheme}")
            thr = ev[model]["threshold"][row]
            ax.axhline(thr, color="r", ls="--", lw=0.8)
            ax.axhline(-thr, color="r", ls="--", lw=0.8)
            ax.set_ylabel(f"{model} {axis} ({unit})")
            ax.set_ylim(-10 * thr, 10 * thr)
    axes[1, 0].set_xlabel("time (s)")
    axes[1, 1].set_xlabel("time (s)")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("seed 001, main trajectory, grade N1: velocity (rate model) and position (pseudorange model) error")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


@click.command("range_rate")
@click.option("--runs", default=100, show_default=True, help="Trajectories for Table 5 (the first is the main one).")
@click.option("--json", "json_path", type=click.Path(path_type=Path), default=None, help="Write all figures here.")
@click.option(
    "--plot", "plot_path", type=click.Path(path_type=Path), default=None, help="Draw the main trajectory's statistics."
)
@click.option("--quick", is_flag=True, help="3 trajectories, no product or real-data part (a smoke test).")
def command(runs: int, json_path: Path | None, plot_path: Path | None, quick: bool) -> int:
    """Seed 001: Table 5 false alarms, thresholds, detection of the Table 3 schemes, free-INS drift, this
    implementation's rule, real GSI stations."""
    opts = BenchOptions(runs=3 if quick else runs, product=not quick, real=not quick)
    t0 = time.perf_counter()
    with progress(show_progress()) as report:
        paper = paper_scenario(opts, report)
    summary = summarise(paper["evals"])
    product = product_rule(opts) if opts.product else None
    real = real_stations() if opts.real and GSI.exists() else None
    print_report(summary, product, real)
    console().print(f"bench time {time.perf_counter() - t0:.0f} s")
    if json_path:
        json_path.write_text(
            json.dumps(_json_ready({"summary": summary, "product": product, "real": real, "paper": PAPER}), indent=1)
        )
    if plot_path and paper["main"] is not None:
        plot_main(paper["main"], opts, plot_path)
        click.echo(f"plot: {plot_path}")
    return 0
