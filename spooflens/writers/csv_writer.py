"""Write an EpochTable as a spooflens CSV log: a directory with one CSV per non-empty frame."""

from __future__ import annotations

import shutil
from pathlib import Path

from spooflens.epoch_table import EpochTable

FILES = {
    "fixes": "fixes.csv",
    "imu": "imu.csv",
    "observations": "observations.csv",
    "satellites": "satellites.csv",
    "truth": "truth.csv",
}


def write_csv(table: EpochTable, path: Path) -> None:
    path = Path(path)
    if path.exists():
        shutil.rmtree(path) if path.is_dir() else path.unlink()
    path.mkdir(parents=True)
    body = next((s.body_frame for s in table.streams if s.role == "imu" and s.body_frame), "FLU")
    for frame, name in FILES.items():
        df = table.frame(frame)
        if not len(df):
            continue
        with (path / name).open("w", encoding="utf-8") as f:
            f.write(
                f"# spooflens CSV log, frame {frame}\n# time_reference: {table.time_reference}\n"
                f"# t0_ns: {table.t0_ns}\n"
            )
            if frame == "imu":
                f.write(f"# body_frame: {body}\n")
            if frame == "fixes":  # provenance: firmware, receiver, the meaning of the state codes
                f.writelines(f"# metadata {k}: {v}\n" for k, v in table.metadata.items() if "\n" not in v)
            df.to_csv(f, index=False, float_format="%.17g")
