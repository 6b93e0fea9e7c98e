"""`spooflens bench baseline`: attacks that fill a whole log, caught with a vehicle's baseline and without.

Simulated (`spooflens.bench.baseline_sim`): per vehicle, a baseline learned from N = 1, 2, 4, 8 of its
clean logs (`spooflens.baseline.learn`, exactly what `spooflens baseline` writes); then logs attacked
from their first fix to their last and more clean logs, each analysed (`analyze_table`, what `spooflens
analyze` runs) without a baseline and with each. Measured: whether anything flags the attack (an
incident or a one-class anomaly), whether the verdict is spoofing, how much of the log the flags cover;
on clean logs, spoofing incidents and anomalies with and without.

Real: logs of one receiver type in ../shared/real, each analysed with a baseline learned from the others
of its group (leave one out) and without: incidents the baseline adds are false (the logs are clean).
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import click
import numpy as np
from rich.table import Table

from spooflens.bench.baseline_sim import ATTACKS, TWO_RECEIVER_ATTACKS, VEHICLES, LogSpec, coverage, simulate_log
from spooflens.output.console import console, progress, show_progress

NS = (1, 2, 4, 8)
REAL = Path(__file__).resolve().parents[2].parent / "shared" / "real"
# logs of one receiver type (and installation, where the group says so)
REAL_GROUPS: dict[str, tuple[str, ...]] = {
    "ArduPlane aircraft, u-blox (two flights of one aircraft)": (
        "ardupilot_dataflash/flightdata_center_0003.bin",
        "corpus/pyflightcoach/pilot_0004.BIN",
    ),
    "u-blox ZED-F9P, UBX captures (gpsd)": (
        "corpus/gpsd/ublox-zed-f9p-hp.log",
        "corpus/gpsd/ublox-zed-f9p-rtk.log",
        "corpus/gpsd/ublox-zed-f9p-sfrbx.log",
        "ubx_receivers/gpsd_ublox-zed-f9p_hpg1.11.log",
    ),
    "Android phone, GnssLogger 1.4 (two logs of 2016)": (
        "android_gnsslogger/gps-measurement-tools/pseudoranges_log_2016_06_30_21_26_07.txt",
        "android_gnsslogger/gps-measurement-tools/pseudoranges_log_2016_08_22_14_45_50.txt",
    ),
}


@dataclass(frozen=True)
class Plan:
    vehicles: tuple[str, ...]
    vehicle_seeds: tuple[int, ...]
    attacks: tuple[str, ...]
    ns: tuple[int, ...]
    clean_tests: int
    attacked_tests: int

    @property
    def baseline_logs(self) -> int:
        return max(self.ns)


def _measure(spec: LogSpec) -> Any:
    """One clean log of a vehicle, analysed and measured for its baseline."""
    from spooflens.baseline.measure import measure
    from spooflens.pipeline.run import analyze_table

    table, _ = simulate_log(spec)
    return measure(analyze_table(table, clean_coasts=True), f"{spec.vehicle} seed {spec.log_seed}", "simulated")


def _outcome(analysis: Any, t_first: float, t_last: float) -> dict[str, Any]:
    incidents = analysis.verdict.incidents
    spoofing = [i for i in incidents if i.is_spoofing]
    return {
        "flagged": bool(incidents),
        "spoofing": bool(spoofing),
        "coverage": coverage(incidents, t_first, t_last),
        "coverage_spoofing": coverage(spoofing, t_first, t_last),
        "spoofing_incidents": len(spoofing),
        "anomalies": len(incidents) - len(spoofing),
        "evidence": sorted({str(e) for i in incidents for e in i.corroborating}),
        "headline": analysis.verdict.headline,
    }


def _judge(spec: LogSpec, baselines: dict[int, Any]) -> list[dict[str, Any]]:
    """A test log analysed without a baseline and with each one (n clean logs -> LoadedBaseline)."""
    from spooflens.baseline.loaded import check
    from spooflens.pipeline.registry import AnalyzeOptions
    from spooflens.pipeline.run import analyze_table

    table, _ = simulate_log(spec)
    t = table.fixes["t_s"].to_numpy(dtype=float)
    rows = []
    for n in (0, *sorted(baselines)):
        options = AnalyzeOptions(baseline=check(baselines[n], table) if n else None)
        out = _outcome(analyze_table(table, options), float(t.min()), float(t.max()))
        rows.append(asdict(spec) | {"n": n, "hours": float(table.duration_s) / 3600.0} | out)
    return rows


def _loaded(measurements: list[Any], label: str) -> Any:
    from spooflens.baseline.learn import aggregate
    from spooflens.baseline.loaded import LoadedBaseline

    return LoadedBaseline(aggregate(measurements), label, "simulated")


def run_simulated(plan: Plan, workers: int, show: bool) -> list[dict[str, Any]]:
    clean_specs = [
        LogSpec(v, s, 1000 * s + k)
        for v in plan.vehicles
        for s in plan.vehicle_seeds
        for k in range(plan.baseline_logs)
    ]
    tests = [
        LogSpec(v, s, 1000 * s + 500 + k)
        for v in plan.vehicles
        for s in plan.vehicle_seeds
        for k in range(plan.clean_tests)
    ]
    for v in plan.vehicles:
        for a in plan.attacks:
            if (a in TWO_RECEIVER_ATTACKS) != (v == "car_two_receivers"):
                continue
            tests += [
                LogSpec(v, s, 1000 * s + 600 + k, a) for s in plan.vehicle_seeds for k in range(plan.attacked_tests)
            ]
    rows: list[dict[str, Any]] = []
    with progress(show) as report, ProcessPoolExecutor(max_workers=workers) as pool:
        measured: dict[LogSpec, Any] = {}
        futures = {pool.submit(_measure, spec): spec for spec in clean_specs}
        for done, f in enumerate(as_completed(futures), 1):
            measured[futures[f]] = f.result()
            report("clean logs measured for the baselines", done, len(futures))
        baselines: dict[tuple[str, int], dict[int, Any]] = {}
        for v in plan.vehicles:
            for s in plan.vehicle_seeds:
                logs = [measured[LogSpec(v, s, 1000 * s + k)] for k in range(plan.baseline_logs)]
                baselines[(v, s)] = {n: _loaded(logs[:n], f"{v} vehicle {s}, {n} log(s)") for n in plan.ns}
        judged = {pool.submit(_judge, spec, baselines[(spec.vehicle, spec.vehicle_seed)]): spec for spec in tests}
        for done, f in enumerate(as_completed(judged), 1):
            rows += f.result()
            report("test logs analysed, without and with each baseline", done, len(judged))
    return rows


def summarise(rows: list[dict[str, Any]], ns: Iterable[int]) -> dict[str, Any]:
    attacked = [r for r in rows if r["attack"] is not None]
    clean = [r for r in rows if r["attack"] is None]
    per_attack: dict[str, dict[str, Any]] = {}
    for attack in dict.fromkeys(r["attack"] for r in attacked):
        for n in (0, *ns):
            rs = [r for r in attacked if r["attack"] == attack and r["n"] == n]
            if not rs:
                continue
            cov = [r["coverage"] for r in rs]
            per_attack.setdefault(attack, {})[str(n)] = {
                "runs": len(rs),
                "flagged": float(np.mean([r["flagged"] for r in rs])),
                "spoofing": float(np.mean([r["spoofing"] for r in rs])),
                "most_of_log": float(np.mean([c >= 0.5 for c in cov])),
                "coverage_median": float(np.median(cov)),
                "coverage_min": float(np.min(cov)),
                "spoofing_coverage_median": float(np.median([r["coverage_spoofing"] for r in rs])),
            }
    per_clean: dict[str, dict[str, Any]] = {}
    for n in (0, *ns):
        rs = [r for r in clean if r["n"] == n]
        if rs:
            hours = float(sum(r["hours"] for r in rs))
            per_clean[str(n)] = {
                "logs": len(rs),
                "hours": hours,
                "spoofing_incidents": int(sum(r["spoofing_incidents"] for r in rs)),
                "anomalies": int(sum(r["anomalies"] for r in rs)),
            }
    return {"per_attack": per_attack, "clean": per_clean}


def _real_measure(path: str) -> Any:
    from spooflens.baseline.measure import measure
    from spooflens.output.report.provenance import identify
    from spooflens.pipeline.run import analyze_segments
    from spooflens.service import read_table

    table = read_table(Path(path), {}, False)
    analyses = analyze_segments(table, clean_coasts=True)
    out: list[Any] = []  # a measurement, or why the log was refused
    for a in analyses:
        try:
            out.append(measure(a, Path(path).name, identify(Path(path)).sha256))
        except ValueError as err:
            out.append(str(err))
    return out


def _real_judge(path: str, baseline: Any) -> dict[str, Any]:
    from spooflens.baseline.loaded import check
    from spooflens.pipeline.registry import AnalyzeOptions
    from spooflens.pipeline.run import analyze_segments
    from spooflens.service import read_table

    table = read_table(Path(path), {}, False)
    out: dict[str, Any] = {"log": path}
    try:
        loaded = check(baseline, table)
    except Exception as err:  # noqa: BLE001 - a refused baseline is a result here
        return out | {"refused": str(err)}
    out["warnings"] = list(loaded.warnings)
    for key, options in (("without", AnalyzeOptions()), ("with", AnalyzeOptions(baseline=loaded))):
        out[key] = verdict_counts(analyze_segments(table, options))
    return out


def verdict_counts(analyses: list[Any]) -> dict[str, Any]:
    incidents = [i for a in analyses for i in a.verdict.incidents]
    spoofing = [i for i in incidents if i.is_spoofing]
    return {
        "spoofing_incidents": len(spoofing),
        "anomalies": len(incidents) - len(spoofing),
        "spans": [[round(i.start_s, 1), round(i.end_s, 1), i.confidence, list(i.detectors)] for i in incidents],
        "headline": "; ".join(a.verdict.headline for a in analyses),
    }


def run_real(workers: int, show: bool, root: Path = REAL) -> list[dict[str, Any]]:
    """Leave one out within each group of ../shared/real logs of one receiver type."""
    from spooflens.baseline.learn import aggregate
    from spooflens.baseline.loaded import LoadedBaseline

    paths = {rel: str(root / rel) for logs in REAL_GROUPS.values() for rel in logs if (root / rel).exists()}
    rows: list[dict[str, Any]] = []
    with progress(show) as report, ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(_real_measure, p): rel for rel, p in paths.items()}
        measured: dict[str, list[Any]] = {}
        for done, f in enumerate(as_completed(futures), 1):
            measured[futures[f]] = f.result()
            report("real logs measured", done, len(futures))
        jobs = {}
        for group, logs in REAL_GROUPS.items():
            for held in logs:
                if held not in measured:
                    continue
                others = [m for rel in logs if rel != held and rel in measured for m in measured[rel]]
                usable = [m for m in others if not isinstance(m, str)]
                if not usable:
                    continue
                loaded = LoadedBaseline(aggregate(usable), f"leave-one-out baseline of {group}", "")
                f = pool.submit(_real_judge, paths[held], loaded)
                jobs[f] = (group, held, len(usable))
        for done, f in enumerate(as_completed(jobs), 1):
            group, held, n = jobs[f]
            rows.append({"group": group, "held_out": held, "baseline_logs": n} | f.result())
            report("real logs analysed with and without", done, len(jobs))
    return sorted(rows, key=lambda r: (r["group"], r["held_out"]))


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.0f}%"


def print_results(out: dict[str, Any]) -> None:
    c = console()
    s = out["summary"]
    for attack, by_n in s["per_attack"].items():
        t = Table(
            "baseline",
            "runs",
            "flagged",
            "spoofing verdict",
            "flagged over half the log",
            "median coverage",
            "least coverage",
            title=f"{attack}, from the first fix to the last (simulated)",
        )
        for n, k in by_n.items():
            t.add_row(
                "none" if n == "0" else f"{n} clean log(s)",
                str(k["runs"]),
                _pct(k["flagged"]),
                _pct(k["spoofing"]),
                _pct(k["most_of_log"]),
                _pct(k["coverage_median"]),
                _pct(k["coverage_min"]),
            )
        c.print(t)
    t = Table("baseline", "clean logs", "hours", "spoofing incidents", "anomalies", title="Clean logs (simulated)")
    for n, k in s["clean"].items():
        t.add_row(
            "none" if n == "0" else f"{n} clean log(s)",
            str(k["logs"]),
            f"{k['hours']:.1f}",
            str(k["spoofing_incidents"]),
            str(k["anomalies"]),
        )
    c.print(t)
    if out.get("real"):
        t = Table(
            "group",
            "held-out log",
            "baseline logs",
            "without: spoofing / anomalies",
            "with: spoofing / anomalies",
            "warnings",
            title="Real logs: a baseline from the others of the group (leave one out)",
        )
        for r in out["real"]:
            if "refused" in r:
                t.add_row(
                    r["group"], Path(r["held_out"]).name, str(r["baseline_logs"]), "-", f"refused: {r['refused']}", ""
                )
                continue
            w, b = r["without"], r["with"]
            t.add_row(
                r["group"],
                Path(r["held_out"]).name,
                str(r["baseline_logs"]),
                f"{w['spoofing_incidents']} / {w['anomalies']}",
                f"{b['spoofing_incidents']} / {b['anomalies']}",
                "; ".join(r["warnings"]),
            )
        c.print(t)


@click.command("baseline")
@click.option(
    "--vehicle",
    "vehicles",
    multiple=True,
    type=click.Choice(list(VEHICLES)),
    help="Only these simulated vehicles (repeatable; default all).",
)
@click.option("--attack", "attacks", multiple=True, type=click.Choice(list(ATTACKS)), help="Only these attacks.")
@click.option("--vehicles-per-kind", default=2, show_default=True, help="Simulated vehicles (receivers) per kind.")
@click.option("--clean-tests", default=3, show_default=True, help="Clean test logs per vehicle.")
@click.option("--attacked-tests", default=2, show_default=True, help="Attacked logs per vehicle and attack.")
@click.option("--workers", default=2, show_default=True, help="Processes.")
@click.option("--seed", default=1, show_default=True, help="First vehicle seed.")
@click.option("--no-real", is_flag=True, help="Leave out the real logs (../shared/real).")
@click.option("--json", "json_path", type=click.Path(path_type=Path), default=None, help="Write every row here.")
@click.option("--quick", is_flag=True, help="One vehicle per kind, baselines of 1 and 4 logs (a smoke test).")
def command(
    vehicles: tuple[str, ...],
    attacks: tuple[str, ...],
    vehicles_per_kind: int,
    clean_tests: int,
    attacked_tests: int,
    workers: int,
    seed: int,
    no_real: bool,
    json_path: Path | None,
    quick: bool,
) -> int:
    """Whole-log attacks caught with a vehicle's baseline against without, false incidents on clean logs with
    it, how many clean logs a baseline needs (N = 1, 2, 4, 8); real logs with a baseline of their kind."""
    ns = (1, 4) if quick else NS
    plan = Plan(
        vehicles or tuple(VEHICLES),
        tuple(range(seed, seed + (1 if quick else vehicles_per_kind))),
        attacks or tuple(ATTACKS),
        ns,
        1 if quick else clean_tests,
        1 if quick else attacked_tests,
    )
    show = show_progress()
    rows = run_simulated(plan, workers, show)
    out: dict[str, Any] = {"plan": asdict(plan), "summary": summarise(rows, ns), "rows": rows, "simulated": True}
    out["real"] = [] if no_real else run_real(workers, show)
    print_results(out)
    if json_path:
        json_path.write_text(json.dumps(out, indent=1, default=str))
    return 0
