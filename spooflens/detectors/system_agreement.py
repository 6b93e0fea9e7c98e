"""Do the satellite systems agree? A receiver's position from its GPS satellites alone against the one from
its Galileo (or BeiDou) satellites alone. Declared in `ANALYSIS` (docs/detectors.md)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.detectors.base import Alarm, DetectorResult, Finding, Series, alarm_intervals, rise_start
from spooflens.estimation.quantiles import chi2_isf, halfnorm_ppf
from spooflens.geodesy import ecef_to_enu_vectors, ecef_to_geodetic
from spooflens.gnss.fault_exclusion import RaimOptions, solve_with_fde
from spooflens.gnss.signals import SYSTEM_NAMES
from spooflens.gnss.single_point import SinglePointOptions, SinglePointSolution, ranged_by_receiver
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.preconditions import ORBIT_TIMING, time_tags_off
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo, probability

NAME = "system_agreement"
FloatArray = NDArray[np.float64]
_Q25_ABS_NORMAL = halfnorm_ppf(0.25)
QUIET_LEVEL = 4.6  # chi-square(2)'s 90th percentile


@dataclass(frozen=True)
class SystemAgreementOptions:
    p_false_alarm: float = 1e-5  # per epoch
    min_satellites: int = 5  # per system and epoch: a position and one residual to check it with
    min_scale_m: float = 1.0
    max_scale_m: float = 10.0
    min_separation_m: float = 50.0
    min_epochs: int = 5


def _describe(metres: float) -> str:
    return f"{metres / 1000:.3g} km" if metres >= 1000 else f"{metres:.0f} m"


def _solutions(
    obs: pd.DataFrame, t_gps: FloatArray | None, options: SinglePointOptions, opts: SystemAgreementOptions
) -> dict[str, SinglePointSolution]:
    """Each system's own solution (RAIM FDE inside it), systems with enough satellites at some epoch."""
    system = obs["sv_id"].astype(str).str[0].to_numpy()
    out = {}
    for s in sorted(set(system)):
        rows = obs[system == s].reset_index(drop=True)
        if rows.groupby("t_s").size().max() < opts.min_satellites:
            continue
        t = None if t_gps is None else t_gps[system == s]
        sol = solve_with_fde(rows, t, options, RaimOptions()).solution
        sol_ok = sol.ok & (sol.sats_used >= opts.min_satellites)
        out[s] = replace(sol, ecef_m=np.where(sol_ok[:, None], sol.ecef_m, np.nan))
    return out


def separation(a: SinglePointSolution, b: SinglePointSolution) -> tuple[FloatArray, FloatArray]:
    """Epochs both solved, and b's position minus a's there (east, north), in a's local frame."""
    t, ia, ib = np.intersect1d(a.t_s, b.t_s, return_indices=True)
    ok = a.ok[ia] & b.ok[ib]
    t, ia, ib = t[ok], ia[ok], ib[ok]
    lat, lon, _ = ecef_to_geodetic(a.ecef_m[ia])
    d = ecef_to_enu_vectors(lat, lon, b.ecef_m[ib] - a.ecef_m[ia])
    return t, d[:, :2]


def _persistent(flags: NDArray[np.bool_], min_epochs: int) -> NDArray[np.bool_]:
    """Flags that belong to a run of at least `min_epochs`, one missing epoch bridged."""
    bridged = flags.copy()
    bridged[1:-1] |= flags[:-2] & flags[2:]
    edges = np.diff(np.r_[0, bridged.astype(np.int8), 0])
    keep = np.zeros_like(flags)
    for s, e in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
        if flags[s:e].sum() >= min_epochs:
            keep[s:e] = True
    return keep


def check_pair(
    rid: str, names: tuple[str, str], t: FloatArray, d: FloatArray, opts: SystemAgreementOptions
) -> tuple[list[Alarm], list[Finding], list[Series]]:
    a, b = (SYSTEM_NAMES.get(n, n) for n in names)
    distance = np.hypot(d[:, 0], d[:, 1])
    q = np.nanpercentile(np.abs(d), 25, axis=0) / _Q25_ABS_NORMAL
    scale = np.clip(np.nan_to_num(q, nan=opts.min_scale_m), opts.min_scale_m, opts.max_scale_m)
    stat = np.sum((d / scale) ** 2, axis=1)
    threshold = float(chi2_isf(opts.p_false_alarm, 2))
    flags = _persistent((stat > threshold) & (distance >= opts.min_separation_m), opts.min_epochs)
    tag = f"{rid}/{names[0]}{names[1]}"
    series = [
        Series(f"{tag}_separation", t, distance, "m", opts.min_separation_m),
        Series(f"{tag}_statistic", t, stat, "chi2(2)", threshold),
    ]
    alarms, findings = [], []
    usual = float(np.percentile(distance, 25))
    for al in alarm_intervals(t, distance, flags, merge_gap_s=10.0):
        # from where the separation left its floor (chi-square(2)'s 90th percentile) to the first fix beyond it
        rise, last_quiet = rise_start(t, stat, al.start_s, QUIET_LEVEL)
        interval = (float(t[rise]), float(t[min(last_quiet + 1, len(t) - 1)]))
        alarms.append(Alarm(al.start_s, al.end_s, al.peak_statistic, al.peak_s, interval[1], interval, rid))
        findings.append(
            Finding(
                f"{rid}: its {a} and {b} satellites gave positions up to {_describe(al.peak_statistic)} apart, "
                f"{al.start_s:.1f}-{al.end_s:.1f} s (a quarter of its epochs within {usual:.0f} m): one "
                f"system's signals were not real (open SDR spoofers transmit GPS L1 C/A alone)",
                al.start_s,
                al.end_s,
                (),
                rid,
            )
        )
    return alarms, findings, series


def run_system_agreement(ctx: AnalysisContext, opts: SystemAgreementOptions | None = None) -> DetectorResult:
    opts = opts or SystemAgreementOptions()
    table = ctx.table
    result = DetectorResult(NAME, True, evidence=Evidence.RAW_MEASUREMENT)
    notes = []
    tags_off = time_tags_off(ctx)
    for rid, rows, t_gps in ranged_by_receiver(table):
        if rid in tags_off:
            notes.append(f"{rid}: not judged, {tags_off[rid].describe()}")
            continue
        sols = _solutions(rows, t_gps, SinglePointOptions(iono=table.ionosphere), opts)
        if len(sols) < 2:
            continue
        # every other system against the one with the most solved epochs (GPS on a tie)
        ref = max(sols, key=lambda s: (int(sols[s].ok.sum()), s == "G"))
        for other in sorted(s for s in sols if s != ref):
            t, d = separation(sols[ref], sols[other])
            if len(t) < opts.min_epochs:
                continue
            alarms, findings, series = check_pair(rid, (ref, other), t, d, opts)
            result.alarms += alarms
            result.findings += findings
            result.series += series
            notes.append(
                f"{rid}: {SYSTEM_NAMES.get(ref, ref)} vs {SYSTEM_NAMES.get(other, other)} at {len(t)} epochs, "
                f"median separation {float(np.median(np.hypot(d[:, 0], d[:, 1]))):.1f} m"
            )
    if not notes:
        return DetectorResult.skipped(
            NAME,
            f"needs two satellite systems with orbits and {opts.min_satellites} satellites each at one epoch",
            Evidence.RAW_MEASUREMENT,
        )
    result.reason = "; ".join(notes)
    result.alarms.sort(key=lambda a: a.start_s)
    return result


_O = SystemAgreementOptions()
_P = probability(_O.p_false_alarm)
ANALYSIS = AnalysisSpec(
    NAME,
    "two satellite systems' positions against each other: a spoofer of one system (GPS) leaves the other real",
    ("satellite_states",),
    lambda ctx: [run_system_agreement(ctx)],
    (
        DetectorInfo(
            NAME,
            Evidence.RAW_MEASUREMENT,
            "the position from one system's satellites (GPS) far from the other's (Galileo)",
            method="The open SDR spoofers (gps-sdr-sim and its descendants) transmit GPS L1 C/A alone: before a "
            "multi-constellation receiver they move every GPS pseudorange consistently, which GPS-only RAIM cannot "
            "see, while the Galileo satellites keep ranging from where the receiver is. Per epoch each system's own "
            f"single-point solution (RAIM's exclusion inside it, its own clock, {_O.min_satellites} satellites or "
            "more); their horizontal separation per axis against the scale of its quietest quarter in the log "
            f"(which an attack on up to three quarters of it cannot move), floored at {_O.min_scale_m:g} m and "
            f"capped at {_O.max_scale_m:g} m (what two honest systems show on a single-frequency receiver, so a log "
            f"spoofed from its first fix still shows it). An alarm needs chi-square(2) at {_P} "
            f"exceeded, {_O.min_separation_m:g} m or more, for {_O.min_epochs} epochs in a row (one missing "
            "allowed); the onset interval runs from where the separation left its floor to the first epoch beyond "
            "it. A finding names the two systems. Its reference is the other system's satellites and the orbits, "
            "like RAIM's: it explains what RAIM sees, it adds no class of its own.",
            p_false_alarm=f"{_P} per epoch; persistence for an alarm",
            threshold=f"chi-square(2) at {_P}, >= {_O.min_separation_m:g} m, {_O.min_epochs} epochs",
            checked="Simulation only (no real log here has orbits for two systems): on a simulated car with a GPS + "
            "Galileo receiver the two agree within a median of 1.5 m; a 3 m/s ramp or a 141 m step on the GPS "
            "pseudoranges from 150 s alarms from 150-163 s to the end; one Galileo satellite 3 km late does not "
            "(`tests/detectors/test_system_agreement.py`).",
        ),
    ),
    preconditions=(ORBIT_TIMING,),
)
