"""Run `spooflens inspect` (or `analyze`) on every file under ../shared/real and tabulate the outcome.

Not a test: a helper for the readers' coverage of real logs. Usage:
    python tests/support/corpus_survey.py [--command inspect|analyze] [--jobs 2] OUT.tsv
Each row: path, MANIFEST format, exit code, the first line of the error (or the first line of output).
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from paths import REAL

SKIP_NAMES = ("LICENSE", "COPYING", "README", "SOURCE", "MANIFEST", "REUSE")


def manifest_formats() -> dict[str, str]:
    manifest = REAL / "corpus" / "MANIFEST.tsv"
    with manifest.open(newline="") as f:
        return {f"corpus/{row['path']}": row["format"] for row in csv.DictReader(f, delimiter="\t")}


def log_files() -> list[Path]:
    return sorted(p for p in REAL.rglob("*") if p.is_file() and not p.name.startswith(SKIP_NAMES))


def run(path: Path, command: str, timeout: float) -> tuple[int, str]:
    exe = Path(sys.executable).with_name("spooflens")
    args = [str(exe), command, str(path)]
    if command == "analyze":
        out_dir = Path(os.environ.get("TMPDIR", "/tmp")) / "corpus_survey_rrd"
        out_dir.mkdir(exist_ok=True)
        args += ["--quiet", "-o", str(out_dir / f"{path.name}.rrd")]
    try:
        done = subprocess.run(args, capture_output=True, text=True, timeout=timeout, env=os.environ.copy())
    except subprocess.TimeoutExpired:
        return -9, "TIMEOUT"
    lines = [ln for ln in (done.stderr.splitlines() + done.stdout.splitlines()) if ln.strip()]
    err = [ln for ln in done.stderr.splitlines() if ln.strip()]
    first = (err[-1] if done.returncode not in (0, 3) and err else (lines[0] if lines else "")).strip()
    return done.returncode, first[:300]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("out")
    parser.add_argument("--command", default="inspect")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--timeout", type=float, default=600)
    parser.add_argument("--only", default="", help="substring a path must contain")
    opts = parser.parse_args()
    kinds = manifest_formats()
    files = [p for p in log_files() if opts.only in str(p)]
    with ThreadPoolExecutor(opts.jobs) as pool:
        results = list(pool.map(lambda p: run(p, opts.command, opts.timeout), files))
    with Path(opts.out).open("w", newline="") as f:
        out = csv.writer(f, delimiter="\t")
        out.writerow(["path", "format", "exit", "message"])
        for path, (code, message) in zip(files, results, strict=True):
            rel = str(path.relative_to(REAL))
            out.writerow([rel, kinds.get(rel, "-"), code, message])
    print(f"{len(files)} files -> {opts.out}")


if __name__ == "__main__":
    main()
