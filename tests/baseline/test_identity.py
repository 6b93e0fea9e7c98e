"""Which receiver, firmware and IMU a log names, as each reader puts it in the metadata."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from paths import real_log

from spooflens.baseline.identity import identify, same_model
from spooflens.epoch_table import EpochTable
from spooflens.schema import make_frame
from spooflens.service import read_table


def _table(metadata: dict[str, str], receivers: tuple[str, ...] = ("gps",)) -> EpochTable:
    n = len(receivers)
    columns = {"t_s": np.zeros(n), "receiver_id": np.array(receivers), "lat_deg": np.ones(n)}
    fixes = make_frame("fixes", columns | {"lon_deg": np.ones(n), "height_m": np.ones(n), "fix_type": np.full(n, 2)})
    return EpochTable(Path("x.log"), "test", 0, "unix", fixes=fixes, metadata=metadata)


@pytest.mark.parametrize(
    ("metadata", "model"),
    [
        ({"receiver.extensions": "ROM BASE 0x118B2060; FWVER=SPG 4.04; PROTVER=32.01; MOD=NEO-M9N"}, "NEO-M9N"),
        ({"log_header": "Name: x | Chipset: u-blox  ZED-F9P, firmware hpg1.11 | Date: 2019"}, "u-blox ZED-F9P"),
        ({"receivers": "GPS 1: detected as u-blox at 230400 baud"}, "u-blox"),
        (
            {"receivers": "GPS 1: probing for u-blox at 230400 baud; u-blox 1 HW: 00080000 SW: EXT CORE 3.01"},
            "u-blox HW 00080000",
        ),
        ({"firmware": "v3.0.6.4 Platform: 14 Manufacturer: Google Model: Pixel 7"}, "Google Pixel 7"),
        ({"firmware": "PX4 v1.15"}, None),
        ({}, None),
    ],
)
def test_the_receiver_model_each_reader_names(metadata: dict[str, str], model: str | None) -> None:
    assert identify(_table(metadata)).receivers == {"gps": model}


def test_px4_names_each_receiver_from_its_device_id() -> None:
    meta = {
        "receiver": "gps0: u-blox F9P on serial bus 2 (device_id 0xA80015); "
        "gps1: u-blox M8 on serial bus 3 (device_id 0xA80016)",
        "px4.device_id.gps0": "11010069",
        "px4.device_id.gps1": "11010070",
        "firmware": "PX4 v1.15.0",
    }
    ident = identify(_table(meta, ("gps0", "gps1")))
    assert ident.receivers == {"gps0": "u-blox F9P", "gps1": "u-blox M8"}
    assert ident.firmware == ("PX4 v1.15.0",)


def test_same_model_means_the_words_of_one_are_in_the_other() -> None:
    assert same_model("ZED-F9P", "u-blox  ZED-F9P")
    assert same_model("u-blox", "u-blox HW 00080000")
    assert not same_model("u-blox ZED-F9P", "u-blox NEO-M8N")
    assert not same_model("Google Pixel 7", "Google Pixel 4")
    assert not same_model("", "ZED-F9P")


def test_real_logs_name_their_receivers() -> None:
    hp = identify(read_table(real_log("corpus/gpsd/ublox-zed-f9p-hp.log"), {}, False))
    assert hp.receivers == {"ubx": "ZED-F9P"} and hp.receiver_firmware == ("HPG 1.11",)
    plane = identify(read_table(real_log("ardupilot_dataflash/flightdata_center_0003.bin"), {}, False))
    assert plane.receivers == {"GPS[0]": "u-blox"} and plane.firmware == ("ArduPlane V4.2.3 (55685c43)",)
