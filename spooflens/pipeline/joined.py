"""One result per detector from an analysis run on each navigated stretch of a log (its IMU stopped, and
the navigation ran anew between the gaps: `spooflens.navigation.segments`).

Statistics, curves over time and tracks run end to end with a NaN sample between two stretches: nothing
was computed there, and a drawn line breaks instead of pretending the stretches were one. Alarms and
findings are every stretch's; facts the stretches agree on are given once, the others per stretch
(`navigated_spans`); the reason and what limited each stretch are said with its span.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from spooflens.detectors.base import Curve, DetectorResult, Series, Track

FloatArray = NDArray[np.float64]
Span = tuple[float, float]  # a navigated stretch, s
NAVIGATED_SPANS = "navigated_spans"  # the fact listing the stretches, each with the facts it alone has
_T = TypeVar("_T", Series, Curve, Track)


def spanned(span: Span) -> str:
    return f"{span[0]:.1f}-{span[1]:.1f} s"


def joined(parts: Sequence[tuple[Span, Sequence[DetectorResult]]]) -> list[DetectorResult]:
    """Each detector's results of the stretches (in time order) as one result, in the order they came."""
    names = dict.fromkeys(r.name for _, results in parts for r in results)
    return [_joined([(span, r) for span, results in parts for r in results if r.name == name]) for name in names]


def _joined(parts: list[tuple[Span, DetectorResult]]) -> DetectorResult:
    first = parts[0][1]
    ran = [(span, r) for span, r in parts if r.ran]
    limitations = [replace(u, found=f"{spanned(span)}: {u.found}") for span, r in ran for u in r.limitations]
    if not ran:
        return replace(first, reason=_reasons(parts, ()), limitations=limitations)
    # a stretch where the model did not fit (MODEL MISMATCH) keeps its alarms out when another stretch counts
    counted = [(span, r) for span, r in ran if not r.advisory] or ran
    left_out = tuple(span for span, r in ran if r.advisory) if len(counted) < len(ran) else ()
    return DetectorResult(
        name=first.name,
        ran=True,
        reason=_reasons(parts, left_out),
        alarms=sorted((a for _, r in counted for a in r.alarms), key=lambda a: a.start_s),
        series=_end_to_end([r.series for _, r in ran], _series),
        curves=_end_to_end([r.curves for _, r in ran], _curve),
        tracks=_end_to_end([r.tracks for _, r in ran], _track),
        extras=_extras(ran),
        advisory=len(counted) == len(ran) and all(r.advisory for _, r in ran),
        evidence=first.evidence,
        findings=[f for _, r in ran for f in r.findings],
        histograms=[h for _, r in ran for h in r.histograms],
        limitations=limitations,
    )


def _reasons(parts: list[tuple[Span, DetectorResult]], left_out: tuple[Span, ...]) -> str:
    said = []
    for span, r in parts:
        text = r.reason if r.ran else f"not run: {r.reason}"
        if span in left_out:
            text += " (its alarms left out: another stretch's count)"
        said.append(f"on {spanned(span)}: {text}")
    return "; ".join(said)


def _end_to_end(per_part: list[list[_T]], join: Callable[[list[_T]], _T]) -> list[_T]:
    """Items of the same name from every stretch, joined end to end; in the order they first came."""
    names = dict.fromkeys(x.name for items in per_part for x in items)
    return [join([x for items in per_part for x in items if x.name == name]) for name in names]


def _with_breaks(t: list[FloatArray], values: list[FloatArray]) -> tuple[FloatArray, FloatArray]:
    """Pieces end to end, a NaN row between two at the middle of the time between them."""
    ts: list[FloatArray] = []
    vs: list[FloatArray] = []
    for k, (tk, vk) in enumerate(zip(t, values, strict=True)):
        tk, vk = np.asarray(tk, dtype=float), np.asarray(vk, dtype=float)
        if k and len(ts[-1]) and len(tk):
            ts.append(np.array([0.5 * (ts[-1][-1] + tk[0])]))
            vs.append(np.full((1, *vk.shape[1:]), np.nan))
        ts.append(tk)
        vs.append(vk)
    return np.concatenate(ts), np.concatenate(vs)


def _series(pieces: list[Series]) -> Series:
    t, v = _with_breaks([p.t for p in pieces], [p.values for p in pieces])
    return replace(pieces[0], t=t, values=v)


def _curve(pieces: list[Curve]) -> Curve:
    x, y = _with_breaks([p.x for p in pieces], [p.y for p in pieces])
    return replace(pieces[0], x=x, y=y)


def _track(pieces: list[Track]) -> Track:
    llh = [np.c_[p.lat_deg, p.lon_deg, p.height_m] for p in pieces]
    t, v = _with_breaks([p.t for p in pieces], llh)
    return replace(pieces[0], t=t, lat_deg=v[:, 0], lon_deg=v[:, 1], height_m=v[:, 2])


def _extras(ran: list[tuple[Span, DetectorResult]]) -> dict[str, object]:
    """The facts every stretch states alike once; per stretch, those that differ or it alone states."""
    keys = dict.fromkeys(k for _, r in ran for k in r.extras)
    alike = {
        k: ran[0][1].extras[k]
        for k in keys
        if all(k in r.extras and _same(r.extras[k], ran[0][1].extras[k]) for _, r in ran)
    }
    spans = [
        {"from_s": span[0], "to_s": span[1], **{k: v for k, v in r.extras.items() if k not in alike}} for span, r in ran
    ]
    return {**alike, NAVIGATED_SPANS: spans}


def _same(a: object, b: object) -> bool:
    try:
        return bool(a == b)
    except ValueError:  # arrays: ambiguous truth
        return False
