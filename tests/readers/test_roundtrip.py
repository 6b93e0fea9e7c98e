"""Every writer's output reads back into the same table (for the columns the format can carry)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pipeline_support import circling_table

from readers import read_log
from spooflens.epoch_table import EpochTable
from spooflens.writers import SUFFIX, WRITERS, write_log

# What each format cannot carry: NavSatFix has no satellite count; a covariance needs both accuracies;
# Foxglove JSON/protobuf have no GNSS velocity message.
LOSSY = {"ros": {"h_acc_m", "sats_used"}, "foxglove": {"h_acc_m", "sats_used", "vel_e_mps", "vel_n_mps", "vel_u_mps"}}


def _lost(fmt: str) -> set[str]:
    if fmt == "csv":
        return set()
    return LOSSY["foxglove"] if fmt in ("mcap-json", "mcap-protobuf") else LOSSY["ros"]


@pytest.fixture(scope="module")
def table():
    return circling_table(ramp_mps=2.0, seconds=60.0)


# ULog has its own conventions (below); RINEX holds raw observations only (tests/writers/test_rinex_writer.py)
@pytest.mark.parametrize("fmt", sorted(set(WRITERS) - {"ulog", "rinex"}))
def test_write_then_read_gives_the_same_table(fmt: str, table, tmp_path: Path) -> None:
    path = tmp_path / f"log{SUFFIX[fmt]}"
    write_log(table, path, fmt)
    back = read_log(path)
    assert back.t0_ns == table.t0_ns and back.time_reference == "unix"
    assert back.skipped == []
    for frame in ("imu", "fixes"):
        a, b = table.frame(frame), back.frame(frame)
        assert len(a) == len(b)
        floats = [c for c in a.columns if a[c].dtype.kind == "f" and c not in _lost(fmt)]
        np.testing.assert_allclose(b[floats].to_numpy(float), a[floats].to_numpy(float), rtol=0, atol=1e-9)
        key = "imu_id" if frame == "imu" else "receiver_id"
        assert list(b[key]) == list(a[key])
    assert sorted((s.role, s.stream_id, s.count) for s in back.streams if s.role in ("imu", "fix")) == [
        ("fix", "/gps/fix", len(table.fixes)),
        ("imu", "/imu", len(table.imu)),
    ]


def test_ulog_round_trip_in_px4_conventions(table, tmp_path: Path) -> None:
    """ULog stores float32, an FRD body frame and NED velocity; the reader maps them back."""
    path = tmp_path / "log.ulg"
    write_log(table, path, "ulog")
    back = read_log(path)
    assert back.format == "ulog" and back.time_reference == "unix" and back.t0_ns == table.t0_ns
    imu_info = next(s for s in back.streams if s.role == "imu")
    assert imu_info.body_frame == "FRD"
    flu_to_frd = np.array([1.0, -1.0, -1.0])
    np.testing.assert_allclose(
        back.imu[["ax_mps2", "ay_mps2", "az_mps2"]].to_numpy(),
        table.imu[["ax_mps2", "ay_mps2", "az_mps2"]].to_numpy() * flu_to_frd,
        atol=1e-5,
    )
    cols = ["lat_deg", "lon_deg", "height_m", "sats_used"]
    np.testing.assert_allclose(back.fixes[cols].to_numpy(), table.fixes[cols].to_numpy(), rtol=0, atol=1e-7)
    vel = ["vel_e_mps", "vel_n_mps", "vel_u_mps", "h_acc_m"]
    np.testing.assert_allclose(back.fixes[vel].to_numpy(), table.fixes[vel].to_numpy(), atol=1e-5)


def test_ulog_keeps_the_receivers_spoofing_and_jamming_indications(table, tmp_path: Path) -> None:
    """PX4 logs carry the receiver's own spoofing_state and jamming_indicator: an investigator wants them."""
    from spooflens.schema import SpoofingFlag

    flagged = table.fixes.copy()
    later = flagged["t_s"] > flagged["t_s"].median()
    flagged["spoofing_flag"] = np.where(later, SpoofingFlag.INDICATED, SpoofingFlag.CLEAR).astype(np.int8)
    flagged["jamming_indicator"] = np.where(later, 80.0, 5.0)
    path = tmp_path / "flags.ulg"
    write_log(EpochTable(**{**table.__dict__, "fixes": flagged}), path, "ulog")
    back = read_log(path).fixes
    np.testing.assert_array_equal(back["spoofing_flag"], flagged["spoofing_flag"])
    np.testing.assert_array_equal(back["jamming_indicator"], flagged["jamming_indicator"])
