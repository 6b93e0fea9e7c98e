"""Mutation fuzzing: damaged copies of every log format, each run through the CLI in a process of its own.

`spooflens bench fuzz --n N [--seed S]` takes the seed logs (every sample log, the real logs in
`../shared/real/` with its corpus of ~250 logs of ~100 receivers in every format a reader reads, packed
RINEX and NMEA 2000 included, and short simulated logs in the formats neither has: ULog, protobuf MCAP, ROS2 MCAP
bag, RINEX 3, the PX4 CSV dialect; and the sample CSV's fixes file alone), makes N mutants
(`spooflens.bench.mutations`), and runs `spooflens inspect` on each, then `spooflens analyze` when
inspect read something (`--command` picks one), in a sandboxed child (`spooflens.bench.sandbox`: time
limit, address-space cap, peak RSS measured).

Outcomes: exit 0, 2, 3, 4 are what the README documents (done; bad input with one line; damaged and
analysed; spoofed with --fail-on-spoof) and count as handled. Exit 1 or any other code is an internal
error, `timeout` a hang, `rss` a child over the memory cap, `signal` a crash. Each failing input is
copied to the failures directory with a `repro.txt` (the command, the mutation, the error), so it can
be rerun by hand.
"""

from __future__ import annotations

import contextlib
import gzip
import io
import json
import random
import re
import selectors
import shutil
import tempfile
import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

import click
from rich.table import Table

from spooflens.bench.mutations import Mutant, SeedLog, make_mutant
from spooflens.bench.sandbox import Limits, RunResult, Sandbox
from spooflens.output.console import console, err_console, progress, show_progress

ROOT = Path(__file__).resolve().parents[2]
SAMPLE_LOGS = ROOT / "sample_logs"
REAL_LOGS = ROOT.parent / "shared" / "real"
HANDLED = ("exit-0", "exit-2", "exit-3", "exit-4")
FAILURES = ("internal", "timeout", "rss", "signal")
_NOT_LOGS = (".md", ".toml", ".yaml", ".json", ".png")
# simulated seeds in the formats the sample and real logs lack: (name, scenario, format, seconds)
SIMULATED = (
    ("sim.ulg", "ground", "ulog", 40.0),
    ("sim_protobuf.mcap", "ground", "mcap-protobuf", 30.0),
    ("sim_ros2bag_mcap", "ground", "ros2bag-mcap", 30.0),
    ("sim_rinex", "ground_raw", "rinex", 60.0),
)


def _is_companion(path: Path) -> bool:
    return path.name.endswith((".truth.csv", ".attack.json"))


def sample_seeds(root: Path = SAMPLE_LOGS) -> list[SeedLog]:
    """Every sample log with its truth file; plus the sample CSV's fixes file alone (a single-file CSV)."""
    seeds = []
    for p in sorted(root.iterdir()):
        if _is_companion(p) or p.suffix in _NOT_LOGS or p.name == "screenshots":
            continue
        companions = tuple(c for c in (Path(f"{p}.truth.csv"),) if c.exists())
        seeds.append(SeedLog(p, companions))
    if (root / "ground_csv" / "fixes.csv").exists():
        seeds.append(SeedLog(root / "ground_csv" / "fixes.csv"))
    return seeds


def _is_navigation(path: Path) -> bool:
    """A RINEX navigation file (`.05n`, `.16n`): it goes beside the observation logs, not fuzzed alone."""
    return re.fullmatch(r"\.\d\d[nNgG]", path.suffix) is not None


def real_seeds(root: Path = REAL_LOGS) -> list[SeedLog]:
    """The real logs a reader reads (navigation files and licences go along as companions)."""
    from readers import sniff_format
    from spooflens.errors import SpooflensError

    seeds = []
    for folder in sorted({p.parent for p in root.rglob("*") if p.is_file()}):
        files = sorted(p for p in folder.iterdir() if p.is_file())
        logs = []
        for p in files:
            if p.suffix in _NOT_LOGS or p.name.startswith(("LICENSE", "COPYING", "RTKLIB")) or _is_navigation(p):
                continue
            try:
                sniff_format(p)
            except SpooflensError:
                continue
            logs.append(p)
        navigation = tuple(p for p in files if _is_navigation(p))
        seeds += [SeedLog(p, navigation) for p in logs]
    return seeds


def simulated_seeds(workdir: Path) -> list[SeedLog]:
    from pyulog.ulog2csv import convert_ulog2csv

    from spooflens.simulation.simulate import SCENARIOS, simulate, write_with_truth

    seeds = []
    for name, scenario, fmt, seconds in SIMULATED:
        path = workdir / name
        if not path.exists():
            write_with_truth(simulate(SCENARIOS[scenario], seed=0, duration_s=seconds).table, path, fmt)
        seeds.append(SeedLog(path, (Path(f"{path}.truth.csv"),)))
    px4_csv = workdir / "sim_px4_csv"  # the PX4 CSV dialect: the ULog through PX4's own ulog2csv
    if not px4_csv.exists():
        px4_csv.mkdir()
        with contextlib.redirect_stdout(io.StringIO()):  # it prints a line per file
            convert_ulog2csv(str(workdir / "sim.ulg"), None, str(px4_csv), ",", None, None)
    seeds.append(SeedLog(px4_csv))
    # packed as shipped (readers/packed.py): a compressed stream, and an archive of a log's folder
    ulog_gz = workdir / "sim.ulg.gz"
    if not ulog_gz.exists():
        ulog_gz.write_bytes(gzip.compress((workdir / "sim.ulg").read_bytes()))
    bag_zip = workdir / "sim_ros2bag_mcap.zip"
    if not bag_zip.exists():
        shutil.make_archive(str(bag_zip.with_suffix("")), "zip", workdir, "sim_ros2bag_mcap")
    seeds += [SeedLog(ulog_gz), SeedLog(bag_zip)]
    return seeds


@dataclass
class Case:
    mutant: Mutant
    command: str
    result: RunResult


@dataclass
class FuzzReport:
    n: int
    seed: int
    commands: str
    counts: dict[str, int] = field(default_factory=dict)  # outcome -> runs
    per_seed: dict[str, dict[str, int]] = field(default_factory=dict)
    peak_rss_mb: float = 0.0
    peak_rss_case: str = ""
    slowest_s: float = 0.0
    slowest_case: str = ""
    seconds: float = 0.0
    failures: list[dict[str, str]] = field(default_factory=list)
    failures_dir: str = ""
    baseline: dict[str, str] = field(default_factory=dict)  # seed -> outcome of the unmutated log

    @property
    def failed(self) -> int:
        """Failing runs so far (counts are keyed "<command> <outcome>", so they are not summed here)."""
        return len(self.failures)


def _argv(command: str, log: Path, workdir: Path) -> list[str]:
    if command == "inspect":
        return ["inspect", str(log)]
    return ["analyze", str(log), "-o", str(workdir / "out.rrd"), "--json", str(workdir / "out.json"), "--quiet"]


def _save_failure(case: Case, failures: Path, workdir: Path) -> dict[str, str]:
    """Copy the failing mutant (and what sits beside it) with a repro note; returns the report row."""
    m = case.mutant
    failures.mkdir(parents=True, exist_ok=True)
    dest = failures / f"{len(list(failures.iterdir())):05d}_{case.result.outcome}_{m.seed.name}"
    dest.mkdir(parents=True)
    if m.path.parent != workdir:  # an unmutated seed: the log itself, and what belongs beside it
        for p in (m.path, *m.seed.companions):
            (shutil.copytree if p.is_dir() else shutil.copyfile)(p, dest / p.name)
    for p in workdir.iterdir() if m.path.parent == workdir else ():
        if p.name in ("stdout.txt", "stderr.txt", "out.rrd", "out.json"):
            continue
        (shutil.copytree if p.is_dir() else shutil.copyfile)(p, dest / p.name)
    argv = _argv(case.command, dest / m.path.name, dest)
    row = {
        "outcome": case.result.outcome,
        "seed": str(m.seed.path),
        "mutation": m.description,
        "command": "spooflens " + " ".join(argv),
        "error": case.result.stderr_tail,
        "dir": str(dest),
    }
    (dest / "repro.txt").write_text("\n".join(f"{k}: {v}" for k, v in row.items()) + "\n")
    return row


class _Pool:
    """Sandboxes working in parallel: `run` many (argv, workdir) and get each result as it comes."""

    def __init__(self, jobs: int, warm_argv: list[str]) -> None:
        self.boxes = [Sandbox(warm_argv) for _ in range(jobs)]
        self.selector = selectors.DefaultSelector()
        for box in self.boxes:
            self.selector.register(box.fileno(), selectors.EVENT_READ, box)

    def free(self) -> Sandbox | None:
        return next((b for b in self.boxes if not b.busy), None)

    def wait(self) -> list[Sandbox]:
        return [key.data for key, _ in self.selector.select()]

    def close(self) -> None:
        for box in self.boxes:
            box.close()


def run_fuzz(
    n: int,
    seed: int = 0,
    commands: tuple[str, ...] = ("inspect", "analyze"),
    jobs: int = 1,
    limits: Limits | None = None,
    seeds: list[SeedLog] | None = None,
    failures_dir: Path | None = None,
    max_seed_mb: float = 8.0,
    show: bool = False,
) -> FuzzReport:
    """Fuzz `n` mutants; `commands` run in order, each only while the previous read something (exit 0/3)."""
    limits = limits or Limits()
    report = FuzzReport(n, seed, "+".join(commands))
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="spooflens-fuzz-") as tmp:
        work = Path(tmp)
        if seeds is None:
            (work / "seeds").mkdir()
            seeds = sample_seeds() + real_seeds() + simulated_seeds(work / "seeds")
        seeds = [s for s in seeds if _size_mb(s.path) <= max_seed_mb]
        if not seeds:
            raise click.UsageError("no seed logs found")
        warm = next((s for s in seeds if s.name == "ground_csv"), seeds[0])
        pool = _Pool(jobs, _argv(commands[-1], warm.path, work))
        failures = failures_dir or Path.cwd() / "spooflens-fuzz-failures"
        counts: Counter[str] = Counter()
        per_seed: dict[str, Counter[str]] = {}
        rng = random.Random(seed)
        # the unmutated seeds first (each must itself be handled), then the mutants
        pending = [_Job(s, -1 - i, 0, work / "baseline" / str(i)) for i, s in enumerate(seeds)]
        pending += [_Job(rng.choice(seeds), i, 0, work / "mutants" / str(i)) for i in range(n)]
        running: dict[int, _Job] = {}
        done, total = 0, len(pending)
        log_every = max(1, (n + len(seeds)) // 20)
        with progress(show) as bar:
            while pending or running:
                box = pool.free()
                while box is not None and pending:
                    job = pending.pop(0)
                    if job.mutant is None:
                        job.mutant = _materialise(job, seed)
                    box.submit(_argv(commands[job.step], job.mutant.path, job.workdir), job.workdir, limits)
                    running[id(box)] = job
                    box = pool.free()
                for box in pool.wait():
                    result = box.result()
                    job = running.pop(id(box))
                    assert job.mutant is not None
                    case = Case(job.mutant, commands[job.step], result)
                    outcome = result.outcome
                    counts[f"{case.command} {outcome}"] += 1
                    per_seed.setdefault(job.seed.name, Counter())[outcome] += 1
                    if job.index < 0 and job.step == 0:
                        report.baseline[job.seed.name] = outcome
                    if result.peak_rss_mb > report.peak_rss_mb:
                        report.peak_rss_mb, report.peak_rss_case = result.peak_rss_mb, _label(case)
                    if result.seconds > report.slowest_s:
                        report.slowest_s, report.slowest_case = result.seconds, _label(case)
                    if outcome in FAILURES:
                        report.failures.append(_save_failure(case, failures, job.workdir))
                        report.failures_dir = str(failures)
                    if outcome in ("exit-0", "exit-3") and job.step + 1 < len(commands):
                        pending.insert(0, _Job(job.seed, job.index, job.step + 1, job.workdir, job.mutant))
                        total += 1
                    else:
                        shutil.rmtree(job.workdir, ignore_errors=True)
                    done += 1
                    bar(f"fuzzing ({report.failed} failed)", done, total)
                    if not show and done % log_every == 0:  # no terminal: a line now and then instead of a bar
                        err_console.print(f"fuzzing: {done}/{total} runs, {report.failed} failed")
        pool.close()
    report.counts = dict(sorted(counts.items()))
    report.per_seed = {k: dict(v) for k, v in sorted(per_seed.items())}
    report.seconds = time.monotonic() - started
    return report


def _size_mb(path: Path) -> float:
    files = [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]
    return sum(p.stat().st_size for p in files) / 1e6


def _label(case: Case) -> str:
    return f"{case.command} {case.mutant.seed.name}: {case.mutant.description}"


@dataclass
class _Job:
    seed: SeedLog
    index: int  # negative: the unmutated seed
    step: int  # which of the commands
    workdir: Path
    mutant: Mutant | None = None


def _materialise(job: _Job, base_seed: int) -> Mutant:
    if job.index < 0:
        job.workdir.mkdir(parents=True, exist_ok=True)
        return Mutant(job.seed, job.seed.path, "unmutated")
    return make_mutant(job.seed, job.index, base_seed, job.workdir)


def print_report(report: FuzzReport) -> None:
    out = console()
    t = Table("command", "outcome", "runs", title=f"{report.n} mutants, seed {report.seed}, {report.seconds:.0f} s")
    for key, count in report.counts.items():
        command, outcome = key.split(" ", 1)
        t.add_row(command, outcome + ("" if outcome in HANDLED else "  FAILURE"), str(count))
    out.print(t)
    bad = [s for s, o in report.baseline.items() if o not in HANDLED]
    if bad:
        out.print(f"unmutated seeds not handled: {bad}")
    out.print(f"peak RSS {report.peak_rss_mb:.0f} MB ({report.peak_rss_case})")
    out.print(f"slowest run {report.slowest_s:.1f} s ({report.slowest_case})")
    internal = sum(v for k, v in report.counts.items() if k.endswith(" internal") or k.endswith(" signal"))
    hangs = sum(v for k, v in report.counts.items() if k.endswith(" timeout"))
    rss = sum(v for k, v in report.counts.items() if k.endswith(" rss"))
    out.print(f"internal errors {internal}, hangs {hangs}, over the memory cap {rss}")
    for row in report.failures[:20]:
        out.print(f"  {row['outcome']}: {row['command']}  [{row['mutation']}]  {row['error'].splitlines()[-1:]}")
    if report.failures:
        out.print(f"failing inputs saved in {report.failures_dir} (each with repro.txt)")


@click.command()
@click.option("--n", "n", type=click.IntRange(min=0), default=200, show_default=True, help="Mutants to run.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed: same seed, same mutants.")
@click.option(
    "--command",
    "command",
    type=click.Choice(["inspect", "analyze", "both"]),
    default="both",
    show_default=True,
    help="What runs on each mutant; 'both': inspect, then analyze when inspect read something.",
)
@click.option("--jobs", type=click.IntRange(min=1), default=1, show_default=True, help="Mutants run in parallel.")
@click.option("--timeout", type=float, default=120.0, show_default=True, help="Seconds before a run counts as a hang.")
@click.option("--rss-cap-mb", type=float, default=1024.0, show_default=True, help="Peak RSS above this is a failure.")
@click.option(
    "--failures",
    type=click.Path(path_type=Path),
    default=None,
    help="Where failing inputs are saved (default ./spooflens-fuzz-failures, made only when one fails).",
)
@click.option("--max-seed-mb", type=float, default=8.0, show_default=True, help="Leave out seed logs larger than this.")
@click.option("--json", "json_path", type=click.Path(path_type=Path), default=None, help="Write the report here.")
def command(
    n: int,
    seed: int,
    command: str,
    jobs: int,
    timeout: float,
    rss_cap_mb: float,
    failures: Path | None,
    max_seed_mb: float,
    json_path: Path | None,
) -> int:
    """Mutation fuzzing of every log format through inspect/analyze: internal errors, hangs, memory."""
    commands = ("inspect", "analyze") if command == "both" else (command,)
    err_console.print(f"fuzzing {n} mutants ({'+'.join(commands)}), {jobs} job(s)")
    report = run_fuzz(
        n,
        seed,
        commands,
        jobs,
        Limits(timeout_s=timeout, rss_cap_mb=rss_cap_mb),
        failures_dir=failures,
        max_seed_mb=max_seed_mb,
        show=show_progress(),
    )
    print_report(report)
    if json_path:
        json_path.write_text(json.dumps(asdict(report), indent=1))
    return 1 if report.failed else 0
