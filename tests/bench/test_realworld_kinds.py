"""The realworld bench's confusion table of event kinds: what the verdict named over each attack."""

from __future__ import annotations

from types import SimpleNamespace

from spooflens.bench.realworld_bench import called_kind, kinds_called
from spooflens.pipeline.verdict import Kind


def _analysis(*events: tuple[Kind, float, float]) -> SimpleNamespace:
    return SimpleNamespace(
        verdict=SimpleNamespace(events=[SimpleNamespace(kind=k, start_s=a, end_s=b) for k, a, b in events])
    )


def test_the_most_serious_kind_over_the_attack_is_the_one_named() -> None:
    analysis = _analysis((Kind.DEGRADATION, 90.0, 120.0), (Kind.JAMMING, 100.0, 130.0), (Kind.SPOOFING, 131.0, 200.0))
    assert called_kind(analysis, 100.0, 130.0) == "spoofing"  # a spoofing alarm within 5 s after still counts
    assert called_kind(analysis, 100.0, 130.0, late_s=-1.0) == "jamming"  # the jamming phase alone
    assert called_kind(analysis, 10.0, 20.0) == "nothing"


def test_each_attack_and_each_phase_of_jam_then_capture_gets_a_row_of_shares() -> None:
    runs = [
        {"attack": "jam 15 dB", "called": "jamming"},
        {"attack": "jam 15 dB", "called": "spoofing"},
        {"attack": "jam then capture", "called": "jamming", "called_capture": "spoofing"},
        {"attack": "capture", "called": "nothing"},
    ]
    table = kinds_called(runs)
    assert table["jam 15 dB"]["jamming"] == 0.5 and table["jam 15 dB"]["spoofing"] == 0.5
    assert table["jam then capture: the jamming"]["jamming"] == 1.0
    assert table["jam then capture: the capture"]["spoofing"] == 1.0
    assert table["capture"]["nothing"] == 1.0 and table["capture"]["runs"] == 1.0
