"""The report's figures stay readable and quick with hundreds of incidents (a real boat's log had 196
anomalies: a patch and a label each took 21 s to draw and collapsed the track's axes under its legend)."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.collections import LineCollection, PolyCollection

from spooflens.output.report import figures
from spooflens.pipeline.verdict import Incident


def _incident(k: int) -> Incident:
    """An anomaly (one evidence class: not spoofing) from 10 k s to 10 k + 4 s."""
    t = 10.0 * k
    return Incident(t + 1.0, t + 4.0, t, None, ("x",), "low")


def test_bands_and_lines_are_one_collection_per_colour_and_widen_x_as_axvspan_did() -> None:
    _fig, (ax,) = figures._figure(1)
    ax.plot([0.0, 10.0], [0.0, 1.0])
    incidents = [_incident(k) for k in range(200)]
    figures._shade_incidents(ax, incidents, label_them=True)
    polys = [c for c in ax.collections if isinstance(c, PolyCollection)]
    lines = [c for c in ax.collections if isinstance(c, LineCollection)]
    assert len(polys) == 1 and len(polys[0].get_paths()) == 200
    assert len(lines) == 1 and len(lines[0].get_segments()) == 200
    assert not ax.patches and len(ax.lines) == 1
    lo, hi = ax.get_xlim()
    assert lo <= 0.0 and hi >= incidents[-1].end_s  # the last band is inside the view, as with axvspan
    assert ax.get_ylim()[1] < 2.0  # the bands span the height in axes units, not y data


def test_a_few_incidents_are_labelled_and_many_are_not(monkeypatch: pytest.MonkeyPatch) -> None:
    t = np.linspace(0.0, 2000.0, 2001)
    xy = np.column_stack([t, np.sin(t / 100.0)])
    for n, labelled in ((3, True), (figures.MAX_LABELLED + 1, False), (200, False)):
        _fig, (ax,) = figures._figure(1)
        incidents = [_incident(k) for k in range(n)]
        figures._during_incidents(ax, "GP", t, xy, incidents)
        figures._onsets_and_ends(ax, [(t, xy, "GP")], incidents)
        names = [str(line.get_label()) for line in ax.lines if not str(line.get_label()).startswith("_")]
        if labelled:
            assert len(names) == n and len(ax.texts) == 2 * n
        else:
            assert names == [f"GP during the {n} anomalies"] and not ax.texts
            assert len(ax.lines) == 3  # the track inside them, and the onsets' and ends' markers
