"""The report page: one self-contained HTML file (inline CSS and SVG, no script, nothing fetched).

Sections in the order an operator reads them: the verdict, the timeline, the track, the evidence,
data quality, provenance and method notes. Everything is taken from the analysis as declared (the
verdict, each result's series and alarms, the detector declarations, the table's streams and
metadata), so a new detector or evidence class shows up without an edit here.
"""

from __future__ import annotations

import html
import math
import platform
from collections.abc import Iterable, Sequence
from dataclasses import asdict, fields, is_dataclass
from datetime import UTC, datetime
from importlib.metadata import PackageNotFoundError, version
from typing import Any

from spooflens import __version__
from spooflens.detectors.base import DetectorResult
from spooflens.epoch_table import TIME_REFERENCES, EpochTable
from spooflens.inventory import computed, skipped_or_repaired, stream_rows
from spooflens.output.report.figures import MAX_LABELLED, Plot
from spooflens.output.report.provenance import InputIdentity
from spooflens.pipeline.departure import Departure, gnss_departure
from spooflens.pipeline.evidence import EVIDENCE, NOT_SPOOFING, label
from spooflens.pipeline.registry import DetectorInfo
from spooflens.pipeline.run import Analysis
from spooflens.pipeline.verdict import KIND_LABELS, Incident, Kind, Verdict

CSS = """
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;color:#212529;margin:0;
background:#f8f9fa}
main{max-width:1120px;margin:0 auto;padding:12px 20px 40px;background:#fff}
h1{font-size:20px;margin:8px 0 2px}h2{font-size:17px;border-bottom:2px solid #dee2e6;padding-bottom:3px;margin-top:28px}
h3{font-size:14.5px;margin:18px 0 4px}
nav{font-size:13px;color:#495057;margin-bottom:8px}nav a{margin-right:12px;color:#1864ab}
.verdict{border-radius:6px;padding:12px 16px;margin:10px 0;color:#fff}
.verdict .big{font-size:24px;font-weight:700;letter-spacing:.02em}
.spoofed{background:#c92a2a}.jammed{background:#d9480f}.clean{background:#2b8a3e}.none{background:#868e96}
.verdict p{margin:6px 0 0}
table{border-collapse:collapse;font-size:12.5px;margin:6px 0;width:100%}
th,td{border:1px solid #dee2e6;padding:3px 6px;text-align:left;vertical-align:top}
th{background:#f1f3f5}td.num{text-align:right;font-variant-numeric:tabular-nums}
.muted{color:#868e96}.small{font-size:12px}.advisory{color:#868e96}
figure.plot{margin:14px 0;border:1px solid #e9ecef;border-radius:4px;padding:6px}
figure.plot svg{width:100%;height:auto;display:block}
figcaption{font-size:12px;color:#495057;margin-top:3px}figcaption b{color:#212529}
code{font-size:12px;background:#f1f3f5;padding:0 3px;border-radius:3px}
ul{margin:4px 0 4px 18px;padding:0}
@media print{body{background:#fff}main{max-width:none}figure.plot{break-inside:avoid}}
"""


def esc(x: object) -> str:
    return html.escape(str(x), quote=True)


def _table(head: Sequence[str], rows: Iterable[Sequence[object]], numeric: Sequence[int] = ()) -> str:
    out = ["<table><thead><tr>", *(f"<th>{esc(h)}</th>" for h in head), "</tr></thead><tbody>"]
    for row in rows:
        cells = (
            f'<td class="num">{esc(c)}</td>' if i in numeric else f"<td>{c if isinstance(c, Raw) else esc(c)}</td>"
            for i, c in enumerate(row)
        )
        out += ["<tr>", *cells, "</tr>"]
    out.append("</tbody></table>")
    return "".join(out)


class Raw(str):
    """Markup already escaped, to put in a table cell as it is."""


def _when(table: EpochTable, t_s: float | None) -> str:
    if t_s is None or not math.isfinite(t_s):
        return "-"
    clock = f" ({table.absolute_iso(t_s)})" if table.unix_ns(t_s) is not None else ""
    return f"{t_s:.2f} s{clock}"


def _interval(iv: tuple[float, float] | None) -> str:
    return f"{iv[0]:.2f}-{iv[1]:.2f} s" if iv else ""


def _end(table: EpochTable, inc: Incident) -> str:
    if inc.ongoing_at_end:
        return "still going on at the end of the log"
    iv = getattr(inc, "end_interval_s", None)
    how = getattr(inc, "end_method", "")
    return _when(table, inc.end_s) + (f", interval {_interval(iv)}" if iv else "") + (f" ({how})" if how else "")


def _departures(deps: Sequence[Departure]) -> str:
    return "; ".join(
        f"{d.receiver_id}: peak {d.peak_m:.1f} m at {d.peak_s:.1f} s, {d.end_m:.1f} m at {d.end_s:.1f} s" for d in deps
    )


def _evidence_text(inc: Incident) -> str:
    """The classes that agreed in time, then any that alarmed in the incident at another time."""
    agreeing = inc.corroborating
    text = ", ".join(label(e) for e in agreeing)
    apart = [label(e) for e in inc.evidence if e not in agreeing]
    return (text or "none confirmed") + (f" (also, at other times: {', '.join(apart)})" if apart else "")


def _incident_sentence(table: EpochTable, inc: Incident, n: int, deps: Sequence[Departure]) -> str:
    onset = _when(table, inc.onset_s)
    iv = f" (interval {_interval(inc.onset_interval_s)})" if inc.onset_interval_s else ""
    evidence = _evidence_text(inc)
    sats = f" Satellites found inconsistent: {', '.join(inc.satellites)}." if inc.satellites else ""
    rx = f" Receivers: {', '.join(inc.receivers)}." if inc.receivers else ""
    far = ""
    if deps:
        d = max(deps, key=lambda x: x.peak_m)
        far = (
            f" GNSS went up to {d.peak_m:.0f} m from the reconstructed track ({d.end_m:.0f} m at the end of the"
            " incident)."
        )
    return (
        f"Incident {n}: GNSS spoofed from {onset}{iv} to {_end(table, inc)}; first alarm at "
        f"{inc.start_s:.2f} s. Agreeing: {', '.join(inc.detectors)} ({evidence}); confidence {inc.confidence}."
        f"{rx}{sats}{far}"
    )


def _kind_of(inc: Incident) -> Kind:
    return inc.kind if inc.kind is not None else Kind.SPOOFING if inc.is_spoofing else Kind.UNKNOWN


def _kind_cell(inc: Incident) -> str:
    kind = _kind_of(inc)
    if kind == Kind.SPOOFING:
        return "spoofing"
    if kind == Kind.UNKNOWN and inc.confidence_of_alarms != "low":
        return "anomaly (one evidence class left once the others were explained: not spoofing)"
    if kind == Kind.UNKNOWN:
        return "anomaly (no second class at the same time: not spoofing)"
    return f"{KIND_LABELS[kind]} (not spoofing)"


def _explanation_cell(inc: Incident) -> str:
    """The natural causes weighed: for a spoofing incident those that held but did not reach its evidence."""
    texts = [e.text for e in inc.explanations]
    if not texts:
        return "-"
    if inc.is_spoofing:
        return f"weighed, not enough ({', '.join(label(c) for c in inc.unexplained)} unexplained): " + "; ".join(texts)
    return "; ".join(texts)


def _banner(verdict: Verdict) -> tuple[str, str]:
    """(css class, big words): the kind of event first."""
    if not verdict.detectors_run:
        return "none", "NO VERDICT"
    if verdict.spoofed:
        return "spoofed", "SPOOFING DETECTED"
    if verdict.events_of(Kind.JAMMING):
        return "jammed", "JAMMING / INTERFERENCE"
    return "clean", "NO SPOOFING DETECTED"


def _kind_sentences(verdict: Verdict) -> list[str]:
    """One sentence per kind of event other than spoofing and unexplained anomalies: its first event."""
    out = []
    for kind in (Kind.JAMMING, Kind.DEGRADATION, Kind.RECEIVER_FAULT):
        events = verdict.events_of(kind)
        if events:
            more = f" ({len(events) - 1} more in the table below)" if len(events) > 1 else ""
            first = events[0]
            why = f": {first.evidence_for[0]}" if first.evidence_for else ""
            end = "the end of the log" if first.ongoing_at_end else f"{first.end_s:.2f} s"
            name = KIND_LABELS[kind]
            out.append(f"{name[:1].upper()}{name[1:]} from {first.start_s:.2f} s to {end}{why}{more}.")
    return out


def verdict_section(analysis: Analysis) -> str:
    table, verdict, results = analysis.table, analysis.verdict, analysis.results
    kind, big = _banner(verdict)
    deciding = verdict.deciding_incident
    deps = gnss_departure(table, results, verdict, deciding) if deciding is not None and deciding.is_spoofing else []
    lines = [f'<div class="verdict {kind}" id="verdict-banner"><div class="big">{big}</div>']
    lines.append(f"<p>{esc(verdict.headline)}</p>")
    if deciding is not None and deciding.is_spoofing:
        n = verdict.incidents.index(deciding) + 1
        lines.append(f"<p>{esc(_incident_sentence(table, deciding, n, deps))}</p>")
        if deciding.explanations:
            lines.append(f"<p>Natural causes weighed: {esc(_explanation_cell(deciding))}.</p>")
    lines += [f"<p>{esc(text)}</p>" for text in _kind_sentences(verdict)]
    lines.append("</div>")
    if verdict.incidents:
        rows = []
        for i, inc in enumerate(verdict.incidents, 1):
            d = gnss_departure(table, results, verdict, inc) if inc is deciding and inc.is_spoofing else []
            rows.append(
                (
                    i,
                    _kind_cell(inc),
                    _when(table, inc.onset_s)
                    + (f", interval {_interval(inc.onset_interval_s)}" if inc.onset_interval_s else ""),
                    f"{inc.start_s:.2f} s",
                    _end(table, inc),
                    ", ".join(inc.detectors),
                    _evidence_text(inc),
                    inc.confidence
                    + (
                        f" (alarms alone: {inc.confidence_of_alarms})"
                        if inc.confidence_of_alarms != inc.confidence
                        else ""
                    ),
                    _explanation_cell(inc),
                    ", ".join(inc.receivers) or "-",
                    ", ".join(inc.satellites) or "-",
                    _departures(d) or "-",
                )
            )
        lines.append(incidents_table(rows, [inc.is_spoofing for inc in verdict.incidents]))
    if verdict.findings:
        lines.append("<h3>Findings</h3><ul>")
        lines += [f"<li>{esc(f.text)} ({f.start_s:.1f}-{f.end_s:.1f} s)</li>" for f in verdict.findings]
        lines.append("</ul>")
    lines.append(_detector_status(results, verdict))
    return "\n".join(lines)


INCIDENT_COLUMNS = (
    "#",
    "kind",
    "onset (estimated)",
    "first alarm",
    "end",
    "detectors",
    "evidence",
    "confidence of spoofing",
    "natural explanation",
    "receivers",
    "satellites",
    "GNSS off the reconstructed track",
)


def incidents_table(rows: Sequence[Sequence[object]], spoofing: Sequence[bool]) -> str:
    """The incidents, a row each. Beyond MAX_LABELLED, the anomalies (one evidence class, not spoofing)
    fold into a <details> below the spoofing incidents: two hundred of them on a real boat's log buried
    the page under the verdict."""
    if len(rows) <= MAX_LABELLED or all(spoofing):
        return _table(INCIDENT_COLUMNS, rows)
    shown = [r for r, s in zip(rows, spoofing, strict=True) if s]
    folded = [r for r, s in zip(rows, spoofing, strict=True) if not s]
    summary = f"{len(folded)} anomalies and natural events (not spoofing): show them"
    parts = [_table(INCIDENT_COLUMNS, shown)] if shown else []
    return "".join([*parts, f"<details><summary>{esc(summary)}</summary>{_table(INCIDENT_COLUMNS, folded)}</details>"])


def _detector_status(results: Sequence[DetectorResult], verdict: Verdict) -> str:
    """The detectors that ran; those that did not are listed, folded, at the end of the page."""
    rows = []
    for r in results:
        if not r.is_detector or not r.ran:
            continue
        status = (
            "counted"
            if r.name in verdict.detectors_run
            else "reported (no spoofing evidence)"
            if r.evidence in NOT_SPOOFING
            else "advisory"
        )
        rows.append((r.name, label(r.evidence) if r.evidence else "", status, len(r.alarms), r.reason))
    not_run = sum(not r.ran for r in results)
    if not rows and not not_run:
        return ""
    table = _table(("detector", "evidence", "status", "alarms", "note"), rows, numeric=(3,)) if rows else ""
    later = (
        f'<p class="muted small">{not_run} analyses did not run on this log: '
        '<a href="#not-run">listed at the end of the page</a>.</p>'
    )
    return "<h3>Detectors</h3>" + table + (later if not_run else "")


def _plots(plots: Sequence[Plot]) -> str:
    return "\n".join(
        f'<figure class="plot" id="plot-{esc(p.key)}" data-plot="{esc(p.key)}">{p.svg}'
        f"<figcaption><b>{esc(p.title)}.</b> {esc(p.caption)}</figcaption></figure>"
        for p in plots
    )


def data_quality_section(table: EpochTable) -> str:
    rows = [(r.role, r.stream, r.source, r.type, r.count, r.rate, r.span, r.body_frame) for r in stream_rows(table)]
    out = [
        f"<p>{esc(table.format)} log, {table.duration_s:.1f} s. Times in seconds since the log start.</p>",
        _table(("role", "stream", "source", "type", "count", "rate (Hz)", "span (s)", "body frame"), rows),
    ]
    lost = skipped_or_repaired(table)
    out.append("<h3>Skipped or repaired</h3>")
    out.append(
        _table(("stream", "action", "count", "reason"), [(s.stream, s.action, s.count, s.reason) for s in lost], (2,))
        if lost
        else '<p class="muted">Nothing was skipped or repaired.</p>'
    )
    made = computed(table)
    if made:
        out.append("<h3>Computed</h3>")
        out.append(_table(("stream", "count", "how"), [(s.stream, s.count, s.reason) for s in made], (1,)))
    segments = getattr(table, "segments", None)
    if segments:
        out.append("<h3>Segments</h3>")
        out.append(_records(segments))
    return "\n".join(out)


def _records(items: Iterable[Any]) -> str:
    """A table of whatever records the table carries (dataclasses, mappings, or plain values)."""
    items = list(items)
    if items and all(is_dataclass(x) and not isinstance(x, type) for x in items):
        head = [f.name for f in fields(items[0])]
        return _table(head, [[asdict(x).get(h, "") for h in head] for x in items])
    if items and all(isinstance(x, dict) for x in items):
        head = list(dict.fromkeys(k for x in items for k in x))
        return _table(head, [[x.get(h, "") for h in head] for x in items])
    return "<ul>" + "".join(f"<li>{esc(x)}</li>" for x in items) + "</ul>"


def _library_versions() -> str:
    names = ("numpy", "scipy", "pandas", "matplotlib", "rerun-sdk")
    out = []
    for n in names:
        try:
            out.append(f"{n} {version(n)}")
        except PackageNotFoundError:
            continue
    return ", ".join([f"Python {platform.python_version()}", *out])


def _baseline_rows(analysis: Analysis) -> list[tuple[str, object]]:
    """The vehicle baseline the analysis judged the log against: its file, SHA-256, what each analysis
    took from it, and how the log differs from the logs it was learned from."""
    loaded = analysis.options.baseline
    if loaded is None:
        return []
    from spooflens.output.summary import baseline_block

    block = baseline_block(loaded, analysis.results)
    rows: list[tuple[str, object]] = [
        ("baseline", f"{block['file']} ({block['logs']} clean log(s), made {block['created_utc']})"),
        ("baseline SHA-256", Raw(f"<code>{esc(block['sha256'])}</code>")),
    ]
    rows += [(f"from the baseline: {name}", what) for name, what in block["used_by"].items()]
    rows += [("baseline warning", w) for w in block["warnings"]]
    return rows


def provenance_section(analysis: Analysis, identity: InputIdentity) -> str:
    table = analysis.table
    meta = dict(table.metadata)
    enums = {k.removeprefix("enum."): v for k, v in meta.items() if k.startswith("enum.")}
    other = {k: v for k, v in meta.items() if not k.startswith("enum.")}
    options = {
        f.name: getattr(analysis.options, f.name)
        for f in fields(analysis.options)
        if f.name != "baseline" and getattr(analysis.options, f.name) not in (None, {}, "")
    }
    start = table.absolute_iso(0.0)
    rows: list[tuple[str, object]] = [
        ("file", identity.name),
        ("path given", str(table.source)),
        ("size", f"{identity.size_bytes:,} bytes"),
        ("SHA-256", Raw(f"<code>{esc(identity.sha256)}</code> <span class='muted'>({esc(identity.how)})</span>")),
        ("format", table.format),
        ("time reference", f"{table.time_reference}: {TIME_REFERENCES.get(table.time_reference, '')}"),
        ("log start", f"{start} (t0 = {table.t0_ns} ns in the log's clock)"),
        ("duration", f"{table.duration_s:.3f} s"),
        ("spooflens version", __version__),
        ("options", ", ".join(f"{k}={v}" for k, v in options.items()) or "defaults"),
        ("libraries", _library_versions()),
        ("report written", datetime.now(UTC).isoformat(timespec="seconds")),
    ]
    rows += _baseline_rows(analysis)
    rows += [(k, v) for k, v in sorted(other.items())]
    out = [_table(("what", "value"), rows)]
    out.append("<h3>Enum meanings applied</h3>")
    out.append(
        _table(("column", "meaning applied"), sorted(enums.items()))
        if enums
        else '<p class="muted">The log carries no receiver state codes whose meaning had to be chosen.</p>'
    )
    return "\n".join(out)


def methods_section(results: Sequence[DetectorResult], infos: dict[str, DetectorInfo]) -> str:
    """Per detector that ran, its declaration (`spooflens.docs.declaration`: the text of docs/detectors.md)
    and what it assumed on this log; the detectors that did not run, and why."""
    from spooflens.docs import declaration

    out = []
    for r in results:
        if not r.ran:
            continue
        info = infos.get(r.name)
        head = f"<h3>{esc(r.name)}"
        if r.evidence is not None:
            ev = EVIDENCE[r.evidence]
            head += f' <span class="muted small">{esc(ev.label)}: compares GNSS with {esc(ev.reference)}</span>'
        out.append(head + "</h3>")
        parts = []
        if info is not None:
            parts.append(f"<p>{esc(info.summary[:1].upper() + info.summary[1:])}.</p>")
            shown = ("Paper", "Method", "Threshold", "Stated false-alarm rate", "Its model requires")
            parts += [f"<p><b>{esc(k)}</b>: {esc(v)}</p>" for k, v in declaration(info) if k in shown]
        if r.advisory:
            parts.append("<p><b>Advisory on this log</b>: its alarms are drawn but do not count in the verdict.</p>")
        if r.reason:
            parts.append(f"<p><b>On this log</b>: {esc(r.reason)}.</p>")
        out += parts
        if r.extras:
            facts = ", ".join(f"{k} = {_fact(v)}" for k, v in r.extras.items())
            out.append(f'<p class="small muted">Facts: {esc(facts)}</p>')
    not_run = [r for r in results if not r.ran]
    if not_run:
        what = f"{len(not_run)} analyses did not run on this log (what each lacks)"
        out.append(f'<details id="not-run"><summary>{what}</summary><ul>')
        for r in not_run:
            why = esc(r.reason)
            if r.precondition is not None:
                why = f"its model requires what this log does not have ({esc(r.precondition.name)}): {why}"
            kind = f" ({esc(label(r.evidence))})" if r.evidence else ""
            out.append(f"<li><b>{esc(r.name)}</b>{kind}: {why}</li>")
        out.append("</ul></details>")
    return "\n".join(out)


def _fact(v: object) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


SECTIONS = (
    ("verdict", "Verdict"),
    ("timeline", "Timeline"),
    ("track", "Track"),
    ("evidence", "Evidence"),
    ("data-quality", "Data quality"),
    ("provenance", "Provenance"),
    ("methods", "Method notes"),
)


def page(analysis: Analysis, plots: Sequence[Plot], identity: InputIdentity, infos: dict[str, DetectorInfo]) -> str:
    by = {s: [p for p in plots if p.section == s] for s in ("timeline", "track", "evidence", "receiver", "curves")}
    body = {
        "verdict": verdict_section(analysis),
        "timeline": _plots(by["timeline"]) or '<p class="muted">No stream spooflens reads: nothing to draw.</p>',
        "track": _plots(by["track"]) or '<p class="muted">No GNSS or truth track to draw.</p>',
        "evidence": (
            _plots(by["evidence"])
            + ("<h3>Receiver quality</h3>" + _plots(by["receiver"]) if by["receiver"] else "")
            + ("<h3>Statistics over other axes</h3>" + _plots(by["curves"]) if by["curves"] else "")
        ),
        "data-quality": data_quality_section(analysis.table),
        "provenance": provenance_section(analysis, identity),
        "methods": methods_section(analysis.results, infos),
    }
    nav = "".join(f'<a href="#{k}">{esc(t)}</a>' for k, t in SECTIONS)
    sections = "\n".join(f'<section id="{k}"><h2>{esc(t)}</h2>\n{body[k]}\n</section>' for k, t in SECTIONS)
    title = f"spooflens report: {identity.name}"
    return (
        "<!DOCTYPE html>\n"
        '<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        # nothing on this page may be fetched: no script, no remote image, font or style
        "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; style-src 'unsafe-inline'; "
        'img-src data:">'
        f"<title>{esc(title)}</title><style>{CSS}</style></head>\n<body><main>\n"
        f"<h1>{esc(title)}</h1><nav>{nav}</nav>\n{sections}\n</main></body></html>\n"
    )
