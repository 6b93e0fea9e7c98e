"""`spooflens bench realworld`: the whole analysis (`spooflens.pipeline.run.analyze_table`, exactly what
`spooflens analyze` runs) on simulated vehicles whose receivers behave like real ones, attacked and clean.

Each run draws a receiver (`spooflens.simulation.sensors.realistic_receiver`: Gauss-Markov errors of
30-300 s, reported accuracies 0.2-5 times the real scatter, indicators with their own fluctuation) on one
of the vehicles (multirotor hovering and cruising, car, ship, aircraft), simulates the log, injects one
attack kind from a random time in the log's middle third to its end (`capture` takes the receiver over
before dragging it; the ramps, the step and the velocity pull are the plain fix-level kinds; a car
whose receiver logs raw GPS and Galileo observations, or GPS alone, meets a GPS-only spoofer instead), and
analyses it.
Measured: the detection rate, the delay from the first spoofed fix to the first alarm of the incident
that made the verdict, whether the onset interval covers the true onset, whether the incident runs to
the end of the log; and on clean logs the false spoofing incidents per 100 hours.
Jamming (`jam` for a minute, `jam_spoof`: jamming then a capture) is scored by the interference detector's
alarms: detected, onset and end delays, how much of the jammed interval its alarms cover, whether its
onset interval holds the jammer's start; and how often jamming alone drew a spoofing verdict; for
`jam_spoof` also the capture, by the spoofing detectors' first alarm after the takeover. On clean logs the
interference events per 100 hours. Vehicles `*_sky` have receivers that report their sky (per-satellite
C/N0); the others log the mean C/N0 and the front end's indicators only.
Every figure is from simulation (there is no real spoofed log to measure on here) and says so.
"""

from __future__ import annotations

import json
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import click
import numpy as np
from rich.table import Table

from spooflens.output.console import console, progress, show_progress

# vehicle -> (scenario, seconds of log)
VEHICLES: dict[str, tuple[str, float]] = {
    "multirotor": ("multirotor", 600.0),
    "car": ("ground", 300.0),
    "ship": ("ship", 1200.0),
    "aircraft": ("aircraft", 600.0),
    "ship_nmea": ("ship", 1200.0),
    "car_raw": ("ground_raw", 300.0),
    "car_raw_gps": ("ground_raw", 300.0),
    "car_raw_gps_orbits": ("ground_raw", 300.0),
    "multirotor_sky": ("multirotor", 600.0),
    "car_sky": ("ground", 300.0),
}
# receivers that report their sky (`spooflens.simulation.sky`): per-satellite C/N0 for the interference detector
SKY_VEHICLES = frozenset({"multirotor_sky", "car_sky"})
# a ship's voyage record: GNSS fixes, its compass and its speed log (`realistic_compass`), no IMU; the
# heading reference is the only independent evidence there
VOYAGE_RECORDS = frozenset({"ship_nmea"})
# a car whose receiver logs raw observations (white code noise) of GPS and Galileo, or of GPS alone, and
# solves its own fixes; it meets the GPS-only spoofer, the others the fix-level attacks
RAW_CONSTELLATIONS = {
    "car_raw": "synthetic_gps_galileo",
    "car_raw_gps": "synthetic",
    "car_raw_gps_orbits": "synthetic_gps_galileo",
}
# car_raw's very logs (same seed, same log), analysed as a tool that models GPS orbits alone would: its
# Galileo rows keep their measurements without satellite states
GPS_ORBITS_ONLY = frozenset({"car_raw_gps_orbits"})
ATTACKS: dict[str, str] = {
    "capture": "capture",
    "ramp 1 m/s": "ramp:rate=1,vel=1",
    "ramp 2 m/s": "ramp:rate=2,vel=1",
    "ramp 5 m/s": "ramp:rate=5,vel=1",
    "step 50 m": "step:offset=50",
    "velocity pull 0.5 m/s": "velocity_pull:dv=0.5,axes=en",
    "GPS-only ramp 2 m/s": "ramp:rate=2,vel=1,systems=G",
    "jam 15 dB": "jam:cn0=15",
    "jam 8 dB": "jam:cn0=8",
    "jam then capture": "jam_spoof:jam=30",
}
JAM_ATTACKS = frozenset({"jam 15 dB", "jam 8 dB", "jam then capture"})
JAM_S = 60.0  # how long a `jam` lasts (a jam_spoof's capture goes on to the log's end)
RAW_ATTACKS = frozenset({"GPS-only ramp 2 m/s"})  # act on pseudoranges: only for RAW_CONSTELLATIONS vehicles
GOAL_CAPTURE_DETECTED = 0.99
GOAL_CAPTURE_DELAY_S = 2.0
GOAL_FALSE_PER_100H = 1.0


@dataclass(frozen=True)
class Run:
    vehicle: str
    attack: str | None  # a key of ATTACKS, None for a clean run
    seed: int


def _table(run: Run) -> tuple[Any, float | None]:
    """The simulated (and attacked) log of a run, and the attack's first spoofed fix time."""
    table, first, _ = _attacked(run)
    return table, first


def _attacked(run: Run) -> tuple[Any, float | None, Any]:
    """The simulated (and attacked) log of a run, the attack's first spoofed fix time and its truth."""
    from spooflens.attacks import apply_attack, parse_attack
    from spooflens.schema import empty_frame
    from spooflens.simulation.sensors import realistic_compass, realistic_receiver
    from spooflens.simulation.simulate import SCENARIOS, simulate

    scenario, seconds = VEHICLES[run.vehicle]
    rng = np.random.default_rng(run.seed)
    sc = replace(SCENARIOS[scenario], receiver=realistic_receiver(rng))
    if run.vehicle in VOYAGE_RECORDS:
        sc = replace(sc, compass=realistic_compass(rng))
    if run.vehicle in RAW_CONSTELLATIONS:
        sc = replace(sc, constellation=RAW_CONSTELLATIONS[run.vehicle])
    if run.vehicle in SKY_VEHICLES:
        sc = replace(sc, satellite_reports=True)
    table = simulate(sc, seed=run.seed, duration_s=seconds).table
    if run.vehicle in VOYAGE_RECORDS:
        table = replace(table, imu=empty_frame("imu"), streams=[s for s in table.streams if s.role != "imu"])
    if run.attack is None:
        return _orbits_seen(run, table), None, None
    start = float(rng.uniform(seconds / 3, 2 * seconds / 3))
    text = ATTACKS[run.attack]
    window = f"start={start:.1f}" + (f",end={start + JAM_S:.1f}" if text.startswith("jam:") else "")
    spoofed, truth = apply_attack(table, parse_attack(f"{text}{',' if ':' in text else ':'}{window}"))
    t = spoofed.fixes["t_s"].to_numpy()
    first = float(t[t >= start][0]) if (t >= start).any() else start
    return _orbits_seen(run, spoofed), first, truth


def _orbits_seen(run: Run, table: Any) -> Any:
    """The table as the run's analysis sees it: without Galileo satellite states for GPS_ORBITS_ONLY."""
    if run.vehicle not in GPS_ORBITS_ONLY:
        return table
    from spooflens.gnss.single_point import SV_COLUMNS, SV_VEL_COLUMNS

    obs = table.observations.copy()
    galileo = obs["sv_id"].astype(str).str.startswith("E").to_numpy()
    for col in (*SV_COLUMNS, *SV_VEL_COLUMNS, "sv_clock_bias_m", "sv_clock_drift_mps"):
        obs.loc[galileo, col] = np.nan
    return replace(table, observations=obs)


def _interference_alarms(analysis: Any) -> list[Any]:
    return [a for r in analysis.results if r.name == "interference" and r.ran for a in r.alarms]


# the kind named over an attack: the most serious kind of any event that overlaps it
KIND_ORDER = ("spoofing", "jamming", "degradation", "receiver_fault", "unknown")


def called_kind(analysis: Any, start: float, end: float, late_s: float = 5.0) -> str:
    """What the verdict called the stretch [start, end]: the first of KIND_ORDER among the events overlapping
    it (an alarm up to `late_s` after it still counts), or 'nothing'."""
    kinds = {str(e.kind) for e in analysis.verdict.events if e.start_s <= end + late_s and e.end_s >= start - 1.0}
    return next((k for k in KIND_ORDER if k in kinds), "nothing")


def jam_scores(analysis: Any, truth: Any, table: Any) -> dict[str, Any]:
    """How the interference detector saw the jamming phase (truth.phases[0]) and, for jam_spoof, how the
    spoofing detectors saw the capture after it."""
    jam = truth.phases[0]
    start, end = float(jam["start_s"]), float(jam["end_s"])
    alarms = [a for a in _interference_alarms(analysis) if a.end_s >= start - 1.0 and a.start_s <= end + 5.0]
    t = table.fixes["t_s"].to_numpy(float)
    period = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    # jam then capture: the jamming phase alone, before the takeover's own alarms
    late_s = 5.0 if truth.kind == "jam" else -1.0
    out: dict[str, Any] = {"jam_detected": bool(alarms), "called": called_kind(analysis, start, end, late_s)}
    if alarms:
        first, last = alarms[0], max(alarms, key=lambda a: a.end_s)
        covered = sum(max(0.0, min(a.end_s, end) - max(a.start_s, start)) for a in alarms)
        lo, hi = first.onset_interval_s or (first.start_s, first.start_s)
        out |= {
            "jam_delay_s": max(first.start_s - start, 0.0),
            "jam_end_error_s": last.end_s - end,
            "jam_coverage": covered / max(end - start, 1e-9),
            "jam_onset_covered": lo - period - 1e-6 <= start <= hi + period + 1e-6,
            "jam_onset_interval_width_s": hi - lo,
        }
    spoofing = [i for i in analysis.verdict.incidents if i.is_spoofing]
    if truth.kind == "jam":
        called = [i for i in spoofing if i.start_s <= end + 5.0 and i.end_s >= start - 1.0]
        out["jam_called_spoofing"] = bool(called)
        out["jam_spoofing_evidence"] = sorted({str(e) for i in called for e in i.corroborating})
        return out
    capture = truth.phases[1]
    takeover = float(capture["start_s"])
    out["called_capture"] = called_kind(analysis, takeover, float(capture["end_s"]))
    # the capture's own alarms: spoofing-class detectors alarming from the takeover on
    after = [
        a.start_s
        for r in analysis.results
        if r.is_detector and r.ran and not r.advisory and r.evidence is not None and r.name != "interference"
        for a in r.alarms
        if a.start_s >= takeover - 1.0 and a.start_s <= takeover + 30.0
    ]
    out["capture_detected"] = bool(after) and any(i.end_s >= takeover for i in spoofing)
    if out["capture_detected"]:
        out["capture_delay_s"] = max(min(after) - takeover, 0.0)
    return out


def one_run(run: Run) -> dict[str, Any]:
    from spooflens.pipeline.run import analyze_table

    table, first, truth = _attacked(run)
    t0 = time.perf_counter()
    analysis = analyze_table(table)
    wall = time.perf_counter() - t0
    duration = float(table.duration_s)
    spoofing = [i for i in analysis.verdict.incidents if i.is_spoofing]
    out: dict[str, Any] = {
        "vehicle": run.vehicle,
        "attack": run.attack,
        "seed": run.seed,
        "hours": duration / 3600.0,
        "wall_s": wall,
        "false_incidents": 0,
        "interference_alarms": len(_interference_alarms(analysis)),
    }
    if first is None:
        out["false_incidents"] = len(spoofing)
        return out
    if run.attack in JAM_ATTACKS:
        out |= jam_scores(analysis, truth, table)
        jam_start = float(truth.phases[0]["start_s"])
        out["false_incidents"] = sum(1 for i in spoofing if i.end_s < jam_start - 5.0)
        return out
    # the incident that catches the attack: the first spoofing incident that reaches past its start
    hit = next((i for i in spoofing if i.end_s >= first - 1.0), None)
    out["false_incidents"] = sum(1 for i in spoofing if i.end_s < first - 5.0)
    out["detected"] = hit is not None
    out["called"] = called_kind(analysis, first, duration)
    if hit is not None:
        out["delay_s"] = max(hit.start_s - first, 0.0)
        out["onset_error_s"] = hit.onset_s - first
        lo, hi = hit.onset_interval_s if hit.onset_interval_s else (hit.onset_s, hit.onset_s)
        period = float(np.median(np.diff(table.fixes["t_s"].to_numpy())))
        out["onset_covered"] = lo - period - 1e-6 <= first <= hi + period + 1e-6
        out["onset_interval_width_s"] = hi - lo
        out["to_end"] = hit.ongoing_at_end or hit.end_s >= duration - 2.0
        out["confidence"] = hit.confidence
        out["evidence"] = [str(e) for e in hit.evidence]
    return out


HUSKY = Path(__file__).resolve().parents[2].parent / "shared/real/ros1_husky_navsat/test1.bag"
HUSKY_CASES = (
    "clean",
    "ramp:rate=1,start=200",
    "ramp:rate=2,start=200",
    "ramp:rate=5,start=200",
    "capture:start=200",
    "ramp:rate=1,start=200,end=300",
    "ramp:rate=2,start=200,end=300",
    "ramp:rate=5,start=200,end=300",
    "capture:start=200,end=300",
)


def husky_case(path: str, attack: str) -> dict[str, Any]:
    """The real husky bag (clean, consumer IMU, wheel odometry, SBAS fixes) with an injected attack."""
    from readers import read_log
    from spooflens.attacks import apply_attack, parse_attack
    from spooflens.pipeline.run import analyze_table

    table = read_log(path)
    if attack != "clean":
        table, _ = apply_attack(table, parse_attack(attack))
    a = analyze_table(table)
    spoofing = [i for i in a.verdict.incidents if i.is_spoofing]
    out: dict[str, Any] = {"attack": attack, "verdict": a.verdict.headline, "incidents": len(spoofing)}
    if spoofing:
        i = spoofing[0]
        out |= {
            "alarm_s": i.start_s,
            "onset_s": i.onset_s,
            "end_s": i.end_s,
            "end_interval_s": i.end_interval_s,
            "to_end": i.ongoing_at_end,
            "evidence": [str(e) for e in i.evidence],
        }
    return out


def husky(path: Path = HUSKY, workers: int = 2) -> list[dict[str, Any]]:
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(husky_case, [str(path)] * len(HUSKY_CASES), HUSKY_CASES))


def plan(
    runs: int, clean_hours: float, vehicles: tuple[str, ...], seed: int, attacks: tuple[str, ...] = ()
) -> list[Run]:
    out = []
    k = seed
    for v in vehicles:
        for a in attacks or tuple(ATTACKS):
            if a in JAM_ATTACKS:  # jamming: every vehicle but car_raw's twins analysed otherwise
                if v in RAW_CONSTELLATIONS and v != "car_raw":
                    continue
            elif (a in RAW_ATTACKS) != (v in RAW_CONSTELLATIONS):
                continue
            for _ in range(runs):
                out.append(Run(v, a, k))
                k += 1
    per_vehicle = clean_hours / len(vehicles)
    for v in vehicles:
        n = max(1, round(per_vehicle * 3600.0 / VEHICLES[v][1]))
        for _ in range(n):
            out.append(Run(v, None, k))
            k += 1
    return out


def run_bench(
    runs: int = 4,
    clean_hours: float = 10.0,
    workers: int = 2,
    seed: int = 1000,
    vehicles: tuple[str, ...] = (),
    attacks: tuple[str, ...] = (),
) -> dict[str, Any]:
    todo = plan(runs, clean_hours, vehicles or tuple(VEHICLES), seed, attacks)
    results: list[dict[str, Any]] = []
    with progress(show_progress()) as report, ProcessPoolExecutor(max_workers=workers) as pool:
        futures = [pool.submit(one_run, r) for r in todo]
        for n, f in enumerate(as_completed(futures), 1):
            results.append(f.result())
            report("simulated logs analysed", n, len(todo))
    return summarise(results)


def summarise(results: list[dict[str, Any]]) -> dict[str, Any]:
    attacked = [r for r in results if r["attack"] is not None]
    clean = [r for r in results if r["attack"] is None]
    per_kind: dict[str, dict[str, Any]] = {}
    jamming: dict[str, dict[str, Any]] = {}
    for kind in ATTACKS:
        rs = [r for r in attacked if r["attack"] == kind]
        if not rs:
            continue
        if kind in JAM_ATTACKS:
            jamming[kind] = _jam_summary(rs)
            continue
        hit = [r for r in rs if r.get("detected")]
        delays = [r["delay_s"] for r in hit]
        per_kind[kind] = {
            "runs": len(rs),
            "detected": len(hit) / len(rs),
            "within_2_s": sum(d <= GOAL_CAPTURE_DELAY_S for d in delays) / len(rs),
            "delay_median_s": float(np.median(delays)) if delays else None,
            "delay_p90_s": float(np.percentile(delays, 90)) if delays else None,
            "onset_interval_coverage": float(np.mean([r["onset_covered"] for r in hit])) if hit else None,
            "onset_interval_width_median_s": (
                float(np.median([r["onset_interval_width_s"] for r in hit])) if hit else None
            ),
            "to_end": float(np.mean([r["to_end"] for r in hit])) if hit else None,
        }
    hours = float(sum(r["hours"] for r in clean))
    false = int(sum(r["false_incidents"] for r in clean))
    interference = int(sum(r.get("interference_alarms", 0) for r in clean))
    sky_hours = float(sum(r["hours"] for r in clean if r["vehicle"] in SKY_VEHICLES))
    sky_events = int(sum(r.get("interference_alarms", 0) for r in clean if r["vehicle"] in SKY_VEHICLES))
    return {
        "per_attack": per_kind,
        "jamming": jamming,
        "kinds_called": kinds_called(attacked),
        "clean_hours": hours,
        "false_incidents": false,
        "false_per_100h": 100.0 * false / hours if hours else None,
        "false_interference": interference,
        "false_interference_per_100h": 100.0 * interference / hours if hours else None,
        "clean_sky_report_hours": sky_hours,
        "false_interference_with_sky_reports": sky_events,
        "false_before_attacks": int(sum(r["false_incidents"] for r in attacked)),
        "runs": results,
        "simulated": True,
    }


def kinds_called(attacked: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Per attack (and per phase of jam then capture), the share of runs whose verdict named each kind over
    it: the confusion table of the event kinds."""
    out: dict[str, dict[str, float]] = {}
    for kind in ATTACKS:
        two_phases = any("called_capture" in r for r in attacked if r["attack"] == kind)
        first = f"{kind}: the jamming" if two_phases else kind
        for key, row in (("called", first), ("called_capture", f"{kind}: the capture")):
            rs = [r[key] for r in attacked if r["attack"] == kind and key in r]
            if rs:
                out[row] = {k: rs.count(k) / len(rs) for k in (*KIND_ORDER, "nothing")} | {"runs": float(len(rs))}
    return out


def _print_kinds(kinds: dict[str, dict[str, float]]) -> None:
    t = Table(
        "attack",
        "runs",
        *KIND_ORDER,
        "nothing",
        title="The kind of event the verdict named over each attack (the confusion table; simulation only)",
    )
    for row, shares in kinds.items():
        t.add_row(row, f"{shares['runs']:.0f}", *(f"{100 * shares[k]:.0f}%" for k in (*KIND_ORDER, "nothing")))
    console().print(t)


def _jam_summary(rs: list[dict[str, Any]]) -> dict[str, Any]:
    def mean(key: str, among: list[dict[str, Any]]) -> float | None:
        values = [float(r[key]) for r in among if key in r]
        return float(np.mean(values)) if values else None

    def pct(key: str, among: list[dict[str, Any]], q: float) -> float | None:
        values = [float(r[key]) for r in among if key in r]
        return float(np.percentile(values, q)) if values else None

    hit = [r for r in rs if r.get("jam_detected")]
    out: dict[str, Any] = {
        "runs": len(rs),
        "detected": len(hit) / len(rs),
        "onset_delay_median_s": pct("jam_delay_s", hit, 50),
        "onset_delay_p90_s": pct("jam_delay_s", hit, 90),
        "end_error_median_s": pct("jam_end_error_s", hit, 50),
        "interval_coverage_mean": mean("jam_coverage", hit),
        "onset_interval_covers_start": mean("jam_onset_covered", hit),
        "onset_interval_width_median_s": pct("jam_onset_interval_width_s", hit, 50),
        "missed": [(r["vehicle"], r["seed"]) for r in rs if not r.get("jam_detected")],
    }
    if any("jam_called_spoofing" in r for r in rs):
        out["called_spoofing"] = mean("jam_called_spoofing", rs)
        classes = [" + ".join(r["jam_spoofing_evidence"]) for r in rs if r.get("jam_called_spoofing")]
        out["called_spoofing_by"] = {c: classes.count(c) for c in sorted(set(classes))}
    if any("capture_detected" in r for r in rs):
        out["capture_detected"] = mean("capture_detected", rs)
        out["capture_delay_median_s"] = pct("capture_delay_s", rs, 50)
        out["both_phases"] = float(np.mean([bool(r.get("jam_detected") and r.get("capture_detected")) for r in rs]))
    return out


def _print_jamming(jamming: dict[str, dict[str, Any]], vehicles: tuple[str, ...]) -> None:
    def pct(x: float | None) -> str:
        return "-" if x is None else f"{100 * x:.0f}%"

    def sec(x: float | None) -> str:
        return "-" if x is None else f"{x:.1f}"

    t = Table(
        "attack",
        "runs",
        "jamming detected",
        "median onset delay (s)",
        "90% onset delay (s)",
        "median end error (s)",
        "jammed interval covered",
        "onset interval holds the start",
        "called spoofing",
        "capture detected",
        "median capture delay (s)",
        title=f"Jamming ({', '.join(vehicles or VEHICLES)}): the interference detector; jam_spoof's capture by "
        "the spoofing detectors. Simulation only",
    )
    for kind, k in jamming.items():
        t.add_row(
            kind,
            str(k["runs"]),
            pct(k["detected"]),
            sec(k["onset_delay_median_s"]),
            sec(k["onset_delay_p90_s"]),
            sec(k["end_error_median_s"]),
            pct(k["interval_coverage_mean"]),
            pct(k["onset_interval_covers_start"]),
            pct(k.get("called_spoofing")),
            pct(k.get("capture_detected")),
            sec(k.get("capture_delay_median_s")),
        )
    console().print(t)
    for kind, k in jamming.items():
        for vehicle, seed in k["missed"]:
            console().print(f"  {kind} missed: {vehicle}, seed {seed}")
        if k.get("called_spoofing_by"):
            by = ", ".join(f"{n} by {classes}" for classes, n in k["called_spoofing_by"].items())
            console().print(f"  {kind} drew a spoofing verdict: {by} (the evidence classes that agreed)")


@click.command("realworld")
@click.option("--runs", default=4, show_default=True, help="Attacked runs per vehicle and attack kind.")
@click.option("--clean-hours", default=10.0, show_default=True, help="Hours of clean logs (false incidents).")
@click.option("--workers", default=2, show_default=True, help="Processes.")
@click.option("--seed", default=1000, show_default=True)
@click.option(
    "--vehicle",
    "vehicles",
    multiple=True,
    type=click.Choice(list(VEHICLES)),
    help="Only these vehicles (repeatable; default all). ship_nmea: a voyage record, compass and log, no IMU; "
    "car_raw, car_raw_gps: raw GPS + Galileo, or GPS, observations before a GPS-only spoofer; "
    "car_raw_gps_orbits: car_raw's logs analysed with GPS orbits alone; multirotor_sky, car_sky: receivers "
    "that report their sky (per-satellite C/N0), for the jamming cases.",
)
@click.option(
    "--attack",
    "attacks",
    multiple=True,
    type=click.Choice(list(ATTACKS)),
    help="Only these attack kinds (repeatable; default all), e.g. many captures for the 99 % goal.",
)
@click.option("--json", "json_path", type=click.Path(path_type=Path), default=None, help="Write all figures here.")
@click.option("--quick", is_flag=True, help="One run per case and 1 h clean (a smoke test, not the figures).")
@click.option(
    "--husky",
    "husky_path",
    type=click.Path(path_type=Path),
    default=HUSKY,
    show_default=True,
    help="The real clean husky bag, attacked by injection (skipped if missing).",
)
def command(
    runs: int,
    clean_hours: float,
    workers: int,
    seed: int,
    vehicles: tuple[str, ...],
    attacks: tuple[str, ...],
    json_path: Path | None,
    quick: bool,
    husky_path: Path,
) -> int:
    """Real-world-like Monte Carlo: detection and delay per attack kind, false incidents per 100 h; the
    real husky bag with injected ramps and captures."""
    if quick:
        runs, clean_hours = 1, 1.0
    husky_rows = husky(husky_path, workers) if husky_path.exists() else []
    if husky_rows:
        t = Table(
            "attack on the real husky bag",
            "verdict",
            "first alarm (s)",
            "onset (s)",
            "end (s)",
            "end interval (s)",
            "evidence",
            title="Real log (husky: consumer IMU, wheel odometry, SBAS fixes), attacks injected with spooflens inject",
        )
        for r in husky_rows:
            iv = r.get("end_interval_s")
            t.add_row(
                r["attack"],
                r["verdict"][:60],
                f"{r['alarm_s']:.1f}" if "alarm_s" in r else "-",
                f"{r['onset_s']:.1f}" if "onset_s" in r else "-",
                ("end of log" if r.get("to_end") else f"{r['end_s']:.1f}") if "end_s" in r else "-",
                f"{iv[0]:.1f}-{iv[1]:.1f}" if iv else "-",
                ", ".join(r.get("evidence", [])),
            )
        console().print(t)
    out = run_bench(runs, clean_hours, workers, seed, vehicles, attacks)
    out["husky"] = husky_rows
    t = Table(
        "attack",
        "runs",
        "detected",
        "within 2 s",
        "median delay (s)",
        "90% delay (s)",
        "onset interval covers truth",
        "median interval width (s)",
        "incident runs to log end",
        title=f"Simulated vehicles ({', '.join(vehicles or VEHICLES)}) with realistic receivers: the whole analysis",
    )
    for kind, k in out["per_attack"].items():

        def pct(x: float | None) -> str:
            return "-" if x is None else f"{100 * x:.0f}%"

        def sec(x: float | None) -> str:
            return "-" if x is None else f"{x:.1f}"

        t.add_row(
            kind,
            str(k["runs"]),
            pct(k["detected"]),
            pct(k["within_2_s"]),
            sec(k["delay_median_s"]),
            sec(k["delay_p90_s"]),
            pct(k["onset_interval_coverage"]),
            sec(k["onset_interval_width_median_s"]),
            pct(k["to_end"]),
        )
    if out["per_attack"]:
        console().print(t)
    if out["jamming"]:
        _print_jamming(out["jamming"], vehicles)
    if out["kinds_called"]:
        _print_kinds(out["kinds_called"])
    cap = out["per_attack"].get("capture")
    if cap:
        console().print(
            f"captures detected within {GOAL_CAPTURE_DELAY_S:g} s of the first spoofed fix: "
            f"{100 * cap['within_2_s']:.0f}% of {cap['runs']} (goal >= {100 * GOAL_CAPTURE_DETECTED:.0f}%)"
        )
    late = [
        r
        for r in out["runs"]
        if r["attack"] == "capture" and not (r.get("detected") and r["delay_s"] <= GOAL_CAPTURE_DELAY_S)
    ]
    for r in sorted(late, key=lambda r: (r["vehicle"], r["seed"])):
        how = f"caught {r['delay_s']:.1f} s after the first spoofed fix" if r.get("detected") else "missed"
        console().print(f"  capture {how}: {r['vehicle']}, seed {r['seed']}")
    fp = out["false_per_100h"]
    console().print(
        f"clean logs: {out['false_incidents']} false spoofing incident(s) in {out['clean_hours']:.1f} h = "
        f"{'-' if fp is None else f'{fp:.1f}'} per 100 h (goal <= {GOAL_FALSE_PER_100H:g}); "
        f"before the attack in attacked logs: {out['false_before_attacks']}. Simulation only."
    )
    fi = out["false_interference_per_100h"]
    console().print(
        f"clean logs: {out['false_interference']} interference event(s) in {out['clean_hours']:.1f} h = "
        f"{'-' if fi is None else f'{fi:.1f}'} per 100 h ({out['false_interference_with_sky_reports']} in the "
        f"{out['clean_sky_report_hours']:.1f} h whose receivers report their sky). Simulation only."
    )
    if json_path:
        json_path.write_text(json.dumps(out, indent=1, default=str))
    return 0
