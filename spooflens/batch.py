"""`spooflens batch`: every log of a day (a fleet, a folder tree) analysed on dask.distributed.

    spooflens batch 'logs/**/*' -o results/ [--scheduler tcp://host:8786] [--workers N]

One task per log, on a LocalCluster of `--workers` processes (one thread each: the analysis is
single-threaded numpy and numba) or on a running cluster given by its scheduler's address (its workers
need spooflens installed and the logs and `-o` on a filesystem they share with this machine). Each task
does what `spooflens analyze LOG -o .rrd --json .json --html .html` does (the same functions) and writes
into `results/<log name>-<hash>/`, then a `done.json` naming the log's content hash: a rerun skips every
log whose content was analysed already (a log that failed is tried again). A log that cannot be read or
analysed is reported with its one-line error and never stops the batch. At the end, from every
`done.json` under `results/`: `incidents.parquet` (one row per incident of every log: the fleet table)
and `logs.parquet` (one row per log: verdict, status, outputs), and a summary on the console.

What counts as a log: every path the patterns match that the readers recognise by content (the same
sniffing `analyze` does). A directory that is one log (a ROS2 bag with its metadata.yaml or .db3, a
CSV, RINEX or NMEA folder) is one log and the files inside it are not taken again; a folder that only
holds other logs (e.g. flights as .mcap files) is not a log itself, nor is a CSV, RINEX or NMEA folder
that also holds logs of another format (`readers.separate_logs`): each of its files is a log. Files no
reader recognises (the truth and attack sidecars, READMEs) and files that serve a log rather than being
one (RINEX navigation files: `ReaderFormat.companion`) are counted as not logs.
"""

from __future__ import annotations

import glob
import hashlib
import json
import logging
import os
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click
from rich.table import Table

from spooflens.cli import baseline_option
from spooflens.output.console import console, progress, show_progress

EXIT_OK, EXIT_DAMAGED = 0, 3
DONE = "done.json"
SIDECARS = (".truth.csv", ".attack.json", ".rrd", ".html", ".parquet")
_HASH_BLOCK = 1 << 20


@dataclass(frozen=True)
class LogJob:
    path: Path
    digest: str  # sha256 of the content (a directory: of its files' relative names and contents)

    @property
    def name(self) -> str:
        """Folder of this log's outputs: its name and the start of its hash (two logs may share a name)."""
        stem = re.sub(r"[^A-Za-z0-9_.-]", "_", self.path.name.rstrip("/")) or "log"
        return f"{stem}-{self.digest[:12]}"


def content_hash(path: Path) -> str:
    h = hashlib.sha256()
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    for f in files:
        if path.is_dir():
            h.update(str(f.relative_to(path)).encode() + b"\0")
        with f.open("rb") as stream:
            while block := stream.read(_HASH_BLOCK):
                h.update(block)
    return h.hexdigest()


def largest_first(jobs: list[LogJob]) -> list[LogJob]:
    """The order the tasks are given to the workers: the largest logs first (an analysis takes about the
    time its log's size says), so the last tasks to finish are short ones and the workers end together
    rather than one waiting on a long log."""
    return sorted(jobs, key=lambda j: log_size(j.path), reverse=True)


def log_size(path: Path) -> int:
    """Bytes of a log (a directory: of its files)."""
    if path.is_file():
        return path.stat().st_size
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def _is_log_dir(path: Path) -> bool:
    """A directory that is one log (not a folder of logs)."""
    from readers import recognised_format

    try:
        return recognised_format(path) is not None
    except Exception:  # noqa: BLE001 - not a log: that is all sniffing says
        return False


def find_logs(patterns: tuple[str, ...]) -> tuple[list[Path], list[Path]]:
    """(logs, paths that are not logs) matched by shell-style `patterns` (`**` recursive)."""
    from readers import is_companion, sniff_format

    matched: list[Path] = []
    for pattern in patterns:
        literal = not any(c in pattern for c in "*?[")
        if literal and Path(pattern).is_dir() and not _is_log_dir(Path(pattern)):
            # a folder named as it is (`spooflens batch flights/`) means the logs in it, at any depth
            pattern = glob.escape(pattern.rstrip("/")) + "/**/*"
        hits = sorted(glob.glob(pattern, recursive=True)) or ([pattern] if Path(pattern).exists() else [])  # noqa: PTH207
        matched += [Path(h) for h in hits]
    matched = list(dict.fromkeys(p.resolve() for p in matched))
    log_dirs = [p for p in matched if p.is_dir() and _is_log_dir(p)]
    logs: list[Path] = []
    not_logs: list[Path] = []
    for p in matched:
        if any(d != p and d in p.parents for d in log_dirs):
            continue  # a file (or folder) inside a log directory belongs to that log
        if p.is_dir():
            if p in log_dirs:
                logs.append(p)
            continue
        if p.name.endswith(SIDECARS) or p.name == DONE:
            not_logs.append(p)
            continue
        try:
            fmt = sniff_format(p)
        except Exception:  # noqa: BLE001 - unknown content: not a log (reported as such)
            not_logs.append(p)
            continue
        (not_logs if is_companion(p, fmt) else logs).append(p)
    return logs, not_logs


def analyse_one(
    log: str, digest: str, out_dir: str, imu_grade: str | None, baseline: str | None = None
) -> dict[str, Any]:
    """The task: analyse one log and write its outputs; never raises (a failure is a record). `baseline`:
    the vehicle's baseline file, read by the worker (a log of another receiver model fails)."""
    from spooflens.errors import SpooflensError
    from spooflens.pipeline.registry import AnalyzeOptions
    from spooflens.pipeline.run import analyze_segments
    from spooflens.service import (
        checked_baseline,
        damage,
        load_baseline_option,
        read_table,
        require_data,
        segments_summary,
        write_outputs,
    )
    from spooflens.threads import limited

    path, out = Path(log), Path(out_dir)
    record: dict[str, Any] = {"log": str(path), "sha256": digest, "outputs": str(out)}
    t0 = time.perf_counter()
    try:
        loaded = load_baseline_option(Path(baseline) if baseline else None)
        table = read_table(path, {}, False)
        require_data(path, table)
        loaded = checked_baseline(loaded, table)
        if loaded is not None:
            record["baseline_sha256"] = loaded.sha256
            record["baseline_warnings"] = list(loaded.warnings)
        with limited(1):  # one task per core already: a second thread per task would only contend
            analyses = analyze_segments(table, AnalyzeOptions(imu_grade=imu_grade, baseline=loaded))
        out.mkdir(parents=True, exist_ok=True)
        stem = path.name.rstrip("/")
        files = {"rrd": out / f"{stem}.rrd", "json": out / f"{stem}.json", "html": out / f"{stem}.html"}
        summaries = write_outputs(analyses, files["rrd"], files["json"], files["html"])
    except SpooflensError as err:
        return record | {"status": "failed", "error": str(err), "seconds": time.perf_counter() - t0}
    except Exception as err:  # noqa: BLE001 - a bug on one log is reported, the batch goes on
        return record | {
            "status": "failed",
            "error": f"internal error: {type(err).__name__}: {err}",
            "seconds": time.perf_counter() - t0,
        }
    # a log that joins several recordings: one verdict over all, every recording's incidents
    verdict = segments_summary(summaries)["verdict"]
    damaged = list(dict.fromkeys(d for a in analyses for d in damage(a.table)))
    record |= {
        "status": "damaged" if damaged else "done",
        "error": "; ".join(damaged),
        "seconds": time.perf_counter() - t0,
        "spoofed": bool(verdict["spoofed"]),
        "headline": verdict["headline"],
        "duration_s": float(sum(a.table.duration_s for a in analyses)),
        "start_utc": analyses[0].table.absolute_iso(0.0),
        "recordings": len(analyses),
        "files": {k: str(v) for k, v in files.items()},
        "incidents": [i for s in summaries for i in s["verdict"]["incidents"]],
    }
    (out / DONE).write_text(json.dumps(record, indent=1))
    return record


def done_records(results: Path) -> dict[str, dict[str, Any]]:
    """sha256 -> record of every log analysed into `results` before (its done.json)."""
    out: dict[str, dict[str, Any]] = {}
    for marker in sorted(results.glob(f"*/{DONE}")):
        try:
            record = json.loads(marker.read_text())
            out[str(record["sha256"])] = record
        except (OSError, ValueError, KeyError):
            continue  # a marker cut short by a killed run: that log is analysed again
    return out


def write_fleet_tables(results: Path, records: list[dict[str, Any]]) -> tuple[Path, Path]:
    """incidents.parquet (every incident of every log) and logs.parquet (every log) in `results`."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    incident_rows = []
    for r in records:
        for i, inc in enumerate(r.get("incidents") or []):
            incident_rows.append(
                {
                    "log": r["log"],
                    "sha256": r["sha256"],
                    "incident": i,
                    "is_spoofing": bool(inc.get("spoofing", inc.get("confidence") != "low")),
                    "kind": inc.get("kind"),
                    "confidence": inc.get("confidence"),
                    "onset_s": inc.get("onset_s"),
                    "start_s": inc.get("start_s"),
                    "end_s": inc.get("end_s"),
                    "onset_utc": inc.get("onset_utc"),
                    "ongoing_at_end": bool(inc.get("ongoing_at_end", False)),
                    "evidence": ",".join(inc.get("evidence_labels") or []),
                    "detectors": ",".join(inc.get("detectors") or []),
                    "satellites": ",".join(inc.get("satellites") or []),
                }
            )
    schema = pa.schema(
        [
            ("log", pa.string()),
            ("sha256", pa.string()),
            ("incident", pa.int32()),
            ("is_spoofing", pa.bool_()),
            ("kind", pa.string()),
            ("confidence", pa.string()),
            ("onset_s", pa.float64()),
            ("start_s", pa.float64()),
            ("end_s", pa.float64()),
            ("onset_utc", pa.string()),
            ("ongoing_at_end", pa.bool_()),
            ("evidence", pa.string()),
            ("detectors", pa.string()),
            ("satellites", pa.string()),
        ]
    )
    incidents = results / "incidents.parquet"
    pq.write_table(pa.Table.from_pylist(incident_rows, schema=schema), incidents)
    log_rows = [
        {
            "log": r["log"],
            "sha256": r["sha256"],
            "status": r["status"],
            "spoofed": r.get("spoofed"),
            "headline": r.get("headline") or r.get("error"),
            "incidents": len(r.get("incidents") or []),
            "duration_s": r.get("duration_s"),
            "start_utc": r.get("start_utc"),
            "outputs": r.get("outputs"),
        }
        for r in records
    ]
    logs = results / "logs.parquet"
    log_schema = pa.schema(
        [
            ("log", pa.string()),
            ("sha256", pa.string()),
            ("status", pa.string()),
            ("spoofed", pa.bool_()),
            ("headline", pa.string()),
            ("incidents", pa.int32()),
            ("duration_s", pa.float64()),
            ("start_utc", pa.string()),
            ("outputs", pa.string()),
        ]
    )
    pq.write_table(pa.Table.from_pylist(log_rows, schema=log_schema), logs)
    return incidents, logs


@dataclass
class BatchResult:
    analysed: list[dict[str, Any]]  # this run's records (done, damaged, failed)
    skipped: list[dict[str, Any]]  # logs whose content was analysed before
    not_logs: list[Path]
    wall_s: float  # the whole run, cluster start and fleet tables included
    tasks_s: float  # from the first task submitted to the last result
    workers: int
    incidents_path: Path
    logs_path: Path


def run_batch(
    patterns: tuple[str, ...],
    results: Path,
    scheduler: str | None = None,
    workers: int | None = None,
    imu_grade: str | None = None,
    show: bool = False,
    baseline: Path | None = None,
) -> BatchResult:
    """Analyse every log `patterns` match that `results` has not seen (by content) on dask; write the
    fleet tables over everything in `results`."""
    from dask.distributed import Client, LocalCluster, as_completed

    t0 = time.perf_counter()
    results.mkdir(parents=True, exist_ok=True)
    logs, not_logs = find_logs(patterns)
    results_dir = results.resolve()
    logs = [p for p in logs if results_dir not in p.parents and p != results_dir]  # never our own outputs
    # a log analysed before with another baseline (or none) is analysed again
    baseline_sha = hashlib.sha256(baseline.read_bytes()).hexdigest() if baseline is not None else None
    before = {k: r for k, r in done_records(results).items() if r.get("baseline_sha256") == baseline_sha}
    jobs: list[LogJob] = []
    skipped: list[dict[str, Any]] = []
    first_of: dict[str, Path] = {}
    for p in logs:
        job = LogJob(p, content_hash(p))
        if job.digest in before:
            skipped.append(before[job.digest])
        elif job.digest in first_of:  # the same bytes twice in this batch: analysed once
            same = {"log": str(p), "sha256": job.digest, "headline": f"same content as {first_of[job.digest]}"}
            skipped.append(same)
        else:
            first_of[job.digest] = p
            jobs.append(job)
    analysed: list[dict[str, Any]] = []
    n_workers, tasks_s = 0, 0.0
    if jobs:
        cluster = None
        if scheduler is None:
            cluster = LocalCluster(
                n_workers=workers or max(1, min(os.cpu_count() or 1, len(jobs))),
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
                silence_logs=logging.ERROR,
            )
        client = Client(cluster if cluster is not None else scheduler, set_as_default=False)
        try:
            n_workers = len(client.scheduler_info(n_workers=-1)["workers"])
            t_submit = time.perf_counter()
            by_size = largest_first(jobs)
            futures = [
                client.submit(
                    analyse_one,
                    str(j.path),
                    j.digest,
                    str(results / j.name),
                    imu_grade,
                    str(baseline.resolve()) if baseline is not None else None,
                    key=f"spooflens-{j.digest}",
                    priority=len(by_size) - rank,
                )
                for rank, j in enumerate(by_size)
            ]
            with progress(show) as report:
                report("analysing logs", 0, len(futures))
                for done, future in enumerate(as_completed(futures, loop=client.loop), start=1):
                    analysed.append(future.result())
                    report("analysing logs", done, len(futures))
            tasks_s = time.perf_counter() - t_submit
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    records = list(done_records(results).values()) + [r for r in analysed if r["status"] == "failed"]
    incidents_path, logs_path = write_fleet_tables(results, records)
    wall_s = time.perf_counter() - t0
    return BatchResult(analysed, skipped, not_logs, wall_s, tasks_s, n_workers, incidents_path, logs_path)


def _print(result: BatchResult) -> None:
    out = console()
    t = Table("log", "status", "verdict", "incidents", "time (s)", title="spooflens batch")
    for r in sorted(result.analysed, key=lambda r: r["log"]):
        t.add_row(
            r["log"],
            r["status"],
            r.get("headline") or r.get("error", ""),
            str(len(r.get("incidents") or [])),
            f"{r['seconds']:.1f}",
        )
    for r in result.skipped:
        t.add_row(r["log"], "already done", r.get("headline", ""), str(len(r.get("incidents") or [])), "-")
    out.print(t)
    failed = [r for r in result.analysed if r["status"] == "failed"]
    done = [r for r in result.analysed if r["status"] != "failed"]
    spoofed = [r for r in [*done, *result.skipped] if r.get("spoofed")]
    rate = len(done) / result.wall_s * 3600 if done else 0.0
    out.print(
        f"{len(done)} analysed, {len(failed)} failed, {len(result.skipped)} already done, "
        f"{len(result.not_logs)} paths not logs; {len(spoofed)} log(s) with spoofing; "
        f"{result.wall_s:.1f} s on {result.workers or 0} worker(s) ({rate:.0f} logs/h)"
    )
    for r in failed:
        out.print(f"  failed: {r['error']}")
    if result.not_logs:
        names = ", ".join(p.name for p in result.not_logs[:10]) + (", ..." if len(result.not_logs) > 10 else "")
        out.print(f"  not logs (no reader recognises them): {names}")
    out.print(f"fleet table: {result.incidents_path}   logs: {result.logs_path}")


@click.command("batch")
@click.argument("patterns", nargs=-1, required=True)
@click.option("-o", "--output", type=click.Path(path_type=Path), required=True, help="Results folder.")
@click.option("--scheduler", default=None, help="Address of a running dask scheduler (default: a LocalCluster).")
@click.option(
    "--workers",
    type=int,
    default=None,
    help="LocalCluster worker processes (default: one per core, at most one per log).",
)
@click.option("--imu-grade", default=None, help="IMU noise preset for every log (default: from each log).")
@baseline_option
@click.option("--quiet", is_flag=True, help="Print only the summary line.")
def command(
    patterns: tuple[str, ...],
    output: Path,
    scheduler: str | None,
    workers: int | None,
    imu_grade: str | None,
    baseline_path: Path | None,
    quiet: bool,
) -> int:
    """Analyse every log PATTERNS match ('logs/**/*', quoted) on dask: per-log outputs, a fleet table."""
    from spooflens.service import load_baseline_option, make_output_folder

    load_baseline_option(baseline_path)  # a bad baseline is refused before any log is analysed
    make_output_folder(output, "--output")
    result = run_batch(
        patterns, output, scheduler, workers, imu_grade, show=not quiet and show_progress(), baseline=baseline_path
    )
    if quiet:
        failed = sum(r["status"] == "failed" for r in result.analysed)
        click.echo(f"{len(result.analysed) - failed} analysed, {failed} failed, {len(result.skipped)} already done")
    else:
        _print(result)
    bad = any(r["status"] != "done" for r in result.analysed)
    return EXIT_DAMAGED if bad else EXIT_OK
