"""Seed 000's Table 1 and beyond: detection delays of the KF innovation test, GLRT and MLRT.

In depth: docs/methods/mlrt.md."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import click
import numpy as np
from numpy.typing import NDArray
from rich.table import Table
from scipy import stats

from spooflens.attacks import apply_attack, parse_attack
from spooflens.detectors.innovation_tests import position_nis
from spooflens.estimation.kalman import forward_filter
from spooflens.estimation.marginalised_likelihood import paper_two_filter
from spooflens.estimation.ramp_signature import RampPass
from spooflens.estimation.statespace import LinearGaussianModel
from spooflens.navigation.loosely_coupled import FilterOptions, run_filter
from spooflens.navigation.strapdown import NavState
from spooflens.output.console import console, fmt, progress, show_progress
from spooflens.simulation.simulate import SCENARIOS, simulate

FloatArray = NDArray[np.float64]
METHODS = ("KF", "GLRT", "MLRT (paper two-filter, l>0)", "MLRT (ramp, flat, l>0)", "MLRT calibrated")
PAPER_TABLE1: dict[str, dict[int, float | None]] = {
    "KF": {2: None, 3: 3.4, 5: 1.9},
    "GLRT": {2: 2.63, 3: 1.59, 5: 1.03},
    "MLRT": {2: 2.57, 3: 1.57, 5: 0.56},
}
PAPER_VERTICAL_MLRT = 1.93
PAPER_MIN_RATE = 1.8
KF_THRESHOLD = float(stats.chi2.isf(1e-5, 3))  # 25.9, the paper's


@dataclass(frozen=True)
class BenchOptions:
    runs: int = 100
    onset_s: float = 10.0
    sigma_rate: tuple[float, float, float] = (3.0, 3.0, 3.0)
    attacks_per_hour: float = 0.1
    posterior_alarm: float = 0.99
    paper_L: int = 3
    equal_fa_hours: int = 200
    husky: Path | None = None
    methods: tuple[str, ...] = METHODS
    thresholds: dict[str, float] = field(default_factory=dict)  # overrides for the equal-FA part


def _paper_model(seed: int, attack: str | None) -> LinearGaussianModel:
    sc = SCENARIOS["seed000"]
    sim = simulate(sc, seed=seed)
    table = sim.table
    if attack:
        table, _ = apply_attack(table, parse_attack(attack))
    tr = sim.truth
    init = NavState(0.0, tr.lat[0], tr.lon[0], tr.h[0], tr.v_enu[0].copy(), tr.C[0].copy())
    opts = FilterOptions(grade=sc.imu_grade, initial=init, min_sigma_pos_m=0.0, min_sigma_vel_mps=0.0)
    return run_filter(table, options=opts).error_model()


def method_statistics(
    model: LinearGaussianModel, opts: BenchOptions, window_s: float = 15.0, step_s: float = 1.0, paper: bool = True
) -> dict[str, FloatArray]:
    """Each method's decision statistic per epoch, oriented so that 'alarm' is 'statistic > threshold'."""
    fwd = forward_filter(model)
    r = RampPass(model, (0, 1, 2), window_s, step_s, np.array(opts.sigma_rate), opts.attacks_per_hour, 1).whole_log(fwd)
    odds = np.exp(np.clip(r.log_odds, -700, 700))
    out = {
        "KF": position_nis(fwd),
        "GLRT": r.glr,
        "MLRT (ramp, flat, l>0)": r.mlr,
        "MLRT calibrated": odds / (1 + odds),
    }
    if paper:
        prior = np.asarray(np.linalg.inv(model.P0 + 1e-30 * np.eye(model.n_states)) * 1e-6, dtype=np.float64)
        vals = np.full(model.n_epochs, np.nan)
        for t in range(opts.paper_L + 1, model.n_epochs):
            res = paper_two_filter(model, t, opts.paper_L, prior_information=prior)
            vals[t] = np.max(res.ell) if len(res.ell) else np.nan
        out["MLRT (paper two-filter, l>0)"] = vals
    return out


def default_thresholds(opts: BenchOptions) -> dict[str, float]:
    return {
        "KF": KF_THRESHOLD,
        "GLRT": KF_THRESHOLD,
        "MLRT (paper two-filter, l>0)": 0.0,
        "MLRT (ramp, flat, l>0)": 0.0,
        "MLRT calibrated": opts.posterior_alarm,
        **opts.thresholds,
    }


def first_alarm(t: FloatArray, stat: FloatArray, threshold: float, after: float) -> float | None:
    hit = np.flatnonzero((t >= after) & (np.nan_to_num(stat, nan=-np.inf) > threshold))
    return float(t[hit[0]]) if len(hit) else None


def paper_scenario(opts: BenchOptions, on_progress=None) -> dict[str, Any]:
    thr = default_thresholds(opts)
    cases = [("en", 2.0), ("en", 3.0), ("en", 5.0), ("u", 25.0)]
    delays: dict[str, dict[str, list[float | None]]] = {m: {f"{a}:{r:g}": [] for a, r in cases} for m in opts.methods}
    false_alarms = {m: 0 for m in opts.methods}
    for i in range(opts.runs):
        clean = method_statistics(_paper_model(i, None), opts)
        t = np.arange(len(next(iter(clean.values()))), dtype=float)
        for m in opts.methods:
            false_alarms[m] += first_alarm(t, clean[m], thr[m], 1.0) is not None
        for axes, rate in cases:
            stat = method_statistics(_paper_model(i, f"ramp:rate={rate},axes={axes},start={opts.onset_s}"), opts)
            for m in opts.methods:
                hit = first_alarm(t, stat[m], thr[m], opts.onset_s)
                delays[m][f"{axes}:{rate:g}"].append(None if hit is None else hit - opts.onset_s)
        if on_progress:
            on_progress(i + 1, opts.runs)
    return {
        "delays": delays,
        "false_alarm_fraction": {m: n / opts.runs for m, n in false_alarms.items()},
        "thresholds": thr,
    }


def minimum_rate(
    opts: BenchOptions, rates: tuple[float, ...] = (0.5, 1.0, 1.5, 1.8, 2.0, 2.5, 3.0), runs: int = 40
) -> dict[str, Any]:
    thr = default_thresholds(opts)
    detected: dict[str, list[float]] = {m: [] for m in opts.methods}
    for rate in rates:
        hits = {m: 0 for m in opts.methods}
        for i in range(runs):
            stat = method_statistics(_paper_model(1000 + i, f"ramp:rate={rate},axes=en,start={opts.onset_s}"), opts)
            t = np.arange(len(stat["KF"]), dtype=float)
            for m in opts.methods:
                hits[m] += first_alarm(t, stat[m], thr[m], opts.onset_s) is not None
        for m in opts.methods:
            detected[m].append(hits[m] / runs)
    minimum = {m: next((r for r, f in zip(rates, detected[m], strict=True) if f >= 0.5), None) for m in opts.methods}
    return {"rates": list(rates), "detection_fraction": detected, "minimum_rate": minimum}


def summarise(values: list[float | None]) -> tuple[float | None, float | None, float | None, float]:
    """(median, 25th, 75th percentile of the delays of detected runs, fraction detected)."""
    got = np.array([v for v in values if v is not None], dtype=float)
    frac = len(got) / max(len(values), 1)
    if not len(got):
        return None, None, None, frac
    q = np.percentile(got, [50, 25, 75])
    return float(q[0]), float(q[1]), float(q[2]), frac


# --- equal false-alarm rates --------------------------------------------------------------------------


def _redraw(model: LinearGaussianModel, rng: np.random.Generator) -> LinearGaussianModel:
    """The same model with fresh noise: y drawn from it under H0 (no attack)."""
    n, N = model.n_states, model.n_epochs
    x = rng.multivariate_normal(np.zeros(n), model.P0)
    y = np.empty_like(model.y)
    for k in range(N):
        if k:
            x = model.A.at(k) @ x + rng.multivariate_normal(np.zeros(n), model.Q.at(k), method="eigh")
        y[k] = model.C[k] @ x + rng.multivariate_normal(np.zeros(model.n_measurements), model.R[k])
    return replace(model, y=np.where(np.isfinite(model.y), y, np.nan))


def _with_ramp(model: LinearGaussianModel, onset: int, rate: float) -> LinearGaussianModel:
    y = model.y.copy()
    dt = np.clip(model.t - model.t[onset], 0.0, None)
    # INS minus GNSS: a GNSS position dragged east and north by +rate*dt appears as -rate*dt
    y[:, 0] -= rate * dt
    y[:, 1] -= rate * dt
    return replace(model, y=y)


def equal_false_alarm(opts: BenchOptions, hours: int | None = None, on_progress=None) -> dict[str, Any]:
    """Thresholds for 1, 10, 100 false alarms per 1000 h from per-hour maxima (Gumbel tail), then delays."""
    hours = hours or opts.equal_fa_hours
    sc = replace(
        SCENARIOS["aircraft"],
        imu_hz=160.0,
        gnss_hz=1.0,
        imu_grade=SCENARIOS["seed000"].imu_grade,
        gnss=SCENARIOS["seed000"].gnss,
    )
    sim = simulate(sc, seed=99, duration_s=3600.0)
    tr = sim.truth
    init = NavState(0.0, tr.lat[0], tr.lon[0], tr.h[0], tr.v_enu[0].copy(), tr.C[0].copy())
    base = run_filter(
        sim.table, options=FilterOptions(grade=sc.imu_grade, initial=init, min_sigma_pos_m=0.0, min_sigma_vel_mps=0.0)
    ).error_model()
    methods = [m for m in opts.methods if m != "MLRT (paper two-filter, l>0)"]
    rng = np.random.default_rng(7)
    maxima: dict[str, list[float]] = {m: [] for m in methods}
    for h in range(hours):
        st = method_statistics(_redraw(base, rng), opts, window_s=30.0, paper=False)
        for m in methods:
            v = st[m][base.t > 60.0]
            if m == "MLRT calibrated":
                v = np.log(np.clip(v, 1e-300, None)) - np.log(np.clip(1 - v, 1e-300, None))  # log odds
            maxima[m].append(float(np.nanmax(v)))
        if on_progress:
            on_progress(h + 1, hours)
    rates_per_1000h = (1.0, 10.0, 100.0)
    thresholds: dict[str, dict[float, float]] = {}
    for m in methods:
        loc, scale = stats.gumbel_r.fit(maxima[m])
        thresholds[m] = {r: float(stats.gumbel_r.isf(r / 1000.0, loc, scale)) for r in rates_per_1000h}
    delays: dict[str, dict[str, dict[float, float | None]]] = {m: {} for m in methods}
    onset = int(np.searchsorted(base.t, 1800.0))
    for ramp in (2.0, 3.0, 5.0):
        runs = [_with_ramp(_redraw(base, rng), onset, ramp) for _ in range(20)]
        stats_runs = [method_statistics(r, opts, window_s=30.0, paper=False) for r in runs]
        for m in methods:
            delays[m][f"{ramp:g}"] = {}
            for r_fa, thr in thresholds[m].items():
                got = []
                for st in stats_runs:
                    v = st[m]
                    if m == "MLRT calibrated":
                        v = np.log(np.clip(v, 1e-300, None)) - np.log(np.clip(1 - v, 1e-300, None))
                    hit = first_alarm(base.t, v, thr, base.t[onset])
                    got.append(None if hit is None else hit - base.t[onset])
                delays[m][f"{ramp:g}"][r_fa] = summarise(got)[0]
    return {
        "hours": hours,
        "thresholds": thresholds,
        "delays": delays,
        "note": "MLRT calibrated thresholds are on the log posterior odds",
    }


# --- real data ----------------------------------------------------------------------------------------


def husky(path: Path) -> dict[str, Any]:
    from readers import read_log
    from spooflens.detectors.mlrt import MlrtOptions, detect
    from spooflens.navigation.imu_models import grade

    table = read_log(path)
    out: dict[str, Any] = {}
    for label, attack in (
        ("clean", None),
        ("ramp 2 m/s from 200 s", "ramp:rate=2,axes=en,start=200"),
        ("ramp 5 m/s from 200 s", "ramp:rate=5,axes=en,start=200"),
    ):
        t = table if attack is None else apply_attack(table, parse_attack(attack))[0]
        sol = run_filter(t, options=FilterOptions(grade=grade("consumer_mems")))
        res = detect(sol.error_model(), MlrtOptions(offline=False))
        out[label] = {
            r.name: {
                "alarms": len(r.alarms),
                "advisory": r.advisory,
                "first_alarm_s": r.alarms[0].start_s if r.alarms else None,
                "delay_after_200_s": next((a.start_s - 200.0 for a in r.alarms if a.start_s >= 200.0), None),
                "whiteness": r.extras.get("innovation_whiteness"),
            }
            for r in res
        }
    return out


def runtime() -> dict[str, float]:
    from spooflens.detectors.mlrt import MlrtOptions, detect

    sim = simulate("aircraft", seed=1, duration_s=3600.0)
    sol = run_filter(sim.table, options=FilterOptions(grade=SCENARIOS["aircraft"].imu_grade))
    model = sol.error_model()
    warm = replace(
        model, t=model.t[:200], A=model.A[:200], Q=model.Q[:200], C=model.C[:200], R=model.R[:200], y=model.y[:200]
    )
    detect(warm)
    t0 = time.perf_counter()
    detect(model, MlrtOptions())
    return {"epochs": float(model.n_epochs), "detectors_s": time.perf_counter() - t0}


def plot(out: dict[str, Any], path: Path) -> None:
    """Box plots of the paper-scenario delays per method and case, with the paper's values marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = ("en:2", "en:3", "en:5", "u:25")
    methods = [m for m in out["paper"]["delays"] if "l>0" not in m]
    fig, axes = plt.subplots(1, len(cases), figsize=(14, 4), sharey=True)
    for ax, case in zip(axes, cases, strict=True):
        data = [[v for v in out["paper"]["delays"][m][case] if v is not None] or [np.nan] for m in methods]
        ax.boxplot(data, tick_labels=[m.replace("MLRT calibrated", "MLRT\ncalibrated") for m in methods])
        ax.set_title(f"ramp {case.split(':')[1]} m/s ({'east+north' if case.startswith('en') else 'up'})")
        rate = int(case.split(":")[1])
        for i, m in enumerate(methods, start=1):
            key = "MLRT" if m.startswith("MLRT") else m
            ref = PAPER_VERTICAL_MLRT if case == "u:25" and key == "MLRT" else PAPER_TABLE1.get(key, {}).get(rate)
            if ref is not None:
                ax.plot(i, ref, "r*", markersize=12, label="paper" if i == 1 else None)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("detection delay (s)")
    fig.suptitle("Seed 000 scenario: detection delay over Monte Carlo runs (red stars: paper's Table 1)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


@click.command("mlrt")
@click.option("--runs", default=100, show_default=True, help="Monte Carlo runs per case of the paper's scenario.")
@click.option("--hours", default=200, show_default=True, help="Attack-free hours for the equal false-alarm part.")
@click.option(
    "--husky",
    "husky_path",
    type=click.Path(path_type=Path),
    default=Path(__file__).resolve().parents[2].parent / "shared/real/ros1_husky_navsat/test1.bag",
    show_default=True,
    help="Real clean log for the real-data part (skipped if missing).",
)
@click.option("--json", "json_path", type=click.Path(path_type=Path), default=None, help="Write all figures here.")
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(path_type=Path),
    default=None,
    help="Write a PNG of the delay distributions here.",
)
@click.option("--quick", is_flag=True, help="Fewer runs everywhere (a smoke test, not the reported figures).")
def command(
    runs: int, hours: int, husky_path: Path, json_path: Path | None, plot_path: Path | None, quick: bool
) -> int:
    """Seed 000's Table 1 (KF, GLRT, MLRT delays), false alarms, equal-FA delays, real data, runtime."""
    if quick:
        runs, hours = min(runs, 5), min(hours, 10)
    opts = BenchOptions(runs=runs, equal_fa_hours=hours)
    out: dict[str, Any] = {}
    with progress(show_progress()) as report:
        out["paper"] = paper_scenario(opts, lambda d, n: report("paper scenario (Monte Carlo)", d, n))
        out["minimum_rate"] = minimum_rate(opts, runs=8 if quick else 40)
        out["equal_fa"] = equal_false_alarm(opts, hours, lambda d, n: report("attack-free hours", d, n))
    if husky_path.exists():
        out["husky"] = husky(husky_path)
    out["runtime"] = runtime()
    _print_seed000(out, runs)
    if json_path:
        json_path.write_text(json.dumps(out, indent=1, default=str))
    if plot_path:
        plot(out, plot_path)
        click.echo(f"plot: {plot_path}")
    return 0


def _print_seed000(out: dict[str, Any], runs: int) -> None:
    out_console = console()
    paper = out["paper"]
    t = Table(
        "method",
        *[f"{c} m/s" for c in ("2", "3", "5")],
        "25 m/s up",
        "clean runs alarmed",
        title=f"Seed 000 scenario, {runs} runs: median delay s [25-75%] (detected %)  | paper Table 1",
    )
    for m, cases in paper["delays"].items():
        cells = []
        for key in ("en:2", "en:3", "en:5", "u:25"):
            med, lo, hi, frac = summarise(cases[key])
            cells.append(f"{fmt(med)} [{fmt(lo)}-{fmt(hi)}] ({100 * frac:.0f}%)")
        t.add_row(m, *cells, f"{100 * paper['false_alarm_fraction'][m]:.0f}%")
    for name, row in PAPER_TABLE1.items():
        vertical = f"{PAPER_VERTICAL_MLRT}" if name == "MLRT" else ""
        t.add_row(f"paper: {name}", *[fmt(row[r]) for r in (2, 3, 5)], vertical, "")
    out_console.print(t)
    mr = out["minimum_rate"]
    out_console.print(
        f"smallest east+north ramp detected in >= 50% of runs (paper: MLRT {PAPER_MIN_RATE} m/s): "
        + ", ".join(f"{m} {fmt(v)}" for m, v in mr["minimum_rate"].items())
    )
    eq = out["equal_fa"]
    t = Table(
        "method",
        *[f"{r} m/s @ {fa:g}/1000h" for r in ("2", "5") for fa in (1.0, 10.0, 100.0)],
        title=f"Equal false-alarm rates ({eq['hours']} attack-free hours, Gumbel tail): median delay s",
    )
    for m, d in eq["delays"].items():
        t.add_row(m, *[fmt(d[r][fa]) for r in ("2", "5") for fa in (1.0, 10.0, 100.0)])
    out_console.print(t)
    if "husky" in out:
        t = Table(
            "husky bag",
            *out["husky"]["clean"].keys(),
            title="Real data (husky, consumer IMU): alarms when clean, delay (s) of the first alarm after "
            "an injected ramp's onset",
        )
        for label, res in out["husky"].items():
            key = "alarms" if label == "clean" else "delay_after_200_s"
            t.add_row(
                label,
                *[
                    (f"{v[key]:.1f}" if isinstance(v[key], float) else f"{v[key]}" if v[key] is not None else "-")
                    + (" (advisory)" if v["advisory"] else "")
                    for v in res.values()
                ],
            )
        out_console.print(t)
    rt = out["runtime"]
    out_console.print(
        f"runtime: all seed-000 detectors (online + offline l_N(m)) over {rt['epochs']:.0f} epochs "
        f"(1 h of 10 Hz GNSS): {rt['detectors_s']:.1f} s (goal < 10 s)"
    )
