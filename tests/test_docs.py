"""docs/detectors.md is what the detectors declare: a fresh generation equals the committed file."""

from __future__ import annotations

import re

from spooflens.docs import DETECTORS_MD, main, render_detectors
from spooflens.pipeline.registry import detector_infos


def test_the_committed_detectors_page_is_a_fresh_generation() -> None:
    assert DETECTORS_MD.read_text() == render_detectors(), "run `python -m spooflens.docs` and commit docs/detectors.md"
    assert main(["--check"]) == 0


def test_every_detector_declares_what_it_tests_and_how() -> None:
    for name, info in detector_infos().items():
        assert info.summary and info.method, name
        if info.evidence is not None:  # a detector, not an analysis product
            assert info.threshold and info.p_false_alarm, name


def test_no_detector_text_shows_a_placeholder_left_unformatted() -> None:
    # a line of a method text without its f-prefix printed `{_O.min_satellites}` into the page
    for name, info in detector_infos().items():
        for text in (info.summary, info.method, info.threshold, info.p_false_alarm):
            assert not re.search(r"\{_?[A-Za-z][\w.]*(![rs])?(:[^{}]*)?\}", text or ""), (name, text)
