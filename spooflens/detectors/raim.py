"""RAIM as a detector: satellites whose pseudoranges disagree with the others and the broadcast orbits
(fault detection and exclusion of `spooflens.gnss.fault_exclusion`). Declared in `ANALYSIS`
(docs/detectors.md)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from spooflens.detectors.base import Alarm, DetectorResult, Finding, Series, alarm_intervals, nearest
from spooflens.geodesy import ecef_to_enu_vectors, geodetic_to_ecef
from spooflens.gnss.fault_exclusion import FAULT, RaimOptions, RaimResult, solve_with_fde
from spooflens.gnss.single_point import SinglePointOptions, SinglePointSolution, ranged_by_receiver
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.preconditions import ORBIT_TIMING, time_tags_off
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo, probability

NAME = "raim"


@dataclass(frozen=True)
class RaimDetectorOptions:
    p_false_alarm: float = 1e-3
    min_epochs: int = 5
    min_inconsistency_m: float = 30.0
    finding_fraction: float = 0.5
    # a receiver's own fix this much beyond its usual distance from the solution of its own pseudoranges,
    # for this many epochs in a row, is a finding (phones: a median of 6-13 m, at most 53 m on the real logs)
    fix_departure_m: float = 100.0
    fix_departure_epochs: int = 5


def _describe(metres: float) -> str:
    return f"{metres / 1000:.3g} km" if abs(metres) >= 1000 else f"{metres:.3g} m"


def raim_of(table_obs: pd.DataFrame, t_gps: np.ndarray | None, iono, opts: RaimDetectorOptions) -> RaimResult:
    return solve_with_fde(
        table_obs, t_gps, SinglePointOptions(iono=iono), RaimOptions(p_false_alarm=opts.p_false_alarm)
    )


def check_receiver(
    rid: str, obs: pd.DataFrame, res: RaimResult, opts: RaimDetectorOptions
) -> tuple[list[Alarm], list[Finding], list[Series]]:
    sol = res.solution
    t = sol.t_s
    epoch = sol.row_epoch
    sv = obs["sv_id"].astype(str).to_numpy()
    alarms: list[Alarm] = []
    findings: list[Finding] = []
    ratio = res.statistic / res.threshold
    series = [
        Series(f"{rid}/residual_test", t, ratio, "ratio", 1.0),
        Series(
            f"{rid}/excluded_satellites",
            t,
            np.bincount(epoch[res.flag == FAULT], minlength=len(t)).astype(float),
            "count",
        ),
    ]
    solvable = np.isfinite(sol.ecef_m).all(axis=1) | (res.dof >= 1)
    for name in sorted(set(sv[res.flag == FAULT])):
        rows = np.flatnonzero(sv == name)
        faulty_epochs = np.zeros(len(t), dtype=bool)
        faulty_epochs[epoch[rows[res.flag[rows] == FAULT]]] = True
        seen = np.zeros(len(t), dtype=bool)
        seen[epoch[rows]] = True
        seen &= solvable
        inc = res.inconsistency_m[rows[res.flag[rows] == FAULT]]
        size = float(np.nanmedian(np.abs(inc))) if np.isfinite(inc).any() else float("nan")
        fraction = faulty_epochs[seen].mean() if seen.any() else 0.0
        if fraction >= opts.finding_fraction and seen.sum() >= opts.min_epochs:
            findings.append(
                Finding(
                    f"{rid}: {name} inconsistent by {_describe(size)}, excluded at {100 * fraction:.0f}% of its "
                    f"{int(seen.sum())} epochs",
                    float(t[faulty_epochs].min()),
                    float(t[faulty_epochs].max()),
                    (name,),
                    rid,
                    size if np.isfinite(size) else None,
                )
            )
        if not size >= opts.min_inconsistency_m:
            continue
        # runs of exclusion over the epochs the satellite was seen in, one missing epoch allowed; each alarm
        # carries its own run's size (median and largest inconsistency), which the verdict weighs
        excluded_rows = rows[res.flag[rows] == FAULT]
        idx = np.flatnonzero(seen)
        flags = faulty_epochs[idx]
        start = None
        misses = 0
        for k, f in enumerate(np.r_[flags, False, False]):
            if f:
                start = k if start is None else start
                misses = 0
                last = k
            elif start is not None:
                misses += 1
                if misses > 1 or k >= len(flags):
                    a, b = idx[start], idx[last]
                    in_run = excluded_rows[(epoch[excluded_rows] >= a) & (epoch[excluded_rows] <= b)]
                    off = np.abs(res.inconsistency_m[in_run])
                    off = off[np.isfinite(off)]
                    run_size = float(np.median(off)) if len(off) else float("nan")
                    if last - start + 1 >= opts.min_epochs and len(off):
                        t0, t1 = float(t[a]), float(t[b])
                        alarm = Alarm(t0, t1, float(off.max()), t0, t0, None, rid, (name,), range_error_m=run_size)
                        alarms.append(alarm)
                    start, misses = None, 0
    return alarms, findings, series


def fix_against_own_solution(
    rid: str, sol: SinglePointSolution, fixes: pd.DataFrame, opts: RaimDetectorOptions
) -> tuple[list[Series], list[Finding]]:
    """How far the receiver's reported fixes lie from the position its own pseudoranges give (RAIM's
    solution, faulty satellites left out), per solved epoch with a fix within half a second. A fix that
    leaves its own measurements did not come from them: its position output was moved (a spoofer on the
    receiver's output or log, a mock location), or it followed satellites RAIM excluded. A finding, not an
    alarm: two short real phone logs are all there is to learn its normal spread from."""
    t_fix = fixes["t_s"].to_numpy(dtype=float)
    if len(t_fix) < opts.fix_departure_epochs or not len(sol.t_s):
        return [], []
    k, gap = nearest(sol.t_s, t_fix)
    lat, lon, h = (fixes[c].to_numpy(dtype=float)[k] for c in ("lat_deg", "lon_deg", "height_m"))
    enu = ecef_to_enu_vectors(lat, lon, sol.ecef_m - geodetic_to_ecef(lat, lon, h))
    distance = np.hypot(enu[:, 0], enu[:, 1])
    distance[gap > 0.5] = np.nan
    if np.isfinite(distance).sum() < opts.fix_departure_epochs:
        return [], []
    usual = float(np.nanpercentile(distance, 25))  # an output moved over most of the log cannot move it
    series = [Series(f"{rid}/fix_from_own_solution", sol.t_s, distance, "m", usual + opts.fix_departure_m)]
    off = np.nan_to_num(distance, nan=0.0) > usual + opts.fix_departure_m
    findings = []
    for a in alarm_intervals(sol.t_s, distance, off, merge_gap_s=10.0):
        inside = (sol.t_s >= a.start_s) & (sol.t_s <= a.end_s)
        if int(off[inside].sum()) < opts.fix_departure_epochs:
            continue
        findings.append(
            Finding(
                f"{rid}: its reported fixes lay up to {_describe(a.peak_statistic)} from the position its own "
                f"pseudoranges give (a quarter of its epochs within {usual:.0f} m), {a.start_s:.1f}-{a.end_s:.1f} s: "
                "those fixes did not come from these measurements (its position output was moved, or it followed "
                "satellites RAIM excluded)",
                a.start_s,
                a.end_s,
                (),
                rid,
            )
        )
    return series, findings


def run_raim(ctx: AnalysisContext, opts: RaimDetectorOptions | None = None) -> DetectorResult:
    opts = opts or RaimDetectorOptions()
    table = ctx.table
    result = DetectorResult(NAME, True, evidence=Evidence.RAW_MEASUREMENT)
    notes = []
    judged = 0
    tags_off = time_tags_off(ctx)
    for rid, rows, t_gps in ranged_by_receiver(table):
        if rid in tags_off:
            notes.append(f"{rid}: not judged, {tags_off[rid].describe()}")
            continue
        res = raim_of(rows, t_gps, table.ionosphere, opts)
        if not (res.dof >= 1).any():
            # as many satellites as unknowns: the residuals are zero whatever the ranges, nothing is tested
            notes.append(f"{rid}: not judged, no epoch with a satellite more than the position and clock it solves")
            continue
        judged += 1
        alarms, findings, series = check_receiver(rid, rows, res, opts)
        own_series, own_findings = fix_against_own_solution(rid, res.solution, table.fixes_of(rid), opts)
        series += own_series
        findings += own_findings
        result.alarms += alarms
        result.findings += findings
        result.series += series
        n_fault = int((res.flag == FAULT).sum())
        notes.append(
            f"{rid}: residual scale {res.scale:.1f} x a-priori, {n_fault} satellite-epochs excluded "
            f"(chi-square at P_FA {opts.p_false_alarm:g} per epoch)"
        )
    if not notes:
        return DetectorResult.skipped(NAME, "no pseudoranges with satellite positions", Evidence.RAW_MEASUREMENT)
    if not judged:
        return DetectorResult.skipped(NAME, "; ".join(notes), Evidence.RAW_MEASUREMENT)
    result.reason = "; ".join(notes)
    result.alarms.sort(key=lambda a: a.start_s)
    return result


_O = RaimDetectorOptions()
_P = probability(_O.p_false_alarm)
ANALYSIS = AnalysisSpec(
    NAME,
    "RAIM fault detection and exclusion on raw pseudoranges: satellites that disagree with the others",
    ("satellite_states",),
    lambda ctx: [run_raim(ctx)],
    (
        DetectorInfo(
            NAME,
            Evidence.RAW_MEASUREMENT,
            "satellites whose pseudoranges disagree with the others, excluded epoch after epoch",
            method="Fault detection and exclusion on every receiver's pseudoranges: the weighted post-fit residual "
            f"chi-square at {_P} per epoch, the residual scale learned from the log (robust to one "
            "satellite wrong throughout), leave-one-out exclusion (leave-two-out where one does not clear the test) "
            "while a degree of freedom remains. A counterfeit satellite, or a spoofer that moved only a few, leaves "
            f"the honest ones to outvote it. An alarm needs the same satellite excluded in {_O.min_epochs} "
            "consecutive solvable epochs (one missing allowed) with a median inconsistency of "
            f"{_O.min_inconsistency_m:g} m: a reflection spike is short and small, a counterfeit signal neither. Each "
            "alarm carries its run's size (median and largest), which the verdict weighs against a reflection's "
            "length (a car's phone passes reflections: its satellites are excluded in runs, rarely at most of their "
            "epochs). A "
            f'satellite excluded at {100 * _O.finding_fraction:.0f}% or more of its epochs is a named finding ("G07 '
            'inconsistent by 100 km, excluded at 100% of its 120 epochs"); the fixes solved from raw observations '
            "use the same exclusion, and each observation row gets a `fault_flag`. Beside it, the receiver's own "
            "reported fixes against the solution of its own pseudoranges: fixes more than "
            f"{_O.fix_departure_m:g} m beyond the distance a quarter of its epochs keep, for "
            f"{_O.fix_departure_epochs} epochs, are a finding, not an alarm (those fixes did not come from these "
            "measurements: a moved position output, a mock location, or satellites RAIM excluded).",
            p_false_alarm=f"{_P} per epoch (the residual test); persistence for an alarm",
            threshold=f"the same satellite excluded in {_O.min_epochs} epochs, median inconsistency >= "
            f"{_O.min_inconsistency_m:g} m",
            checked="On the real phone logs the fix-to-own-solution distance has a median of 6-13 m and a maximum "
            "of 53 m; the same log with its fixes moved 300 m north from 100 s gives the finding from 100.4 s "
            "(`tests/detectors/test_raim.py`).",
        ),
    ),
    preconditions=(ORBIT_TIMING,),
)
