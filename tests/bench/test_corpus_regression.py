"""A fixed sample of the real-log corpus (`../shared/real`), one or more logs of each format, analysed as
`spooflens bench corpus --quick` analyses them, against the verdicts they should get
(`corpus_expected.tsv` beside this file): a clean log is read (with or without damage) and not spoofed;
a log no reader can take is refused, saying why.

Only logs on which today's code already meets its expectation are listed; the others (false SPOOFING
verdicts, internal errors, wrong refusals) join as they are fixed. `spooflens bench corpus` runs all.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import pytest
from paths import REAL

from spooflens.bench.corpus_bench import LogResult, run_corpus
from spooflens.bench.corpus_runs import DAMAGED, READ, REFUSED, spoofed

EXPECTED = Path(__file__).with_name("corpus_expected.tsv")


@dataclass(frozen=True)
class Expected:
    path: str  # relative to ../shared/real
    outcome: str  # "read" (exit 0 or 3) or "refused"
    reason: str  # for "refused": a part of the one-line reason
    spoofed: bool | None  # for "read"


def expectations(path: Path = EXPECTED) -> list[Expected]:
    with path.open(newline="") as f:
        rows = [r for r in csv.DictReader(f, delimiter="\t") if not r["path"].startswith("#")]
    out = []
    for r in rows:
        outcome, _, reason = r["expected"].partition(":")
        spoofed_text = r["spoofed"].strip().lower()
        out.append(
            Expected(
                r["path"], outcome.strip(), reason.strip(), None if spoofed_text == "-" else spoofed_text == "true"
            )
        )
    return out


def mismatch(e: Expected, r: LogResult) -> str | None:
    """What is wrong with one log's clean run, None when it meets its expectation."""
    run = r.clean.analysis if r.clean else None
    if run is None:
        return f"{e.path}: not run"
    if e.outcome == REFUSED:
        if run.outcome != REFUSED or e.reason not in run.error:
            return f"{e.path}: expected refused ({e.reason!r}), got {run.outcome}: {run.error}"
        return None
    if run.outcome not in (READ, DAMAGED) or r.summary is None:
        return f"{e.path}: expected read, got {run.outcome}: {run.error}"
    if e.spoofed is not None and spoofed(r.summary) != e.spoofed:
        headline = (r.summary.get("verdict") or {}).get("headline")
        return f"{e.path}: expected {'SPOOFING' if e.spoofed else 'NO SPOOFING'}, got {headline}"
    return None


def test_the_expectations_cover_every_format_and_both_outcomes() -> None:
    rows = expectations()
    assert len({r.path for r in rows}) == len(rows) >= 15
    assert {r.outcome for r in rows} == {"read", "refused"} and all(r.reason for r in rows if r.outcome == "refused")


def test_the_corpus_sample_gets_the_verdicts_it_should(monkeypatch: pytest.MonkeyPatch) -> None:
    if not REAL.is_dir():
        pytest.fail(f"real logs missing: {REAL} (tests expect ../shared/real beside the checkout)")
    monkeypatch.setenv("SPOOFLENS_THREADS", "1")  # two commands at a time on two cores
    rows = expectations()
    report = run_corpus([REAL], jobs=2, quick=True, only=tuple(r.path for r in rows))
    by_name = {r.log.name: r for r in report.results}
    missing = [r.path for r in rows if r.path not in by_name]
    assert not missing, f"not found as logs under {REAL}: {missing}"
    wrong = [m for e in rows if (m := mismatch(e, by_name[e.path])) is not None]
    assert not wrong, "\n".join(wrong)
