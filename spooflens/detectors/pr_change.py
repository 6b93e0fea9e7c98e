"""Seed 002 on a log: each satellite's pseudorange change at a receiver of known position, predicted by a
constant-acceleration Kalman filter (`pr_change_kf`) and by a recurrent network (`pr_change_rnn`). The
statistics are in `spooflens.detectors.statistics.pseudorange_change`; what the detectors do is declared
in `ANALYSIS` (docs/detectors.md)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from spooflens.detectors.base import Alarm, DetectorResult, Finding, Series, alarm_intervals
from spooflens.detectors.references import Reference, ins_reference, station_reference
from spooflens.detectors.statistics.pseudorange_change import (
    EsnOptions,
    KalmanOptions,
    Prediction,
    PseudorangeChanges,
    compensation,
    esn_predictor,
    kalman_predictor,
    pseudorange_changes,
    train_esn,
)
from spooflens.detectors.statistics.scales import threshold
from spooflens.errors import SpooflensError
from spooflens.gnss.ephemeris import Klobuchar
from spooflens.gnss.grid import ObservationGrid, observation_grid
from spooflens.gnss.stations import stations
from spooflens.navigation.product import navigation_of
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.preconditions import (
    INDEPENDENT_REFERENCE,
    PSEUDORANGE_ARCS,
    STRAPDOWN_IMU,
    unmet_preconditions,
)
from spooflens.pipeline.registry import AnalysisContext, AnalysisSpec, DetectorInfo, probability

FloatArray = NDArray[np.float64]
KF, RNN = "pr_change_kf", "pr_change_rnn"


@dataclass(frozen=True)
class PrChangeOptions:
    p_false_alarm: float = 1e-6  # per satellite and epoch
    alpha: float = 1.0  # compensation factor (spooflens bench pr_change sweeps it)
    window_s: float = 5.0  # free-INS window when the reference is the INS
    mask_deg: float = 10.0
    kalman: KalmanOptions = field(default_factory=KalmanOptions)
    esn: EsnOptions = field(default_factory=EsnOptions)
    clean_margin: int = 2  # epochs either side of a Kalman alarm kept out of the network's training


@dataclass(frozen=True)
class ReceiverRun:
    receiver_id: str
    reference: Reference
    changes: PseudorangeChanges
    threshold: float
    kalman: Prediction
    rnn: Prediction | None
    rnn_note: str


def _threshold(ch: PseudorangeChanges, p: float) -> float:
    per_sat = np.isfinite(ch.z_median).sum(axis=0)
    n = float(np.median(per_sat[per_sat > 0])) if (per_sat > 0).any() else 20.0
    return threshold(p, int(max(n, 20)), 0.0, dof=1)[0]


def run_receiver(
    grid_ref: tuple[ObservationGrid, Reference], iono: Klobuchar | None, opts: PrChangeOptions
) -> ReceiverRun:
    grid, ref = grid_ref
    ch = pseudorange_changes(grid, ref, iono, opts.mask_deg)
    thr = _threshold(ch, opts.p_false_alarm)
    kf = kalman_predictor(ch, thr, opts.kalman)
    clean = np.asarray(~kf.alarm.any(axis=1), dtype=bool)
    for _ in range(opts.clean_margin):
        clean[1:] &= clean[:-1]
        clean[:-1] &= clean[1:]
    rnn, note = None, ""
    try:
        net = train_esn(
            ch.z_median / ch.sigma_m, ch.arc_start, np.broadcast_to(clean[:, None], kf.alarm.shape), opts.esn
        )
        rnn = esn_predictor(ch, net, thr, opts.esn)
        note = f"network trained on {int(clean.sum())} clean epochs, residual variance {net.residual_var:.2f} of z's"
    except ValueError as err:
        note = str(err)
    return ReceiverRun(grid.receiver_id, ref, ch, thr, kf, rnn, note)


def _alarms(run: ReceiverRun, pred: Prediction) -> list[Alarm]:
    ch = run.changes
    epoch_stat = np.nanmax(np.where(np.isfinite(pred.statistic), pred.statistic, -np.inf), axis=1)
    alarm = np.asarray(pred.alarm.any(axis=1), dtype=bool)
    dt = float(np.nanmedian(np.diff(ch.t))) if len(ch.t) > 1 else 1.0
    out: list[Alarm] = []
    for a in alarm_intervals(ch.t, epoch_stat, alarm, 2.5 * dt):
        first = int(np.searchsorted(ch.t, a.start_s))
        inside = (ch.t >= a.start_s) & (ch.t <= a.end_s)
        tainted = any(run.reference.contaminated(first, b.start_s) for b in out)
        sats = () if tainted else tuple(str(s) for s in ch.sv_id[pred.alarm[inside].any(axis=0)])
        prev = np.flatnonzero(ch.t < a.start_s)
        interval = (float(ch.t[prev[-1]]), a.start_s) if len(prev) else None
        out.append(
            replace(a, receiver_id=run.receiver_id, satellites=sats, onset_s=a.start_s, onset_interval_s=interval)
        )
    return out


def _findings(run: ReceiverRun, pred: Prediction, alarms: list[Alarm], offset: FloatArray) -> list[Finding]:
    ch = run.changes
    out = []
    for a in alarms:
        if not a.satellites:
            continue
        inside = np.flatnonzero((ch.t >= a.start_s) & (ch.t <= a.end_s))
        last = inside[-1]
        cols = [int(np.flatnonzero(ch.sv_id == s)[0]) for s in a.satellites]
        parts = [f"{ch.sv_id[j]} {offset[last, j]:+.1f} m" for j in cols]
        out.append(
            Finding(
                f"receiver {run.receiver_id}: pseudorange change against {run.reference.kind} broke the "
                f"{pred.name} prediction at {a.start_s:.1f} s; estimated spoofing offset (beyond what all "
                "satellites share, which the receiver clock absorbs) " + ", ".join(parts),
                a.start_s,
                a.end_s,
                a.satellites,
                run.receiver_id,
                float(np.nanmax(np.abs(offset[last, cols]))) if np.isfinite(offset[last, cols]).any() else None,
            )
        )
    return out


def _result(name: str, runs: list[ReceiverRun], opts: PrChangeOptions, which: str) -> DetectorResult:
    res = DetectorResult(name, True, evidence=runs[0].reference.evidence)
    notes = []
    for run in runs:
        pred = run.kalman if which == "kalman" else run.rnn
        if pred is None:
            notes.append(f"{run.receiver_id}: not run ({run.rnn_note})")
            continue
        ch, rid = run.changes, run.receiver_id
        offset = compensation(pred, ch.arc_start, opts.alpha)
        alarms = _alarms(run, pred)
        res.alarms += alarms
        res.findings += _findings(run, pred, alarms, offset)
        epoch_stat = np.nanmax(np.where(np.isfinite(pred.statistic), pred.statistic, -np.inf), axis=1)
        epoch_stat = np.where(np.isfinite(epoch_stat), epoch_stat, np.nan)
        sats = tuple(ch.sv_id)
        res.series += [
            Series(f"{rid}/max_statistic", ch.t, epoch_stat, "v^2/S", run.threshold),
            Series(f"{rid}/statistic", ch.t, pred.statistic, "v^2/S", run.threshold, sats),
            Series(f"{rid}/z", ch.t, ch.z_median, "m", None, sats),
            Series(
                f"{rid}/estimated_offset", ch.t, np.where(np.isfinite(ch.z_median), offset, np.nan), "m", None, sats
            ),
        ]
        rms = float(np.sqrt(np.nanmean((pred.v / ch.sigma_m) ** 2)))
        notes.append(
            f"{rid}: against {run.reference.description}; threshold {run.threshold:.1f}; residual RMS {rms:.2f} "
            "of z's noise"
            + (f"; {run.rnn_note}" if which == "rnn" else "")
            + (
                f"; {int(np.abs(ch.clock_resets).sum())} millisecond clock resets removed"
                if ch.clock_resets.any()
                else ""
            )
        )
        res.extras[f"{rid}/threshold"] = round(run.threshold, 3)
        res.extras[f"{rid}/residual_rms_sigma"] = round(rms, 3)
        res.extras[f"{rid}/z_sigma_zenith_m"] = round(float(np.nanmin(ch.sigma_m)), 3)
    res.reason = (
        f"cross-satellite median removed (receiver clock); P_FA {opts.p_false_alarm:g} per satellite and epoch; "
        f"compensation alpha {opts.alpha:g}; " + "; ".join(notes)
    )
    res.alarms.sort(key=lambda a: a.start_s)
    return res


def _skipped(reason: str) -> list[DetectorResult]:
    return [
        DetectorResult.skipped(KF, reason, Evidence.KNOWN_STATION),
        DetectorResult.skipped(RNN, reason, Evidence.KNOWN_STATION),
    ]


def references(ctx: AnalysisContext, window_s: float) -> tuple[list[tuple[ObservationGrid, Reference]], str]:
    """(grid, reference) per receiver to run on, or ([], why not)."""
    table = ctx.table
    found, why = stations(table, ctx.options.extra)
    if found:
        out = []
        for rid, st in found.items():
            grid = observation_grid(table, rid)
            out.append((grid, station_reference(grid, st)))
        return out, ""
    if len(table.imu) and not unmet_preconditions((STRAPDOWN_IMU,), ctx):
        try:
            nav = navigation_of(ctx)
        except SpooflensError as err:
            return [], f"no known station, and the INS reference could not be computed: {err}"
        rid = nav.solution.receiver_id
        receivers = set(table.observations["receiver_id"].astype(str))
        if rid not in receivers:
            return [], f"no known station, and the navigation receiver {rid!r} has no raw observations"
        grid = observation_grid(table, rid)
        return [(grid, ins_reference(ctx, grid, window_s))], ""
    reason = "; ".join(f"{r}: {w}" for r, w in why.items())
    return [], f"needs a receiver of known position: a station or an IMU ({reason})"


def run(ctx: AnalysisContext, opts: PrChangeOptions | None = None) -> list[DetectorResult]:
    opts = opts or PrChangeOptions()
    chosen, why = references(ctx, opts.window_s)
    if not chosen:
        return _skipped(why)
    runs = [run_receiver(c, ctx.table.ionosphere, opts) for c in chosen]
    runs = [r for r in runs if np.isfinite(r.changes.z_median).any()]
    if not runs:
        return _skipped("no satellite was tracked over two consecutive epochs with a reference")
    return [_result(KF, runs, opts, "kalman"), _result(RNN, runs, opts, "rnn")]


_PAPER = "Seed 002 (Mosavi et al. 2014, DGPS pseudorange-change residuals)"
_O = PrChangeOptions()
_P = probability(_O.p_false_alarm)
_Z = (
    "Per satellite, z = the change of its pseudorange between epochs minus the change of the modelled range "
    "from the known position (eqs. 4-5), the receiver clock removed by the cross-satellite median, elevations "
    f"below {_O.mask_deg:g} deg left out. Reference: a known station (`--station`, or the RINEX header of a "
    "receiver that stayed put; evidence: known station) for every receiver that has one; otherwise, with an IMU "
    f"fit for strapdown, the INS propagated alone over {_O.window_s:g} s from the GNSS/INS solution (evidence: "
    "inertial). The carrier must confirm a code change (a spoofer delays the whole signal, code multipath moves "
    "the code alone): where the carrier was tracked, it must have moved at least half as far the same way, "
    "unless code and carrier disagree by more than multipath reaches (30 m). The residual v against the "
    "prediction, v^2/S against chi-square(1) per satellite and epoch, widened to F(1, n) for a noise scale read "
    "off n samples per satellite. Each alarm names the satellites whose residual crossed the threshold, with "
    f"the spoofing offset the compensation (eq. 9, alpha {_O.alpha:g}) estimates for them."
)
ANALYSIS = AnalysisSpec(
    "pr_change",
    "seed 002: each satellite's pseudorange change against a receiver of known position (a station, or "
    "the INS over a window), predicted by a Kalman filter and a recurrent network",
    ("observations", "satellite_states"),
    run,
    (
        DetectorInfo(
            KF,
            Evidence.KNOWN_STATION,
            "pseudorange change minus range change from the known position, against a constant-acceleration "
            "Kalman prediction",
            method=f"{_Z} Predictor: a constant-acceleration Kalman filter per satellite arc (eqs. 6-8); an alarmed "
            "satellite coasts a few epochs before its filter restarts at the new level.",
            p_false_alarm=f"{_P} per satellite and epoch (about 1e-5 per epoch with ten satellites)",
            threshold=f"v^2/S > 1 x F(1, n) at {_P}",
            paper=_PAPER,
        ),
        DetectorInfo(
            RNN,
            Evidence.KNOWN_STATION,
            "the same residual against an echo-state network's prediction, trained on the log's clean epochs",
            method=f"{_Z} Predictor: the recurrent network the paper leaves unspecified, a seeded echo-state "
            f"network ({_O.esn.units} units, ridge readout) trained on the epochs the Kalman detector left clean "
            f"({_O.clean_margin} epochs either side of its alarms kept out); same threshold.",
            p_false_alarm=f"{_P} per satellite and epoch",
            threshold=f"v^2/S > 1 x F(1, n) at {_P}",
            paper=_PAPER,
        ),
    ),
    preconditions=(INDEPENDENT_REFERENCE, PSEUDORANGE_ARCS),
    navigated=True,  # the INS reference: run on each stretch the navigation ran on
)
