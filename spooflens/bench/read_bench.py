"""Reader benchmark: one hour of 200 Hz IMU + 10 Hz fixes in a ROS2 MCAP, our reader vs rosbags.

`spooflens bench read` writes the file, then reads it in separate processes (so each peak RSS is its
own): our `read_log`, and a plain rosbags AnyReader loop that deserialises every message (the
baseline a ROS user would write). Goal: ours at least as fast (ratio <= 1) and under 1 GB peak RSS.
With `--formats` the same hour is also written in every other container a vehicle logs to (a ROS1 bag, a
ROS2 sqlite3 bag, a ROS1-encoded MCAP, a PX4 ULog, a CSV) and each read the same way; the ROS bags
beside rosbags' loop over them.
"""

from __future__ import annotations

import contextlib
import tempfile
from pathlib import Path
from typing import Any

import click
import numpy as np
import pandas as pd
from rich.table import Table

from spooflens.bench.common import measure_in_child
from spooflens.epoch_table import StreamInfo, build_table
from spooflens.geodesy import enu_to_geodetic
from spooflens.output.console import console, err_console

T0_NS = 1_750_000_000_000_000_000


def synthetic_table(duration_s: float, imu_hz: float, fix_hz: float):
    rng = np.random.default_rng(0)
    ti = np.arange(0.0, duration_s, 1.0 / imu_hz)
    tf = np.arange(0.0, duration_s, 1.0 / fix_hz)
    m, n = len(ti), len(tf)
    imu = pd.DataFrame(
        {
            "t_ns": T0_NS + np.round(ti * 1e9).astype(np.int64),
            "imu_id": "/imu/data",
            "ax_mps2": rng.normal(0, 0.1, m),
            "ay_mps2": rng.normal(0, 0.1, m),
            "az_mps2": 9.81 + rng.normal(0, 0.1, m),
            "wx_radps": rng.normal(0, 0.01, m),
            "wy_radps": rng.normal(0, 0.01, m),
            "wz_radps": rng.normal(0, 0.01, m),
        }
    )
    lat, lon, h = enu_to_geodetic(np.c_[10 * tf, 5 * tf, np.zeros(n)], 45.0, 7.0, 100.0)
    fixes = pd.DataFrame(
        {
            "t_ns": T0_NS + np.round(tf * 1e9).astype(np.int64),
            "receiver_id": "/gps/fix",
            "lat_deg": lat,
            "lon_deg": lon,
            "height_m": h,
            "h_acc_m": 2.0,
            "v_acc_m": 3.0,
            "fix_type": np.full(n, 2, dtype=np.int8),
        }
    )
    streams = [
        StreamInfo("imu", "/imu/data", "/imu/data", "sensor_msgs/msg/Imu", m, body_frame="FLU"),
        StreamInfo("fix", "/gps/fix", "/gps/fix", "sensor_msgs/msg/NavSatFix", n),
    ]
    return build_table(Path("bench.mcap"), "synthetic", "unix", {"imu": imu, "fixes": fixes}, streams, [])


def read_with_spooflens(path: str) -> int:
    from readers import read_log

    table = read_log(path)
    return len(table.imu) + len(table.fixes)


def read_with_rosbags(path: str) -> int:
    from rosbags.highlevel import AnyReader

    n = 0
    with AnyReader([Path(path)]) as reader:
        for conn, _, raw in reader.messages():
            reader.deserialize(raw, conn.msgtype)
            n += 1
    return n


# (label, writer format, file suffix, whether rosbags reads it too)
OTHER_FORMATS = (
    ("ROS1 bag", "ros1bag", ".bag", True),
    ("ROS2 bag (sqlite3)", "ros2bag-sqlite3", "_db3", True),
    ("MCAP, ROS1 encoding", "mcap-ros1", "_ros1.mcap", False),
    ("PX4 ULog", "ulog", ".ulg", False),
    ("CSV", "csv", ".csv", False),
)


def run_formats_bench(
    workdir: Path, duration_s: float = 3600.0, imu_hz: float = 200.0, fix_hz: float = 10.0
) -> list[dict[str, Any]]:
    """The same hour in each of OTHER_FORMATS (written once, kept in `workdir`), read by `read_log` (and
    rosbags' loop where it reads the format), each in a process of its own."""
    from spooflens.writers import write_log

    table = None
    rows = []
    for label, fmt, suffix, by_rosbags in OTHER_FORMATS:
        path = Path(workdir) / f"bench_{int(duration_s)}s{suffix}"
        if not path.exists():
            table = table if table is not None else synthetic_table(duration_s, imu_hz, fix_hz)
            write_log(table, path, fmt)
        ours = measure_in_child(__name__, "read_with_spooflens", str(path))
        theirs = measure_in_child(__name__, "read_with_rosbags", str(path)) if by_rosbags else None
        rows.append({"format": label, "file": str(path), "spooflens": ours, "rosbags": theirs})
    return rows


def run_read_bench(
    workdir: Path, duration_s: float = 3600.0, imu_hz: float = 200.0, fix_hz: float = 10.0
) -> dict[str, Any]:
    from spooflens.writers import write_log

    path = Path(workdir) / f"bench_{int(duration_s)}s.mcap"
    if not path.exists():
        write_log(synthetic_table(duration_s, imu_hz, fix_hz), path, "mcap-ros2")
    runs = {
        name: measure_in_child(__name__, fn, str(path))
        for name, fn in (
            ("spooflens read_log", "read_with_spooflens"),
            ("rosbags deserialise loop", "read_with_rosbags"),
        )
    }
    n = runs["rosbags deserialise loop"]["result"]
    for r in runs.values():
        r["messages_per_s"] = n / r["wall_s"]
    return {
        "file": str(path),
        "file_mb": path.stat().st_size / 1e6,
        "messages": n,
        "runs": runs,
        "ratio_wall": runs["spooflens read_log"]["wall_s"] / runs["rosbags deserialise loop"]["wall_s"],
    }


@click.command("read")
@click.option("--duration", default=3600.0, show_default=True, help="Seconds of log to synthesise.")
@click.option(
    "--workdir",
    type=click.Path(path_type=Path),
    default=None,
    help="Keep the synthetic MCAP here (reused by the next run); default: a temporary directory, removed after.",
)
@click.option(
    "--formats",
    is_flag=True,
    help="Also the same log as a ROS1 bag, a ROS2 sqlite3 bag, a ROS1-encoded MCAP, a PX4 ULog and a CSV.",
)
def command(duration: float, workdir: Path | None, formats: bool) -> int:
    """Reader speed and memory on a synthetic 200 Hz IMU + 10 Hz fix ROS2 MCAP, beside rosbags."""
    with contextlib.ExitStack() as stack:
        if workdir is None:
            workdir = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="spooflens-bench-read-")))
        workdir.mkdir(parents=True, exist_ok=True)
        with err_console.status("writing the synthetic MCAP and reading it twice..."):
            r = run_read_bench(workdir, duration_s=duration)
        if formats:
            with err_console.status("the same log in the other formats: writing each once, reading it..."):
                other = run_formats_bench(workdir, duration_s=duration)
    t = Table(
        "reader",
        "wall (s)",
        "messages/s",
        "peak RSS (MB)",
        title=f"{r['messages']} messages, {r['file_mb']:.0f} MB MCAP ({r['file']})",
    )
    for name, run in r["runs"].items():
        t.add_row(name, f"{run['wall_s']:.2f}", f"{run['messages_per_s']:,.0f}", f"{run['peak_rss_mb']:.0f}")
    console().print(t)
    verdict = "goal met" if r["ratio_wall"] <= 1.0 else "goal MISSED"
    click.echo(
        f"wall-time ratio spooflens/rosbags = {r['ratio_wall']:.2f} (goal <= 1.0: {verdict}); peak RSS goal < 1024 MB"
    )
    if formats:
        console().print(_formats_table(other, r["messages"]))
    return 0


def _formats_table(rows: list[dict[str, Any]], messages: int) -> Table:
    t = Table(
        "format",
        "rows read",
        "read_log wall (s)",
        "peak RSS (MB)",
        "rosbags loop wall (s)",
        "ratio",
        title=f"the same {messages} messages (IMU samples and fixes) in other formats",
    )
    for row in rows:
        ours, theirs = row["spooflens"], row["rosbags"]
        t.add_row(
            row["format"],
            str(ours["result"]),
            f"{ours['wall_s']:.2f}",
            f"{ours['peak_rss_mb']:.0f}",
            f"{theirs['wall_s']:.2f}" if theirs else "",
            f"{ours['wall_s'] / theirs['wall_s']:.2f}" if theirs else "",
        )
    return t
