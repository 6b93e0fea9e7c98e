"""`spooflens fleet LOG1 LOG2 ... [-o DIR]`: several vehicles (or receivers) over the same time and area.

Each log is analysed on its own (`spooflens.pipeline.run.analyze_table`); each vehicle's offset from its
own independent reference is put on a common UTC time grid; the homology index of the offsets over time
says when the vehicles were moved alike (a common attacker), and that goes into each vehicle's verdict
as fleet evidence with a finding. Writes DIR/fleet.rrd (all tracks, offsets, the index) and
DIR/fleet.json (each vehicle's summary with the fleet detector, the fleet's findings).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import click
import numpy as np
import pandas as pd
import rerun as rr
import rerun.blueprint as rrb
from rich.table import Table

from spooflens.baseline.loaded import LoadedBaseline
from spooflens.cli import baseline_option
from spooflens.detectors.base import DetectorResult
from spooflens.epoch_table import EpochTable, checked
from spooflens.errors import SpooflensError
from spooflens.fleet.offsets import (
    FleetHomology,
    FleetOptions,
    VehicleOffsets,
    fleet_homology,
    overlap_groups,
    vehicle_offsets,
)
from spooflens.output.console import console, progress, show_progress
from spooflens.output.recording import APP_ID, COLOURS, entity
from spooflens.pipeline.registry import AnalysisContext
from spooflens.pipeline.verdict import Verdict

PALETTE = ((230, 60, 50), (60, 120, 230), (40, 180, 90), (200, 160, 40), (150, 80, 200), (20, 180, 200))


@dataclass
class Vehicle:
    name: str
    table: EpochTable
    results: list[DetectorResult]
    verdict: Verdict
    offsets: VehicleOffsets | None
    reason: str
    context: AnalysisContext  # what its results were made from: its verdict is assessed again with the fleet's
    baseline: LoadedBaseline | None = None


def _name(path: Path, taken: set[str]) -> str:
    name = path.name.rstrip("/") or str(path)
    base, i = name, 2
    while name in taken:
        name, i = f"{base}#{i}", i + 1
    taken.add(name)
    return name


def run_fleet(
    logs: list[Path], opts: FleetOptions, report=lambda task, done, total: None, baseline: LoadedBaseline | None = None
) -> tuple[list[Vehicle], FleetHomology | None, list[str]]:
    """Analyse every log, measure offsets, compute the homology, and redo each verdict with fleet evidence.
    `baseline`: one vehicle type's, applied to every log (a log of another receiver model: BaselineError)."""
    from readers import read_log
    from spooflens.fleet.detector import NAME, fleet_result
    from spooflens.gnss.solved_fixes import with_solved_fixes
    from spooflens.pipeline.registry import AnalyzeOptions
    from spooflens.pipeline.run import analyze_table, assess
    from spooflens.service import checked_baseline

    notes: list[str] = []
    vehicles: list[Vehicle] = []
    taken: set[str] = set()
    for i, path in enumerate(logs):
        report("analysing logs", i, len(logs))
        try:
            table = checked(with_solved_fixes(read_log(path)))
        except SpooflensError as err:
            notes.append(f"{path}: not read ({err}); left out")
            continue
        analysis = analyze_table(table, AnalyzeOptions(baseline=checked_baseline(baseline, table)), keep_context=True)
        assert analysis.context is not None  # asked for
        name = _name(path, taken)
        off, reason = vehicle_offsets(name, table, analysis.results, analysis.verdict, opts)
        if off is None:
            notes.append(f"{name}: {reason}; left out of the homology")
        vehicles.append(
            Vehicle(
                name,
                table,
                analysis.results,
                analysis.verdict,
                off,
                reason,
                analysis.context,
                analysis.options.baseline,
            )
        )
    report("analysing logs", len(logs), len(logs))
    with_offsets = [v.offsets for v in vehicles if v.offsets is not None]
    overlapping, overlap_notes = overlap_groups(with_offsets)
    notes += overlap_notes
    fh = fleet_homology(overlapping, opts) if len(overlapping) >= 2 else None
    if fh is None and len(vehicles) >= 2:
        notes.append("fewer than two vehicles with an independent reference overlap in time: no homology")
    members = {v.name for v in overlapping}
    for v in vehicles:
        why = v.reason if v.offsets is None else ("does not overlap in time with any other log")
        res = fleet_result(
            v.table, v.offsets if v.name in members else None, why, fh if v.name in members else None, opts
        )
        v.results = [res if r.name == NAME else r for r in v.results]
        v.verdict = assess(v.context, v.results)
    return vehicles, fh, notes


def _utc(t: float) -> str:
    return pd.Timestamp(t, unit="s", tz="UTC").isoformat()


def _intervals(fh: FleetHomology) -> list[dict[str, object]]:
    out = []
    c = np.concatenate([[0], fh.common.astype(np.int8), [0]])
    starts, ends = np.flatnonzero(np.diff(c) == 1), np.flatnonzero(np.diff(c) == -1) - 1
    for s, e in zip(starts, ends, strict=True):
        names = sorted({n for k in range(s, e + 1) for n in fh.members[k]})
        out.append(
            {
                "start_utc": _utc(fh.t_unix[s]),
                "end_utc": _utc(fh.t_unix[e]),
                "vehicles": names,
                "theta_max": float(np.nanmax(fh.theta[s : e + 1])),
                "threshold": float(np.nanmax(fh.threshold[s : e + 1])),
            }
        )
    return out


def fleet_summary(vehicles: list[Vehicle], fh: FleetHomology | None, notes: list[str], opts: FleetOptions) -> dict:
    from spooflens.output.summary import build_summary

    out: dict[str, object] = {
        "options": {"min_offset_m": opts.min_offset_m, "p_false_alarm": opts.p_false_alarm},
        "notes": notes,
        "vehicles": [
            {
                "name": v.name,
                "log": str(v.table.source),
                "receiver_id": v.offsets.receiver_id if v.offsets else None,
                "reference": v.offsets.reference if v.offsets else None,
                "left_out": None if v.offsets else v.reason,
                "span_utc": [_utc(x) for x in v.offsets.span] if v.offsets else None,
                "summary": build_summary(v.table, v.results, v.verdict, v.baseline),
            }
            for v in vehicles
        ],
    }
    if fh is not None:
        finite = np.isfinite(fh.theta_all)
        out["homology"] = {
            "grid_start_utc": _utc(fh.t_unix[0]),
            "grid_step_s": float(np.median(np.diff(fh.t_unix))) if len(fh.t_unix) > 1 else None,
            "epochs": len(fh.t_unix),
            "theta_all_median": float(np.median(fh.theta_all[finite])) if finite.any() else None,
            "common_attack": _intervals(fh),
        }
    from spooflens.output.summary import json_safe

    return dict(json_safe(out))


def write_fleet_recording(path: Path, vehicles: list[Vehicle], fh: FleetHomology | None) -> None:
    """Every vehicle's reported track and reference on the map, each offset and the index over UTC time."""
    from spooflens.fleet.detector import NAME

    rec = rr.RecordingStream(APP_ID, recording_id="spooflens:fleet")
    blueprint = rrb.Blueprint(
        rrb.Horizontal(
            rrb.MapView(origin="map", name="Map: reported and reference tracks"),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="fleet", name="Homology index and its threshold"),
                rrb.TimeSeriesView(origin="offsets", name="Offsets from each vehicle's reference (m)"),
                rrb.TextLogView(origin="events", name="Findings"),
                row_shares=[2, 2, 1],
            ),
        ),
        collapse_panels=False,
    )
    rec.save(str(path), default_blueprint=blueprint)
    try:
        ev_t, ev_text = [], []
        for i, v in enumerate(vehicles):
            if v.offsets is None:
                continue
            o = v.offsets
            colour = PALETTE[i % len(PALETTE)]
            idx = [rr.TimeColumn("log_time", timestamp=(o.unix_s * 1e9).astype("int64").astype("datetime64[ns]"))]
            for what, llh, c in (("reported", o.fix_llh, colour), ("reference", o.ref_llh, COLOURS["reconstructed"])):
                rec.log(entity("map", v.name, what), rr.GeoLineStrings(lat_lon=[llh[:, :2]], colors=[c]), static=True)
            rec.send_columns(
                entity("map", v.name, "position"), indexes=idx, columns=rr.GeoPoints.columns(positions=o.fix_llh[:, :2])
            )
            rec.log(entity("offsets", v.name), rr.SeriesLines(names=[f"{v.name} east", f"{v.name} north"]), static=True)
            rec.send_columns(entity("offsets", v.name), indexes=idx, columns=rr.Scalars.columns(scalars=o.pov))
            for f in next((r.findings for r in v.results if r.name == NAME), []):
                ev_t.append(float(v.table.unix_ns(f.start_s)) / 1e9)  # type: ignore[arg-type]
                ev_text.append(f"{v.name}: {f.text}")
            ev_t.append(o.span[0])
            ev_text.append(f"{v.name}: {v.verdict.headline}")
        if fh is not None:
            idx = [rr.TimeColumn("log_time", timestamp=(fh.t_unix * 1e9).astype("int64").astype("datetime64[ns]"))]
            for name, values in (
                ("theta", fh.theta),
                ("threshold", fh.threshold),
                ("theta_all_vehicles", fh.theta_all),
            ):
                rec.log(entity("fleet", name), rr.SeriesLines(names=[name]), static=True)
                rec.send_columns(entity("fleet", name), indexes=idx, columns=rr.Scalars.columns(scalars=values))
        if ev_t:
            order = np.argsort(ev_t, kind="stable")
            rec.send_columns(
                "events",
                indexes=[
                    rr.TimeColumn(
                        "log_time", timestamp=(np.asarray(ev_t)[order] * 1e9).astype("int64").astype("datetime64[ns]")
                    )
                ],
                columns=rr.TextLog.columns(text=[ev_text[i] for i in order], level=["WARN"] * len(order)),
            )
    finally:
        rec.disconnect()


@click.command("fleet")
@click.argument("logs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    "out_dir",
    type=click.Path(path_type=Path),
    default=Path(),
    show_default=True,
    help="Directory for fleet.rrd and fleet.json.",
)
@click.option(
    "--reference-sats",
    default="",
    help="Satellites trusted as authentic (G01+G07+...): the reference of raw-observation logs without an IMU "
    "or a surveyed site.",
)
@click.option(
    "--min-offset",
    type=float,
    default=FleetOptions.min_offset_m,
    show_default=True,
    help="Offsets below this (m) do not count as attacked.",
)
@baseline_option
@click.option("--quiet", is_flag=True, help="No progress bars or tables.")
def command(
    logs: tuple[Path, ...],
    out_dir: Path,
    reference_sats: str,
    min_offset: float,
    baseline_path: Path | None,
    quiet: bool,
) -> int:
    """Analyse the logs of several vehicles (or receivers) over the same time and area: each vehicle's offsets
    from its own reference, their homology over time, and a common-attack finding in each verdict."""
    if len(logs) < 2:
        raise click.UsageError("fleet needs at least two logs")
    from spooflens.service import load_baseline_option, make_output_folder

    baseline = load_baseline_option(baseline_path)
    make_output_folder(out_dir, "--output")
    sats = tuple(s.strip().upper() for s in reference_sats.replace(",", "+").split("+") if s.strip())
    opts = FleetOptions(min_offset_m=min_offset, reference_sats=sats)
    with progress(not quiet and show_progress()) as report:
        vehicles, fh, notes = run_fleet(list(logs), opts, report, baseline)
    if len(vehicles) < 2:
        raise SpooflensError("fewer than two logs could be read: " + "; ".join(notes))
    write_fleet_recording(out_dir / "fleet.rrd", vehicles, fh)
    summary = fleet_summary(vehicles, fh, notes, opts)
    (out_dir / "fleet.json").write_text(json.dumps(summary, indent=2))
    if not quiet:
        out = console()
        t = Table("vehicle", "reference", "span (UTC)", "verdict", title="Fleet")
        for v in vehicles:
            span = " to ".join(_utc(x)[11:19] for x in v.offsets.span) if v.offsets else "-"
            t.add_row(v.name, v.offsets.reference if v.offsets else f"(left out: {v.reason})", span, v.verdict.headline)
        out.print(t)
        for iv in summary.get("homology", {}).get("common_attack", []):  # type: ignore[union-attr]
            out.print(
                f"[bold red]common attack[/] on {', '.join(iv['vehicles'])} from {iv['start_utc']} to {iv['end_utc']} "
                f"(theta up to {iv['theta_max']:.3g}, threshold {iv['threshold']:.3g})"
            )
        for n in notes:
            out.print(f"  note: {n}")
        out.print(f"recording: {out_dir / 'fleet.rrd'}   summary: {out_dir / 'fleet.json'}")
    return 0
