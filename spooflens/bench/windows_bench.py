"""Stretches of real clean logs, cut where nobody chose (`spooflens bench windows`).

An investigator rarely hands over a whole voyage: a flight's last five minutes, the hour around an
incident, a drive exported from 17:02 to 17:09. Every clean-sky log of the corpus that `bench corpus` reads
(one recording, GNSS over at least `--min-span` seconds) is cut into stretches of each `--length`, at
starts drawn from a seeded generator (the same seed, log and length give the same starts), and each
stretch is analysed as a log of its own (`EpochTable.between`). A SPOOFING verdict on a stretch is a false
accusation, as on the whole log; so is an internal error. Each false verdict is listed with its log, start
and length, so it can be analysed again (`python -c` on `EpochTable.between`, or this command with
`--only`).

The stretches are analysed in worker processes (`--jobs`), one log at a time, each stretch under a time
limit (`--timeout`).
"""

from __future__ import annotations

import fnmatch
import json
import random
import signal
import time
import zlib
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from pathlib import Path
from types import FrameType
from typing import Any

import click
from rich.table import Table

from spooflens.bench.corpus_bench import default_root
from spooflens.bench.corpus_logs import CorpusLog, discover
from spooflens.bench.natural_changes import CHANGES, changed
from spooflens.output.console import console, progress, show_progress

DEFAULT_LENGTHS_S = (60.0, 150.0, 400.0, 900.0)


@dataclass(frozen=True)
class Stretch:
    """One stretch analysed: where it lies in its log and what the analysis said."""

    log: str
    start_s: float
    length_s: float
    outcome: str  # "analysed", "timeout", "error"
    spoofed: bool = False
    headline: str = ""
    anomalies: int = 0
    seconds: float = 0.0
    error: str = ""


@dataclass(frozen=True)
class Cutting:
    """Where and how the stretches are cut: `draws` of each of `lengths` per log from starts `seed` draws,
    of logs whose GNSS spans at least `min_span_s`, each analysed within `timeout_s`."""

    seed: int = 1
    lengths: tuple[float, ...] = DEFAULT_LENGTHS_S
    draws: int = 2
    min_span_s: float = 240.0
    timeout_s: float = 120.0
    natural: str = ""  # a natural change made to each log first (`bench.natural_changes`); "" none


class _Timeout(Exception):
    pass


def _alarm(signum: int, frame: FrameType | None) -> None:
    raise _Timeout


def starts(seed: int, name: str, span: tuple[float, float], length_s: float, draws: int) -> list[float]:
    """`draws` starts of a stretch of `length_s` within `span`, the same for the same seed, log and length."""
    a, b = span
    if b - a < length_s:
        return []
    rng = random.Random(zlib.crc32(f"{seed}|{name}|{length_s:g}".encode()))
    return [round(rng.uniform(a, b - length_s), 1) for _ in range(draws)]


def stretches_of(path: str, name: str, cutting: Cutting) -> list[Stretch]:
    """Read one log and analyse its stretches (in a worker process). A log that cannot be read, is not one
    recording or holds too little GNSS gives none."""
    from spooflens.errors import SpooflensError
    from spooflens.inventory import has_gnss
    from spooflens.pipeline.run import analyze_segments
    from spooflens.service import read_table

    try:
        table = read_table(Path(path), {}, False)
    except SpooflensError:
        return []
    if cutting.natural:
        natural = changed(table, cutting.natural)
        if natural is None:
            return []
        table = natural
    t = table.fixes["t_s"].to_numpy(dtype=float)
    if not has_gnss(table) or len(table.segments) > 1 or len(t) < 20:
        return []
    span = (float(t.min()), float(t.max()))
    if span[1] - span[0] < cutting.min_span_s:
        return []
    out: list[Stretch] = []
    signal.signal(signal.SIGALRM, _alarm)
    for length in cutting.lengths:
        for start in starts(cutting.seed, name, span, length, cutting.draws):
            t0 = time.perf_counter()
            try:
                signal.setitimer(signal.ITIMER_REAL, cutting.timeout_s)
                analyses = analyze_segments(table.between(start, start + length))
                signal.setitimer(signal.ITIMER_REAL, 0)
            except _Timeout:
                out.append(Stretch(name, start, length, "timeout", seconds=time.perf_counter() - t0))
                continue
            except Exception as err:  # noqa: BLE001 - a bug on one stretch is a record, the bench goes on
                signal.setitimer(signal.ITIMER_REAL, 0)
                error = f"{type(err).__name__}: {err}"[:300]
                out.append(Stretch(name, start, length, "error", seconds=time.perf_counter() - t0, error=error))
                continue
            verdict = analyses[0].verdict
            out.append(
                Stretch(
                    name,
                    start,
                    length,
                    "analysed",
                    spoofed=any(a.verdict.spoofed for a in analyses),
                    headline=verdict.headline,
                    anomalies=sum(not i.is_spoofing for a in analyses for i in a.verdict.incidents),
                    seconds=time.perf_counter() - t0,
                )
            )
    return out


def clean_logs(roots: list[Path], only: tuple[str, ...]) -> list[CorpusLog]:
    """The clean-sky logs a reader recognises, in the corpus bench's terms (`bench.corpus_logs`)."""
    logs = [c for root in roots for c in discover(root).logs if c.clean and c.reader is not None]
    return [c for c in logs if not only or any(fnmatch.fnmatch(c.name, g) for g in only)]


def run_windows(logs: list[CorpusLog], cutting: Cutting, jobs: int, show: bool) -> list[Stretch]:
    out: list[Stretch] = []
    with progress(show) as report, ProcessPoolExecutor(max_workers=max(1, jobs)) as pool:
        futures = [pool.submit(stretches_of, str(c.path), c.name, cutting) for c in logs]
        for done, future in enumerate(as_completed(futures), 1):
            out += future.result()
            report("stretches of clean logs", done, len(futures))
    return sorted(out, key=lambda s: (s.log, s.length_s, s.start_s))


def rows(stretches: list[Stretch]) -> Iterator[tuple[str, int, int, float, int, int, int, int]]:
    """Per length, then in all: (length, logs, stretches analysed, hours, false SPOOFING, anomalies, timeouts,
    internal errors)."""
    lengths = sorted({s.length_s for s in stretches})
    for label, chosen in [(f"{x:g} s", [s for s in stretches if s.length_s == x]) for x in lengths] + [
        ("all", stretches)
    ]:
        done = [s for s in chosen if s.outcome == "analysed"]
        yield (
            label,
            len({s.log for s in chosen}),
            len(done),
            sum(s.length_s for s in done) / 3600.0,
            sum(s.spoofed for s in done),
            sum(s.anomalies for s in done),
            sum(s.outcome == "timeout" for s in chosen),
            sum(s.outcome == "error" for s in chosen),
        )


COLUMNS = ("length", "logs", "stretches", "hours", "false_spoofing", "anomalies", "timeouts", "errors")


def report_json(stretches: list[Stretch], settings: dict[str, Any]) -> dict[str, Any]:
    return {
        "settings": settings,
        "table": [dict(zip(COLUMNS, r, strict=True)) for r in rows(stretches)],
        "false_spoofing": [asdict(s) for s in stretches if s.spoofed],
        "failures": [asdict(s) for s in stretches if s.outcome != "analysed"],
        "stretches": [asdict(s) for s in stretches],
    }


def print_report(stretches: list[Stretch], seconds: float) -> None:
    out = console()
    table = Table(title="Stretches of real clean logs, cut at random (false SPOOFING on each is a false accusation)")
    for col in ("length", "logs", "stretches", "hours", "false SPOOFING", "anomalies", "timeouts", "errors"):
        table.add_column(col, justify="left" if col == "length" else "right")
    for label, logs, n, hours, false, anomalies, timeouts, errors in rows(stretches):
        table.add_row(label, str(logs), str(n), f"{hours:.2f}", str(false), str(anomalies), str(timeouts), str(errors))
    out.print(table)
    for s in stretches:
        if s.spoofed:
            out.print(f"false SPOOFING: {s.log} from {s.start_s:g} s for {s.length_s:g} s: {s.headline}")
    for s in stretches:
        if s.outcome != "analysed":
            out.print(f"{s.outcome}: {s.log} from {s.start_s:g} s for {s.length_s:g} s {s.error}".rstrip())
    out.print(f"{seconds:.0f} s")


@click.command("windows")
@click.argument("dirs", nargs=-1, type=click.Path(path_type=Path, exists=True, file_okay=False))
@click.option("--seed", default=1, show_default=True, help="Where the stretches start (same seed, same stretches).")
@click.option(
    "--length",
    "lengths",
    multiple=True,
    type=float,
    help=f"Stretch length in seconds (repeatable; default {', '.join(f'{x:g}' for x in DEFAULT_LENGTHS_S)}).",
)
@click.option("--draws", default=2, show_default=True, help="Stretches of each length per log.")
@click.option("--min-span", "min_span_s", default=240.0, show_default=True, help="Logs whose GNSS spans less: none.")
@click.option("--timeout", "timeout_s", default=120.0, show_default=True, help="Seconds per stretch.")
@click.option("--jobs", default=2, show_default=True, help="Worker processes.")
@click.option("--only", multiple=True, metavar="GLOB", help="Only logs whose relative path matches (repeatable).")
@click.option(
    "--natural",
    type=click.Choice(sorted(CHANGES)),
    default=None,
    help="First make this natural change to each log it applies to (never an attack; others are left out).",
)
@click.option("--json", "json_path", type=click.Path(path_type=Path), default=None, help="Write everything here.")
def command(
    dirs: tuple[Path, ...],
    seed: int,
    lengths: tuple[float, ...],
    draws: int,
    min_span_s: float,
    timeout_s: float,
    jobs: int,
    only: tuple[str, ...],
    natural: str | None,
    json_path: Path | None,
) -> int:
    """False accusations on stretches of real clean logs cut at random: every clean-sky log of DIRS (default
    ../shared/real) cut into stretches of each length, each analysed as a log of its own."""
    roots = list(dirs) or [default_root()]
    if not all(r.is_dir() for r in roots):
        raise click.UsageError(f"no such folder: {', '.join(str(r) for r in roots if not r.is_dir())}")
    lengths = tuple(lengths) or DEFAULT_LENGTHS_S
    if any(x <= 0 for x in lengths):
        raise click.BadParameter("lengths must be positive", param_hint="--length")
    t0 = time.perf_counter()
    cutting = Cutting(seed, lengths, draws, min_span_s, timeout_s, natural or "")
    stretches = run_windows(clean_logs(roots, only), cutting, jobs, show_progress())
    print_report(stretches, time.perf_counter() - t0)
    if natural:
        console().print(f"each log changed first ({natural}): {(CHANGES[natural].__doc__ or '').strip()}")
    if json_path:
        settings = asdict(cutting) | {"roots": roots}
        json_path.write_text(json.dumps(report_json(stretches, settings), indent=1, default=str))
        console().print(f"JSON: {json_path}")
    return 0


__all__ = ["Cutting", "command", "run_windows", "starts", "stretches_of"]
