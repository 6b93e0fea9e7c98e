"""One task of `spooflens bench corpus`: a log analysed, or attacked and analysed, through the command
line, each command in a process of its own with a time limit; and what its JSON summary says.

Only the CLI is driven (`python -m spooflens.cli analyze LOG --json ...`, `... inject LOG --attack ...`),
so what is measured is what a user gets. Summaries are read defensively: a field this module does not
know (a verdict's `events`, an incident's `explanation`) is kept as it is and passed on.
"""

from __future__ import annotations

import json
import tempfile
import threading
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from spooflens.bench.sandbox import Limits, RunResult, Sandbox
from spooflens.errors import one_line

# exit codes of the CLI (spooflens/cli.py); 4 only comes with --fail-on-spoof, which is never given here
EXIT_OK, EXIT_BUG, EXIT_INPUT, EXIT_DAMAGED = 0, 1, 2, 3
# how a command ended
READ, DAMAGED, REFUSED, INTERNAL, TIMEOUT = "read", "damaged", "refused", "internal error", "timeout"
OUTCOMES = (READ, DAMAGED, REFUSED, INTERNAL, TIMEOUT)
# an incident still counts as at or after the attack start when it ends this close before it
START_TOLERANCE_S = 1.0
# an incident that ends this close to the attack's end (or later) ran to it
END_TOLERANCE_S = 2.0


@dataclass(frozen=True)
class CommandResult:
    outcome: str  # one of OUTCOMES
    exit_code: int | None  # None: killed at the time limit
    error: str  # the command's one-line error ("" when it had none)
    seconds: float


@dataclass(frozen=True)
class Task:
    """A clean analysis of `log` (attack None), or `attack` injected from `start_s` and the copy analysed.
    `companions`: files a copy needs beside it to be read as the log is (its navigation files)."""

    log: str
    name: str
    limits: Limits
    attack: str | None = None
    attack_text: str | None = None
    start_s: float | None = None
    companions: tuple[str, ...] = ()


@dataclass
class TaskRecord:
    name: str
    attack: str | None
    analysis: CommandResult | None = None
    inject: CommandResult | None = None
    summary: dict[str, Any] | None = None  # the analysis's JSON, only when it wrote one
    truth: dict[str, Any] | None = None  # the attack's sidecar (OUT.attack.json)
    attack_text: str | None = None

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def error_line(stderr_tail: str) -> str:
    """The command's own one-line error (the sandbox keeps its `spooflens: ...` lines), else its last line."""
    lines = [line.strip() for line in stderr_tail.strip().splitlines() if line.strip()]
    own = [line for line in lines if line.startswith(("spooflens:", "Error:"))]
    return one_line((own or lines or [""])[-1], 500)


def command_result(run: RunResult) -> CommandResult:
    """How a command ended, in this bench's terms: exit 0 read, 3 read with damage, 2 refused; exit 1,
    any other code, a crash or the memory cap an internal error; the time limit a timeout."""
    error = error_line(run.stderr_tail)
    if run.killed == "timeout":
        return CommandResult(TIMEOUT, None, "killed at the time limit", run.seconds)
    if run.killed is not None:
        what = "over the memory cap" if run.killed == "rss" else f"killed by {run.killed}"
        return CommandResult(INTERNAL, run.exit_code, f"{what}{': ' + error if error else ''}", run.seconds)
    documented = {EXIT_OK: READ, EXIT_DAMAGED: DAMAGED, EXIT_INPUT: REFUSED}
    outcome = documented.get(run.exit_code, INTERNAL) if run.exit_code is not None else INTERNAL
    if outcome == INTERNAL and not error:
        error = f"exit code {run.exit_code} and nothing on stderr"
    return CommandResult(outcome, run.exit_code, "" if outcome == READ else error, run.seconds)


class SandboxPool:
    """Sandboxes (`spooflens.bench.sandbox`: a warmed server that forks each command into a process of its
    own, with a time limit and a memory cap) shared by the threads of this process: each command takes a
    free one, or starts one when none is free. A fresh interpreter per command would spend seconds
    importing before it reads a byte; the logs of the corpus mostly take less than that to analyse."""

    def __init__(self) -> None:
        self._free: list[Sandbox] = []
        self._all: list[Sandbox] = []
        self._lock = threading.Lock()

    def start(self) -> Sandbox:
        """A new sandbox, warmed by analysing the sample flight (every kernel loaded before it forks)."""
        from spooflens.compile.warmup import SAMPLES

        with tempfile.TemporaryDirectory(prefix="spooflens-corpus-warm-") as tmp:
            flight = SAMPLES / "spoofed_flight.mcap"
            warm = ["analyze", str(flight), "-o", f"{tmp}/w.rrd", "--quiet"] if flight.exists() else []
            box = Sandbox(warm)
        with self._lock:
            self._all.append(box)
        return box

    def run(self, argv: list[str], workdir: Path, limits: Limits) -> CommandResult:
        with self._lock:
            box = self._free.pop() if self._free else None
        box = box or self.start()
        try:
            result = box.run(argv, workdir, limits)
        except (RuntimeError, OSError, ValueError) as err:  # the server died: this command failed, not the bench
            with self._lock:
                self._all.remove(box)
            return CommandResult(INTERNAL, None, f"sandbox failed: {one_line(err)}", 0.0)
        with self._lock:
            self._free.append(box)
        return command_result(result)

    def warm(self, n: int) -> None:
        """Start `n` sandboxes now, one after the other (the first may compile kernels numba has not cached)."""
        with self._lock:
            missing = n - len(self._all)
        for _ in range(missing):
            box = self.start()
            with self._lock:
                self._free.append(box)

    def close(self) -> None:
        with self._lock:
            boxes, self._all, self._free = self._all, [], []
        for box in boxes:
            box.close()


# one per process: the bench's threads here, or a dask worker's
SANDBOXES = SandboxPool()


def run_cli(argv: list[str], workdir: Path, limits: Limits) -> CommandResult:
    """`spooflens ARGV` in a process of its own, in `workdir`, within `limits`."""
    workdir.mkdir(parents=True, exist_ok=True)
    return SANDBOXES.run(argv, workdir, limits)


def analyse(log: Path, work: Path, limits: Limits) -> tuple[CommandResult, dict[str, Any] | None]:
    """`spooflens analyze LOG --json` (the recording goes to `work`, which the caller removes)."""
    summary_path = work / "summary.json"
    argv = ["analyze", str(log), "-o", str(work / "out.rrd"), "--json", str(summary_path), "--quiet"]
    result = run_cli(argv, work / "analyze", limits)
    summary = None
    if result.outcome in (READ, DAMAGED):
        try:
            summary = json.loads(summary_path.read_text())
        except (OSError, ValueError) as err:
            result = CommandResult(INTERNAL, result.exit_code, f"no readable JSON summary: {one_line(err)}", 0.0)
    return result, summary


def _attacked_copy_place(task: Task, work: Path) -> Path:
    """Where the attacked copy goes: the log's own name in a folder of its own, its companions linked
    beside it (a RINEX or GnssLogger copy finds its navigation file as the log does)."""
    folder = work / "attacked"
    folder.mkdir()
    for companion in task.companions:
        (folder / Path(companion).name).symlink_to(companion)
    return folder / Path(task.log.rstrip("/")).name


def run_task(task: Task) -> TaskRecord:
    """Run one task in a temporary folder; never raises for what a command does (that is the record)."""
    record = TaskRecord(task.name, task.attack, attack_text=task.attack_text)
    with tempfile.TemporaryDirectory(prefix="spooflens-corpus-") as tmp:
        work = Path(tmp)
        log = Path(task.log)
        if task.attack_text is not None:
            copy = _attacked_copy_place(task, work)
            text = f"{task.attack_text}{',' if ':' in task.attack_text else ':'}start={task.start_s:.1f}"
            record.attack_text = text
            argv = ["inject", str(log), "--attack", text, "-o", str(copy)]
            record.inject = run_cli(argv, work / "inject", task.limits)
            if record.inject.outcome != READ:
                return record
            try:
                record.truth = json.loads(Path(f"{copy}.attack.json").read_text())
            except (OSError, ValueError) as err:
                record.inject = CommandResult(INTERNAL, 0, f"no attack sidecar: {one_line(err)}", record.inject.seconds)
                return record
            log = copy
        record.analysis, record.summary = analyse(log, work, task.limits)
    return record


# ---- what a summary says -------------------------------------------------------------------------------


def segments(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """Each recording's summary (a log that joins several recordings has `segments`)."""
    parts = summary.get("segments")
    return [p for p in parts if isinstance(p, dict)] if isinstance(parts, list) else [summary]


def incidents(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """Every incident of every recording as written (unknown fields kept), with `segment` (its recording,
    from 1) and `t0_abs_ns` (that recording's start) added."""
    out = []
    for k, seg in enumerate(segments(summary), start=1):
        verdict = seg.get("verdict") or {}
        for inc in verdict.get("incidents") or []:
            if isinstance(inc, dict):
                out.append({**inc, "segment": k, "t0_abs_ns": seg.get("t0_abs_ns")})
    return out


def is_spoofing(incident: dict[str, Any]) -> bool:
    """A spoofing incident (two evidence classes), not a one-class anomaly; older summaries had only
    `confidence`."""
    if "spoofing" in incident:
        return bool(incident["spoofing"])
    return incident.get("confidence") not in (None, "low")


def spoofed(summary: dict[str, Any]) -> bool:
    return bool((summary.get("verdict") or {}).get("spoofed"))


GNSS_ROLES = ("fix", "observations", "satellites")
# the longest interval between a receiver's epochs that still counts as logged time (RINEX at 30 s is logged
# throughout); beyond it, a stream's epochs count this long each
MAX_EPOCH_PERIOD_S = 60.0


def hours(summary: dict[str, Any]) -> float:
    """The hours of GNSS the log holds: per recording its duration, but at most what its GNSS streams cover
    (each epoch at most `MAX_EPOCH_PERIOD_S`): a test snippet stitched from sessions years apart holds a
    handful of fixes, not the years between them (pynmeagps' Unicore sample: 78 million seconds)."""
    total = 0.0
    for seg in segments(summary):
        duration = float(seg.get("duration_s") or 0.0)
        streams = [st for st in seg.get("streams") or summary.get("streams") or [] if st.get("role") in GNSS_ROLES]
        covered = max((_covered_s(st) for st in streams), default=0.0)
        total += min(duration, covered) if streams else duration
    return total / 3600.0


def _covered_s(stream: dict[str, Any]) -> float:
    """The seconds a stream's epochs cover: its span, each epoch counted at most `MAX_EPOCH_PERIOD_S`."""
    count = int(stream.get("count") or 0)
    if count < 2:
        return count * MAX_EPOCH_PERIOD_S
    first, last = stream.get("first_s"), stream.get("last_s")
    span = float(last) - float(first) if first is not None and last is not None else 0.0
    return min(span, count * MAX_EPOCH_PERIOD_S)


def verdict_extras(summary: dict[str, Any]) -> dict[str, Any]:
    """What a verdict holds beyond the fields this bench reads (e.g. `events` added later): passed on."""
    known = {
        "spoofed",
        "headline",
        "incidents",
        "detectors_counted",
        "detectors_advisory",
        "detectors_not_run",
        "findings",
    }
    out: dict[str, Any] = {}
    for k, seg in enumerate(segments(summary), start=1):
        extra = {key: v for key, v in (seg.get("verdict") or {}).items() if key not in known and v}
        if extra:
            out[str(k)] = extra
    return out


# references the log holds as another system recorded them (the autopilot's own filter innovations): `inject`
# moves the fixes, not what that filter made of the real ones, so they cannot see an injected attack
RECORDED_REFERENCES = frozenset({"autopilot_ekf"})


@dataclass(frozen=True)
class LogFacts:
    """What the clean analysis says a log has, for choosing the attacks it can take."""

    recordings: int
    logged_fix_receivers: tuple[str, ...]  # receivers whose fixes the log holds (not solved by spooflens)
    fix_receivers: tuple[str, ...]  # logged or solved from raw observations
    observation_receivers: tuple[str, ...]
    fix_span_s: tuple[float, float] | None
    observation_span_s: tuple[float, float] | None
    fix_rate_hz: float | None
    # the evidence classes of the detectors that ran and count: what an attack could be compared with
    classes_run: frozenset[str] = frozenset()
    analyses_run: frozenset[str] = frozenset()  # the names of those detectors


def _span(streams: list[dict[str, Any]]) -> tuple[float, float] | None:
    firsts = [float(s["first_s"]) for s in streams if s.get("first_s") is not None]
    lasts = [float(s["last_s"]) for s in streams if s.get("last_s") is not None]
    return (min(firsts), max(lasts)) if firsts and lasts else None


def log_facts(summary: dict[str, Any]) -> LogFacts:
    parts = segments(summary)
    streams = [s for seg in parts for s in seg.get("streams") or [] if isinstance(s, dict) and s.get("count")]
    computed = {str(c.get("stream")) for seg in parts for c in seg.get("computed") or [] if isinstance(c, dict)}
    fixes = [s for s in streams if s.get("role") == "fix"]
    obs = [s for s in streams if s.get("role") == "observations"]
    rates = [float(s["rate_hz"]) for s in fixes if s.get("rate_hz")]
    counted = [
        a
        for seg in parts
        for a in seg.get("analyses") or []
        if isinstance(a, dict)
        and a.get("ran")
        and a.get("evidence")
        and not a.get("advisory")
        and a.get("name") not in RECORDED_REFERENCES
    ]
    return LogFacts(
        recordings=len(parts),
        logged_fix_receivers=tuple(dict.fromkeys(str(s["stream_id"]) for s in fixes if s["stream_id"] not in computed)),
        fix_receivers=tuple(dict.fromkeys(str(s["stream_id"]) for s in fixes)),
        observation_receivers=tuple(dict.fromkeys(str(s["stream_id"]) for s in obs)),
        fix_span_s=_span(fixes),
        observation_span_s=_span(obs),
        fix_rate_hz=max(rates) if rates else None,
        classes_run=frozenset(str(a["evidence"]) for a in counted),
        analyses_run=frozenset(str(a["name"]) for a in counted),
    )


# ---- scoring an attacked copy against its truth ----------------------------------------------------------


@dataclass
class Score:
    caught: bool
    reason: str = ""  # why not, for a miss
    delay_s: float | None = None  # attack start -> the catching incident's alarm
    onset_covered: bool | None = None
    onset_interval_s: list[float] | None = None
    to_end: bool | None = None  # the incident ran to the attack's end (or past it)
    end_error_s: float | None = None  # incident end - attack end
    incident: dict[str, Any] = field(default_factory=dict)


def _abs_ns(incident: dict[str, Any], key: str) -> float | None:
    """An incident time in the log's clock (ns): `KEY_abs_ns`, else the recording start + `KEY_s`."""
    value = incident.get(f"{key}_abs_ns")
    if value is not None:
        return float(value)
    rel, t0 = incident.get(f"{key}_s"), incident.get("t0_abs_ns")
    return None if rel is None or t0 is None else float(t0) + float(rel) * 1e9


def _describe(found: list[dict[str, Any]]) -> str:
    classes = sorted({e for i in found for e in i.get("evidence") or []})
    detectors = sorted({d for i in found for d in i.get("detectors") or []})
    return f"evidence {', '.join(classes) or 'none'}; detectors {', '.join(detectors) or 'none'}"


def score(truth: dict[str, Any], summary: dict[str, Any], fix_rate_hz: float | None) -> Score:
    """Was the attack of `truth` caught in the attacked copy's `summary`: a SPOOFING verdict with a
    spoofing incident that reaches the attack's start or lies after it; its delay, onset interval and end."""
    t0 = float(truth.get("t0_abs_ns") or 0)
    start = t0 + float(truth["start_s"]) * 1e9
    end = t0 + float(truth["end_s"]) * 1e9 if truth.get("end_s") is not None else None
    period_ns = 1e9 / fix_rate_hz if fix_rate_hz else 1e9
    reach = start - START_TOLERANCE_S * 1e9 - period_ns
    found = incidents(summary)
    after = [i for i in found if (_abs_ns(i, "end") or float("inf")) >= reach or i.get("ongoing_at_end")]
    hits = [i for i in after if is_spoofing(i)]
    if not (spoofed(summary) and hits):
        if not after:
            before = [i for i in found if is_spoofing(i)]
            why = "spoofing incident only before the attack" if before else "no alarm at or after the attack start"
        else:
            why = f"only one-class anomalies at or after the start ({_describe(after)})"
        return Score(False, why)
    hit = min(hits, key=lambda i: _abs_ns(i, "start") or float("inf"))
    alarm = _abs_ns(hit, "start")
    out = Score(True, incident=hit, delay_s=None if alarm is None else (alarm - start) / 1e9)
    recording_t0 = hit.get("t0_abs_ns")
    interval = hit.get("onset_interval_s") or ([hit["onset_s"]] * 2 if hit.get("onset_s") is not None else None)
    if interval and recording_t0 is not None:
        lo, hi = (float(recording_t0) + float(v) * 1e9 for v in interval[:2])
        out.onset_interval_s = [float(v) for v in interval[:2]]
        out.onset_covered = lo - period_ns - 1e3 <= start <= hi + period_ns + 1e3
    incident_end = _abs_ns(hit, "end")
    if end is not None:
        out.to_end = bool(hit.get("ongoing_at_end")) or (
            incident_end is not None and incident_end >= end - END_TOLERANCE_S * 1e9
        )
        out.end_error_s = None if incident_end is None else (incident_end - end) / 1e9
    return out
