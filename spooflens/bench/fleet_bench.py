"""Seed 004's figures: the homology index against the number of attacked satellites for blocking, spoofing
and bias injection (Figs. 4-6), against the bias amplitude (Fig. 7), and the observer example (Figs. 10-12).

In depth: docs/methods/fleet.md."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import click
import numpy as np
from numpy.typing import NDArray
from rich.table import Table

from spooflens.fleet import attack_simulation as sim
from spooflens.fleet.homology import homology_batch
from spooflens.output.console import console, progress, show_progress

FloatArray = NDArray[np.float64]
GSI = Path("../shared/real/rinex_gsi_pair")
PAPER = {
    "blocking": "5.5-6 for n = 1-4 (peak 5.8 at 4), falling to ~2 by n = 7, 2-2.5 after",
    "spoofing": "120-140 for n = 1-3, ~210 at n = 4, lowest ~60 at n = 8",
    "bias_injection": "rises to 39.56 at n = 8 of 16, back to 0 at n = 16, symmetric",
    "amplitude": "flat from 0 to 8e4 ns (one anomalous run whose mean offset stays below 0.1 m)",
}


def error_split(gsi: Path) -> dict[str, float]:
    """Post-fit residual SD of each station and of their between-station difference, and the implied
    common (shared by both) and independent (per receiver) parts."""
    from readers import read_log
    from spooflens.gnss.single_point import solve_logged

    t = read_log(gsi)
    o = t.observations
    sol = solve_logged(t, o)
    o = o.assign(res=sol.residual_m, k=np.round(o["t_s"].to_numpy(float) / 30.0))
    a = o[o["receiver_id"] == "0759"][["k", "sv_id", "res"]]
    b = o[o["receiver_id"] == "3040"][["k", "sv_id", "res"]]
    m = a.merge(b, on=["k", "sv_id"]).dropna()
    sd = float(np.sqrt(0.5 * (m["res_x"].var() + m["res_y"].var())))
    diff = float((m["res_x"] - m["res_y"]).std())
    indep = diff / np.sqrt(2.0)
    return {
        "residual_sd_m": sd,
        "difference_sd_m": diff,
        "common_m": float(np.sqrt(max(sd**2 - indep**2, 0.0))),
        "independent_m": float(indep),
    }


def city_block(
    nav: Path,
    site: FloatArray,
    n_receivers: int,
    block_m: float,
    common_m: float,
    independent_m: float,
    time_spread_s: float,
    seed: int,
    mask_deg: float = 10.0,
) -> sim.Snapshot:
    """SIMULATED receivers at random spots in a block around `site`, with the real navigation file's
    satellites at the instant with the most of them above `mask_deg` (each receiver at that instant plus
    up to `time_spread_s`). Pseudoranges: true geometry, clock, troposphere and broadcast ionosphere
    (which the solver removes), plus an error per satellite common to all receivers and an independent
    one per receiver (sizes from the real pair)."""
    from readers.rinex import read_rinex_nav
    from spooflens.geodesy import add_enu_offset, ecef_to_geodetic, geodetic_to_ecef
    from spooflens.gnss.ephemeris import satellite_states
    from spooflens.gnss.geometry import azimuth_elevation
    from spooflens.simulation.observations import ObservationNoise, simulate_observations

    rng = np.random.default_rng(seed)
    eph = read_rinex_nav(nav)
    sats = np.array(eph.satellites())
    best_t, best_n = 0.0, -1
    for t in np.arange(float(eph.toe_s.min()), float(eph.toe_s.max()), 300.0):
        st = satellite_states(eph, sats, np.full(len(sats), t))
        _, el = azimuth_elevation(st.pos_m, np.broadcast_to(site, st.pos_m.shape))
        n = int(np.sum(st.valid & (el > np.radians(mask_deg + 5.0))))  # margin: visible from the whole block
        if n > best_n:
            best_t, best_n = float(t), n
    lat0, lon0, h0 = (float(v) for v in ecef_to_geodetic(site))
    offsets = np.c_[rng.uniform(-block_m / 2, block_m / 2, (n_receivers, 2)), np.zeros(n_receivers)]
    lat, lon, h = add_enu_offset(
        np.full(n_receivers, lat0), np.full(n_receivers, lon0), np.full(n_receivers, h0), offsets
    )
    rx = geodetic_to_ecef(lat, lon, h)
    t_rx = best_t + rng.uniform(0.0, time_spread_s, n_receivers)
    # independent part: the simulator's elevation-scaled code noise, zenith sigma chosen so its mean is the
    # measured independent part (sqrt(1 + 1/sin^2 el) averages about 1.6 over a sky above 10 deg)
    noise = ObservationNoise(pseudorange_sigma_m=independent_m / 1.6, elevation_mask_deg=mask_deg)
    frames = [
        simulate_observations(
            f"rx{i:02d}", np.zeros(1), np.array([t_rx[i]]), rx[i : i + 1], np.zeros((1, 3)), eph, noise, rng
        )
        for i in range(n_receivers)
    ]
    common_sv = sorted(set.intersection(*[set(f["sv_id"]) for f in frames]))
    common_err = dict(zip(common_sv, rng.normal(0.0, common_m, len(common_sv)), strict=True))
    R, N = n_receivers, len(common_sv)
    pos, clk, pr = np.empty((R, N, 3)), np.empty((R, N)), np.empty((R, N))
    for i, f in enumerate(frames):
        f = f.set_index("sv_id").loc[common_sv]
        pos[i] = f[["sv_x_m", "sv_y_m", "sv_z_m"]].to_numpy(float)
        clk[i] = f["sv_clock_bias_m"].to_numpy(float)
        pr[i] = f["pseudorange_m"].to_numpy(float) + np.array([common_err[s] for s in common_sv])
    return sim.Snapshot(tuple(f"rx{i:02d}" for i in range(R)), tuple(common_sv), pos, clk, pr, t_rx, eph.iono)


def _theta_stats(pov: FloatArray) -> dict[str, float]:
    th = homology_batch(pov)
    th = th[np.isfinite(th)]
    nz = th[th > 0]
    return {
        "mean": float(th.mean()) if len(th) else float("nan"),
        "mean_nonzero": float(nz.mean()) if len(nz) else float("nan"),
        "median": float(np.median(th)) if len(th) else float("nan"),
        "q25": float(np.percentile(th, 25)) if len(th) else float("nan"),
        "q75": float(np.percentile(th, 75)) if len(th) else float("nan"),
        "zero_share": float(np.mean(th == 0)) if len(th) else float("nan"),
        "median_offset_m": float(np.nanmedian(np.linalg.norm(pov, axis=2))),
    }


def attack_curves(
    snap: sim.Snapshot, runs: int, bias_m: float, seed: int, report
) -> dict[str, dict[int, dict[str, float]]]:
    N, R = snap.n_satellites, snap.n_receivers
    full = sim.solve_sets(snap, np.ones((1, R, N), bool))[0]
    ns = {
        "blocking": list(range(1, N - 4 + 1)),
        "spoofing": list(range(1, N - sim.AUTHENTIC + 1)),
        "bias_injection": list(range(1, N + 1)),
    }
    total = sum(len(v) for v in ns.values())
    done = 0
    out: dict[str, dict[int, dict[str, float]]] = {}
    # chunks of runs keep the padded arrays of one solve small
    chunk = max(1, 60_000 // R)
    for kind, values in ns.items():
        out[kind] = {}
        for n in values:
            rng = np.random.default_rng([seed, n, len(kind)])
            parts = []
            for start in range(0, runs, chunk):
                m = min(chunk, runs - start)
                if kind == "blocking":
                    parts.append(sim.blocking(snap, n, m, rng, full).pov)
                elif kind == "spoofing":
                    parts.append(sim.spoofing(snap, n, m, rng, bias_m).pov)
                else:
                    parts.append(sim.bias_injection(snap, n, m, rng, bias_m, full).pov)
            out[kind][n] = _theta_stats(np.concatenate(parts))
            done += 1
            report(f"seed004: {R} receivers x {runs} runs per n", done, total)
    return out


def amplitude_sweep(snap: sim.Snapshot, runs: int, seed: int) -> dict[str, Any]:
    amps = np.linspace(0.0, 8e4, 9)
    pov = sim.amplitude_sweep(snap, amps, runs, np.random.default_rng(seed))
    th = np.stack([homology_batch(pov[:, a]) for a in range(len(amps))], axis=1)  # (runs, amps)
    finite = np.isfinite(th).all(axis=1) & (th[:, 1:] > 0).all(axis=1)
    rel = np.abs(th[finite, 1:] / th[finite, 1:2] - 1.0)
    return {
        "amplitudes_ns": amps.tolist(),
        "mean_theta": [float(np.nanmean(th[finite, a])) for a in range(len(amps))],
        "runs_changing_over_10_percent": int(np.sum(rel.max(axis=1) > 0.1)),
        "runs": int(finite.sum()),
    }


def spoofing_vs_bias(snap: sim.Snapshot, runs: int, seed: int, n: int = 4) -> dict[float, float]:
    out = {}
    for b in (10.0, 30.0, 100.0, 300.0, 1000.0, 3000.0):
        pov = sim.spoofing(snap, n, runs, np.random.default_rng([seed, int(b)]), b).pov
        out[b] = _theta_stats(pov)["mean"]
    return out


def observer_figures() -> dict[str, Any]:
    from spooflens.fleet import dsse_example as ex
    from spooflens.fleet.observer import error_matrix, lyapunov_certificate

    rep = ex.example_report(starts=12)
    printed = ex.evaluate_printed(starts=2)
    decs = ex.decompositions()
    _, lmi = lyapunov_certificate(error_matrix(decs, rep.gains.N, ex.P))
    return {
        "singular_values": rep.singular_values,
        "rank_rtol": ex.RANK_RTOL,
        "open_loop_radius": rep.open_loop_radius,
        "poles": ex.POLES,
        "L_radius": rep.l_radius,
        "N_design": rep.n_objective,
        "N": [n.ravel().round(4).tolist() for n in rep.gains.N],
        "eq26_radius": rep.error_radius,
        "eq26_two_norm": rep.error_norm,
        "theorem2_radius_same_gains": rep.theorem2_radius,
        "exact_closed_loop_radius": rep.full_radius,
        "lmi_min_eigenvalue": lmi,
        "printed_L_radius_range": printed.l_radius,
        "printed_N1_N2_radius_range_with_designed_N3": printed.n_radius_with_designed_n3,
        "printed_N_theorem2_radius_range": printed.n_radius_theorem2_sign,
        "printed_N3_shape": printed.n3_printed_shape,
        "needed_N3_shape": printed.n3_needed_shape,
    }


@click.command("fleet")
@click.option("--runs", default=5000, show_default=True, help="Monte Carlo runs per attack and n (paper: 5000).")
@click.option("--receivers", default=30, show_default=True, help="Simulated receivers in the block (paper: 30 real).")
@click.option("--bias", "bias_m", default=300.0, show_default=True, help="Bias of spoofing and bias injection (m).")
@click.option("--gsi", "gsi", type=click.Path(path_type=Path), default=GSI, show_default=True)
@click.option("--json", "json_path", type=click.Path(path_type=Path), default=None, help="Write all figures here.")
@click.option("--seed", default=0, show_default=True)
def command(runs: int, receivers: int, bias_m: float, gsi: Path, json_path: Path | None, seed: int) -> int:
    """Seed 004: homology against attacked satellites and amplitude (30 simulated receivers, real orbits),
    the real GSI pair, and the observer example with its printed gains."""
    from readers.rinex import rinex_approx_position

    out = console()
    t0 = time.perf_counter()
    figures: dict[str, Any] = {}
    split = error_split(gsi)
    figures["error_split"] = split
    out.print(
        f"Real GSI pair, post-fit pseudorange residuals: SD {split['residual_sd_m']:.2f} m per station, "
        f"{split['difference_sd_m']:.2f} m between stations -> common part {split['common_m']:.2f} m, independent "
        f"{split['independent_m']:.2f} m per receiver (used for the simulated receivers)"
    )
    site = np.array(rinex_approx_position(gsi / "07590920.05o"), dtype=float)
    snap = city_block(
        gsi / "07590920.05n", site, receivers, 500.0, split["common_m"], split["independent_m"], 0.0, seed
    )
    figures["simulated"] = {"receivers": receivers, "satellites": list(snap.sv_id), "block_m": 500.0}
    out.print(
        f"[bold]{receivers} SIMULATED receivers[/] in a 500 m block around GSI 0759 (real GPS orbits of 07590920.05n), "
        f"{snap.n_satellites} satellites seen by all (paper: 30 real receivers, 16 satellites); {runs} runs per n"
    )
    with progress(show_progress()) as report:
        curves = attack_curves(snap, runs, bias_m, seed, report)
    figures["curves"] = curves
    for kind, rows in curves.items():
        t = Table(
            "n",
            "mean theta",
            "mean theta (non-zero runs)",
            "median [q25, q75]",
            "zero runs",
            "median |POV| (m)",
            title=f"{kind} ({receivers} simulated receivers); paper: {PAPER[kind]}",
        )
        for n, s in rows.items():
            t.add_row(
                str(n),
                f"{s['mean']:.3g}",
                f"{s['mean_nonzero']:.3g}",
                f"{s['median']:.3g} [{s['q25']:.3g}, {s['q75']:.3g}]",
                f"{s['zero_share']:.1%}",
                f"{s['median_offset_m']:.3g}",
            )
        out.print(t)
    sweep_runs = max(runs // 5, 50)
    sweep = amplitude_sweep(snap, sweep_runs, seed)
    figures["amplitude_sweep"] = sweep
    out.print(
        f"Amplitude sweep ({sweep['runs']} runs, random count and satellites): mean theta "
        + ", ".join(
            f"{a / 1e3:.0f}k ns: {m:.3g}" for a, m in zip(sweep["amplitudes_ns"], sweep["mean_theta"], strict=True)
        )
        + f"; runs whose theta changes by > 10 %: {sweep['runs_changing_over_10_percent']} "
        f"(paper: {PAPER['amplitude']})"
    )
    vs_bias = spoofing_vs_bias(snap, sweep_runs, seed)
    figures["spoofing_vs_bias_n4"] = vs_bias
    out.print(
        "Spoofing n = 4 against its bias (not given in the paper): "
        + ", ".join(f"{b:g} m: {v:.3g}" for b, v in vs_bias.items())
    )
    spread = city_block(
        gsi / "07590920.05n", site, receivers, 500.0, split["common_m"], split["independent_m"], 1800.0, seed
    )
    half = spread.n_satellites // 2
    sp = sim.bias_injection(spread, half, sweep_runs, np.random.default_rng(seed), bias_m).pov
    figures["time_spread_bias_injection"] = {
        "spread_s": 1800.0,
        "n": half,
        "satellites": spread.n_satellites,
        **_theta_stats(sp),
    }
    out.print(
        f"Receivers recording at random times within 30 min instead of at one instant ({spread.n_satellites} common "
        f"satellites): bias injection n = {half}: mean theta {figures['time_spread_bias_injection']['mean']:.3g} "
        f"(simultaneous: {curves['bias_injection'][min(half, max(curves['bias_injection']))]['mean']:.3g})"
    )
    from readers import read_log

    real = sim.snapshot_from_table(read_log(gsi))
    with progress(show_progress()) as report:
        real_curves = attack_curves(real, sweep_runs, bias_m, seed, report)
    figures["real_pair"] = {"satellites": list(real.sv_id), "curves": real_curves}
    t = Table(
        "attack",
        *[f"n={n}" for n in range(1, real.n_satellites + 1)],
        title=f"Real GSI pair (2 receivers, {real.n_satellites} common satellites, real pseudoranges), "
        f"mean theta over {sweep_runs} runs",
    )
    for kind, rows in real_curves.items():
        t.add_row(kind, *[f"{rows[n]['mean']:.3g}" if n in rows else "-" for n in range(1, real.n_satellites + 1)])
    out.print(t)
    obs = observer_figures()
    figures["observer"] = obs
    ranks = [sum(s > obs["rank_rtol"] * sv[0] for s in sv) if sv else 0 for sv in obs["singular_values"]]
    out.print(
        f"Observer, three-UAV example: rank of (A_i, C_i) {ranks} "
        f"at relative tolerance {obs['rank_rtol']}; open-loop radius {[round(r, 3) for r in obs['open_loop_radius']]}; "
        f"L_i placed at {obs['poles']} -> radius {[round(r, 3) for r in obs['L_radius']]}; N by {obs['N_design']}: "
        f"eq. (26) radius {obs['eq26_radius']:.3f} (2-norm {obs['eq26_two_norm']:.2f}, so the paper's bound does not "
        f"apply), exact closed loop {obs['exact_closed_loop_radius']:.3f}, Theorem 2's printed form with the same "
        f"gains {obs['theorem2_radius_same_gains']:.3f}; corrected LMI min eigenvalue "
        f"{obs['lmi_min_eigenvalue']:.3g} > 0"
    )
    out.print(
        f"Printed gains: L_1, L_2 give radius {[tuple(round(x, 2) for x in r) for r in obs['printed_L_radius_range']]} "
        f"over the order/sign choices of the basis; printed N_3 is {obs['printed_N3_shape']} where "
        f"{obs['needed_N3_shape']} is needed; printed N_1, N_2 with N_3 designed: radius "
        f"{tuple(round(x, 2) for x in obs['printed_N1_N2_radius_range_with_designed_N3'])} over the 64 basis pairs "
        f"(Theorem 2's sign: {tuple(round(x, 2) for x in obs['printed_N_theorem2_radius_range'])})"
    )
    figures["runtime_s"] = time.perf_counter() - t0
    out.print(f"runtime {figures['runtime_s']:.0f} s")
    if json_path:
        json_path.write_text(
            json.dumps(figures, indent=2, default=lambda x: x.tolist() if hasattr(x, "tolist") else str(x))
        )
    return 0
