"""`spooflens bench corpus [DIR ...]`: is spooflens right on real logs nobody tuned it for?

Every log of a real-log corpus (default `../shared/real` beside the repository: its `corpus/` with
`MANIFEST.tsv`, and the folders beside it; `corpus_logs.discover`) goes through two passes, each
command in a process of its own with a time limit (`corpus_runs`):

- the clean pass: `spooflens analyze LOG --json`. Each log is read, read with damage (exit 3), refused
  with its one-line reason (exit 2), an internal error (exit 1, a traceback, a crash) or a timeout. A
  SPOOFING verdict on a log of the clean sky (none of the manifest's not-clean tags) is a false
  accusation: the failure this bench is for.
- the injected pass (not with `--quick`): a standard battery, each attack written into a copy by
  `spooflens inject` from a point in the middle third of the attacked data to the log's end, and the
  copy analysed. Only logs whose clean verdict is NO SPOOFING can show a catch, and only formats that
  `inject` can write back (`ReaderFormat.rewrite`).

Printed: tables by format, vehicle and tag; every false SPOOFING verdict with its incidents; every
internal error, timeout and refusal; every miss of the battery with its reason; what was not run and why.
`--json FILE` keeps everything per log. Analysis logic stays out of here: this module only drives the
CLI and reads the JSON summaries.
"""

from __future__ import annotations

import fnmatch
import hashlib
import json
import os
import re
import statistics
import time
from collections import Counter
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import click
from rich.table import Table

from spooflens.bench.corpus_logs import Corpus, CorpusLog, NotLog, discover, reader_format
from spooflens.bench.corpus_runs import (
    INTERNAL,
    OUTCOMES,
    READ,
    REFUSED,
    SANDBOXES,
    TIMEOUT,
    LogFacts,
    Score,
    Task,
    TaskRecord,
    hours,
    incidents,
    is_spoofing,
    log_facts,
    run_task,
    score,
    segments,
    spoofed,
    verdict_extras,
)
from spooflens.bench.fuzz import REAL_LOGS
from spooflens.bench.realworld_bench import ATTACKS
from spooflens.bench.sandbox import Limits
from spooflens.detectors.raim import NAME as RAIM
from spooflens.detectors.system_agreement import NAME as SYSTEM_AGREEMENT
from spooflens.output.console import console, err_console, progress, show_progress

DEFAULT_TIMEOUT_S = 120.0
DEFAULT_RSS_CAP_MB = 6144.0
# an attack needs this much of the attacked stream: a third before it, two thirds under attack
MIN_ATTACKED_SPAN_S = 30.0
# an attack that reaches fewer of the copy's epochs than this is too short to judge: the alarms' persistence
# (RAIM's 5 consecutive epochs, the other detectors' 3 to 5) cannot be met however clear the attack
MIN_ATTACKED_EPOCHS = 5


@dataclass(frozen=True)
class AttackKind:
    name: str
    text: str  # `inject --attack` without its start
    needs: str  # a key of NEEDS
    # the independent references that see this attack: a log whose clean analysis ran none of them can
    # show the attack only as GNSS-only or receiver evidence, which alone is never a spoofing verdict
    seen_by: frozenset[str] = frozenset()
    # where only some detectors of a class can see it: those detectors, by name (a satellite below the
    # horizon test shares RAIM's class but cannot see a delayed satellite)
    seen_by_analyses: frozenset[str] = frozenset()

    def seen_in(self, facts: LogFacts) -> bool:
        """The log's clean analysis ran a reference that sees this attack."""
        if self.seen_by_analyses:
            return bool(facts.analyses_run & self.seen_by_analyses)
        return bool(facts.classes_run & self.seen_by)


# what each attack needs of a log, and how to tell from its clean analysis
NEEDS: dict[str, Callable[[LogFacts], bool]] = {
    "fixes": lambda f: bool(f.fix_receivers or f.observation_receivers),
    "logged fixes": lambda f: bool(f.logged_fix_receivers),
    "raw observations": lambda f: bool(f.observation_receivers),
    "two receivers with fixes": lambda f: len(f.logged_fix_receivers) >= 2,
}
# the battery: the fix-level kinds as `bench realworld` runs them, one counterfeit satellite where the
# log has raw observations, a single-antenna spoofer where two receivers logged fixes
# the references a spoofer of the fixes cannot move and that compare the fixes with something
FIX_REFERENCES = frozenset({"inertial", "second_receiver", "known_station", "heading"})
BATTERY: tuple[AttackKind, ...] = (
    AttackKind("ramp 2 m/s", ATTACKS["ramp 2 m/s"], "fixes", FIX_REFERENCES),
    AttackKind("step 50 m", ATTACKS["step 50 m"], "fixes", FIX_REFERENCES),
    AttackKind("capture", ATTACKS["capture"], "logged fixes", FIX_REFERENCES),
    AttackKind(
        "counterfeit satellite",
        "pr_delay:count=1,delay=300,cn0=6",
        "raw observations",
        frozenset({"raw_measurement"}),
        frozenset({RAIM, SYSTEM_AGREEMENT}),
    ),
    AttackKind("single antenna", "single_antenna:rate=1", "two receivers with fixes", frozenset({"second_receiver"})),
)
KINDS = {k.name: k for k in BATTERY}


@dataclass
class Injected:
    """An attack `inject` wrote into a copy of the log (or failed to, by an internal error or timeout)."""

    kind: str
    record: TaskRecord
    score: Score | None = None  # None when the copy was not made or not analysed
    # the log carries a reference that sees this attack (`AttackKind.seen_by`): the goal's denominator
    with_reference: bool = True

    @property
    def made(self) -> bool:
        return self.record.inject is not None and self.record.inject.outcome == READ


@dataclass
class LogResult:
    log: CorpusLog
    clean: TaskRecord | None = None
    injected: list[Injected] = field(default_factory=list)
    not_attacked: str | None = None  # why no attack was run on this log at all
    not_injected: dict[str, str] = field(default_factory=dict)  # attack -> why it was not run

    @property
    def outcome(self) -> str:
        return self.clean.analysis.outcome if self.clean and self.clean.analysis else "not run"

    @property
    def summary(self) -> dict[str, Any] | None:
        return self.clean.summary if self.clean else None


def default_root() -> Path:
    """`../shared/real` beside the repository, else beside the current folder."""
    for candidate in (REAL_LOGS, Path.cwd().parent / "shared" / "real", Path.cwd() / "shared" / "real"):
        if candidate.is_dir():
            return candidate.resolve()
    return REAL_LOGS


def log_bytes(path: Path) -> int:
    from spooflens.batch import log_size

    return log_size(path)


def companions_of(log: CorpusLog) -> tuple[str, ...]:
    """The navigation (and other companion) files beside a single-file log, which a copy needs too."""
    from readers import is_companion

    if not log.path.is_file():
        return ()
    out = []
    for p in sorted(log.path.parent.iterdir()):
        fmt = reader_format(p) if p.is_file() and p != log.path else None
        if fmt is not None and is_companion(p, fmt):
            out.append(str(p))
    return tuple(out)


def attack_start(name: str, kind: str, span: tuple[float, float]) -> float:
    """A start in the middle third of `span`, the same for the same log and attack on every run."""
    digest = hashlib.sha256(f"{name}|{kind}".encode()).digest()
    u = int.from_bytes(digest[:8], "big") / 2**64
    first, last = span
    return round(first + (last - first) * (1.0 + u) / 3.0, 1)


def plan_attacks(result: LogResult, limits: Limits, min_span_s: float) -> list[Task]:
    """The battery's tasks for one log; why the log takes none (`result.not_attacked`), or each attack
    it cannot take and why (`result.not_injected`)."""
    log, summary = result.log, result.summary
    result.not_attacked = _why_not_injectable(result)
    if result.not_attacked is not None or summary is None:
        return []
    facts = log_facts(summary)
    tasks = []
    for kind in BATTERY:
        if not NEEDS[kind.needs](facts):
            result.not_injected[kind.name] = f"needs {kind.needs}"
            continue
        span = facts.observation_span_s if kind.needs == "raw observations" else facts.fix_span_s
        span = span or facts.observation_span_s
        if span is None or span[1] - span[0] < min_span_s:
            # the length itself is in the clean run's streams; the reason stays the same for every log
            result.not_injected[kind.name] = f"its data spans less than {min_span_s:g} s"
            continue
        start = attack_start(log.name, kind.name, span)
        tasks.append(Task(str(log.path), log.name, limits, kind.name, kind.text, start, companions_of(log)))
    return tasks


def _why_not_injectable(result: LogResult) -> str | None:
    """Why no attack of the battery is run on this log at all, None when some may be."""
    from readers import formats

    if result.summary is None:
        return f"clean pass: {result.outcome}"
    if spoofed(result.summary):
        return "clean verdict already SPOOFING: a catch cannot be shown"
    reader = result.log.reader
    if reader is None or formats()[reader].rewrite is None:
        return f"not injectable: {reader or result.log.format}"
    recordings = log_facts(result.summary).recordings
    if recordings > 1:
        return f"the log joins {recordings} recordings: attack times would be ambiguous"
    return None


# ---- running tasks --------------------------------------------------------------------------------------


def run_tasks(tasks: list[Task], jobs: int, scheduler: str | None, what: str, show: bool) -> list[TaskRecord]:
    """Every task, the largest logs first so that the last to finish are short; `jobs` at a time here
    (each command a process of its own), or on the dask cluster at `scheduler`."""
    ordered = sorted(tasks, key=lambda t: log_bytes(Path(t.log)), reverse=True)
    if not ordered:
        return []
    with progress(show) as report:
        report(what, 0, len(ordered))
        results = _on_dask(ordered, scheduler, what, report) if scheduler else _on_threads(ordered, jobs, what, report)
    return results


def _on_threads(tasks: list[Task], jobs: int, what: str, report: Callable[[str, int, int], None]) -> list[TaskRecord]:
    """Threads suffice: each only waits on its command's process."""
    out = []
    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        futures = [pool.submit(run_task, t) for t in tasks]
        for n, future in enumerate(as_completed(futures), start=1):
            out.append(future.result())
            report(what, n, len(tasks))
            _note_progress(what, n, len(tasks))
    return out


def _on_dask(
    tasks: list[Task], scheduler: str | None, what: str, report: Callable[[str, int, int], None]
) -> list[TaskRecord]:
    """On a running dask cluster, as `spooflens batch --scheduler` does: its workers need spooflens and
    must see the logs at the same paths."""
    from dask.distributed import Client
    from dask.distributed import as_completed as dask_completed

    client = Client(scheduler, set_as_default=False)
    try:
        futures = [
            client.submit(run_task, t, key=f"spooflens-corpus-{k}-{t.name}-{t.attack}", priority=len(tasks) - k)
            for k, t in enumerate(tasks)
        ]
        out = []
        for n, future in enumerate(dask_completed(futures, loop=client.loop), start=1):
            out.append(future.result())
            report(what, n, len(tasks))
            _note_progress(what, n, len(tasks))
        return out
    finally:
        client.close()


def _note_progress(what: str, done: int, total: int) -> None:
    """Without a terminal (no bar), a line every tenth of the way."""
    if not show_progress() and (done == total or done % max(1, total // 10) == 0):
        err_console.print(f"{what}: {done}/{total}")


def warm_up(jobs: int) -> float:
    """Start a warmed sandbox per job before anything is timed (in a source tree without the
    ahead-of-time kernels the first compiles them into numba's cache); seconds taken."""
    t0 = time.perf_counter()
    SANDBOXES.warm(jobs)
    return time.perf_counter() - t0


# ---- the whole bench ------------------------------------------------------------------------------------


@dataclass
class CorpusReport:
    roots: list[str]
    results: list[LogResult]
    not_logs: list[NotLog]
    quick: bool
    timeout_s: float
    jobs: int
    seconds: dict[str, float] = field(default_factory=dict)  # warm-up, clean pass, injected pass, total
    load: dict[str, float] = field(default_factory=dict)  # the machine's 1-min load average at the start and end
    selection: str = ""  # what --only / --limit left out
    scheduler: str | None = None


def select(logs: list[CorpusLog], only: tuple[str, ...], limit: int | None) -> list[CorpusLog]:
    """The logs whose name (relative path) matches one of `only` (all when none), the first `limit`."""
    chosen = [c for c in logs if not only or any(fnmatch.fnmatch(c.name, g) for g in only)]
    return chosen[:limit] if limit is not None else chosen


def run_corpus(
    roots: list[Path],
    jobs: int = 2,
    limits: Limits | None = None,
    quick: bool = False,
    scheduler: str | None = None,
    only: tuple[str, ...] = (),
    limit: int | None = None,
    min_span_s: float = MIN_ATTACKED_SPAN_S,
    show: bool = False,
) -> CorpusReport:
    """Discover the logs of `roots`, run the clean pass and (unless `quick`) the injected pass."""
    limits = limits or Limits(DEFAULT_TIMEOUT_S, DEFAULT_RSS_CAP_MB, 4 * DEFAULT_RSS_CAP_MB)
    t_start = time.perf_counter()
    load_at_start = os.getloadavg()[0]
    corpus = Corpus()
    for root in roots:
        found = discover(root)
        corpus.logs += found.logs
        corpus.not_logs += found.not_logs
    chosen = select(corpus.logs, only, limit)
    results = [LogResult(c) for c in chosen]
    report = CorpusReport([str(r) for r in roots], results, corpus.not_logs, quick, limits.timeout_s, jobs)
    report.scheduler = scheduler
    if len(chosen) < len(corpus.logs):
        report.selection = f"{len(chosen)} of {len(corpus.logs)} logs (--only {' '.join(only) or '-'}, --limit {limit})"
    # as `spooflens batch` does: the jobs fill the cores, a second thread per analysis would only contend
    if jobs > 1:
        os.environ.setdefault("SPOOFLENS_THREADS", "1")
    try:
        report.seconds["warm-up"] = warm_up(jobs) if scheduler is None else 0.0
        by_name = {r.log.name: r for r in results}
        t0 = time.perf_counter()
        clean_tasks = [Task(str(r.log.path), r.log.name, limits) for r in results]
        for record in run_tasks(clean_tasks, jobs, scheduler, "clean pass", show):
            by_name[record.name].clean = record
        report.seconds["clean pass"] = time.perf_counter() - t0
        if not quick:
            t0 = time.perf_counter()
            attack_tasks = [t for r in results for t in plan_attacks(r, limits, min_span_s)]
            for record in run_tasks(attack_tasks, jobs, scheduler, "injected pass", show):
                take_injected(by_name[record.name], record)
            order = [k.name for k in BATTERY]
            for r in results:
                r.injected.sort(key=lambda i: order.index(i.kind))
            report.seconds["injected pass"] = time.perf_counter() - t0
    finally:
        SANDBOXES.close()
    report.seconds["total"] = time.perf_counter() - t_start
    # the times are the machine's as it was: others' work on a shared machine shows here
    report.load = {"start": load_at_start, "end": os.getloadavg()[0]}
    return report


def take_injected(result: LogResult, record: TaskRecord) -> None:
    """File an injected task's record under its log: an attack `inject` refuses (with its reason) was not
    run; anything else was, and is scored when the copy was analysed."""
    assert record.attack is not None
    if record.inject is not None and record.inject.outcome == REFUSED:
        result.not_injected[record.attack] = f"inject refuses: {refusal_reason(record.inject.error, result.log.path)}"
        return
    reached = attacked_epochs(record.truth) if record.truth is not None else None
    if reached is not None and reached < MIN_ATTACKED_EPOCHS:
        result.not_injected[record.attack] = (
            f"not attacked: the attack reached {reached} epoch(s) of the copy, fewer than the "
            f"{MIN_ATTACKED_EPOCHS} an alarm's persistence needs (too short to judge)"
        )
        return
    scored = None
    facts = log_facts(result.summary) if result.summary else None
    if record.summary is not None and record.truth is not None:
        scored = score(record.truth, record.summary, facts.fix_rate_hz if facts else None)
    seen = bool(facts and KINDS[record.attack].seen_in(facts))
    result.injected.append(Injected(record.attack, record, scored, seen))


def attacked_epochs(truth: dict[str, Any]) -> int | None:
    """How many of its receiver's epochs (fixes, or solved observation epochs) the attack's sidecar lists
    from the attack's start to its end (the most of any receiver); None where it lists none."""
    offsets = truth.get("offsets") or {}
    start, end = float(truth.get("start_s", 0.0)), truth.get("end_s")
    counts = [
        sum(1 for row in rows if row and start <= float(row[0]) and (end is None or float(row[0]) <= float(end)))
        for rows in offsets.values()
    ]
    return max(counts) if counts else None


# ---- tables ---------------------------------------------------------------------------------------------


@dataclass
class GroupRow:
    group: str
    logs: int = 0
    outcomes: Counter[str] = field(default_factory=Counter)
    spoofing: int = 0  # SPOOFING verdicts on logs read
    # on the clean-sky logs read (no not-clean tag): their hours, the SPOOFING verdicts (all false), and
    # their one-class incidents (anomalies noted, not confirmed)
    hours: float = 0.0
    false_spoofing: int = 0
    anomalies: int = 0
    attacks: int = 0  # attacked copies made of logs with a reference that sees the attack (`with_reference`)
    caught: int = 0
    attacks_unseen: int = 0  # ... of logs without one: GNSS-only and receiver evidence is no verdict alone
    caught_unseen: int = 0
    delays: list[float] = field(default_factory=list)
    onset_known: int = 0
    onset_covered: int = 0
    end_known: int = 0
    to_end: int = 0

    def add(self, r: LogResult) -> None:
        self.logs += 1
        self.outcomes[r.outcome] += 1
        summary = r.summary
        if summary is not None:
            self.spoofing += spoofed(summary)
            if r.log.clean:
                self.hours += hours(summary)
                self.anomalies += sum(not is_spoofing(i) for i in incidents(summary))
                self.false_spoofing += spoofed(summary)
        for inj in r.injected:
            if not inj.with_reference:
                self.attacks_unseen += inj.made
                self.caught_unseen += bool(inj.score and inj.score.caught)
                continue
            self.attacks += inj.made
            s = inj.score
            if s is None:
                continue
            self.caught += s.caught
            if s.caught and s.delay_s is not None:
                self.delays.append(s.delay_s)
            if s.onset_covered is not None:
                self.onset_known += 1
                self.onset_covered += s.onset_covered
            if s.to_end is not None:
                self.end_known += 1
                self.to_end += s.to_end

    @property
    def median_delay_s(self) -> float | None:
        return statistics.median(self.delays) if self.delays else None

    def to_json(self) -> dict[str, Any]:
        def share(n: int, d: int) -> float | None:
            return n / d if d else None

        return {
            "group": self.group,
            "logs": self.logs,
            **{o: self.outcomes[o] for o in OUTCOMES},
            "spoofing_verdicts": self.spoofing,
            "clean_sky_hours_read": self.hours,
            "false_spoofing_clean_sky": self.false_spoofing,
            "anomalies_clean_sky": self.anomalies,
            "anomalies_per_hour": self.anomalies / self.hours if self.hours > 0 else None,
            "attacks": self.attacks,
            "caught": self.caught,
            "caught_share": share(self.caught, self.attacks),
            "attacks_without_reference": self.attacks_unseen,
            "caught_without_reference": self.caught_unseen,
            "median_delay_s": self.median_delay_s,
            "onset_covered": self.onset_covered,
            "onset_known": self.onset_known,
            "to_end": self.to_end,
            "end_known": self.end_known,
        }

    def cells(self, injected: bool) -> list[str]:
        def of(n: int, d: int) -> str:
            return f"{n}/{d}" if d else "-"

        per_hour = f" ({self.anomalies / self.hours:.1f})" if self.hours > 0 else ""
        clean = [
            self.group,
            str(self.logs),
            *(str(self.outcomes[o]) for o in OUTCOMES),
            f"{self.hours:.2f}",
            str(self.false_spoofing),
            f"{self.anomalies}{per_hour}",
        ]
        if not injected:
            return clean
        delay = self.median_delay_s
        return [
            *clean,
            of(self.caught, self.attacks),
            of(self.caught_unseen, self.attacks_unseen),
            "-" if delay is None else f"{delay:.1f}",
            of(self.onset_covered, self.onset_known),
            of(self.to_end, self.end_known),
        ]


CLEAN_COLUMNS = ("group", "logs", *OUTCOMES, "clean-sky hours", "false SPOOFING", "anomalies (/h)")
INJECTED_COLUMNS = ("caught", "caught (no reference)", "median delay s", "onset covered", "to attack end")


def grouped(results: Iterable[LogResult], key: Callable[[LogResult], Iterable[str]]) -> list[GroupRow]:
    """One row per group `key` puts a log in (a log may be in several: tags), sorted, and a total row."""
    rows: dict[str, GroupRow] = {}
    total = GroupRow("all")
    for r in results:
        for g in key(r):
            rows.setdefault(g, GroupRow(g)).add(r)
        total.add(r)
    return [rows[g] for g in sorted(rows)] + [total]


GROUPINGS: dict[str, Callable[[LogResult], Iterable[str]]] = {
    "format": lambda r: [r.log.format],
    "vehicle": lambda r: [r.log.vehicle],
    "tag": lambda r: list(r.log.tags) or ["(no tag)"],
}


def false_verdicts(results: Iterable[LogResult], clean_sky: bool = True) -> list[dict[str, Any]]:
    """Every SPOOFING verdict on a clean-sky log (`clean_sky`), or on a not-clean one: the log, and each
    spoofing incident's window, detectors, evidence and confidence, with whatever else it says."""
    out = []
    for r in results:
        if r.summary is None or not spoofed(r.summary) or r.log.clean != clean_sky:
            continue
        found = [i for i in incidents(r.summary) if is_spoofing(i)]
        out.append(
            {
                "log": r.log.name,
                "format": r.log.format,
                "vehicle": r.log.vehicle,
                "tags": list(r.log.tags),
                "headline": (r.summary.get("verdict") or {}).get("headline"),
                "incidents": found,
                "verdict_extras": verdict_extras(r.summary),
            }
        )
    return out


def interference(results: Iterable[LogResult]) -> dict[str, Any]:
    """The interference detector on the clean pass: on how many logs (and hours) it ran, every log where it
    alarmed with what the receiver's own jamming monitor said, the losses it judged no interference, and
    what each receiver's monitor reported over the log (not logged / unknown or off / ok / interference)."""
    ran: list[str] = []
    hours = 0.0
    alarms: list[dict[str, Any]] = []
    rejected: list[dict[str, Any]] = []
    monitors: dict[str, list[str]] = {}
    for r in results:
        if r.summary is None:
            continue
        for k, seg in enumerate(segments(r.summary), start=1):
            found = [a for a in seg.get("analyses") or [] if a.get("name") == "interference" and a.get("ran")]
            if not found:
                continue
            a = found[0]
            ran.append(r.log.name)
            hours += float(seg.get("duration_s") or 0.0) / 3600.0
            facts = a.get("facts") or {}
            said = {rid: f["jamming_monitor"] for rid, f in (facts.get("receivers") or {}).items()}
            for m in said.values():
                monitors.setdefault(m["reported"], []).append(r.log.name)
            if a.get("alarms"):
                alarms.append(
                    {
                        "log": r.log.name,
                        "segment": k,
                        "clean_sky": r.log.clean,
                        "tags": list(r.log.tags),
                        "findings": [f.get("text") for f in a.get("findings") or []],
                        "receiver_said": said,
                    }
                )
            for e in facts.get("rejected") or []:
                rejected.append({"log": r.log.name, "segment": k, **e})
    return {
        "logs": len(set(ran)),
        "hours": hours,
        "alarms": alarms,
        "rejected_losses": rejected,
        "jamming_monitor": {k: sorted(set(v)) for k, v in monitors.items()},
    }


def misses(results: Iterable[LogResult]) -> list[dict[str, Any]]:
    """Every attacked copy whose attack was not caught: the log, the attack, the reason."""
    out = []
    for r in results:
        for inj in r.injected:
            if not inj.made or (inj.score is not None and inj.score.caught):
                continue
            rec = inj.record
            if inj.score is not None:
                why = inj.score.reason
            else:
                failed = rec.analysis
                why = f"attacked copy {failed.outcome}: {failed.error}" if failed else "attacked copy not analysed"
            if not inj.with_reference:
                why = f"no independent reference in this log sees it ({why})"
            out.append(
                {
                    "log": r.log.name,
                    "format": r.log.format,
                    "attack": rec.attack_text,
                    "reason": why,
                    "with_reference": inj.with_reference,
                }
            )
    return out


def late_or_misplaced(results: Iterable[LogResult]) -> list[dict[str, Any]]:
    """Catches whose incident's onset interval does not hold the attack start (an incident that began
    long before the attack, having absorbed an earlier anomaly, is one)."""
    out = []
    for r in results:
        for inj in r.injected:
            s = inj.score
            if s is None or not s.caught or s.onset_covered is not False:
                continue
            out.append(
                {
                    "log": r.log.name,
                    "attack": inj.record.attack_text,
                    "delay_s": s.delay_s,
                    "onset_interval_s": s.onset_interval_s,
                    "detectors": s.incident.get("detectors"),
                }
            )
    return out


def refusal_reason(error: str, log_path: Path) -> str:
    """A refusal's reason without the log's path, up to its first detail, so that alike refusals group:
    "spooflens: error: /x/a.log [nmea]: no usable NMEA sentence (...): ..." -> "no usable NMEA sentence"."""
    text = re.sub(r"^spooflens: (error: )?", "", error.strip())
    for path in (str(log_path), log_path.name):
        text = re.sub(rf"^{re.escape(path)}( \[[^\]]*\])?: ", "", text)
    for cut in (" (", "; ", ": "):
        text = text.split(cut, 1)[0]
    return text.strip()


def refusals(results: Iterable[LogResult]) -> dict[str, list[str]]:
    """reason -> logs refused with it."""
    out: dict[str, list[str]] = {}
    for r in results:
        if r.outcome == REFUSED and r.clean and r.clean.analysis:
            out.setdefault(refusal_reason(r.clean.analysis.error, r.log.path), []).append(r.log.name)
    return dict(sorted(out.items(), key=lambda kv: -len(kv[1])))


def failures(results: Iterable[LogResult]) -> list[dict[str, str]]:
    """Internal errors and timeouts of either pass (`inject` or `analyze`), each with its one-line error."""
    out = []
    for r in results:
        runs = [("clean", "analyze", r.clean.analysis if r.clean else None)]
        for inj in r.injected:
            runs += [(inj.record.attack_text or inj.kind, "inject", inj.record.inject)]
            runs += [(inj.record.attack_text or inj.kind, "analyze", inj.record.analysis)]
        for what, command, run in runs:
            if run is not None and run.outcome in (INTERNAL, TIMEOUT):
                row = {"log": r.log.name, "format": r.log.format, "run": what, "command": command}
                out.append(row | {"outcome": run.outcome, "error": run.error})
    return out


def not_attacked(results: Iterable[LogResult]) -> Counter[str]:
    """why -> logs on which no attack of the battery was run for that reason."""
    return Counter(r.not_attacked for r in results if r.not_attacked is not None)


def not_injected(results: Iterable[LogResult]) -> Counter[str]:
    """ "attack: why" -> logs that were attacked, but not with that attack."""
    return Counter(f"{kind}: {why}" for r in results for kind, why in r.not_injected.items())


def report_json(report: CorpusReport) -> dict[str, Any]:
    """Everything, per log: what the corpus says of it, the clean run, each injected run and its score."""
    logs = []
    for r in report.results:
        logs.append(
            {
                **{k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(r.log).items()},
                "clean_sky": r.log.clean,
                "outcome": r.outcome,
                "clean_run": r.clean.to_json() if r.clean else None,
                "injected": [
                    {"attack": i.kind, "run": i.record.to_json(), "score": asdict(i.score) if i.score else None}
                    for i in r.injected
                ],
                "not_attacked": r.not_attacked,
                "not_injected": r.not_injected,
            }
        )
    return {
        "roots": report.roots,
        "settings": {
            "quick": report.quick,
            "timeout_s": report.timeout_s,
            "jobs": report.jobs,
            "scheduler": report.scheduler,
        },
        "battery": [asdict(k) for k in BATTERY],
        "seconds": report.seconds,
        "load_average": report.load,
        "selection": report.selection,
        "tables": {name: [row.to_json() for row in grouped(report.results, key)] for name, key in GROUPINGS.items()},
        "false_spoofing_clean_sky": false_verdicts(report.results),
        "spoofing_not_clean_sky": false_verdicts(report.results, clean_sky=False),
        "interference": interference(report.results),
        "internal_errors_and_timeouts": failures(report.results),
        "refusals": refusals(report.results),
        "misses": misses(report.results),
        "caught_with_onset_elsewhere": late_or_misplaced(report.results),
        "not_attacked": dict(not_attacked(report.results)),
        "not_injected": dict(not_injected(report.results)),
        "not_logs": [{"path": n.name, "why": n.why} for n in report.not_logs],
        "logs": logs,
    }


def _window(i: dict[str, Any]) -> str:
    def s(v: Any) -> str:
        return "-" if v is None else f"{float(v):.1f}"

    end = "end of log" if i.get("ongoing_at_end") else s(i.get("end_s"))
    seg = f"recording {i['segment']}: " if i.get("segment", 1) != 1 else ""
    return f"{seg}onset {s(i.get('onset_s'))} s, alarm {s(i.get('start_s'))} s to {end}"


def print_report(report: CorpusReport) -> None:
    out = console()
    results = report.results
    columns = CLEAN_COLUMNS + (() if report.quick else INJECTED_COLUMNS)
    for name, key in GROUPINGS.items():
        t = Table(title=f"By {name}")
        for column in columns:
            t.add_column(column, no_wrap=column == "group")
        for row in grouped(results, key):
            t.add_row(*row.cells(not report.quick))
        out.print(t)
    out.print(
        "[dim]read / damaged / refused / internal error / timeout: how `analyze` ended on the log. clean-sky "
        "hours, false SPOOFING, anomalies: on the clean-sky logs read (no not-clean tag): their hours, their "
        "SPOOFING verdicts, their one-class incidents (per hour). caught: attacks caught of the copies `inject` made "
        "(logs whose clean verdict is NO SPOOFING) whose clean analysis ran a reference that sees the attack (INS, "
        "second receiver, known station, compass for the fix attacks; raw-measurement checks for a counterfeit "
        "satellite; a second receiver for a single antenna); caught (no reference): the same on the other logs, "
        "where GNSS-only and receiver evidence alone can make no spoofing verdict; delay from the attack start "
        "to the alarm; onset covered: "
        "the incident's onset interval holds the attack start; to attack end: the incident lasts as long.[/]"
    )
    false = false_verdicts(results)
    out.print(f"[bold]False SPOOFING verdicts on clean-sky logs: {len(false)}[/]")
    for f in false:
        out.print(f"  {f['log']} ({f['format']}, {f['vehicle']}{', ' + ', '.join(f['tags']) if f['tags'] else ''})")
        for i in f["incidents"]:
            explanation = f"; {i['explanation']}" if i.get("explanation") else ""
            out.print(
                f"    {_window(i)}: detectors {', '.join(i.get('detectors') or [])}; evidence "
                f"{', '.join(i.get('evidence') or [])}; confidence {i.get('confidence')}{explanation}"
            )
        for k, extra in f["verdict_extras"].items():
            out.print(f"    verdict (recording {k}) also says: {json.dumps(extra, default=str)[:300]}")
    other = false_verdicts(results, clean_sky=False)
    if other:
        out.print(f"SPOOFING verdicts on logs that are not clean sky (not counted): {len(other)}")
        for f in other:
            out.print(f"  {f['log']} ({', '.join(f['tags'])}): {f['headline']}")
    jam = interference(results)
    out.print(
        f"[bold]Interference alarms on the clean pass: {len(jam['alarms'])}[/] (the detector ran on "
        f"{jam['logs']} logs, {jam['hours']:.2f} h; {len(jam['rejected_losses'])} signal losses judged no "
        "interference)"
    )
    for a in jam["alarms"]:
        said = "; ".join(f"{rid}: monitor {m['reported']}" for rid, m in a["receiver_said"].items())
        out.print(f"  {a['log']}{' (not clean sky)' if not a['clean_sky'] else ''}: {said}")
        for text in a["findings"]:
            out.print(f"    {text}")
    for e in jam["rejected_losses"]:
        out.print(f"  no interference: {e['log']} {e['start_s']:.0f}-{e['end_s']:.0f} s: {e['because']}")
    for reported, names in jam["jamming_monitor"].items():
        out.print(f"  receivers' jamming monitor {reported}: {len(names)} log(s)")
    broken = failures(results)
    out.print(f"[bold]Internal errors and timeouts: {len(broken)}[/]")
    for b in broken:
        out.print(f"  {b['outcome']}: {b['log']} ({b['format']}), {b['run']}, {b['command']}: {b['error']}")
    out.print("[bold]Refusals by reason[/]")
    for reason, names in refusals(results).items():
        shown = ", ".join(names[:6]) + (f" and {len(names) - 6} more" if len(names) > 6 else "")
        out.print(f"  {len(names)} x {reason}: {shown}")
    if not report.quick:
        missed = misses(results)
        seen = [m for m in missed if m["with_reference"]]
        out.print(f"[bold]Attacks missed on logs with a reference that sees them: {len(seen)}[/]")
        for m in seen:
            out.print(f"  {m['log']} ({m['format']}), {m['attack']}: {m['reason']}")
        unseen = len(missed) - len(seen)
        out.print(f"Attacks missed on logs without such a reference: {unseen} (listed in the JSON's misses)")
        elsewhere = late_or_misplaced(results)
        out.print(f"[bold]Caught, but the onset interval does not hold the attack start: {len(elsewhere)}[/]")
        for c in elsewhere:
            delay = "-" if c["delay_s"] is None else f"{c['delay_s']:.1f} s"
            interval = c["onset_interval_s"] or []
            out.print(
                f"  {c['log']}, {c['attack']}: alarm {delay} from the attack start, onset interval "
                f"{'-'.join(f'{v:.1f}' for v in interval) or '-'} s ({', '.join(c['detectors'] or [])})"
            )
        out.print("[bold]Logs not attacked, and why[/]")
        for why, n in not_attacked(results).most_common():
            out.print(f"  {n} log(s): {why}")
        out.print("[bold]Attacks a log could not take, and why[/]")
        for why, n in not_injected(results).most_common():
            out.print(f"  {n} log(s): {why}")
    else:
        out.print("--quick: the injected pass was skipped")
    if report.selection:
        out.print(f"selection: {report.selection}")
    out.print(f"not logs: {len(report.not_logs)} ({', '.join(sorted({n.why for n in report.not_logs}))})")
    times = ", ".join(f"{k} {v:.0f} s" for k, v in report.seconds.items())
    load = ", ".join(f"{k} {v:.1f}" for k, v in report.load.items())
    where = f"on the dask cluster at {report.scheduler}" if report.scheduler else f"{report.jobs} job(s)"
    out.print(
        f"{len(results)} logs, {where}, time limit {report.timeout_s:g} s per command: {times} (load average at {load})"
    )


@click.command("corpus")
@click.argument("dirs", nargs=-1, type=click.Path(path_type=Path, exists=True, file_okay=False))
@click.option("--jobs", default=2, show_default=True, help="Commands at a time, each a process of its own.")
@click.option("--timeout", "timeout_s", default=DEFAULT_TIMEOUT_S, show_default=True, help="Seconds per command.")
@click.option(
    "--rss-cap-mb",
    default=DEFAULT_RSS_CAP_MB,
    show_default=True,
    help="A command above this resident memory is killed.",
)
@click.option("--quick", is_flag=True, help="The clean pass only (no injected attacks).")
@click.option("--scheduler", default=None, help="Address of a running dask scheduler (default: local processes).")
@click.option("--only", multiple=True, metavar="GLOB", help="Only logs whose relative path matches (repeatable).")
@click.option("--limit", type=int, default=None, help="Only the first N logs (by path).")
@click.option(
    "--min-attacked-span",
    "min_span_s",
    default=MIN_ATTACKED_SPAN_S,
    show_default=True,
    help="Seconds of fixes (or observations) a log needs to be attacked.",
)
@click.option("--json", "json_path", type=click.Path(path_type=Path), default=None, help="Write everything here.")
def command(
    dirs: tuple[Path, ...],
    jobs: int,
    timeout_s: float,
    rss_cap_mb: float,
    quick: bool,
    scheduler: str | None,
    only: tuple[str, ...],
    limit: int | None,
    min_span_s: float,
    json_path: Path | None,
) -> int:
    """False accusations and catches on real logs: every log of DIRS (default ../shared/real) analysed
    clean, then with injected attacks; tables by format, vehicle and tag."""
    roots = list(dirs) or [default_root()]
    if not all(r.is_dir() for r in roots):
        raise click.UsageError(f"no such folder: {', '.join(str(r) for r in roots if not r.is_dir())}")
    limits = Limits(timeout_s, rss_cap_mb, 4 * rss_cap_mb)
    report = run_corpus(roots, jobs, limits, quick, scheduler, only, limit, min_span_s, show=show_progress())
    print_report(report)
    if json_path:
        json_path.write_text(json.dumps(report_json(report), indent=1, default=str))
        console().print(f"JSON: {json_path}")
    return 0


__all__ = ["OUTCOMES", "command", "run_corpus"]
