"""Do a receiver's pseudoranges fit the broadcast orbits at the times its log gives them?

Every reader puts each satellite where it was when the signal left (`states_at_transmission`: the epoch's
time tag less the pseudorange's flight time). If the tags are off the time the signals were measured at by
`offset` seconds, every satellite is put where it was `offset` seconds away from where it was, and each
pseudorange misses its prediction by that satellite's own range rate times the offset: up to 800 m per
second of offset, different for every satellite, which no position or clock can absorb. A single-point
solution is then kilometres off and its residuals hundreds of times their a-priori size; RAIM's test of one
satellite against the others means nothing there, since every satellite is wrong.

The residuals are the range rates times the offset, so each epoch with a redundant satellite gives one
estimate once its own position and clocks are projected out. A true time fault gives the same offset at
every epoch and leaves residuals at their a-priori size once applied; one satellite off (a counterfeit, a
reflection) gives offsets that change with the geometry from epoch to epoch and explains little. Both are
asked of the offsets before the tags are called off (`TimeTagOptions`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.gnss.ephemeris import GM_GPS, OMEGA_E_GPS
from spooflens.gnss.fault_exclusion import residual_design
from spooflens.gnss.geometry import expected_range_rate
from spooflens.gnss.single_point import SV_COLUMNS, SV_VEL_COLUMNS, SinglePointOptions, SinglePointSolution, solve

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class TimeTagOptions:
    # a tag 10 ms off moves a pseudorange by 8 m at most, within a receiver's own noise; clean receivers'
    # offsets were within 4 ms of zero (the GSI stations, phones), a time fault is a second or more
    min_offset_s: float = 0.05
    # the epochs' offsets agree when their interquartile range is within this fraction of their median
    max_relative_spread: float = 0.2
    # and moving the tags shrinks the residuals' typical size this many times
    min_improvement: float = 3.0
    min_epochs: int = 20  # epochs with a redundant satellite and the range rates not all alike


@dataclass(frozen=True)
class TimeTagFit:
    """How far a receiver's time tags are from the time its pseudoranges fit the orbits at."""

    offset_s: float  # median over epochs: the pseudoranges fit the orbits this much after the tags
    spread_s: float  # interquartile range of the epochs' offsets
    epochs: int  # epochs that gave an offset
    scale_logged: float  # typical weighted residual (x the a-priori sigma) at the logged times
    scale_moved: float  # the same with every epoch's tag moved by `offset_s`

    def tags_off(self, opts: TimeTagOptions | None = None) -> bool:
        """The tags are off: a large offset, the same at every epoch, that explains the residuals."""
        o = opts or TimeTagOptions()
        return (
            self.epochs >= o.min_epochs
            and abs(self.offset_s) >= o.min_offset_s
            and self.spread_s <= o.max_relative_spread * abs(self.offset_s)
            and self.scale_logged >= o.min_improvement * self.scale_moved
        )

    def describe(self) -> str:
        """'its pseudoranges fit the broadcast orbits 2.98 s after the logged times, not at them (residuals 683 x
        a-priori at the logged times, 0.47 x with the tags moved; 320 epochs)'."""
        when = "after" if self.offset_s > 0 else "before"
        return (
            f"its pseudoranges fit the broadcast orbits {abs(self.offset_s):.3g} s {when} the logged times, not at "
            f"them (residuals {self.scale_logged:.3g} x a-priori at the logged times, {self.scale_moved:.2g} x with "
            f"the tags moved; {self.epochs} epochs)"
        )


def satellite_acceleration(pos: FloatArray, vel: FloatArray) -> FloatArray:
    """A satellite's acceleration in the Earth-fixed frame its position and velocity are given in (m/s^2):
    the central gravity with the rotating frame's Coriolis and centrifugal terms (J2 is 1e-4 of it)."""
    w = OMEGA_E_GPS
    frame = np.stack(
        [2 * w * vel[:, 1] + w**2 * pos[:, 0], -2 * w * vel[:, 0] + w**2 * pos[:, 1], np.zeros(len(pos))], 1
    )
    return -GM_GPS * pos / np.linalg.norm(pos, axis=1, keepdims=True) ** 3 + frame


def range_rates(obs: pd.DataFrame, sol: SinglePointSolution) -> FloatArray:
    """How fast each row's predicted pseudorange changes with the time its satellite is taken at (m/s): the
    satellite's velocity along the line of sight and its clock drift, the receiver held where it is."""
    rx = sol.ecef_m[sol.row_epoch]
    return expected_range_rate(
        obs[SV_COLUMNS].to_numpy(float),
        obs[SV_VEL_COLUMNS].to_numpy(float),
        obs["sv_clock_drift_mps"].to_numpy(float),
        rx,
        np.zeros_like(rx),
        np.zeros(len(obs)),
    )


def moved_satellites(obs: pd.DataFrame, offset_s: float) -> pd.DataFrame:
    """`obs` with every satellite taken `offset_s` later (position and velocity to second order in the
    offset, clock to first: a metre at ten seconds, millimetres at three)."""
    pos = obs[SV_COLUMNS].to_numpy(float)
    vel = obs[SV_VEL_COLUMNS].to_numpy(float)
    acc = satellite_acceleration(pos, vel)
    out = obs.copy()
    out[SV_COLUMNS] = pos + vel * offset_s + acc * offset_s**2 / 2
    out[SV_VEL_COLUMNS] = vel + acc * offset_s
    drift = obs["sv_clock_drift_mps"].to_numpy(float)
    out["sv_clock_bias_m"] = obs["sv_clock_bias_m"].to_numpy(float) + drift * offset_s
    return out


@dataclass(frozen=True)
class EpochSums:
    """Per epoch with a redundant satellite: weighted products of the range rates (g) and the residuals (r)
    with the epoch's position and clocks projected out, and its degrees of freedom."""

    gg: FloatArray
    gr: FloatArray
    rr: FloatArray
    dof: NDArray[np.int64]

    @property
    def offset_s(self) -> FloatArray:
        """The time offset that best explains each epoch's residuals."""
        return self.gr / self.gg

    def scale2(self, offset_s: float) -> FloatArray:
        """Each epoch's squared residual scale with its satellites taken `offset_s` later."""
        return np.maximum(self.rr - 2 * offset_s * self.gr + offset_s**2 * self.gg, 0.0) / self.dof


def epoch_sums(obs: pd.DataFrame, sol: SinglePointSolution, options: SinglePointOptions | None = None) -> EpochSums:
    """`EpochSums` of one receiver's rows at its single-point solution `sol`."""
    opts = options or SinglePointOptions()
    epoch, slot, H, W, r = residual_design(obs, sol, opts, np.isfinite(sol.residual_m))
    rate = range_rates(obs, sol)
    G = np.zeros_like(W)
    on = (W[epoch, slot] > 0) & np.isfinite(rate)
    G[epoch[on], slot[on]] = rate[on]
    W = np.where(G != 0, W, 0.0)  # a row without a range rate says nothing of the offset
    used = W > 0
    systems_seen = np.count_nonzero(np.any((H[:, :, 3:] != 0) & used[..., None], axis=1), axis=1)
    dof = np.count_nonzero(used, axis=1) - 3 - systems_seen
    keep = dof >= 1
    H, W, r, G, dof = H[keep], W[keep], r[keep], G[keep], dof[keep]
    WH = W[..., None] * H
    # an epoch without a satellite of some system has an empty clock column: the pseudo-inverse leaves it out
    N_inv = np.linalg.pinv(np.einsum("eki,ekj->eij", WH, H))

    def projected(x: FloatArray, y: FloatArray) -> FloatArray:
        """x' (W - W H N^-1 H' W) y, per epoch."""
        hx, hy = np.einsum("ek,eki->ei", x, WH), np.einsum("ek,eki->ei", y, WH)
        return np.einsum("ek,ek,ek->e", x, W, y) - np.einsum("ei,eij,ej->e", hx, N_inv, hy)

    gg, gr, rr = projected(G, G), projected(G, r), projected(r, r)
    # an epoch whose range rates its position and clock columns already span cannot see an offset
    seen = gg > 1e-6 * np.einsum("ek,ek,ek->e", G, W, G)
    return EpochSums(gg[seen], gr[seen], rr[seen], dof[seen].astype(np.int64))


def time_tag_fit(
    obs: pd.DataFrame,
    t_gps_s: FloatArray | None = None,
    options: SinglePointOptions | None = None,
    tag_options: TimeTagOptions | None = None,
) -> TimeTagFit | None:
    """The time offset at which `obs` (one receiver's rows, with satellite states; `solve`'s arguments) fit the
    orbits; None without an epoch that shows one.

    The solution at the logged times is kilometres off when the tags are: its own nonlinearity (and the line
    of sight from the wrong place) leaves a few per cent of the offset unseen, so an offset worth a verdict
    is refined: the satellites moved by it, the rest found from a second solution at their new places."""
    sums = epoch_sums(obs, solve(obs, t_gps_s, options), options)
    if not len(sums.dof):
        return None
    logged = float(np.sqrt(np.median(sums.scale2(0.0))))
    # the median epoch, not the mean: a satellite off by a whole code period at a few epochs weighs nothing
    offset = float(np.median(sums.offset_s))
    left = offset  # what remains to move the satellites of `sums` by
    if abs(offset) >= (tag_options or TimeTagOptions()).min_offset_s / 2:
        moved = moved_satellites(obs, offset)
        sums = epoch_sums(moved, solve(moved, t_gps_s, options), options)
        if not len(sums.dof):
            return None
        left = float(np.median(sums.offset_s))
        offset += left
    q1, q3 = np.percentile(sums.offset_s, [25, 75])
    return TimeTagFit(
        offset_s=offset,
        spread_s=float(q3 - q1),
        epochs=len(sums.dof),
        scale_logged=logged,
        scale_moved=float(np.sqrt(np.median(sums.scale2(left)))),
    )
