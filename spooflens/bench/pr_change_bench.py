"""Seed 002's experiment: spoofing on samples 500-900 of a static station, detected by the Kalman and the
recurrent predictor of the pseudorange change and compensated.

In depth: docs/methods/pr-change.md."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import click
import numpy as np
from numpy.typing import NDArray
from rich.table import Table
from scipy import stats

from spooflens.detectors.references import station_reference
from spooflens.detectors.statistics.pseudorange_change import (
    EsnOptions,
    KalmanOptions,
    PseudorangeChanges,
    clock_model_residual,
    compensation,
    esn_predictor,
    kalman_predictor,
    pseudorange_changes,
    train_esn,
)
from spooflens.detectors.statistics.scales import robust_scale, threshold
from spooflens.epoch_table import EpochTable
from spooflens.gnss.grid import ObservationGrid, observation_grid
from spooflens.gnss.stations import Station
from spooflens.output.console import console, progress, show_progress
from spooflens.simulation.observations import ObservationNoise, simulate_observations

FloatArray = NDArray[np.float64]
GSI = Path(__file__).resolve().parents[3] / "shared" / "real" / "rinex_gsi_pair"
NAV = GSI / "07590920.05n"
OBS_0759 = GSI / "07590920.05o"
ALPHAS = tuple(np.round(np.linspace(0.0, 1.0, 11), 2))
PAPER_IMPROVEMENT = {"kalman": 0.45, "rnn": 0.65}


@dataclass(frozen=True)
class BenchOptions:
    runs: int = 50
    epochs: int = 1200
    window: tuple[int, int] = (500, 900)  # attacked samples (inclusive), the paper's
    n_satellites: int = 3
    offset_m: float = 100.0
    gamma: float = 1e-4
    rise_epochs: int = 10
    p_false_alarm: float = 1e-6  # per satellite and epoch, as `spooflens analyze`
    real: bool = True


def attack_offsets(
    grid: ObservationGrid, cols: NDArray[np.int64], window: tuple[int, int], form: str, opts: BenchOptions
) -> FloatArray:
    """(E, S) delay added to each cell: D (built up over `rise_epochs` in the gradual form) plus gamma times
    the pseudorange change since the first attacked sample."""
    E, S = grid.pseudorange_m.shape
    off = np.zeros((E, S))
    a, b = window
    k = np.arange(E)
    inside = (k >= a) & (k <= b)
    ramp = np.ones(E) if form == "step" else np.clip((k - a + 1) / opts.rise_epochs, 0.0, 1.0)
    for j in cols:
        follow = opts.gamma * (grid.pseudorange_m[:, j] - grid.pseudorange_m[a, j])
        off[inside, j] = opts.offset_m * ramp[inside] + np.nan_to_num(follow[inside])
    return off


def attacked(grid: ObservationGrid, off: FloatArray) -> ObservationGrid:
    """The grid with every attacked cell's code and carrier delayed by `off` (Doppler would follow the
    offset's rate; the detectors here use code and carrier only)."""
    return replace(grid, pseudorange_m=grid.pseudorange_m + off, carrier_m=grid.carrier_m + off)


def _clock_variant(ch: PseudorangeChanges) -> PseudorangeChanges:
    """The same changes with the receiver clock removed by the clock model instead of the median."""
    zc, _ = clock_model_residual(ch)
    factor = ch.sigma_m / np.nanmin(ch.sigma_m) if np.isfinite(ch.sigma_m).any() else ch.sigma_m
    scale = robust_scale(zc / factor, 1e-3)
    return replace(ch, z_median=zc, sigma_m=scale * factor)


def evaluate(
    clean: ObservationGrid, station: Station, iono, cols, window, form: str, opts: BenchOptions
) -> dict[str, Any]:
    """Detection delay, false alarms and compensation of both predictors and both clock treatments."""
    off = attack_offsets(clean, cols, window, form, opts)
    grid = attacked(clean, off)
    ref = station_reference(grid, station)
    base = pseudorange_changes(grid, ref, iono)
    a, b = window
    E = grid.n_epochs
    k = np.arange(E)
    away = (k < a) | (k > b + 5)  # the end of the attack is a change too
    out: dict[str, Any] = {}
    for variant, ch in (("median", base), ("clock model", _clock_variant(base))):
        per_sat = np.isfinite(ch.z_median).sum(axis=0)
        thr = threshold(opts.p_false_alarm, int(max(np.median(per_sat[per_sat > 0]), 20)), 0.0, dof=1)[0]
        preds = {"kalman": kalman_predictor(ch, thr, KalmanOptions())}
        clean_epochs = np.asarray(~preds["kalman"].alarm.any(axis=1), dtype=bool)
        try:
            net = train_esn(
                ch.z_median / ch.sigma_m,
                ch.arc_start,
                np.broadcast_to(clean_epochs[:, None], (E, len(ch.sv_id))),
                EsnOptions(),
            )
            preds["rnn"] = esn_predictor(ch, net, thr, EsnOptions())
        except ValueError:
            pass
        vout: dict[str, Any] = {}
        cells = np.zeros_like(off, dtype=bool)
        cells[a : b + 1, cols] = True
        cells &= np.isfinite(ch.z_median) | np.isfinite(grid.pseudorange_m)
        before = float(np.sqrt(np.mean(off[cells] ** 2)))
        for name, p in preds.items():
            hits = np.flatnonzero(p.alarm[:, cols].any(axis=1) & (k >= a) & (k <= b))
            fa_epochs = int(np.sum(p.alarm.any(axis=1) & away))
            improvement = {}
            for alpha in ALPHAS:
                C = compensation(p, ch.arc_start, float(alpha))
                after = float(np.sqrt(np.mean((off - C)[cells] ** 2)))
                improvement[float(alpha)] = 1.0 - after / before if before > 0 else 0.0
            flagged = set(np.flatnonzero(p.alarm[a : b + 1].any(axis=0)).tolist())
            vout[name] = {
                "delay_epochs": int(hits[0] - a) if len(hits) else None,
                "false_alarm_epochs": fa_epochs,
                "epochs_away": int(away.sum()),
                "improvement": improvement,
                "named_right": flagged == set(int(c) for c in cols),
                "residual_rms_sigma": float(np.sqrt(np.nanmean((p.v / ch.sigma_m)[away & clean_epochs] ** 2))),
                "threshold": thr,
            }
        vout["rms_before_m"] = before
        out[variant] = vout
    return out


def _pick(
    grid: ObservationGrid, station: Station, iono, window: tuple[int, int], n: int, rng: np.random.Generator
) -> NDArray[np.int64]:
    """`n` satellites, at random, among those the detector follows through the whole attack window."""
    a, b = window
    ch = pseudorange_changes(grid, station_reference(grid, station), iono)
    through = np.flatnonzero(np.isfinite(ch.z_median[a : b + 1]).all(axis=0))
    return np.sort(rng.choice(through, size=min(n, len(through)), replace=False))


def simulated_station(opts: BenchOptions, report=None) -> list[dict[str, Any]]:
    from readers.rinex import read_rinex_nav, rinex_approx_position

    eph = read_rinex_nav(NAV)
    xyz = np.array(rinex_approx_position(OBS_0759))
    station = Station("sim", xyz, "GSI 0759 surveyed position")
    start = float(np.ceil(np.min(eph.toe_s) / 30.0) * 30.0)
    t = np.arange(opts.epochs, dtype=float)
    rx = np.tile(xyz, (opts.epochs, 1))
    results = []
    for run in range(opts.runs):
        rng = np.random.default_rng(500 + run)
        obs = simulate_observations("sim", t, start + t, rx, np.zeros_like(rx), eph, ObservationNoise(), rng)
        table = EpochTable(Path("seed002-bench"), "simulation", round(start * 1e9), "gps", observations=obs)
        table.ephemerides = eph
        grid = observation_grid(table, "sim")
        cols = _pick(grid, station, eph.iono, opts.window, opts.n_satellites, rng)
        results.append(
            {form: evaluate(grid, station, eph.iono, cols, opts.window, form, opts) for form in ("step", "gradual")}
        )
        if report:
            report("seed002: simulated station", run + 1, opts.runs)
    return results


def real_pair(opts: BenchOptions, tries: int = 10) -> list[dict[str, Any]]:
    """The GSI stations, clean (false alarms of the product rule) and attacked at epochs 50-90."""
    from readers import read_log
    from spooflens.gnss.solved_fixes import with_solved_fixes
    from spooflens.gnss.stations import stations

    table = with_solved_fixes(read_log(GSI))
    found, _ = stations(table, {})
    scale = 120 / opts.epochs
    window = (round(opts.window[0] * scale), round(opts.window[1] * scale))
    ropts = opts  # the rise keeps its 10 epochs (10 m per epoch), not its share of the log (1 epoch here)
    out = []
    for rid, st in found.items():
        grid = observation_grid(table, rid)
        for i in range(tries):
            cols = _pick(grid, st, table.ionosphere, window, opts.n_satellites, np.random.default_rng(900 + i))
            out.append(
                {
                    "receiver": rid,
                    **{f: evaluate(grid, st, table.ionosphere, cols, window, f, ropts) for f in ("step", "gradual")},
                }
            )
    return out


def summarise(results: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {"runs": len(results)}
    for form in ("step", "gradual"):
        fout: dict[str, Any] = {}
        for variant in ("median", "clock model"):
            vout: dict[str, Any] = {}
            for name in ("kalman", "rnn"):
                rs = [r[form][variant][name] for r in results if name in r[form][variant]]
                if not rs:
                    continue
                d = [x["delay_epochs"] for x in rs]
                hit = [x for x in d if x is not None]
                fa = sum(x["false_alarm_epochs"] for x in rs)
                away = sum(x["epochs_away"] for x in rs)
                vout[name] = {
                    "detected": len(hit) / len(d),
                    "median_delay_epochs": float(np.median(hit)) if hit else None,
                    "false_alarm_rate_per_epoch": fa / away if away else None,
                    "false_alarm_epochs": fa,
                    "named_right": float(np.mean([x["named_right"] for x in rs])),
                    "improvement_mean": {
                        a: float(np.mean([x["improvement"][a] for x in rs])) for a in rs[0]["improvement"]
                    },
                    "residual_rms_sigma": float(np.mean([x["residual_rms_sigma"] for x in rs])),
                }
            vout["rms_before_m"] = float(np.mean([r[form][variant]["rms_before_m"] for r in results]))
            fout[variant] = vout
        out[form] = fout
    return out


def print_report(sim: dict[str, Any], real: dict[str, Any] | None) -> None:
    out = console()
    for label, s in (("simulated 1 Hz station, samples 500-900", sim), ("real GSI pair (30 s), epochs 50-90", real)):
        if s is None:
            continue
        t = Table(
            "form",
            "clock",
            "predictor",
            "detected",
            "delay (epochs)",
            "false alarms / epoch",
            "satellites named right",
            "residual RMS (sigma)",
            "RMS before (m)",
            "improvement a=0.5",
            "a=1",
            "paper",
            title=f"{label}: {s['runs']} runs",
        )
        for form in ("step", "gradual"):
            for variant in ("median", "clock model"):
                v = s[form][variant]
                for name in ("kalman", "rnn"):
                    if name not in v:
                        continue
                    m = v[name]
                    imp = m["improvement_mean"]
                    t.add_row(
                        form,
                        variant,
                        name,
                        f"{100 * m['detected']:.0f}%",
                        "-" if m["median_delay_epochs"] is None else f"{m['median_delay_epochs']:.0f}",
                        f"{m['false_alarm_rate_per_epoch']:.1e} ({m['false_alarm_epochs']})",
                        f"{100 * m['named_right']:.0f}%",
                        f"{m['residual_rms_sigma']:.2f}",
                        f"{v['rms_before_m']:.1f}",
                        f"{100 * imp[0.5]:.0f}%",
                        f"{100 * imp[1.0]:.0f}%",
                        f"{100 * PAPER_IMPROVEMENT[name]:.0f}%",
                    )
        out.print(t)
        sweep = Table(
            "form",
            "predictor",
            *[f"a={a:g}" for a in ALPHAS],
            title=f"{label}: RMS improvement against alpha (median clock)",
        )
        for form in ("step", "gradual"):
            for name in ("kalman", "rnn"):
                m = s[form]["median"].get(name)
                if m:
                    sweep.add_row(form, name, *[f"{100 * m['improvement_mean'][a]:.0f}%" for a in ALPHAS])
        out.print(sweep)


@click.command("pr_change")
@click.option("--runs", default=50, show_default=True, help="Monte Carlo runs of the simulated station.")
@click.option("--json", "json_path", type=click.Path(path_type=Path), default=None, help="Write all figures here.")
@click.option("--quick", is_flag=True, help="3 runs, no real-data part (a smoke test).")
def command(runs: int, json_path: Path | None, quick: bool) -> int:
    """Seed 002: detection delay, false alarms and compensation of the Kalman and recurrent predictors on a
    simulated 1 Hz station and on the real GSI pair, beside the paper's 45 % and 65 %."""
    opts = BenchOptions(runs=3 if quick else runs, real=not quick)
    t0 = time.perf_counter()
    with progress(show_progress()) as report:
        sim = summarise(simulated_station(opts, report))
    real = summarise(real_pair(opts)) if opts.real and GSI.exists() else None
    print_report(sim, real)
    console().print(
        f"threshold chi-square(1) at {opts.p_false_alarm:g} per satellite and epoch = "
        f"{stats.chi2.isf(opts.p_false_alarm, 1):.1f} (F-widened for the estimated scale); bench time "
        f"{time.perf_counter() - t0:.0f} s"
    )
    if json_path:
        json_path.write_text(
            json.dumps({"simulated": sim, "real": real, "paper_improvement": PAPER_IMPROVEMENT}, indent=1)
        )
    return 0
