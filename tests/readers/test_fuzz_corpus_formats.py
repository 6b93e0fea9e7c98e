"""Damaged copies of the corpus logs the readers of issue 40 read (old DataFlash, legacy u-blox, packed
RINEX, NMEA 2000, measurement tables, headings-only NMEA), each through `spooflens inspect` in its own
process: handled, never an internal error or a hang. (`spooflens bench fuzz` draws from the whole
corpus; this is the CI's slice of it.)"""

from __future__ import annotations

from pathlib import Path

from paths import real_log

from spooflens.bench.fuzz import HANDLED, SeedLog, real_seeds, run_fuzz
from spooflens.bench.sandbox import Limits

CORPUS_SEEDS = (
    "corpus/dronekit-la-testdata/log171.bin",
    "corpus/gpsd/navisys-gr701w.log",
    "corpus/pyubx2/pygpsdata-SF-calibration.log",
    "corpus/georinex/P43300USA_R_20190012056_17M_15S_MO.crx",
    "corpus/georinex/ab430140.18o.zip",
    "corpus/georinex/CEDA00USA_R_20182100000_23H_15S_MO.rnx.gz",
    "corpus/signalk/aava-n2k.data",
    "corpus/canboat/susteranna2020.raw",
    "corpus/gnss_lib_py/gsdc2022_device_gnss.csv",
    "corpus/gnss_lib_py/smartloc_tu_chemnitz_berlin_1_raw.csv",
    "corpus/gpsd/pypilot.log",
)


def test_the_bench_draws_its_seeds_from_the_corpus() -> None:
    names = {s.path.name for s in real_seeds()}
    assert {Path(p).name for p in CORPUS_SEEDS} <= names


def test_mutants_of_the_new_readers_formats_are_handled(tmp_path: Path) -> None:
    seeds = [SeedLog(real_log(p)) for p in CORPUS_SEEDS]
    report = run_fuzz(
        50,
        seed=40,
        commands=("inspect",),
        limits=Limits(timeout_s=60.0, rss_cap_mb=1024.0),
        seeds=seeds,
        failures_dir=tmp_path / "failures",
    )
    failures = "\n".join(f"{f['command']} [{f['mutation']}]: {f['error']}" for f in report.failures)
    assert report.failed == 0, failures
    assert set(report.baseline.values()) <= set(HANDLED)
    assert report.counts.get("inspect exit-3", 0) > 5  # damage read, and said so
