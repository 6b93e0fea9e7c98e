"""`inject jam` on u-blox captures whose receiver never had a fix but logged its front-end monitor
(MON-HW, MON-RF): each monitor message carries the jammer of its own `receiver_status` row, every other
byte is copied, and `analyze` of the copy finds the jammer in those reports alone."""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from paths import real_log
from pyubx2 import UBXMessage

from readers import read_log
from readers.ubx.frames import split_frames
from spooflens.attacks import apply_attack, parse_attack
from spooflens.attacks.spec import AttackError
from spooflens.cli import main

WEEK, TOW0_MS = 2300, 300_000_000  # a dated capture: NAV-TIMEGPS states its week
MONITORS = {(0x0A, 0x09), (0x0A, 0x38), (0x27, 0x09)}
COLUMNS = ["agc", "noise_per_ms", "jamming_indicator", "jamming_state"]


def monitor_capture(path: Path, seconds: int, epochs: bool) -> Path:
    """`seconds` of MON-HW at 1 Hz from a receiver without a fix, its noise, AGC and jamming indicator
    jittering as a real front end's do; with `epochs`, each second opens with NAV-PVT (fixType 0) and a
    NAV-TIMEGPS that dates it, else the monitor is all the capture holds."""
    rng = np.random.default_rng(7)
    out = bytearray()
    for k in range(seconds):
        itow = TOW0_MS + 1000 * k
        if epochs:
            out += UBXMessage("NAV", "NAV-PVT", 0, iTOW=itow, fixType=0, numSV=0).serialize()
            out += UBXMessage(
                "NAV", "NAV-TIMEGPS", 0, iTOW=itow, week=WEEK, leapS=18, towValid=1, weekValid=1, leapSValid=1
            ).serialize()
        out += UBXMessage(
            "MON",
            "MON-HW",
            0,
            noisePerMS=int(rng.integers(85, 96)),
            agcCnt=int(rng.integers(4900, 5100)),
            jamInd=int(rng.integers(5, 14)),
            jammingState=1,  # the monitor is on and says ok
        ).serialize()
    path.write_bytes(bytes(out))
    return path


def reports(path: Path) -> pd.DataFrame:
    status = read_log(path).receiver_status
    return status.set_index(status["t_s"].round(3))[COLUMNS].astype(float)


def non_monitor_bytes(path: Path) -> tuple[bytes, list[int]]:
    """The file with its monitor messages cut out, and those messages' lengths."""
    data = path.read_bytes()
    kept, lengths, pos = bytearray(), [], 0
    for f in split_frames(data).ubx:
        if (f.msg_class, f.msg_id) in MONITORS:
            kept += data[pos : f.offset]
            lengths.append(f.raw_length)
            pos = f.offset + f.raw_length
    return bytes(kept + data[pos:]), lengths


def inject(src: Path, attack: str, out: Path) -> None:
    assert main(["inject", str(src), "--attack", attack, "-o", str(out)]) == 0


@pytest.mark.parametrize("epochs", [True, False], ids=["dated epochs", "monitor alone"])
def test_each_monitor_report_carries_the_jammer_and_every_other_byte_is_copied(tmp_path: Path, epochs: bool) -> None:
    src = monitor_capture(tmp_path / "monitor.ubx", 120, epochs)
    out = tmp_path / "jammed.ubx"
    inject(src, "jam:start=40,end=80", out)
    before, after = reports(src), reports(out)
    assert len(before) == 120 and before.index.equals(after.index)
    t = before.index.to_numpy(float)
    outside = (t < 40.0) | (t > 80.0)
    pd.testing.assert_frame_equal(before[outside], after[outside])
    full = (t >= 42.0) & (t <= 78.0)  # the jammer's 2 s ramp done
    b, a = before[full], after[full]
    np.testing.assert_allclose(a["agc"], np.round(b["agc"] * 0.6), atol=1.0)  # agc=0.6 at full power
    np.testing.assert_allclose(a["noise_per_ms"], np.round(b["noise_per_ms"] * 1.5), atol=1.0)
    np.testing.assert_array_equal(a["jamming_indicator"], np.minimum(b["jamming_indicator"] + 150.0, 255.0))
    # a 15 dB drop: the monitor that was on says critical, the receiver having no fix
    assert (a["jamming_state"] == 3.0).all()
    cut_src, lengths_src = non_monitor_bytes(src)
    cut_out, lengths_out = non_monitor_bytes(out)
    assert cut_src == cut_out and lengths_src == lengths_out
    truth = json.loads(Path(f"{out}.attack.json").read_text())
    assert truth["kind"] == "jam" and truth["receivers"] == ["ubx"]


def analyze_json(path: Path, tmp_path: Path) -> dict[str, Any]:
    report = tmp_path / f"{path.name}.json"
    assert main(["analyze", str(path), "-o", str(tmp_path / "x.rrd"), "--json", str(report), "--quiet"]) == 0
    summary: dict[str, Any] = json.loads(report.read_text())
    return summary


def test_analyze_of_the_jammed_monitor_only_capture_names_the_jamming(tmp_path: Path) -> None:
    src = monitor_capture(tmp_path / "monitor.ubx", 120, epochs=True)
    out = tmp_path / "jammed.ubx"
    inject(src, "jam:start=40,end=80", out)
    for log in (src, out):
        summary = analyze_json(log, tmp_path)
        events = summary["verdict"]["events"]
        (result,) = [a for a in summary["analyses"] if a["name"] == "interference"]
        if log == src:
            assert not events and not result["alarms"], (events, result["alarms"])
            continue
        assert not summary["verdict"]["spoofed"]
        (event,) = [e for e in events if e["kind"] == "jamming"]
        assert 39.0 <= event["start_s"] <= 44.0 and 78.0 <= event["end_s"] <= 86.0, event
        (alarm,) = result["alarms"]
        assert 39.0 <= alarm["start_s"] <= 44.0 and 78.0 <= alarm["end_s"] <= 86.0, alarm


def test_inject_jam_on_a_real_capture_with_two_monitor_reports_and_no_fix(tmp_path: Path) -> None:
    # pyubx2's MON capture: MON-RF and MON-HW (one output cycle, no time in it), then a second MON-RF
    src = real_log("corpus/pyubx2/pygpsdata-MON.log")
    out = tmp_path / "mon_jam.ubx"
    inject(src, "jam:start=0,ramp=0", out)
    before, after = reports(src), reports(out)
    assert before["agc"].tolist() == [1404.0, 1404.0] and after["agc"].tolist() == [842.0, 842.0]
    assert after["noise_per_ms"].tolist() == [138.0, 138.0]
    assert after["jamming_indicator"].tolist() == [157.0, 255.0]  # 7 + 150; 255 already at the top
    assert after["jamming_state"].tolist() == [3.0, 3.0]
    assert non_monitor_bytes(src) == non_monitor_bytes(out)
    assert len(src.read_bytes()) == len(out.read_bytes()) and src.read_bytes() != out.read_bytes()


def test_a_table_without_any_gnss_is_refused_for_what_it_lacks() -> None:
    table = read_log(real_log("corpus/pyubx2/pygpsdata-MON.log"))
    jammed, truth = apply_attack(table, parse_attack("jam:start=0,ramp=0"))
    assert truth.receivers == ["ubx"] and (jammed.receiver_status["agc"] < 1404.0).all()
    bare = copy.copy(table)
    bare.receiver_status = table.receiver_status.iloc[:0]
    lacks = "no GNSS receiver to jam (no fixes, satellites, observations or monitor reports)"
    with pytest.raises(AttackError, match=re.escape(lacks)):
        apply_attack(bare, parse_attack("jam:start=0"))
