"""Where the navigation runs on a log whose IMU stopped: the stretches between the IMU's gaps, and which
of them are long enough to navigate.

Strapdown integrates each IMU sample over the interval to the next: across a gap longer than the
`strapdown_imu` precondition allows (`MAX_IMU_GAP_S`) the rotation and the acceleration in it are lost,
and a filter carried across would alarm on the attitude it lost, not on GNSS. So the navigation is never
carried over a gap: after one it starts again, aligned and its noise learned anew, as on a log of its own
(`spooflens.pipeline.registry.navigation_parts` runs it, and every analysis on it, once per stretch).

A stretch is navigated when its fixes are enough for the noise learning to learn from
(`LearnOptions.enough`: 50 fixes over 30 s after the filter's first 20 s, so 50 s at least), which also
covers the alignment (20 s of fixes when it matches velocities) and the 20 s the inertial tests wait for
the filter to settle. A whole log shorter than that is still navigated on the noise prior, since nothing
better can be had from it, and says so (`noise_learning`); a stretch of a longer log is not: a filter on
the preset noise beside filters on the log's own would alarm on its own misfit, for seconds of coverage.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spooflens.navigation.noise_learning import LearnOptions

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ImuSpan:
    """A stretch of the IMU's time span: navigated, or not and why (a gap, or too short)."""

    start_s: float
    end_s: float
    navigated: bool
    why: str = ""

    def describe(self) -> str:
        return f"{self.start_s:.1f}-{self.end_s:.1f} s" + (f" ({self.why})" if self.why else "")


def imu_spans(
    t_imu: FloatArray, t_fix: FloatArray, max_gap_s: float, learn: LearnOptions | None = None
) -> tuple[ImuSpan, ...]:
    """The IMU's span from its first sample to its last, cut at every gap longer than `max_gap_s`: each
    gap not navigated, each stretch between gaps navigated when the fixes (`t_fix`) inside it are enough
    to learn the noise from."""
    learn = learn or LearnOptions()
    t = np.asarray(t_imu, dtype=float)
    tf = np.asarray(t_fix, dtype=float)
    if not len(t):
        return ()
    cuts = np.flatnonzero(np.diff(t) > max_gap_s)
    firsts, lasts = np.r_[0, cuts + 1], np.r_[cuts, len(t) - 1]
    out: list[ImuSpan] = []
    for k, (i, j) in enumerate(zip(firsts, lasts, strict=True)):
        a, b = float(t[i]), float(t[j])
        if k:
            before = float(t[lasts[k - 1]])
            out.append(ImuSpan(before, a, False, f"the IMU stopped for {a - before:.2f} s"))
        inside = tf[(tf >= a) & (tf <= b)]
        if learn.enough(inside):
            out.append(ImuSpan(a, b, True))
            continue
        fixes_s = float(inside[-1] - inside[0]) if len(inside) >= 2 else 0.0
        out.append(
            ImuSpan(
                a,
                b,
                False,
                f"{len(inside)} fixes over {fixes_s:.0f} s with the IMU: too few to align and learn the noise from "
                f"({learn.min_scored_epochs} over {learn.min_scored_s:g} s after the filter's first "
                f"{learn.settle_s:g} s needed)",
            )
        )
    return tuple(out)
