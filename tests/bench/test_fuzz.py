"""A hundred and more damaged inputs through `spooflens inspect`, each in its own process: no internal
error, no hang, no runaway memory. (`spooflens bench fuzz --n 10000` is the full run; see README.)"""

from __future__ import annotations

from pathlib import Path

import pytest
from paths import REAL, SAMPLE_LOGS

from spooflens.bench.fuzz import HANDLED, SeedLog, run_fuzz
from spooflens.bench.mutations import make_mutant
from spooflens.bench.sandbox import Limits, RunResult, Sandbox
from spooflens.simulation.simulate import SCENARIOS, simulate
from spooflens.writers import write_log


def _seeds(tmp: Path) -> list[SeedLog]:
    """Small logs of every container and text format (the full bench uses every sample and real log)."""
    ulog = tmp / "sim.ulg"
    write_log(simulate(SCENARIOS["ground"], seed=0, duration_s=15.0).table, ulog, "ulog")
    gsi = REAL / "rinex_gsi_pair"
    return [
        SeedLog(SAMPLE_LOGS / "ground.bag"),
        SeedLog(SAMPLE_LOGS / "ground_ros2.mcap"),
        SeedLog(SAMPLE_LOGS / "ground_json.mcap"),
        SeedLog(SAMPLE_LOGS / "ground_ros1.mcap"),
        SeedLog(SAMPLE_LOGS / "ground_ros2_sqlite3"),
        SeedLog(SAMPLE_LOGS / "ground_csv", (SAMPLE_LOGS / "ground_csv.truth.csv",)),
        SeedLog(ulog),
        SeedLog(gsi / "07590920.05o", (gsi / "07590920.05n",)),
        SeedLog(REAL / "nmea_boats" / "gpsd_saab-r4.log"),
        SeedLog(REAL / "ubx_receivers" / "gpsd_ublox-zed-f9r.log"),
        SeedLog(REAL / "ardupilot_dataflash" / "amc_backend_log_80k.bin"),
        SeedLog(REAL / "android_gnsslogger" / "gnss_lib_py" / "pixel6.txt"),
    ]


# in every test run: a hundred and more, a few of each seed's kinds of damage (the bench's 2,000 are the figure)
MUTANTS = 130


def test_a_hundred_mutants_are_all_handled(tmp_path: Path) -> None:
    report = run_fuzz(
        MUTANTS,
        seed=12,
        commands=("inspect",),
        limits=Limits(timeout_s=60.0, rss_cap_mb=1024.0),
        seeds=_seeds(tmp_path),
        failures_dir=tmp_path / "failures",
    )
    failures = "\n".join(f"{f['command']} [{f['mutation']}]: {f['error']}" for f in report.failures)
    assert report.failed == 0, failures
    assert sum(report.counts.values()) == MUTANTS + 12  # every mutant and every unmutated seed ran
    assert set(report.baseline.values()) <= set(HANDLED) and report.peak_rss_mb < 1024
    assert report.counts.get("inspect exit-2", 0) > 10 and report.counts.get("inspect exit-3", 0) > 10


def test_the_sandbox_sees_crashes_hangs_and_memory(tmp_path: Path) -> None:
    """The harness itself can fail: an internal error, a hang and a runaway allocation are each caught."""
    with Sandbox() as box:
        assert box.run(["inspect", str(tmp_path / "none")], tmp_path / "a", Limits()).outcome == "exit-2"
        slow = Limits(timeout_s=1.0)
        fifo_dir = tmp_path / "b"
        fifo_dir.mkdir()
        result: RunResult = box.run(["--debug", "bench", "mlrt", "--quick"], fifo_dir, slow)
        assert result.outcome == "timeout" and result.seconds < 10
        # the child starts as big as its warmed-up server (100-300 MB): a 50 MB cap must stop it
        small = Limits(rss_cap_mb=50.0)
        assert box.run(["inspect", str(SAMPLE_LOGS / "ground.bag")], tmp_path / "c", small).outcome == "rss"


def test_mutants_are_reproducible(tmp_path: Path) -> None:
    seed = SeedLog(SAMPLE_LOGS / "ground_csv")
    a = make_mutant(seed, 7, 3, tmp_path / "a")
    b = make_mutant(seed, 7, 3, tmp_path / "b")
    assert a.description == b.description
    for f in (tmp_path / "a" / "ground_csv").iterdir():
        assert f.read_bytes() == (tmp_path / "b" / "ground_csv" / f.name).read_bytes()


@pytest.mark.parametrize("outcome", [(0, None, "exit-0"), (1, None, "internal"), (5, None, "internal")])
def test_outcomes(outcome: tuple[int, str | None, str]) -> None:
    code, killed, name = outcome
    assert RunResult(code, killed, 100.0, 1.0, "").outcome == name
    assert RunResult(None, "signal 11", 100.0, 1.0, "").outcome == "signal"


def test_an_analysis_ends_in_a_sandbox_that_warmed_up_by_analysing(tmp_path: Path) -> None:
    """`bench fuzz --command both` warms its server with an analysis, whose worker threads stay in the
    server; every forked analysis after it waited on them for ever until the child made its own pool."""
    warm = ["analyze", str(SAMPLE_LOGS / "ground.bag"), "-o", str(tmp_path / "warm.rrd"), "--quiet"]
    with Sandbox(warm) as box:
        argv = ["analyze", str(SAMPLE_LOGS / "ground.bag"), "-o", str(tmp_path / "again.rrd"), "--quiet"]
        result = box.run(argv, tmp_path / "again", Limits(timeout_s=120.0))
    assert result.outcome == "exit-0", result
