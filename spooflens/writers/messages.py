"""An EpochTable as the time-ordered messages a log file would hold.

Topic conventions (the readers find them again): IMU streams on their imu_id, receivers on their
receiver_id (a leading '/' added), a receiver's velocity on `<receiver>_velocity`, truth on
`/truth/fix`, odometry on its odometry_id.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pandas as pd

from spooflens.epoch_table import EpochTable

TRUTH_TOPIC = "/truth/fix"
VELOCITY_SUFFIX = "_velocity"


def topic_name(stream_id: str) -> str:
    return stream_id if stream_id.startswith("/") else "/" + stream_id


@dataclass(frozen=True)
class OutStream:
    topic: str
    kind: str  # navsatfix | imu | twist_cov | odometry
    t_ns: np.ndarray
    rows: pd.DataFrame  # the table rows of this stream, aligned with t_ns
    frame_id: str


def out_streams(table: EpochTable) -> list[OutStream]:
    """Every stream of the table as the topic, message kind and rows a writer emits."""
    out: list[OutStream] = []
    for iid in table.imus():
        rows = table.imu_of(iid)
        info = table.stream("imu", iid)
        out.append(
            OutStream(
                topic_name(iid),
                "imu",
                table.absolute_ns(rows["t_s"].to_numpy()),
                rows,
                (info.frame_id if info and info.frame_id else "imu_link"),
            )
        )
    for rid in table.receivers():
        rows = table.fixes_of(rid)
        info = table.stream("fix", rid)
        t_ns = table.absolute_ns(rows["t_s"].to_numpy())
        frame = info.frame_id if info and info.frame_id else "gnss"
        out.append(OutStream(topic_name(rid), "navsatfix", t_ns, rows, frame))
        has_vel = rows[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].notna().all(axis=1).to_numpy()
        if has_vel.any():
            out.append(
                OutStream(
                    topic_name(rid) + VELOCITY_SUFFIX,
                    "twist_cov",
                    t_ns[has_vel],
                    rows[has_vel].reset_index(drop=True),
                    frame,
                )
            )
    if len(table.truth):
        out.append(
            OutStream(
                TRUTH_TOPIC,
                "navsatfix",
                table.absolute_ns(table.truth["t_s"].to_numpy()),
                table.truth.assign(fix_type=2, h_acc_m=np.nan, v_acc_m=np.nan),
                "truth",
            )
        )
    for oid in dict.fromkeys(table.odometry["odometry_id"].astype(str)):
        rows = table.odometry[table.odometry["odometry_id"] == oid].reset_index(drop=True)
        out.append(OutStream(topic_name(oid), "odometry", table.absolute_ns(rows["t_s"].to_numpy()), rows, "odom"))
    return out


def in_time_order(streams: list[OutStream]) -> Iterator[tuple[OutStream, int, int]]:
    """(stream, row index, t_ns) over all streams, merged by time (stable per stream)."""
    if not streams:
        return
    t = np.concatenate([s.t_ns for s in streams])
    which = np.concatenate([np.full(len(s.t_ns), i) for i, s in enumerate(streams)])
    row = np.concatenate([np.arange(len(s.t_ns)) for s in streams])
    for k in np.argsort(t, kind="stable"):
        yield streams[which[k]], int(row[k]), int(t[k])
