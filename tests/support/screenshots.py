"""Regenerate the README's reference screenshots of the sample reports: `python tests/support/screenshots.py`.

Each sample log goes through `spooflens report`; headless Chromium (tests/support/browser.py) shows the page
at 1100 CSS pixels and the top of it (verdict, timeline, track) is kept, palette-reduced so the PNG
stays small. tests/output/test_report.py takes the same screenshots and checks them.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from browser import Browser
from paths import ROOT
from PIL import Image

from spooflens.cli import main

SAMPLES = {
    "spoofed_flight": ROOT / "sample_logs" / "spoofed_flight.mcap",
    "ground": ROOT / "sample_logs" / "ground.bag",
}
OUT = ROOT / "sample_logs" / "screenshots"
WIDTH, TOP = 1100, 1500


def small_png(src: Path, dst: Path, colours: int = 96) -> None:
    Image.open(src).convert("RGB").quantize(colours, method=Image.Quantize.MEDIANCUT).save(dst, optimize=True)


def regenerate() -> list[Path]:
    OUT.mkdir(exist_ok=True)
    written = []
    with tempfile.TemporaryDirectory() as tmp, Browser(width=WIDTH) as browser:
        for name, log in SAMPLES.items():
            html = Path(tmp, f"{name}.html")
            code = main(["report", str(log), "-o", str(html), "--quiet"])
            if code not in (0, 4):
                raise SystemExit(f"{log}: spooflens report exited {code}")
            page = browser.open(html.as_uri())
            raw = Path(tmp, f"{name}.png")
            page.screenshot(raw, width=WIDTH, height=TOP)
            small_png(raw, OUT / f"{name}.png")
            written.append(OUT / f"{name}.png")
    return written


if __name__ == "__main__":
    for path in regenerate():
        print(f"{path.relative_to(ROOT)}: {path.stat().st_size / 1e3:.0f} kB")
