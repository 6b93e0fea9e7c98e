"""What each detector's model requires of the data: named checks, run before the detector.

A stream being present (`registry.REQUIREMENTS`) is not enough. Strapdown needs the IMU at tens of Hz
without long gaps, the dual-receiver tests two receivers with independent errors, a known-station
method a receiver that stayed put. An analysis declares the checks its model needs
(`AnalysisSpec.preconditions`, or a detector's own in its `DetectorInfo`); each returns `Unmet`, saying
in words what the log has and what the model needs, or None. Most stop the detector; a limiting one
(noise learning on a short log) lets it run and says what it could not do. docs/detectors.md lists them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from spooflens.detectors.base import Unmet
from spooflens.errors import SpooflensError
from spooflens.gnss.single_point import SinglePointOptions, ranged_by_receiver
from spooflens.gnss.time_tags import TimeTagFit, TimeTagOptions, time_tag_fit

if TYPE_CHECKING:
    from spooflens.navigation.segments import ImuSpan
    from spooflens.pipeline.context import AnalysisContext

# Strapdown integrates each IMU sample over the interval to the next: below tens of Hz a vehicle's
# rotation between samples is not captured, and across a gap it is lost (a turn at 30 deg/s for 0.5 s
# is 15 degrees of heading the INS never sees)
MIN_STRAPDOWN_HZ = 20.0
MAX_IMU_GAP_S = 0.5
# Epoch differences of raw observations (pseudorange changes, carrier-phase rates): the noise scales and
# predictions are learned from them, per receiver; with a handful of epochs a threshold is a guess
MIN_DIFFERENCED_EPOCHS = 20
MIN_DIFFERENCED_SATELLITES = 5  # a velocity, a clock drift per system and one redundant rate
MAX_CARRIER_INTERVAL_S = 60.0  # as RateOptions.max_interval_s: carrier differences over longer gaps are not used
MAX_PSEUDORANGE_INTERVAL_S = 120.0  # as pseudorange_changes(max_gap_s): a longer gap starts a new arc


@dataclass(frozen=True)
class Precondition:
    """A named check of what a model requires of the data. `requires` says it in words (docs); `check`
    returns what the log lacks, or None. `stops`: when unmet the detector does not run; otherwise it runs
    on what there is and its result says what could not be done."""

    requires: str
    check: Callable[[AnalysisContext], Unmet | None]
    stops: bool = True


def unmet_preconditions(names: Sequence[str], ctx: AnalysisContext) -> list[Unmet]:
    """The named preconditions this log does not meet, in the order given (each checked once per
    analysis: several analyses share them)."""
    out = []
    for name in names:
        found: Unmet | None = ctx.cached(f"precondition/{name}", partial(_checked, name, ctx))
        if found is not None:
            out.append(found)
    return out


def _checked(name: str, ctx: AnalysisContext) -> Unmet | None:
    precondition = PRECONDITIONS[name]
    try:
        return precondition.check(ctx)
    except SpooflensError as err:  # what the check could not read is what the log lacks
        return Unmet(name, str(err), precondition.requires, stops=precondition.stops)


# --- the INS ---------------------------------------------------------------------------------------


def navigation_streams(ctx: AnalysisContext) -> tuple[str, str]:
    """(IMU, receiver) the GNSS/INS navigation runs on (its own choice of streams)."""
    from spooflens.navigation.loosely_coupled import select_streams

    imu_id, receiver_id, _ = select_streams(ctx.table, ctx.options.imu_id, ctx.options.receiver_id)
    return imu_id, receiver_id


def imu_rate_and_gap(t: np.ndarray) -> tuple[float, float, float]:
    """(rate from the median sample interval, Hz; longest gap, s; where it began, s)."""
    dt = np.diff(np.asarray(t, dtype=float))
    if not len(dt) or not np.median(dt) > 0:
        return 0.0, float("inf"), float(t[0]) if len(t) else 0.0
    k = int(np.argmax(dt))
    return float(1.0 / np.median(dt)), float(dt[k]), float(t[k])


def imu_spans_of(ctx: AnalysisContext) -> tuple[ImuSpan, ...]:
    """The navigation IMU's span cut at its gaps over MAX_IMU_GAP_S, each stretch navigated or not and why
    (`spooflens.navigation.segments`; computed once per analysis)."""
    from spooflens.navigation.segments import imu_spans

    def cut() -> tuple[ImuSpan, ...]:
        imu_id, receiver_id = navigation_streams(ctx)
        ti = ctx.table.imu_of(imu_id)["t_s"].to_numpy(dtype=float)
        return imu_spans(ti, ctx.table.fixes_of(receiver_id)["t_s"].to_numpy(dtype=float), MAX_IMU_GAP_S)

    spans: tuple[ImuSpan, ...] = ctx.cached("imu_spans", cut)
    return spans


def strapdown_imu(ctx: AnalysisContext) -> Unmet | None:
    """Unmet and stopping below the rate strapdown needs, or when no stretch between the IMU's gaps is long
    enough to navigate; unmet and limiting when there are gaps and the navigation runs between them."""
    imu_id, _ = navigation_streams(ctx)
    t = ctx.table.imu_of(imu_id)["t_s"].to_numpy(dtype=float)
    rate, gap, at = imu_rate_and_gap(t)
    values: dict[str, float | int | str] = {"imu": imu_id, "rate_hz": round(rate, 3), "longest_gap_s": round(gap, 3)}
    if rate < MIN_STRAPDOWN_HZ:
        return Unmet(
            STRAPDOWN_IMU, f"IMU {imu_id} at {rate:.2g} Hz", f"strapdown needs >= {MIN_STRAPDOWN_HZ:g} Hz", values
        )
    if gap <= MAX_IMU_GAP_S:
        return None
    gaps = int(np.count_nonzero(np.diff(t) > MAX_IMU_GAP_S))
    spans = imu_spans_of(ctx)
    navigated = [s for s in spans if s.navigated]
    values |= {"gaps": gaps, "navigated_s": round(sum(s.end_s - s.start_s for s in navigated), 3)}
    found = f"IMU {imu_id} stops for {gap:.2f} s at {at:.1f} s" + (
        f" and {gaps - 1} more time(s) for over {MAX_IMU_GAP_S:g} s" if gaps > 1 else ""
    )
    lost = f"strapdown needs no gap over {MAX_IMU_GAP_S:g} s (the rotation in it is lost)"
    if not navigated:
        return Unmet(
            STRAPDOWN_IMU,
            f"{found}; no stretch between its gaps is long enough to navigate",
            f"{lost}, over a stretch long enough to align and learn the noise",
            values,
        )
    return Unmet(
        STRAPDOWN_IMU,
        found,
        f"{lost}: navigated anew on each stretch between the gaps, on {', '.join(s.describe() for s in navigated)}; "
        f"not navigated on {'; '.join(s.describe() for s in spans if not s.navigated)}",
        values,
        stops=False,
    )


def _fixes_with_imu(ctx: AnalysisContext) -> np.ndarray:
    """Times of the navigation receiver's fixes inside its IMU's span."""
    imu_id, receiver_id = navigation_streams(ctx)
    ti = ctx.table.imu_of(imu_id)["t_s"].to_numpy(dtype=float)
    tf = ctx.table.fixes_of(receiver_id)["t_s"].to_numpy(dtype=float)
    return tf[(tf >= ti[0]) & (tf <= ti[-1])] if len(ti) else tf[:0]


def inertial_span(ctx: AnalysisContext) -> Unmet | None:
    from spooflens.navigation.loosely_coupled import FILTER_SETTLE_S

    tf = _fixes_with_imu(ctx)
    span = float(tf[-1] - tf[0]) if len(tf) >= 2 else 0.0
    if span > FILTER_SETTLE_S:
        return None
    return Unmet(
        INERTIAL_SPAN,
        f"GNSS with the IMU for {span:.1f} s",
        f"the inertial tests do not alarm in the {FILTER_SETTLE_S:g} s the filter settles in, so they need more",
        {"span_s": round(span, 3)},
    )


def noise_learning(ctx: AnalysisContext) -> Unmet | None:
    """What the noise learning (`spooflens.navigation.noise_learning`) cannot learn from this log's length:
    anything, below its minimum of scored data (the prior stands); the receiver's slow wander, below the
    window it reads."""
    from spooflens.navigation.noise_learning import LearnOptions

    o = LearnOptions()
    tf = _fixes_with_imu(ctx)
    span = float(tf[-1] - tf[0]) if len(tf) >= 2 else 0.0
    scored, _ = o.scored(tf)
    values: dict[str, float | int | str] = {"span_s": round(span, 3), "scored_epochs": scored}
    if not o.enough(tf):
        return Unmet(
            NOISE_LEARNING,
            f"GNSS with the IMU for {span:.0f} s ({scored} epochs after the filter's {o.settle_s:g} s settling)",
            f"noise learning needs {o.min_scored_s:g} s and {o.min_scored_epochs} epochs after it: nothing was "
            "learned, the prior stands (the IMU preset, and the fixes' own scatter as their white noise)",
            values,
            stops=False,
        )
    if span < o.min_window_s:
        return Unmet(
            NOISE_LEARNING,
            f"GNSS with the IMU for {span:.0f} s",
            f"noise learning reads {o.min_window_s:g} s: from less, the receiver's slow wander (its Gauss-Markov "
            "errors) and their time constants are poorly determined",
            values,
            stops=False,
        )
    return None


# --- raw observations --------------------------------------------------------------------------------


def _differenced_epochs(ctx: AnalysisContext, carrier: bool) -> dict[str, int]:
    """Per receiver with raw observations: the epochs at which MIN_DIFFERENCED_SATELLITES satellites have
    a measurement differenced against the epoch before (carrier: a carrier phase at both epochs at most
    MAX_CARRIER_INTERVAL_S apart, or a Doppler; else a pseudorange at both, MAX_PSEUDORANGE_INTERVAL_S)."""
    counts: dict[bool, dict[str, int]] = ctx.cached("differenced_epochs", lambda: _count_differenced(ctx))
    return counts[carrier]


def _count_differenced(ctx: AnalysisContext) -> dict[bool, dict[str, int]]:
    from spooflens.gnss.grid import observation_grid

    out: dict[bool, dict[str, int]] = {True: {}, False: {}}
    for rid in dict.fromkeys(ctx.table.observations["receiver_id"].astype(str)):
        grid = observation_grid(ctx.table, rid)
        dt = np.diff(grid.t_s)
        for carrier, value, limit in (
            (True, grid.carrier_m, MAX_CARRIER_INTERVAL_S),
            (False, grid.pseudorange_m, MAX_PSEUDORANGE_INTERVAL_S),
        ):
            ok = grid.usable & np.isfinite(value)
            both = np.zeros_like(ok)
            both[1:] = ok[1:] & ok[:-1] & (dt <= limit)[:, None]
            if carrier:
                if grid.carrier_arc_start is not None:  # the receiver says the carrier is not continuous there
                    both &= ~grid.carrier_arc_start
                both |= grid.usable & np.isfinite(grid.rate_mps)
            out[carrier][rid] = int(np.sum(both.sum(axis=1) >= MIN_DIFFERENCED_SATELLITES))
    return out


def _arcs(ctx: AnalysisContext, carrier: bool) -> Unmet | None:
    counts = _differenced_epochs(ctx, carrier)
    if any(n >= MIN_DIFFERENCED_EPOCHS for n in counts.values()):
        return None
    if carrier:
        what = "carrier-phase rates (or Doppler)"
        why = f"the rate tests learn their noise scales from them: {MIN_DIFFERENCED_EPOCHS} epochs needed"
    else:
        what = "pseudorange changes"
        why = f"the change predictors learn their noise from them: {MIN_DIFFERENCED_EPOCHS} epochs needed"
    at = ", ".join(f"{n} ({rid})" for rid, n in counts.items())
    return Unmet(
        CARRIER_CONTINUITY if carrier else PSEUDORANGE_ARCS,
        f"{what} of {MIN_DIFFERENCED_SATELLITES} or more satellites at {at} epochs",
        why,
        {f"epochs/{rid}": n for rid, n in counts.items()},
    )


def carrier_continuity(ctx: AnalysisContext) -> Unmet | None:
    return _arcs(ctx, carrier=True)


def pseudorange_arcs(ctx: AnalysisContext) -> Unmet | None:
    return _arcs(ctx, carrier=False)


# --- references a spoofer of the receiver cannot move ------------------------------------------------


def known_stations(ctx: AnalysisContext) -> tuple[dict[str, object], dict[str, str]]:
    """`spooflens.detectors.references.stations` of this analysis (computed once)."""
    from spooflens.gnss.stations import stations

    found: tuple[dict[str, object], dict[str, str]] = ctx.cached(
        "known_stations", lambda: stations(ctx.table, ctx.options.extra)
    )
    return found


def independent_reference(ctx: AnalysisContext) -> Unmet | None:
    """An IMU strapdown can use, or a known static station."""
    ins = strapdown_imu(ctx) if len(ctx.table.imu) else None
    if len(ctx.table.imu) and (ins is None or not ins.stops):  # navigated, if only between its gaps
        return None
    found, why = known_stations(ctx)
    if found:
        return None
    no_station = "; ".join(f"{rid}: {w}" for rid, w in why.items()) or "no receiver with observations"
    imu = ins.text if ins is not None else "no IMU"
    return Unmet(
        INDEPENDENT_REFERENCE,
        f"{imu}; no known station ({no_station})",
        "these tests need where the receiver was, known without its GNSS",
        dict(ins.values) if ins is not None else {},
    )


def independent_receivers(ctx: AnalysisContext) -> Unmet | None:
    from spooflens.gnss.same_receiver import receiver_groups

    groups = receiver_groups(ctx)
    if len(groups) >= 2:
        return None
    described = "; ".join(g.describe() for g in groups)
    return Unmet(
        INDEPENDENT_RECEIVERS,
        described,
        "the dual-receiver tests need two receivers with independent errors",
        {"receivers": len(ctx.table.receivers()), "independent": len(groups)},
    )


def surveyed_sites(ctx: AnalysisContext) -> Unmet | None:
    """Two independent receivers, each a known station (the baseline vector is then known)."""
    from spooflens.gnss.same_receiver import receiver_groups

    found, why = known_stations(ctx)
    sited = [g.receivers[0] for g in receiver_groups(ctx) if g.receivers[0] in found]
    if len(sited) >= 2:
        return None
    reasons = "; ".join(f"{rid}: {w}" for rid, w in why.items()) or "no receiver with observations"
    return Unmet(
        SURVEYED_SITES,
        f"{len(sited)} independent receiver(s) at a known station ({reasons})",
        "the baseline error needs two, so the baseline vector is known",
        {"sited": len(sited)},
    )


# --- raw observations against the orbits ------------------------------------------------------------


def receiver_time_tags(ctx: AnalysisContext) -> dict[str, TimeTagFit | None]:
    """Each receiver with pseudoranges and satellite states: how far its time tags are from the time its
    pseudoranges fit the orbits at (None where no epoch shows it); computed once per analysis."""

    def fits() -> dict[str, TimeTagFit | None]:
        options = SinglePointOptions(iono=ctx.table.ionosphere)
        return {rid: time_tag_fit(rows, t_gps, options) for rid, rows, t_gps in ranged_by_receiver(ctx.table)}

    found: dict[str, TimeTagFit | None] = ctx.cached("receiver_time_tags", fits)
    return found


def time_tags_off(ctx: AnalysisContext) -> dict[str, TimeTagFit]:
    """The receivers whose pseudoranges fit the orbits only at other times than their tags: a test of one
    satellite against the others cannot judge them (every satellite is off)."""
    return {rid: fit for rid, fit in receiver_time_tags(ctx).items() if fit is not None and fit.tags_off()}


def orbit_timing(ctx: AnalysisContext) -> Unmet | None:
    """Some receiver whose pseudoranges fit the orbits at their logged times (each one that does not is
    left out by the detector itself)."""
    fits = receiver_time_tags(ctx)
    off = time_tags_off(ctx)
    if not fits or len(off) < len(fits):
        return None
    return Unmet(
        ORBIT_TIMING,
        "; ".join(f"{rid}: {fit.describe()}" for rid, fit in off.items()),
        "the raw-measurement tests need pseudoranges that fit the orbits at their logged times (tags off the "
        "time the signals were measured at, a receiver clock or logging fault, put every satellite off by its "
        "range rate times the offset: no satellite or system can be judged against the others)",
        {f"time_tag_offset_s.{rid}": round(fit.offset_s, 4) for rid, fit in off.items()},
    )


STRAPDOWN_IMU = "strapdown_imu"
INERTIAL_SPAN = "inertial_span"
NOISE_LEARNING = "noise_learning"
CARRIER_CONTINUITY = "carrier_continuity"
PSEUDORANGE_ARCS = "pseudorange_arcs"
INDEPENDENT_REFERENCE = "independent_reference"
INDEPENDENT_RECEIVERS = "independent_receivers"
SURVEYED_SITES = "surveyed_sites"
ORBIT_TIMING = "orbit_timing"
_TAGS = TimeTagOptions()

PRECONDITIONS: dict[str, Precondition] = {
    STRAPDOWN_IMU: Precondition(
        f"the IMU the navigation uses at >= {MIN_STRAPDOWN_HZ:g} Hz (median sample interval) with no gap over "
        f"{MAX_IMU_GAP_S:g} s: strapdown integrates each sample over the interval to the next. An IMU that stops "
        "for longer is navigated anew on each stretch between its gaps whose fixes the noise learning can learn "
        "from (50 over 30 s after the filter's first 20 s), every inertial test with it: this limits, and says "
        "which spans were navigated and why the others were not; it stops when no stretch is long enough",
        strapdown_imu,
    ),
    INERTIAL_SPAN: Precondition(
        "GNSS fixes inside the IMU's span for longer than the 20 s the filter settles in (the inertial tests "
        "do not alarm before)",
        inertial_span,
    ),
    NOISE_LEARNING: Precondition(
        "GNSS with the IMU long enough to learn the sensors' noise from the log: 30 s and 50 epochs after the "
        "filter settles to learn anything (else the prior stands), 300 s to learn the receiver's slow wander. "
        "Limits, does not stop: the result says what could not be learned",
        noise_learning,
        stops=False,
    ),
    CARRIER_CONTINUITY: Precondition(
        f"a receiver with rates of {MIN_DIFFERENCED_SATELLITES} or more satellites at {MIN_DIFFERENCED_EPOCHS} "
        f"or more epochs: a carrier phase continued from the epoch before (at most {MAX_CARRIER_INTERVAL_S:g} s "
        "earlier), or a Doppler; the scales are learned from them",
        carrier_continuity,
    ),
    PSEUDORANGE_ARCS: Precondition(
        f"a receiver with pseudorange changes of {MIN_DIFFERENCED_SATELLITES} or more satellites at "
        f"{MIN_DIFFERENCED_EPOCHS} or more epochs (the same satellite at the epoch before, at most "
        f"{MAX_PSEUDORANGE_INTERVAL_S:g} s earlier): the noise scale and the Kalman prediction are learned "
        "from them",
        pseudorange_arcs,
    ),
    INDEPENDENT_REFERENCE: Precondition(
        "where the receiver was, known without its GNSS: an IMU that meets strapdown_imu, or a known static "
        "station (`--station`, or a RINEX header position that the receiver's fixes of its first 5 minutes stay "
        "at and start within 100 m of)",
        independent_reference,
    ),
    INDEPENDENT_RECEIVERS: Precondition(
        "two receivers with independent errors: not NMEA talkers of one receiver (GP, GL, GN... of one "
        "stream), nor one receiver relayed twice (the same fixes, after rounding to the coarser resolution, "
        "at 90% of common epochs at a constant delay, zero included)",
        independent_receivers,
    ),
    SURVEYED_SITES: Precondition(
        "two independent receivers each at a known static station (RINEX header positions, checked as for "
        "independent_reference): the baseline vector is then known",
        surveyed_sites,
    ),
    ORBIT_TIMING: Precondition(
        "a receiver whose pseudoranges fit the broadcast orbits at their logged times: not a time offset of "
        f"{_TAGS.min_offset_s:g} s or more that its epochs agree on (interquartile range within "
        f"{_TAGS.max_relative_spread:.0%} of it, over {_TAGS.min_epochs} or more epochs with a redundant satellite) "
        f"and that shrinks the residuals {_TAGS.min_improvement:g} times or more (`spooflens.gnss.time_tags`); "
        "a receiver that fails it is left out",
        orbit_timing,
    ),
}
