"""The operator report, tried as a person would: rendered in headless Chromium, looked at, screenshotted.

Two sample logs go through the command line once each (module fixtures): the spoofed flight through
`analyze --html --json --quiet` and the clean car through `report --json --fail-on-spoof`. Chromium
(Debian's, installed by the README's test command) opens each report from disk; the tests read the
page as a person would (the verdict, how many plots are drawn and that each has something in it, the
console, the network) and take a screenshot.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from browser import Browser, chromium_path
from paths import SAMPLE_LOGS
from PIL import Image
from rerun.chunk import RrdReader

from spooflens.cli import main

SAMPLES = SAMPLE_LOGS
SCREENSHOTS = SAMPLES / "screenshots"
WIDTH = 1100
TOP = 1500  # the reference screenshot: verdict, timeline and track

# what the sample's attack did (sample_logs/README.md): 2 m/s east and north from 150 s to the end (240 s)
FLIGHT_DRAG_M = 2.0 * np.sqrt(2.0) * (240.0 - 150.0)


@dataclass
class Run:
    code: int
    stdout: str
    html: Path
    summary: dict
    rrd: Path | None
    rerun_config: Path  # XDG_CONFIG_HOME during the run: Rerun must not have created its analytics config


def _run(args: list[str], tmp: Path) -> tuple[int, str]:
    """Run the CLI with a private XDG_CONFIG_HOME and its stdout captured."""
    old = os.environ.get("XDG_CONFIG_HOME")
    os.environ["XDG_CONFIG_HOME"] = str(tmp / "config")
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            code = main(args)
    finally:
        if old is None:
            os.environ.pop("XDG_CONFIG_HOME", None)
        else:
            os.environ["XDG_CONFIG_HOME"] = old
    return code, out.getvalue()


@pytest.fixture(scope="module")
def spoofed(tmp_path_factory: pytest.TempPathFactory) -> Run:
    tmp = tmp_path_factory.mktemp("spoofed")
    html, js, rrd = tmp / "spoofed_flight.html", tmp / "s.json", tmp / "s.rrd"
    log = str(SAMPLES / "spoofed_flight.mcap")
    code, out = _run(["analyze", log, "-o", str(rrd), "--json", str(js), "--html", str(html), "--quiet"], tmp)
    return Run(code, out, html, json.loads(js.read_text()), rrd, tmp / "config")


@pytest.fixture(scope="module")
def clean(tmp_path_factory: pytest.TempPathFactory) -> Run:
    tmp = tmp_path_factory.mktemp("clean")
    html, js = tmp / "ground.html", tmp / "g.json"
    code, out = _run(
        ["report", str(SAMPLES / "ground.bag"), "-o", str(html), "--json", str(js), "--fail-on-spoof"], tmp
    )
    return Run(code, out, html, json.loads(js.read_text()), None, tmp / "config")


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    if chromium_path() is None:
        pytest.fail("chromium is not installed: the README's test command installs it (apt-get install -y chromium)")
    with Browser(width=WIDTH) as b:
        yield b


# the page's own account of its plots: each figure's size on screen, and how many vertices it draws
# inside its axes (matplotlib clips data, and only data, to the axes: lines, bands, bars, markers)
PLOTS_JS = """
[...document.querySelectorAll('figure.plot')].map(f => {
  const svg = f.querySelector('svg');
  const box = svg ? svg.getBoundingClientRect() : {width: 0, height: 0};
  const data = svg ? [...svg.querySelectorAll('path[clip-path], use[clip-path], g[clip-path] path')] : [];
  const vertices = data.reduce((n, p) => n + ((p.getAttribute('d') || 'M').match(/[ML]/g) || []).length, 0);
  return {key: f.dataset.plot, width: box.width, height: box.height, vertices: vertices};
})
"""


def _look(browser: Browser, run: Run, name: str, tmp_path: Path) -> tuple[dict, list[dict]]:
    page = browser.open(run.html.resolve().as_uri())
    plots = page.evaluate(PLOTS_JS)
    banner = page.evaluate(
        "(() => { const b = document.getElementById('verdict-banner').getBoundingClientRect();"
        " return {x: b.x + 8, y: b.y + 8, text: document.getElementById('verdict-banner').innerText}; })()"
    )
    shot = tmp_path / f"{name}.png"
    page.screenshot(shot, width=WIDTH, height=TOP)
    browser.collect(page)
    seen = {"requests": page.requests, "errors": page.errors, "banner": banner, "shot": shot}
    return seen, plots


def _expected_plot_owners(summary: dict) -> set[str]:
    """Every analysis that ran and declared a series must have at least one plot of its own."""
    return {a["name"] for a in summary["analyses"] if a["ran"] and a.get("series")}


@pytest.mark.parametrize(
    ("name", "verdict", "colour"),
    [
        ("spoofed_flight", "SPOOFING DETECTED", (0xC9, 0x2A, 0x2A)),
        ("ground", "NO SPOOFING DETECTED", (0x2B, 0x8A, 0x3E)),
    ],
)
def test_report_in_chromium(
    name: str, verdict: str, colour: tuple[int, int, int], spoofed: Run, clean: Run, browser: Browser, tmp_path: Path
) -> None:
    run = spoofed if name == "spoofed_flight" else clean
    seen, plots = _look(browser, run, name, tmp_path)
    # the verdict first, in words
    assert seen["banner"]["text"].startswith(verdict)
    assert run.summary["verdict"]["headline"] in seen["banner"]["text"]
    # every plot of the page is drawn, at a readable size, with something in it
    markup = run.html.read_text()
    assert len(plots) == markup.count('<figure class="plot"') >= 10
    empty = [p for p in plots if p["width"] < 600 or p["height"] < 100 or p["vertices"] < 10]
    assert not empty, empty
    keys = [p["key"] for p in plots]
    assert {"timeline", "track", "receiver:/gps/fix"} <= set(keys)
    assert ("departure" in keys) == (name == "spoofed_flight")  # a reconstructed track only when spoofed
    for owner in _expected_plot_owners(run.summary):
        assert any(k.startswith(owner + ":") for k in keys), owner
    # nothing fetched but the page itself, nothing complained about
    assert seen["requests"] == [run.html.resolve().as_uri()]
    assert seen["errors"] == []
    # the screenshot shows the page: the verdict banner in its colour, and far from blank
    img = Image.open(seen["shot"]).convert("RGB")
    assert img.size == (WIDTH, TOP)
    x, y = int(seen["banner"]["x"]), int(seen["banner"]["y"])
    assert img.getpixel((x, y)) == colour
    assert len(img.getcolors(maxcolors=1 << 20) or []) > 200
    # the reference screenshot kept for the README is of this page, at this size
    reference = SCREENSHOTS / f"{name}.png"
    assert reference.exists(), "regenerate with: python tests/support/screenshots.py"
    assert Image.open(reference).size[0] == WIDTH


def test_report_is_one_self_contained_small_file(spoofed: Run, clean: Run) -> None:
    for run in (spoofed, clean):
        text = run.html.read_text()
        assert "<script" not in text and not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", text)
        assert "default-src 'none'" in text  # the browser may fetch nothing for this page
        assert run.html.stat().st_size < 2_000_000
        assert text.count("<svg") == text.count('<figure class="plot"')


def test_report_names_every_evidence_class_and_method(spoofed: Run) -> None:
    text = spoofed.html.read_text()
    timeline = re.search(r'id="plot-timeline".*?</figure>', text, re.S)
    assert timeline is not None
    # a strip per class whose analyses ran, and the lane of the event kinds above them
    ran = {a["evidence_label"] for a in spoofed.summary["analyses"] if a["evidence_label"] and a["ran"]}
    for label in ran | {"events by kind", "spoofing"}:
        assert label in timeline.group(0)
    # the analyses that did not run: one folded list at the end of the page, after every figure
    not_run = [a for a in spoofed.summary["analyses"] if not a["ran"]]
    folded = text[text.index('<details id="not-run">') :]
    assert text.rindex('<figure class="plot"') < text.index('<details id="not-run">')
    assert f"{len(not_run)} analyses did not run" in folded
    for a in not_run:
        assert f"<b>{a['name']}</b>" in folded
    verdict = text[text.index('<section id="verdict">') : text.index('<section id="timeline">')]
    assert "did not run</td>" not in verdict and "listed at the end of the page" in verdict
    methods = text[text.index('<section id="methods">') :]
    for a in spoofed.summary["analyses"]:
        if a["ran"]:
            assert f"<h3>{a['name']}" in methods
    provenance = text[text.index('<section id="provenance">') : text.index('<section id="methods">')]
    import hashlib

    digest = hashlib.sha256((SAMPLES / "spoofed_flight.mcap").read_bytes()).hexdigest()
    assert digest in provenance and "spooflens version" in provenance and "time reference" in provenance


def test_quiet_prints_the_one_line_verdict_and_json_says_how_far_gnss_went(spoofed: Run) -> None:
    assert spoofed.code == 0
    assert spoofed.stdout.splitlines() == [spoofed.summary["verdict"]["headline"]]
    incident = spoofed.summary["verdict"]["incidents"][0]
    (far,) = incident["gnss_departure"]
    assert far["receiver_id"] == "/gps/fix" and far["track"].startswith("reconstructed")
    # the attack dragged the fix 254.6 m away by the end of the log; the reconstruction stayed put
    assert abs(far["peak_m"] - FLIGHT_DRAG_M) < 0.1 * FLIGHT_DRAG_M
    assert abs(far["end_m"] - FLIGHT_DRAG_M) < 0.1 * FLIGHT_DRAG_M and far["at_end_s"] == pytest.approx(240.0)


def test_a_clean_log_exits_0_with_fail_on_spoof(clean: Run) -> None:
    assert clean.code == 0 and not clean.summary["verdict"]["spoofed"]
    assert all("gnss_departure" not in i for i in clean.summary["verdict"]["incidents"])


def test_recording_holds_truth_overview_and_writing_it_started_no_analytics(spoofed: Run) -> None:
    assert spoofed.rrd is not None
    paths = {str(p) for p in RrdReader(str(spoofed.rrd)).store().schema().entity_paths()}
    assert "/map/truth/track" in paths  # the truth file beside the log, drawn in blue
    assert {"/overview/GNSS-only_consistency", "/overview/inertial_reference", "/overview/spoofing_incidents"} <= paths
    assert not (spoofed.rerun_config / "rerun").exists()  # no Rerun analytics config: analytics never started


def test_many_anomalies_fold_below_the_spoofing_incidents() -> None:
    from spooflens.output.report.figures import MAX_LABELLED
    from spooflens.output.report.page import INCIDENT_COLUMNS, incidents_table

    def row(i: int, kind: str) -> tuple[object, ...]:
        return (i, kind, *("-" for _ in INCIDENT_COLUMNS[2:]))

    few = incidents_table([row(1, "spoofing"), row(2, "anomaly")], [True, False])
    assert "<details>" not in few and few.count("<tr>") == 3
    n = MAX_LABELLED + 8
    kinds = [i == 5 for i in range(1, n + 1)]
    many = incidents_table([row(i, "spoofing" if s else "anomaly") for i, s in enumerate(kinds, 1)], kinds)
    shown, folded = many.split("<details>")
    assert "<td>5</td><td>spoofing</td>" in shown and "anomaly" not in shown
    assert f"{n - 1} anomalies" in folded and folded.count("<td>anomaly</td>") == n - 1
    assert many.count("<td>spoofing</td>") == 1
    all_spoofing = incidents_table([row(i, "spoofing") for i in range(1, n + 1)], [True] * n)
    assert "<details>" not in all_spoofing and all_spoofing.count("<td>spoofing</td>") == n
