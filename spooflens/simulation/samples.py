"""The sample logs in `sample_logs/`: made here, deterministically, so anyone can regenerate them.

    python -m spooflens.simulation.samples sample_logs

Each sample is a simulated scenario written in one format, with its ground truth beside it
(`<name>.truth.csv`: the true trajectory) and, for spoofed samples, the attack
(`<name>.attack.json`, made by the same code as `spooflens inject`). The README in the folder is
written by this module too.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, replace
from pathlib import Path

from spooflens.attacks import apply_attack, parse_attack, sidecar_path
from spooflens.simulation.simulate import SCENARIOS, simulate, write_with_truth


@dataclass(frozen=True)
class Sample:
    name: str  # file or directory name in sample_logs/
    fmt: str
    scenario: str
    seconds: float
    imu_hz: float
    gnss_hz: float
    seed: int
    attack: str | None = None
    what: str = ""


SAMPLES: tuple[Sample, ...] = (
    Sample(
        "spoofed_flight.mcap",
        "mcap-ros2",
        "aircraft",
        240.0,
        50.0,
        5.0,
        7,
        "ramp:rate=2,axes=en,start=150",
        "aircraft climbing and turning; GNSS position pulled away at 2 m/s east and north from 150 s "
        "(velocity untouched, seed 000's attack)",
    ),
    Sample("ground_ros2.mcap", "mcap-ros2", "ground", 60.0, 25.0, 5.0, 1, what="car, clean, ROS2 CDR channels"),
    Sample("ground_ros1.mcap", "mcap-ros1", "ground", 60.0, 25.0, 5.0, 1, what="the same car, ROS1 channels"),
    Sample(
        "ground_json.mcap",
        "mcap-json",
        "ground",
        60.0,
        25.0,
        5.0,
        1,
        what="the same car, JSON channels (foxglove.LocationFix, spooflens.Imu)",
    ),
    Sample("ground.bag", "ros1bag", "ground", 60.0, 25.0, 5.0, 1, what="the same car, ROS1 bag"),
    Sample(
        "ground_ros2_sqlite3",
        "ros2bag-sqlite3",
        "ground",
        60.0,
        25.0,
        5.0,
        1,
        what="the same car, ROS2 bag directory, sqlite3 storage",
    ),
    Sample("ground_csv", "csv", "ground", 60.0, 25.0, 5.0, 1, what="the same car, spooflens CSV log (directory)"),
    Sample(
        "meaconed_raw",
        "csv",
        "ground_raw",
        180.0,
        25.0,
        1.0,
        5,
        "meaconing:east=300,north=100,start=120",
        "car whose receiver logs raw GPS observations (pseudorange, carrier phase, Doppler, C/N0; synthetic "
        "constellation, satellite positions included) and reports its own single-point solution; from 120 s a "
        "meaconer 300 m east and 100 m north of it re-broadcasts the sky, so every pseudorange, and the fix, "
        "becomes the meaconer's",
    ),
    Sample(
        "dual_receiver.mcap",
        "mcap-ros2",
        "dual_receiver",
        420.0,
        25.0,
        5.0,
        2,
        "single_antenna:rate=1,start=360",
        "car with two GNSS receivers 1.2 m apart (/gps/fix, /gps2/fix); from 360 s one spoofer antenna feeds "
        "both (seed 003's attack): the baseline collapses (the six minutes before show the pair's own wander)",
    ),
)


def make(sample: Sample, outdir: Path) -> Path:
    sc = replace(SCENARIOS[sample.scenario], imu_hz=sample.imu_hz, gnss_hz=sample.gnss_hz)
    sim = simulate(sc, seed=sample.seed, duration_s=sample.seconds)
    table = sim.table
    path = outdir / sample.name
    if sample.attack:
        table, truth = apply_attack(table, parse_attack(sample.attack))
        truth.source = f"simulation {sample.scenario} seed {sample.seed}"
        truth.write(sidecar_path(path))
    write_with_truth(table, path, sample.fmt)
    return path


def readme(samples: tuple[Sample, ...] = SAMPLES) -> str:
    lines = [
        "# Sample logs",
        "",
        "Simulated, deterministic logs in every supported format, each with its ground truth beside it.",
        "Regenerate them all with `python -m spooflens.simulation.samples sample_logs` (a test checks that",
        "the committed files equal a fresh run).",
        "",
        "| log | format | what is in it | how it was made |",
        "|---|---|---|---|",
    ]
    for s in samples:
        made = (
            f"scenario `{s.scenario}`, seed {s.seed}, {s.seconds:.0f} s, IMU {s.imu_hz:.0f} Hz, "
            f"GNSS {s.gnss_hz:.0f} Hz" + (f", then `spooflens inject --attack {s.attack}`" if s.attack else "")
        )
        truth = f"`{s.name}.truth.csv`" + (f", `{s.name}.attack.json`" if s.attack else "")
        lines.append(f"| `{s.name}` | {s.fmt} | {s.what}; truth: {truth} | {made} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    outdir = Path((argv or sys.argv[1:] or ["sample_logs"])[0])
    outdir.mkdir(parents=True, exist_ok=True)
    for s in SAMPLES:
        print(make(s, outdir))
    (outdir / "README.md").write_text(readme())
    return 0


if __name__ == "__main__":
    sys.exit(main())
