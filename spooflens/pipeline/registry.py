"""Which analyses a log supports, and running them.

An analysis is one module that declares `ANALYSIS` (an `AnalysisSpec`): the streams it needs, what its
model requires of the data (named checks in `spooflens.pipeline.preconditions`), the detectors it
produces (each a `DetectorInfo`: evidence class, method, threshold, false-alarm rate) and its run
function. `ANALYSIS_MODULES` lists them in the order they run; adding a detector is one module plus
one line there, and the verdict, recording, report, CLI and docs/detectors.md pick it up from the
declaration (docs/architecture.md). `run_analyses` runs every analysis whose inputs are present and
whose preconditions hold, and says, for each detector it could not run, what was missing or unmet.

Work several analyses share (the GNSS/INS navigation solution) is computed once, on first use,
through the `AnalysisContext`. An analysis whose results wait on work begun in the background (the
navigation's smoothed track) returns `Later`: the analyses after it run meanwhile.
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial

import numpy as np
import pandas as pd

from spooflens.detectors.base import DetectorResult, Unmet
from spooflens.epoch_table import EpochTable
from spooflens.errors import SpooflensError
from spooflens.pipeline.context import AnalysisContext, AnalyzeOptions
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.joined import joined, spanned
from spooflens.pipeline.preconditions import STRAPDOWN_IMU, imu_spans_of, unmet_preconditions

MIN_FIXES = 3
MIN_IMU_SAMPLES = 50
MIN_AUTOPILOT_ROWS = 20
MIN_TIMED_FIXES = 20

# Every analysis, in the order it runs. One line per module; the module declares the rest.
ANALYSIS_MODULES: tuple[str, ...] = (
    "spooflens.detectors.gnss_consistency",
    "spooflens.detectors.receiver_evidence",
    "spooflens.detectors.interference",
    "spooflens.detectors.autopilot_ekf",
    "spooflens.detectors.heading_reference",
    "spooflens.detectors.receiver_time",
    "spooflens.detectors.raim",
    "spooflens.detectors.system_agreement",
    "spooflens.detectors.satellite_signals",
    "spooflens.detectors.navigation_message",
    "spooflens.navigation.product",
    "spooflens.detectors.mlrt",
    "spooflens.detectors.innovation_tests",
    "spooflens.detectors.dual_receiver",
    "spooflens.fleet.detector",
    "spooflens.detectors.range_rate",
    "spooflens.detectors.pr_change",
)


def _has_fixes(table: EpochTable) -> str | None:
    n = len(table.fixes)
    return None if n >= MIN_FIXES else f"GNSS fixes ({n} found, {MIN_FIXES} needed)"


def _has_imu(table: EpochTable) -> str | None:
    n = len(table.imu)
    return None if n >= MIN_IMU_SAMPLES else f"IMU samples ({n} found, {MIN_IMU_SAMPLES} needed)"


def _has_fix_velocity(table: EpochTable) -> str | None:
    v = table.fixes[["vel_e_mps", "vel_n_mps"]].to_numpy(dtype=float)
    return None if len(v) and np.isfinite(v).all(axis=1).any() else "GNSS velocity"


def _has_observations(table: EpochTable) -> str | None:
    return None if len(table.observations) else "raw GNSS observations (pseudoranges)"


def _has_satellite_states(table: EpochTable) -> str | None:
    obs = table.observations
    if not len(obs):
        return "raw GNSS observations (pseudoranges)"
    ok = np.isfinite(obs[["sv_x_m", "sv_y_m", "sv_z_m"]].to_numpy(dtype=float)).all(axis=1)
    if ok.any():
        return None
    if table.ephemerides is not None and len(table.ephemerides):
        return "satellite positions: no orbit of the navigation data given is of the observations' time (see skipped)"
    return "satellite positions (a navigation file or logged ephemerides)"


SATELLITE_REPORTS = "per-satellite reports (NAV-SAT, GSV, PX4 satellite_info, GnssLogger Status)"


def _has_satellite_view(table: EpochTable) -> str | None:
    if len(table.satellites):
        return None
    obs = table.observations
    if len(obs) and (np.isfinite(obs["cn0_dbhz"].to_numpy(dtype=float)).any() or _has_satellite_states(table) is None):
        return None
    return f"{SATELLITE_REPORTS} or raw observations with C/N0 or satellite positions" + _no_cn0(obs)


def _has_signal_levels(table: EpochTable) -> str | None:
    if _has_fixes(table) is None or len(table.satellites) or len(table.receiver_status):
        return None
    obs = table.observations
    if len(obs) and np.isfinite(obs["cn0_dbhz"].to_numpy(dtype=float)).any():
        return None
    return "GNSS fixes, monitor messages, satellite reports or raw observations with C/N0" + _no_cn0(obs)


def _no_cn0(obs: pd.DataFrame) -> str:
    """Why raw observations that are there do not count: they carry no C/N0 (none written, or none in dB-Hz)."""
    return f" (its {len(obs)} raw observations carry no C/N0 in dB-Hz)" if len(obs) else ""


def _has_received_ephemerides(table: EpochTable) -> str | None:
    eph = table.ephemerides
    if eph is not None and np.isfinite(eph.received_s).any():
        return None
    return "navigation messages decoded from the signals (u-blox RXM-SFRBX)"


def _has_two_receivers(table: EpochTable) -> str | None:
    n = len(table.receivers())
    return None if n >= 2 else f"two GNSS receivers ({n} found)"


def _has_autopilot_ekf(table: EpochTable) -> str | None:
    n = len(table.frame("autopilot_ekf"))
    return (
        None if n >= MIN_AUTOPILOT_ROWS else f"the autopilot's GNSS innovations ({n} rows, {MIN_AUTOPILOT_ROWS} needed)"
    )


def _has_headings(table: EpochTable) -> str | None:
    return None if len(table.frame("headings")) else "a compass heading (NMEA HDT, HDG, THS or VHW)"


def _has_time_offset(table: EpochTable) -> str | None:
    fixes = table.fixes
    n = int(np.isfinite(fixes["time_offset_s"].to_numpy(dtype=float)).sum()) if "time_offset_s" in fixes else 0
    return (
        None
        if n >= MIN_TIMED_FIXES
        else "the receiver's time beside the log's own clock (PX4 time_utc_usec, ArduPilot GWk/GMS, GnssLogger "
        f"Fix, NMEA with logger times, ROS TimeReference, tlog GPS_RAW_INT; {n} of {len(fixes)} fixes have both, "
        f"{MIN_TIMED_FIXES} needed)"
    )


def _has_fleet(table: EpochTable) -> str | None:
    """One log is never a fleet: `spooflens fleet` runs the fleet analysis with the other vehicles' logs."""
    return "logs of other vehicles over the same time and area (run `spooflens fleet LOG1 LOG2 ...`)"


@dataclass(frozen=True)
class Requirement:
    """A stream an analysis needs: what it is, in words (docs/detectors.md), and the check that says
    what the log lacks (None when present)."""

    what: str
    missing: Callable[[EpochTable], str | None]


REQUIREMENTS: dict[str, Requirement] = {
    "fixes": Requirement(f"GNSS fixes ({MIN_FIXES} or more)", _has_fixes),
    "imu": Requirement(f"IMU samples ({MIN_IMU_SAMPLES} or more)", _has_imu),
    "fix_velocity": Requirement("GNSS velocity", _has_fix_velocity),
    "observations": Requirement("raw GNSS observations (pseudoranges)", _has_observations),
    "satellite_states": Requirement(
        "raw observations with satellite positions (a navigation file or logged ephemerides)", _has_satellite_states
    ),
    "satellite_view": Requirement(
        f"{SATELLITE_REPORTS} or raw observations with C/N0 or satellite positions",
        _has_satellite_view,
    ),
    "signal_levels": Requirement(
        "signal levels: GNSS fixes (their mean C/N0, AGC, noise, jamming indicator or state), the receiver's "
        "monitor messages (MON-RF, MON-HW, SEC-SIG), per-satellite reports or raw observations with C/N0",
        _has_signal_levels,
    ),
    "received_ephemerides": Requirement(
        "navigation messages decoded from the signals (u-blox RXM-SFRBX, GnssLogger Nav)", _has_received_ephemerides
    ),
    "two_receivers": Requirement("two GNSS receivers", _has_two_receivers),
    "fleet": Requirement("other vehicles' logs (`spooflens fleet`)", _has_fleet),
    "autopilot_ekf": Requirement(
        f"the autopilot's GNSS innovations or test ratios ({MIN_AUTOPILOT_ROWS} rows or more: ArduPilot XKF3/XKF4, "
        "NKF3/NKF4; PX4 estimator_innovations + estimator_innovation_test_ratios; tlog EKF_STATUS_REPORT)",
        _has_autopilot_ekf,
    ),
    "headings": Requirement("a compass heading (NMEA HDT, HDG, THS or VHW)", _has_headings),
    "time_offset": Requirement(
        f"the receiver's time beside the log's own clock ({MIN_TIMED_FIXES} fixes or more)", _has_time_offset
    ),
}


def probability(p: float) -> str:
    """A false-alarm rate as declarations write it: 1e-5, 0.01 (not 1e-05)."""
    return f"{p:g}" if p >= 1e-3 else re.sub(r"e-0*", "e-", f"{p:.0e}")


@dataclass(frozen=True)
class DetectorInfo:
    """One detector an analysis produces, as declared: the one source of its method text, threshold,
    false-alarm rate and evidence class for the report's method notes and docs/detectors.md.

    `needs` and `preconditions` are filled from the analysis (`AnalysisSpec`); a detector may declare
    preconditions of its own (checked before it runs, beside its analysis's)."""

    name: str
    evidence: Evidence | None  # None: an analysis product (not counted in the verdict)
    summary: str  # what it tests, one line
    method: str = ""  # how, in a paragraph: what it compares, the statistic, the choices made
    p_false_alarm: str = ""  # the stated false-alarm rate, e.g. "1e-5 per epoch"
    threshold: str = ""  # the decision rule's level, e.g. "chi-square(3) at 1e-5: 25.9"
    paper: str = ""  # the seed paper it implements, when it does
    checked: str = ""  # what it does on real and simulated logs, with the command or test that shows it
    preconditions: tuple[str, ...] = ()  # names in spooflens.pipeline.preconditions.PRECONDITIONS
    needs: tuple[str, ...] = ()  # names in REQUIREMENTS (from the analysis)
    analysis: str = ""  # the analysis that produces it (from the analysis)


@dataclass(frozen=True)
class Later:
    """An analysis's results that wait on work begun in the background (the navigation's smoothed
    track): the analyses after it run meanwhile, and its results take their place in the run order when
    every analysis has run (an error raised then counts as raised by the analysis)."""

    finish: Callable[[], list[DetectorResult]]


@dataclass(frozen=True)
class AnalysisSpec:
    name: str
    description: str
    needs: tuple[str, ...]
    run: Callable[[AnalysisContext], list[DetectorResult] | Later]
    detectors: tuple[DetectorInfo, ...] = ()
    # what the model of every detector here requires of the data, checked before it runs (names in
    # spooflens.pipeline.preconditions.PRECONDITIONS)
    preconditions: tuple[str, ...] = ()
    # runs on the GNSS/INS navigation: where the navigation runs between the IMU's gaps, this runs on
    # each stretch it ran on (`navigation_parts`, each with its own preconditions), the results joined
    navigated: bool = False

    def __post_init__(self) -> None:
        unknown = [n for n in self.needs if n not in REQUIREMENTS]
        if unknown:
            raise ValueError(f"analysis {self.name!r} needs {unknown}, which REQUIREMENTS does not know")
        declared = tuple(
            replace(
                d,
                needs=self.needs,
                analysis=self.name,
                preconditions=tuple(dict.fromkeys(self.preconditions + d.preconditions)),
            )
            for d in self.detectors
        )
        object.__setattr__(self, "detectors", declared)  # frozen: the declaration completed once, here

    def missing(self, table: EpochTable) -> list[str]:
        return [m for need in self.needs if (m := REQUIREMENTS[need].missing(table)) is not None]

    def unmet(self, ctx: AnalysisContext) -> list[Unmet]:
        """The analysis's preconditions this log does not meet (those that stop it first)."""
        return unmet_preconditions(self.preconditions, ctx)


def analyses() -> list[AnalysisSpec]:
    """Every registered analysis, in run order (each module's `ANALYSIS`)."""
    specs: list[AnalysisSpec] = []
    for module in ANALYSIS_MODULES:
        spec = importlib.import_module(module).ANALYSIS
        if any(s.name == spec.name for s in specs):
            raise ValueError(f"analysis {spec.name!r} registered twice")
        specs.append(spec)
    return specs


def detector_infos() -> dict[str, DetectorInfo]:
    """name -> DetectorInfo of every detector of every analysis."""
    return {d.name: d for spec in analyses() for d in spec.detectors}


def _declared(spec: AnalysisSpec, result: DetectorResult, ctx: AnalysisContext, limits: list[Unmet]) -> DetectorResult:
    """A result as declared: its evidence class from the declaration unless it set one itself; not run when
    a precondition of its own detector stops it; carrying what its analysis's preconditions limited."""
    info = next((d for d in spec.detectors if d.name == result.name), None)
    if info is None:
        return result
    own = [u for u in unmet_preconditions(info.preconditions[len(spec.preconditions) :], ctx) if u.stops]
    if own and result.ran:
        return _skipped(info.name, own, result.evidence or info.evidence)
    if result.evidence is None and info.evidence is not None:
        result = replace(result, evidence=info.evidence)
    if limits and result.ran:
        result = replace(result, limitations=[*result.limitations, *limits])
        result.reason += "".join(f"; LIMITED: {u.text}" for u in limits)
    return result


def _skipped(name: str, unmet: list[Unmet], evidence: Evidence | None) -> DetectorResult:
    return DetectorResult.skipped(name, "; ".join(u.text for u in unmet), evidence, unmet[0])


def _not_run(spec: AnalysisSpec, reason: str, unmet: list[Unmet] | None = None) -> list[DetectorResult]:
    precondition = unmet[0] if unmet else None
    if not spec.detectors:
        return [DetectorResult.skipped(spec.name, reason, None, precondition)]
    return [DetectorResult.skipped(d.name, reason, d.evidence, precondition) for d in spec.detectors]


def run_analyses(
    table: EpochTable, options: AnalyzeOptions | None = None, on_step: Callable[[str], None] | None = None
) -> list[DetectorResult]:
    """Run every analysis the table supports; the others come back as not run, with the reason."""
    return run_with_context(AnalysisContext(table, options or AnalyzeOptions()), on_step)


NAVIGATION_PARTS = "navigation_parts"


def navigation_parts(ctx: AnalysisContext) -> list[AnalysisContext]:
    """The contexts the navigation, and every analysis on it, runs on: the log's own; or, when the IMU
    stops for longer than strapdown bridges and the navigation runs between its gaps (`strapdown_imu`
    limits), one per stretch navigated, holding the log's rows in it on the same time axis
    (`spooflens.navigation.segments`). Made once per analysis."""
    parts: list[AnalysisContext] | None = ctx.cached(NAVIGATION_PARTS, partial(_stretches, ctx))
    return parts if parts is not None else [ctx]


def navigation_coverage(ctx: AnalysisContext) -> Unmet | None:
    """What the navigation covers, when it runs between the IMU's gaps: where it ran, where not and why
    (`strapdown_imu`, unmet and limiting); None when it runs on the whole log or not at all."""
    if _has_imu(ctx.table) is not None or _has_fixes(ctx.table) is not None or ctx.span_s is not None:
        return None
    found = unmet_preconditions((STRAPDOWN_IMU,), ctx)
    return found[0] if found and not found[0].stops else None


def _stretches(ctx: AnalysisContext) -> list[AnalysisContext] | None:
    if navigation_coverage(ctx) is None:
        return None
    return [
        AnalysisContext(ctx.table.between(s.start_s, s.end_s), ctx.options, span_s=(s.start_s, s.end_s))
        for s in imu_spans_of(ctx)
        if s.navigated
    ]


def run_with_context(ctx: AnalysisContext, on_step: Callable[[str], None] | None = None) -> list[DetectorResult]:
    later: list[tuple[int, AnalysisSpec, Later]] = []  # where each one's results go in ctx.results
    for spec in analyses():
        # an analysis the log lacks the streams for does not run anywhere: said once, for the whole log
        parts = navigation_parts(ctx) if spec.navigated and not spec.missing(ctx.table) else [ctx]
        if parts[0] is ctx:
            out = _started(spec, ctx, on_step)
        else:
            out = _on_parts(spec, parts, navigation_coverage(ctx), on_step)
        if isinstance(out, Later):
            later.append((len(ctx.results), spec, out))
        else:
            ctx.results.extend(out)
    if on_step and later:  # the time waited for them is theirs, not the last analysis's
        on_step("finishing " + ", ".join(spec.name for _, spec, _ in later))
    finished = [(at, pending.finish()) for at, _, pending in later]
    for at, results in reversed(finished):  # the last first: the earlier places stay where they were
        ctx.results[at:at] = results
    return ctx.results


def _started(
    spec: AnalysisSpec, ctx: AnalysisContext, on_step: Callable[[str], None] | None
) -> list[DetectorResult] | Later:
    """`spec` run on `ctx`, its results as declared; or not run, saying why; `Later` when they wait on work
    begun in the background (its finish raises nothing: an error then is the analysis's not running)."""
    missing = spec.missing(ctx.table)
    if missing:
        return _not_run(spec, "needs " + ", ".join(dict.fromkeys(missing)))
    unmet = spec.unmet(ctx)
    stops = [u for u in unmet if u.stops]
    if stops:
        return _not_run(spec, "; ".join(u.text for u in stops), stops)
    limits = [u for u in unmet if not u.stops]
    if on_step:
        on_step(spec.name if ctx.span_s is None else f"{spec.name} on {spanned(ctx.span_s)}")
    try:
        out = spec.run(ctx)
    except SpooflensError as err:
        return _not_run(spec, str(err))
    if isinstance(out, Later):
        return Later(partial(_finished, spec, out, ctx, limits))
    return [_declared(spec, r, ctx, limits) for r in out]


def _on_parts(
    spec: AnalysisSpec, parts: list[AnalysisContext], coverage: Unmet | None, on_step: Callable[[str], None] | None
) -> list[DetectorResult] | Later:
    """`spec` on each stretch the navigation ran on, its results joined, each saying what the navigation
    covered (`coverage`)."""
    outs = [_started(spec, part, on_step) for part in parts]

    def finish() -> list[DetectorResult]:
        done = [out.finish() if isinstance(out, Later) else out for out in outs]
        spans = [part.span_s or (np.nan, np.nan) for part in parts]
        return [_covered(r, coverage) for r in joined(list(zip(spans, done, strict=True)))]

    return Later(finish) if any(isinstance(out, Later) for out in outs) else finish()


def _covered(result: DetectorResult, coverage: Unmet | None) -> DetectorResult:
    if coverage is None:
        return result
    result = replace(result, reason=f"{result.reason}; LIMITED: {coverage.text}")
    return replace(result, limitations=[coverage, *result.limitations]) if result.ran else result


def _finished(spec: AnalysisSpec, pending: Later, ctx: AnalysisContext, limits: list[Unmet]) -> list[DetectorResult]:
    try:
        return [_declared(spec, r, ctx, limits) for r in pending.finish()]
    except SpooflensError as err:
        return _not_run(spec, str(err))
