"""Attacked copies of u-blox captures through `spooflens inject`: NAV-PVT rewritten in place, and a refusal
where the capture's fixes come from messages the rewriter does not edit (an unmoved copy with an attack's
truth beside it would be a lie)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from paths import real_log

from readers import read_log
from spooflens.cli import main


def test_a_ramp_moves_the_nav_pvt_fixes_of_a_real_capture_after_its_start(tmp_path: Path) -> None:
    log = real_log("ubx_receivers/gpsd_ublox-zed-f9r.log")
    out = tmp_path / "f9r_ramp.ubx"
    assert main(["inject", str(log), "--attack", "ramp:start=10,rate=2", "-o", str(out)]) == 0
    clean, spoofed = read_log(log).fixes, read_log(out).fixes
    assert len(clean) == len(spoofed)
    t = clean["t_s"].to_numpy()
    north = (spoofed["lat_deg"].to_numpy() - clean["lat_deg"].to_numpy()) * 111_320.0
    east = (
        (spoofed["lon_deg"].to_numpy() - clean["lon_deg"].to_numpy())
        * 111_320.0
        * np.cos(np.radians(clean["lat_deg"].to_numpy()))
    )
    moved = np.hypot(north, east)
    assert moved[t < 9.9].max() < 0.01
    # 2 m/s on each of east and north: 2.83 m more per second after the start (to the message's 1e-7 deg)
    late = t > 12.0
    np.testing.assert_allclose(moved[late], 2.0 * np.sqrt(2.0) * (t[late] - 10.0), rtol=0.01, atol=0.05)


def test_a_capture_whose_fixes_are_not_nav_pvt_is_refused_and_nothing_is_written(tmp_path: Path) -> None:
    out = tmp_path / "gr701w_ramp.ubx"
    code = main(
        ["inject", str(real_log("corpus/gpsd/navisys-gr701w.log")), "--attack", "ramp:start=10", "-o", str(out)]
    )
    assert code == 2
    assert not out.exists() and not Path(f"{out}.attack.json").exists()
