"""`spooflens batch` on a LocalCluster: a clean and a spoofed log analysed in parallel, a bad log reported
without stopping the batch, a file that is no log counted, the fleet table of incidents, and a rerun
(on an existing cluster, by its address) that skips what was done by content hash."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from paths import SAMPLE_LOGS

from spooflens.batch import find_logs, run_batch
from spooflens.cli import main

SAMPLES = SAMPLE_LOGS


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """logs/: a clean 60 s ground log, the same with GNSS dragged 5 m/s from 20 s (in a subfolder), a ROS2
    bag directory, a truncated MCAP, and a text file."""
    logs = tmp_path_factory.mktemp("fleet") / "logs"
    (logs / "tuesday").mkdir(parents=True)
    shutil.copy(SAMPLES / "ground_ros2.mcap", logs / "clean.mcap")
    shutil.copy(SAMPLES / "ground_ros2.mcap.truth.csv", logs / "clean.mcap.truth.csv")
    code = main(
        [
            "inject",
            str(SAMPLES / "ground_ros2.mcap"),
            "--attack",
            "ramp:rate=5,start=20,vel=1",
            "-o",
            str(logs / "tuesday" / "spoofed.mcap"),
        ]
    )
    assert code == 0
    shutil.copytree(SAMPLES / "ground_ros2_sqlite3", logs / "tuesday" / "bag")
    (logs / "tuesday" / "cut.mcap").write_bytes((SAMPLES / "ground_ros1.mcap").read_bytes()[:5000])
    (logs / "notes.txt").write_text("flight notes\n")
    return logs


def test_logs_are_found_by_content_and_a_bag_directory_is_one_log(fleet: Path) -> None:
    logs, not_logs = find_logs((f"{fleet}/**/*",))
    names = sorted(p.name for p in logs)
    assert names == ["bag", "clean.mcap", "cut.mcap", "spoofed.mcap"]  # nothing inside the bag taken again
    assert sorted(p.name for p in not_logs) == [
        "clean.mcap.truth.csv",
        "notes.txt",
        "spoofed.mcap.attack.json",
    ]


def test_batch_analyses_reports_and_skips_on_rerun(fleet: Path, tmp_path: Path, capsys) -> None:
    from dask.distributed import LocalCluster

    results = tmp_path / "results"
    code = main(["batch", f"{fleet}/**/*", "-o", str(results), "--workers", "2"])
    out = capsys.readouterr().out
    assert code == 3  # one log failed: the batch finished, and says so
    assert "3 analysed, 1 failed, 0 already done, 3 paths not logs" in out
    assert "cut.mcap: not a readable MCAP file" in out

    logs = pq.read_table(results / "logs.parquet").to_pandas().set_index("log")
    assert sorted(Path(p).name for p in logs.index) == ["bag", "clean.mcap", "cut.mcap", "spoofed.mcap"]
    status = {Path(p).name: s for p, s in logs["status"].items()}
    assert status == {"bag": "done", "clean.mcap": "done", "cut.mcap": "failed", "spoofed.mcap": "done"}
    incidents = pq.read_table(results / "incidents.parquet").to_pandas()
    by_log = incidents.groupby(incidents["log"].map(lambda p: Path(p).name)).size().to_dict()
    assert by_log == {"spoofed.mcap": 1}  # the ramp, and nothing on the clean logs
    onset = float(incidents["onset_s"].iloc[0])
    assert 15.0 <= onset <= 25.0  # the attack starts at 20 s

    for name in ("clean.mcap", "spoofed.mcap"):
        (folder,) = results.glob(f"{name}-*")
        assert {p.name for p in folder.iterdir()} == {"done.json", f"{name}.json", f"{name}.rrd", f"{name}.html"}
        summary = json.loads((folder / f"{name}.json").read_text())
        assert len(summary["verdict"]["incidents"]) == (1 if name == "spoofed.mcap" else 0)

    # rerun on an existing cluster, by address: everything done is skipped by content, the bad log retried
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        again = run_batch((f"{fleet}/**/*",), results, scheduler=cluster.scheduler_address)
    assert sorted(Path(r["log"]).name for r in again.skipped) == ["bag", "clean.mcap", "spoofed.mcap"]
    assert [(Path(r["log"]).name, r["status"]) for r in again.analysed] == [("cut.mcap", "failed")]
    assert again.workers == 1
    assert len(pq.read_table(results / "incidents.parquet")) == 1


def test_the_largest_logs_are_given_to_the_workers_first(fleet: Path) -> None:
    from spooflens.batch import LogJob, largest_first

    logs, _ = find_logs((f"{fleet}/**/*",))
    order = [j.path.name for j in largest_first([LogJob(p, "") for p in sorted(logs)])]
    sizes = {p.name: sum(f.stat().st_size for f in ([p] if p.is_file() else p.rglob("*")) if f.is_file()) for p in logs}
    assert order == sorted(sizes, key=lambda name: -sizes[name])
    assert order[-1] == "cut.mcap"  # the 5 kB truncated file
