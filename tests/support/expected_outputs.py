"""Expected outputs: the JSON summary of every sample log and every real log in ../shared/real (outside the
corpus), normalised so that only what the analysis says remains (no version, no absolute paths).

`python tests/support/expected_outputs.py` rewrites the files in tests/expected; a
behaviour change then shows as a reviewed diff of them. `test_expected_outputs.py` compares a fresh analysis
with them.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

from paths import REAL, ROOT
from paths import SAMPLE_LOGS as SAMPLE_LOGS_DIR

HERE = ROOT / "tests" / "expected"

SAMPLE_LOGS = (
    "spoofed_flight.mcap",
    "dual_receiver.mcap",
    "meaconed_raw",
    "ground.bag",
    "ground_csv",
    "ground_json.mcap",
    "ground_ros1.mcap",
    "ground_ros2.mcap",
    "ground_ros2_sqlite3",
)
REAL_LOGS = (
    "ros1_husky_navsat/test1.bag",
    "ubx_receivers/gpsd_ublox-zed-f9p_hpg1.11.log",
    "ubx_receivers/gpsd_ublox-zed-f9r.log",
    "nmea_boats/gpsd_bundg_zeus_9.log",
    "nmea_boats/gpsd_saab-r4.log",
    "nmea_boats/signalk_plaka.log",
    "rinex_gsi_pair/07590920.05o",
    "rinex_gsi_pair/30400920.05o",
    "android_gnsslogger/gnss_lib_py/pixel6.txt",
    "android_gnsslogger/gnss_lib_py/pixel6.nmea",
    "android_gnsslogger/gnss_lib_py/pixel6.23o",
    "android_gnsslogger/gps-measurement-tools/pseudoranges_log_2016_06_30_21_26_07.txt",
    "android_gnsslogger/gps-measurement-tools/pseudoranges_log_2016_08_22_14_45_50.txt",
    "ardupilot_dataflash/amc_backend_log_80k.bin",
    "ardupilot_dataflash/flightdata_center_0003.bin",
)


def logs() -> dict[str, Path]:
    """expected file name -> log path, samples first."""
    out = {f"sample_logs__{name}": SAMPLE_LOGS_DIR / name for name in SAMPLE_LOGS}
    out |= {"real__" + rel.replace("/", "__"): REAL / rel for rel in REAL_LOGS}
    return out


def _normal(x: Any) -> Any:
    """Paths of this machine out; floats as JSON writes them (NaN as null, as the summary does)."""
    if isinstance(x, str):
        return x.replace(str(REAL), "<real>").replace(str(ROOT), "<repo>")
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _normal(v) for k, v in x.items() if k != "spooflens_version"}
    if isinstance(x, list | tuple):
        return [_normal(v) for v in x]
    return x


def summary_of(log: Path) -> dict[str, Any]:
    """What `spooflens analyze LOG --json` writes, normalised (an error: its one line, as the CLI prints it)."""
    from spooflens.errors import SpooflensError
    from spooflens.output.summary import build_summary
    from spooflens.pipeline.run import analyze_segments
    from spooflens.service import read_table, require_gnss, segments_summary

    try:
        table = read_table(log, {}, show_progress=False)
        require_gnss(log, table)
        analyses = analyze_segments(table)
    except SpooflensError as err:
        return {"error": _normal(str(err))}
    summaries = [build_summary(a.table, a.results, a.verdict) for a in analyses]
    return dict(_normal(json.loads(json.dumps(segments_summary(summaries)))))


def expected_path(name: str) -> Path:
    return HERE / f"{name}.json"


def main(names: list[str]) -> None:
    for name, log in logs().items():
        if names and name not in names:
            continue
        print(name, flush=True)
        expected_path(name).write_text(json.dumps(summary_of(log), indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
