"""Seed 004's fleet evidence on one vehicle: its offset from its own reference is one of a set, across
vehicles in the same area and time, more alike than chance (a common attacker). Declared in `ANALYSIS`
(docs/detectors.md); `spooflens fleet` runs it.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from spooflens.detectors.base import Alarm, DetectorResult, Finding, Series, alarm_intervals
from spooflens.epoch_table import EpochTable
from spooflens.fleet.offsets import FleetHomology, FleetOptions, VehicleOffsets
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo, probability

NAME = "fleet_homology"
NEEDS_FLEET = "logs of other vehicles over the same time and area (run `spooflens fleet LOG1 LOG2 ...`)"


def _utc(t_unix: float) -> str:
    return pd.Timestamp(t_unix, unit="s", tz="UTC").isoformat()


def fleet_result(
    table: EpochTable, vehicle: VehicleOffsets | None, reason: str, fh: FleetHomology | None, opts: FleetOptions
) -> DetectorResult:
    """This vehicle's fleet detector: alarms where it is one of the vehicles under a common attack."""
    if vehicle is None or fh is None:
        return DetectorResult.skipped(NAME, reason, Evidence.FLEET)
    t0 = float(table.unix_ns(0.0)) / 1e9  # type: ignore[arg-type]  # vehicles have an absolute clock
    t_log = fh.t_unix - t0
    pov = fh.pov[vehicle.name]
    mine = fh.common & np.array([vehicle.name in m for m in fh.members])
    res = DetectorResult(NAME, True, evidence=Evidence.FLEET)
    res.reason = (
        f"offsets of {vehicle.receiver_id} against {vehicle.reference}; homology over {len(fh.pov)} vehicles, "
        f"common attack when >= 2 offsets above {opts.min_offset_m:g} m are more alike than chance "
        f"(P_FA {opts.p_false_alarm:g} per epoch)"
    )
    res.series = [
        Series("offset", t_log, pov, "m", components=("east", "north")),
        Series("homology", t_log, fh.theta, "theta", None),
        Series("homology_threshold", t_log, fh.threshold, "theta"),
        Series("homology_all_vehicles", t_log, fh.theta_all, "theta"),
    ]
    for a in alarm_intervals(t_log, np.nan_to_num(fh.theta), mine, opts.merge_gap_s):
        res.alarms.append(
            Alarm(a.start_s, a.end_s, a.peak_statistic, a.peak_s, onset_s=a.start_s, receiver_id=vehicle.receiver_id)
        )
    any_common = alarm_intervals(t_log, np.nan_to_num(fh.theta), fh.common, opts.merge_gap_s)
    for a in any_common:
        inside = (t_log >= a.start_s) & (t_log <= a.end_s)
        others = sorted({n for k in np.flatnonzero(inside) for n in fh.members[k]} - {vehicle.name})
        mean = np.nanmean(pov[inside], axis=0) if np.isfinite(pov[inside]).any() else np.full(2, np.nan)
        when = f"{_utc(a.start_s + t0)} to {_utc(a.end_s + t0)}"
        if mine[inside].any():
            text = (
                f"common attack with {', '.join(others)}: homologous offsets (theta up to {a.peak_statistic:.3g}) "
                f"{when}; this vehicle's mean offset {np.hypot(*mean):.1f} m (east {mean[0]:.1f}, north {mean[1]:.1f})"
            )
        else:
            text = (
                f"vehicles {', '.join(others)} show a common attack {when}; this vehicle's offset stayed below "
                f"{opts.min_offset_m:g} m or unlike theirs"
            )
        res.findings.append(Finding(text, a.start_s, a.end_s, receiver_id=vehicle.receiver_id))
    res.extras = {
        "reference": vehicle.reference,
        "vehicles": sorted(fh.pov),
        "common_epochs": int(mine.sum()),
        "min_offset_m": opts.min_offset_m,
        "p_false_alarm": opts.p_false_alarm,
    }
    return res


def _run(ctx: AnalysisContext) -> list[DetectorResult]:
    return [DetectorResult.skipped(NAME, "needs " + NEEDS_FLEET, Evidence.FLEET)]


_O = FleetOptions()
_P = probability(_O.p_false_alarm)
ANALYSIS = AnalysisSpec(
    "fleet",
    "seed 004: homology of the position offsets of several vehicles (spooflens fleet)",
    ("fixes", "fleet"),
    _run,
    (
        DetectorInfo(
            NAME,
            Evidence.FLEET,
            "offsets from each vehicle's own reference more alike across vehicles than chance (a common attacker)",
            method="Each vehicle's offset is its reported position minus its own independent reference (a surveyed "
            "site, the INS reconstruction, or an authentic-subset solution); the homology index (Algorithm 1: "
            "1/c_vx + 1/c_vy after rotating the mean offset to 45 degrees) of the offsets above "
            f"{_O.min_offset_m:g} m is compared with its distribution for independent isotropic offsets "
            f"(scale-free, so it depends only on the number of vehicles) at {_P} per epoch: the "
            "chance that displaced vehicles look alike; being displaced by more than "
            f"{_O.min_offset_m:g} m from an independent reference is the rare part without an attacker. One log is "
            "never a fleet: `analyze` lists it as not run, `spooflens fleet LOG1 LOG2 ...` runs it.",
            p_false_alarm=f"{_P} per epoch that unrelated offsets look alike; offsets above "
            f"{_O.min_offset_m:g} m from independent references",
            threshold=f"the homology index's {1 - _O.p_false_alarm:g} quantile for independent offsets",
            paper="Seed 004 (homology of position offsets and a distributed secure state observer)",
        ),
    ),
)
