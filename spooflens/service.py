"""What every front end of spooflens shares (`analyze`, `inspect`, `inject`, `report`, `batch`, `fleet`, the
benches): reading a log into its epoch table, analysing it, writing its outputs and printing its verdict.

Exit codes: 0 done; 1 internal error (a bug: rerun with --debug); 2 bad input or usage (nothing
analysed, nothing written); 3 the input was damaged and only what could be read was analysed (outputs
written); 4 the verdict is spoofing and --fail-on-spoof was given; 5 the verdict names jamming /
interference (and no spoofing, or no --fail-on-spoof) and --fail-on-jam was given. 4 and 5 win over 3.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

import click
from rich.table import Table

from spooflens.epoch_table import HOLDS, EpochTable
from spooflens.errors import NoGnssError
from spooflens.inventory import has_gnss, without_gnss
from spooflens.output.console import console, progress, show_progress
from spooflens.output.early_recording import EarlyRecording
from spooflens.pipeline.verdict import KIND_LABELS, Kind
from spooflens.threads import side_work

if TYPE_CHECKING:
    from spooflens.baseline.loaded import LoadedBaseline
    from spooflens.pipeline.run import Analysis

EXIT_OK, EXIT_BUG, EXIT_INPUT, EXIT_DAMAGED, EXIT_SPOOFED, EXIT_JAMMED = 0, 1, 2, 3, 4, 5


def parse_topics(values: tuple[str, ...]) -> dict[str, str]:
    topics = {}
    for v in values:
        role, sep, name = v.partition("=")
        if not sep or not role or not name:
            raise click.BadParameter(f"{v!r}: expected ROLE=/topic, e.g. fix=/gps2/fix", param_hint="--topic")
        topics[role.strip()] = name.strip()
    return topics


def read_table(log: Path, topics: dict[str, str], show_progress: bool, solve_fixes: bool = True) -> EpochTable:
    """The log as an epoch table; with `solve_fixes` (every command but `inject`), receivers that logged
    only raw pseudoranges get fixes from their single-point solution (listed as computed), and the truth
    file beside the log, if any, fills the truth frame (drawn, never analysed)."""
    from readers import read_log
    from spooflens.epoch_table import checked
    from spooflens.gnss.solved_fixes import with_solved_fixes
    from spooflens.truth import with_truth_beside

    with progress(show_progress) as report:
        table = read_log(log, topics=topics or None, progress=lambda done, total: report("reading", done, total))
    return checked(with_truth_beside(with_solved_fixes(table), log)) if solve_fixes else table


def damage(table: EpochTable) -> list[str]:
    return [str(s) for s in table.skipped if s.action == "lost"]


def analyse_log(
    log: Path,
    topics: tuple[str, ...],
    imu_grade: str | None,
    quiet: bool,
    station_texts: tuple[str, ...] = (),
    recording: EarlyRecording | None = None,
    baseline: LoadedBaseline | None = None,
) -> list[Analysis]:
    """Read and analyse LOG (its truth file beside it joins the table, for drawing only): one analysis per
    recording the log joins (usually one). `recording`: the log's recording, begun meanwhile
    (`recording_side_work`). `baseline`: the vehicle's (`load_baseline_option`), checked against the log
    before anything is analysed (another receiver model: BaselineError); how the log differs from the
    baseline's logs is warned on stderr.

    A log without any data raises NoGnssError before anything is written: a failed analysis leaves no
    files. One without GNSS data that holds other data is analysed to a NO VERDICT that says why.
    """
    from spooflens.gnss.stations import STATION_OPTION, parse_station
    from spooflens.pipeline.registry import AnalyzeOptions
    from spooflens.pipeline.run import analyze_segments

    try:
        given_stations = [parse_station(text) for text in station_texts]
    except ValueError as err:
        raise click.BadParameter(str(err), param_hint="--station") from None
    table = read_table(log, parse_topics(topics), not quiet and show_progress())
    require_data(log, table)
    baseline = checked_baseline(baseline, table)
    with_obs = list(dict.fromkeys(table.observations["receiver_id"].astype(str)))
    for rid, *_ in given_stations:
        if rid is not None and rid not in with_obs:
            raise click.BadParameter(
                f"no receiver {rid!r} with raw observations in {log}; receivers with them: {with_obs or 'none'}",
                param_hint="--station",
            )
    options = AnalyzeOptions(
        imu_grade=imu_grade, extra={STATION_OPTION: given_stations} if given_stations else {}, baseline=baseline
    )
    with progress(not quiet and show_progress()) as report:
        steps: list[str] = []

        def on_step(name: str) -> None:
            steps.append(name)
            report(f"analysing: {name}", len(steps), len(steps) + 1)

        with side_work(recording_side_work(table, recording)):
            return analyze_segments(table, options, on_step)


def load_baseline_option(path: Path | None) -> LoadedBaseline | None:
    """The `--baseline` file, read and checked before any log is (a bad one: BaselineError, exit 2)."""
    if path is None:
        return None
    from spooflens.baseline.loaded import load

    return load(path)


def checked_baseline(loaded: LoadedBaseline | None, table: EpochTable) -> LoadedBaseline | None:
    """The baseline checked against the log (BaselineError for another receiver model); how the log
    differs from the baseline's logs is said on stderr, one line each."""
    if loaded is None:
        return None
    from spooflens.baseline.loaded import check

    loaded = check(loaded, table)
    for w in loaded.warnings:
        click.echo(f"spooflens: warning: {table.source.name}: baseline {loaded.file}: {w}", err=True)
    return loaded


def recording_side_work(table: EpochTable, recording: EarlyRecording | None) -> Callable[[], None]:
    """What the analysis of `table` may do where it leaves a core idle (`threads.side_work`): begin its
    recording (a log of one recording), else import the recording's library."""
    if recording is not None and len(table.segments) < 2:
        return partial(recording.begin, table)
    return import_writers


def import_writers() -> None:
    """The recording's library, imported while the analysis leaves a core idle."""
    import spooflens.output.recording  # noqa: F401


def require_gnss(log: Path, table: EpochTable) -> None:
    """Raise NoGnssError for a log with no GNSS data at all. Raw observations or satellite reports
    without fixes (a RINEX observation file with no navigation file beside it) are still analysed: the
    detectors that need only them run (C/N0 across satellites), the others say what they lack; so are a
    receiver's monitor messages without a fix (its jamming state, AGC, noise: the interference detector)."""
    if has_gnss(table):
        return
    raise NoGnssError(log, f"{_no_gnss_found(table)}; nothing written")


def require_data(log: Path, table: EpochTable) -> None:
    """Raise NoGnssError for a log that holds no data at all. A log without GNSS data that holds other data
    (an IMU, a heading, a receiver that never had a fix) is analysed: its verdict is NO VERDICT saying why
    (`inventory.without_gnss`), and its recording and report show what it holds."""
    if has_gnss(table) or without_gnss(table):
        return
    raise NoGnssError(log, f"{_no_gnss_found(table)}; nothing written")


def _no_gnss_found(table: EpochTable) -> str:
    lost = "; ".join(str(s) for s in table.skipped if s.action == "lost")
    why = f"; lost: {lost}" if lost else ""
    if HOLDS in table.metadata:
        why = f"; it holds {table.metadata[HOLDS]}{why}"
    return (
        "no GNSS fixes, raw observations or satellite reports found, nor receiver monitor messages "
        f"(streams: {stream_names(table)}{why})"
    )


def finish(log: Path, analyses: list[Analysis], fail_on_spoof: bool, fail_on_jam: bool = False) -> int:
    """The exit code of an analysis that ran: 4 spoofed (with --fail-on-spoof), 5 jamming or interference
    (with --fail-on-jam), 3 damaged input, else 0."""
    damaged = list(dict.fromkeys(d for a in analyses for d in damage(a.table)))
    if damaged:
        click.echo(f"spooflens: {log}: input damaged, analysed what could be read: {'; '.join(damaged)}", err=True)
    if fail_on_spoof and any(a.verdict.spoofed for a in analyses):
        return EXIT_SPOOFED
    if fail_on_jam and any(a.verdict.events_of(Kind.JAMMING) for a in analyses):
        return EXIT_JAMMED
    return EXIT_DAMAGED if damaged else EXIT_OK


def segment_path(path: Path, k: int, n: int) -> Path:
    """An output's path for recording k of n (unchanged for a log of one recording)."""
    return path if n < 2 else path.with_name(f"{path.stem}.seg{k + 1}{path.suffix}")


def segments_summary(summaries: list[dict]) -> dict:
    """The JSON of a log that joins recordings: each recording's summary, and the verdict over all."""
    if len(summaries) == 1:
        return summaries[0]
    spoofed = [i + 1 for i, s in enumerate(summaries) if s["verdict"]["spoofed"]]
    headline = (
        f"SPOOFING DETECTED in recording(s) {', '.join(map(str, spoofed))} of {len(summaries)}"
        if spoofed
        else f"NO SPOOFING DETECTED in any of {len(summaries)} recordings"
    )
    return {"segments": summaries, "verdict": {"spoofed": bool(spoofed), "headline": headline}}


def check_writable(path: Path | None, hint: str, may_be_folder: bool = False) -> None:
    """An output that cannot be written is a usage error, said before the log is read (it was an internal
    error after the whole analysis). `may_be_folder`: a log format written as a folder."""
    if path is None:
        return
    if path.is_dir() and not may_be_folder:
        raise click.BadParameter(f"{path} is a folder, not a file", param_hint=hint)
    _check_folder(path.parent, path, hint)


def _check_folder(folder: Path, output: Path, hint: str) -> None:
    if not folder.is_dir():
        raise click.BadParameter(f"{output}: there is no folder {folder}", param_hint=hint)
    if not os.access(folder, os.W_OK):
        raise click.BadParameter(f"{output}: the folder {folder} cannot be written", param_hint=hint)


def make_output_folder(path: Path, hint: str) -> None:
    """The folder outputs go to, made if missing; one that cannot be made is a usage error, said before
    any log is read."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise click.BadParameter(f"{path}: cannot make this folder ({err.strerror or err})", param_hint=hint) from None
    _check_folder(path, path, hint)


def write_outputs(
    analyses: list[Analysis],
    output: Path,
    json_path: Path | None,
    html_path: Path | None,
    recording: EarlyRecording | None = None,
) -> list[dict]:
    """Write the recording (always), the JSON summary and the operator report of a log's analyses (one per
    recording it joins: `.segN` outputs, one JSON), as `analyze` does (`batch` writes through here too);
    returns each recording's summary. `recording`: the recording begun during the analysis, if any."""
    from spooflens.output.recording import write_recording
    from spooflens.output.summary import build_summary

    n = len(analyses)
    summaries = []
    for k, analysis in enumerate(analyses):
        table, verdict = analysis.table, analysis.verdict
        lines = [(0.0, f"VERDICT: {verdict.headline}", "WARN" if verdict.spoofed else "INFO")]
        path = segment_path(output, k, n)
        begun = recording.take(path, table) if recording is not None else None
        write_recording(path, table, analysis.results, lines, verdict, begun)
        summaries.append(build_summary(table, analysis.results, verdict, analysis.options.baseline))
        if html_path:
            from spooflens.output.report import write_report

            write_report(segment_path(html_path, k, n), analysis)
    if json_path:
        json_path.write_text(json.dumps(segments_summary(summaries), indent=2))
    return summaries


def incident_kind(inc: dict) -> str:
    """How the console names an incident of the JSON summary: a spoofing incident, an event of another
    kind, or an anomaly of one evidence class."""
    kind = inc.get("kind", "spoofing" if inc["confidence"] != "low" else "unknown")
    if kind == "spoofing":
        return "incident"
    if kind == "unknown" and inc.get("confidence_of_alarms", "low") != "low":
        return "anomaly (one evidence class left once the others were explained: not spoofing)"
    if kind == "unknown":
        return "anomaly (no second class at the same time: not spoofing)"
    return f"{KIND_LABELS[Kind(kind)]} (not spoofing)"


def _confidences(inc: dict, index: int, events: list[dict]) -> str:
    """A spoofing incident's confidence; of another kind's, the confidence of spoofing and of the kind (the
    event's: how sure the cause is), which are two things."""
    kind = inc.get("kind", "spoofing")
    if kind in ("spoofing", "unknown"):
        return f"confidence {inc['confidence']}"
    sure = next((e["confidence"] for e in events if e.get("incident") == index and e["kind"] == kind), None)
    of_kind = f", of {KIND_LABELS[Kind(kind)]} {sure}" if sure else ""
    return f"confidence of spoofing {inc['confidence']}{of_kind}"


def stream_names(table: EpochTable) -> str:
    return ", ".join(f"{s.topic} ({s.msgtype})" for s in table.streams) or "none"


def print_analysis(summary: dict, output: Path | None, json_path: Path | None, html_path: Path | None = None) -> None:
    out = console()
    v = summary["verdict"]
    out.print(f"[bold {'red' if v['spoofed'] else 'green'}]{v['headline']}[/]")
    events = v.get("events", [])
    for k, inc in enumerate(v["incidents"]):
        when = f" ({inc['onset_utc']})" if inc.get("onset_utc") else ""
        apart = [e for e in inc["evidence"] if e not in inc.get("corroborating_evidence", inc["evidence"])]
        also = f"; at other times {', '.join(apart)}" if apart else ""
        end = "end of log" if inc.get("ongoing_at_end") else f"{inc['end_s']:.2f} s"
        sats = f", satellites {'+'.join(inc['satellites'])}" if inc.get("satellites") else ""
        before = inc.get("confidence_of_alarms", inc["confidence"])
        alarms_said = f" (the alarms alone: {before})" if before != inc["confidence"] else ""
        out.print(
            f"  {incident_kind(inc)}: onset {inc['onset_s']:.2f} s{when}, alarm {inc['start_s']:.2f} s to {end}, "
            f"evidence {', '.join(inc.get('corroborating_evidence') or inc['evidence']) or 'none confirmed'}{also} "
            f"({', '.join(inc['detectors'])}){sats}, "
            f"{_confidences(inc, k, events)}{alarms_said}"
        )
        for e in inc.get("explanations", []):
            weighed = "weighed, not enough" if inc["spoofing"] else "explained"
            out.print(f"      {weighed}: {e['text']}")
    for e in events:
        if e.get("sequence") and e["sequence"]["followed_by"] is not None:
            then = events[e["sequence"]["followed_by"]]
            out.print(
                f"  attack sequence: {e['kind_label']} from {e['start_s']:.2f} s to {e['end_s']:.2f} s, then "
                f"{then['kind_label']} from {then['onset_s']:.2f} s"
            )
    for f in v.get("findings", []):
        out.print(f"  finding: {f['text']}")
    t = Table("analysis", "evidence", "ran", "alarms", "note")
    for a in summary["analyses"]:
        alarms = str(len(a["alarms"])) + (" (advisory)" if a.get("advisory") and a["alarms"] else "")
        t.add_row(a["name"], a.get("evidence_label") or "(product)", "yes" if a["ran"] else "no", alarms, a["reason"])
    out.print(t)
    if "baseline" in summary:
        b = summary["baseline"]
        out.print(
            f"baseline: {b['file']} (SHA-256 {b['sha256'][:16]}..., {b['logs']} clean log(s))"
            + ("" if b["used_by"] else ": no analysis could use it on this log")
        )
        for name, what in b["used_by"].items():
            out.print(f"  {name}: {what}")
        for w in b["warnings"]:
            out.print(f"  warning: {w}")
    for sk in summary["skipped"]:
        out.print(f"  skipped: {sk['stream']}: {sk['action']} {sk['count']} ({sk['reason']})")
    for made in summary.get("computed", []):
        out.print(f"  computed: {made['stream']}: {made['count']} ({made['reason']})")
    written = [
        f"{what}: {path}"
        for what, path in (("recording", output), ("summary", json_path), ("report", html_path))
        if path is not None
    ]
    out.print("   ".join(written))
    if output is not None:
        out.print(f"view it with: spooflens view {output}")
