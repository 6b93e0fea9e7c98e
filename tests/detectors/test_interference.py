"""The interference detector: a uniform C/N0 loss told from obstruction, a tunnel and attenuation; the front
end's indicators; the receiver's own jamming state, with "unknown" kept apart from "ok"."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from spooflens.detectors.interference import jamming_monitor, jamming_state_meaning, run_interference
from spooflens.detectors.statistics.signal_loss import SkyMatrix, signal_losses
from spooflens.epoch_table import EpochTable, StreamInfo, build_table
from spooflens.pipeline.evidence import Evidence

T0_NS = 1_772_366_400_000_000_000
N_SATS = 12
SVS = [f"G{i:02d}" for i in range(1, 7)] + [f"E{i:02d}" for i in range(1, 7)]


def sky_rows(seconds: float = 300.0, hz: float = 1.0, seed: int = 0) -> pd.DataFrame:
    """A clean sky: 12 satellites at 35-47 dB-Hz by elevation, 1 dB noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / hz)
    elevation = np.linspace(12.0, 80.0, N_SATS)
    base = 33.0 + 14.0 * np.sin(np.radians(elevation))
    cn0 = base[None, :] + rng.normal(0.0, 1.0, (len(t), N_SATS))
    return pd.DataFrame(
        {
            "t_s": np.repeat(t, N_SATS),
            "receiver_id": "rx",
            "sv_id": np.tile(SVS, len(t)),
            "cn0_dbhz": np.round(cn0.reshape(-1)),
            "elevation_deg": np.tile(elevation, len(t)),
            "azimuth_deg": np.tile(np.arange(N_SATS) * 30.0, len(t)),
            "used": 1.0,
        }
    )


def fix_rows(t: np.ndarray, seed: int = 0, **columns: np.ndarray | float) -> pd.DataFrame:
    rng = np.random.default_rng(seed + 1)
    n = len(t)
    out = {
        "t_s": t,
        "receiver_id": "rx",
        "lat_deg": 45.0 + rng.normal(0, 1e-6, n),
        "lon_deg": 7.0 + rng.normal(0, 1e-6, n),
        "height_m": 300.0 + rng.normal(0, 0.1, n),
        "h_acc_m": 1.5 + rng.normal(0, 0.05, n),
        "sats_used": np.full(n, 12.0),
        "fix_type": np.full(n, 2, dtype=np.int8),
    }
    return pd.DataFrame(out | {k: np.broadcast_to(v, n).astype(float) for k, v in columns.items()})


def table_of(sky: pd.DataFrame | None, fixes: pd.DataFrame, metadata: dict[str, str] | None = None) -> EpochTable:
    frames = {"fixes": fixes.assign(t_ns=T0_NS + np.round(fixes.pop("t_s") * 1e9).astype(np.int64))}
    streams = [StreamInfo("fix", "rx", "rx", "test", len(fixes))]
    if sky is not None:
        sky = sky.copy()
        frames["satellites"] = sky.assign(t_ns=T0_NS + np.round(sky.pop("t_s") * 1e9).astype(np.int64))
        streams.append(StreamInfo("satellites", "rx", "rx/sky", "test", int(frames["satellites"]["t_ns"].nunique())))
    return build_table(Path("test"), "test", "unix", frames, streams, [], metadata=metadata or {}, t0_ns=T0_NS)


def dropped(sky: pd.DataFrame, start: float, end: float, db: float, which: list[str] | None = None) -> pd.DataFrame:
    out = sky.copy()
    inside = (out["t_s"] >= start) & (out["t_s"] <= end)
    if which is not None:
        inside &= out["sv_id"].isin(which)
    out.loc[inside, "cn0_dbhz"] -= db
    return out


def test_a_uniform_drop_is_one_loss_with_its_interval_and_a_tunnel_and_a_wall_are_not_uniform() -> None:
    sky = sky_rows()
    events, _ = signal_losses(SkyMatrix.from_rows(dropped(sky, 120.0, 180.0, 15.0)))
    assert len(events) == 1
    e = events[0]
    assert e.onset_interval_s[0] <= 120.0 <= e.onset_interval_s[1] <= 121.0
    assert 180.0 <= e.end_interval_s[1] <= 181.0 and e.end_s <= 180.0
    assert np.nanmedian(e.drop_db) == pytest.approx(15.0, abs=1.0) and not e.lost.any()
    assert not signal_losses(SkyMatrix.from_rows(sky))[0]  # a clean sky: nothing
    quiet = dropped(sky, 120.0, 180.0, 3.0)  # 3 dB: under the 6 dB a loss needs
    assert not signal_losses(SkyMatrix.from_rows(quiet))[0]


def _only_event(table: EpochTable) -> dict[str, object]:
    r = run_interference(table)
    events = [*r.extras["events"], *r.extras["rejected"]]  # type: ignore[misc]
    assert len(events) == 1, events
    return events[0]  # type: ignore[no-any-return]


def test_obstruction_a_tunnel_and_attenuation_are_no_interference_alarm() -> None:
    sky = sky_rows()
    t = np.arange(0.0, 300.0)
    fixes = fix_rows(t, agc=4000.0, noise_per_ms=90.0)
    fixes["agc"] += np.random.default_rng(3).normal(0, 15, len(t))
    # a wall: the six low satellites lose 20 dB, the high ones nothing
    low = [s for s, el in zip(SVS, np.linspace(12.0, 80.0, N_SATS), strict=True) if el < 45]
    wall = _only_event(table_of(dropped(sky, 120.0, 180.0, 20.0, low), fixes.copy()))
    assert not wall["alarm"] and wall["uniform"] is False and wall["signature"] == "uneven drop"
    # a tunnel: every satellite gone
    tunnel = sky[~((sky["t_s"] >= 120) & (sky["t_s"] <= 180))]
    tunnel = pd.concat([tunnel, sky[(sky["t_s"] >= 120) & (sky["t_s"] <= 180)].assign(cn0_dbhz=np.nan)])
    gone = _only_event(table_of(tunnel.sort_values("t_s"), fixes.copy()))
    assert not gone["alarm"] and gone["signature"] == "everything lost"
    # every satellite 12 dB weaker with the AGC and noise as they were: attenuation (a radome, foliage)
    weaker = _only_event(table_of(dropped(sky, 120.0, 180.0, 12.0), fixes.copy()))
    assert weaker["uniform"] is True and not weaker["alarm"] and "attenuated" in str(weaker["because"])


def test_a_uniform_drop_with_the_agc_down_is_jamming_with_systems_bands_and_intervals() -> None:
    sky = dropped(sky_rows(), 120.0, 180.0, 15.0)
    t = np.arange(0.0, 300.0)
    jammed = (t >= 120) & (t <= 180)
    agc = np.where(jammed, 2400.0, 4000.0) + np.random.default_rng(4).normal(0, 15, len(t))
    r = run_interference(table_of(sky, fix_rows(t, agc=agc)))
    assert r.ran and r.evidence == Evidence.INTERFERENCE and len(r.alarms) == 1
    a = r.alarms[0]
    assert a.onset_interval_s is not None and a.onset_interval_s[0] <= 120.0 <= a.onset_interval_s[1]
    assert a.end_interval_s is not None and a.end_interval_s[0] <= 180.0 <= a.end_interval_s[1]
    assert a.systems == ("GPS", "Galileo") and a.bands == ("L1", "E1") and len(a.satellites) == N_SATS
    assert a.peak_statistic == pytest.approx(15.0, abs=1.0)
    text = r.findings[0].text
    assert "all 12 GPS L1 and Galileo E1 satellites fell by" in text and "AGC down 40 %" in text
    assert "fix held" in text
    event = r.extras["events"][0]  # type: ignore[index]
    assert event["uniform"] is True and event["rf_verdict"] == "power up"


def test_without_rf_indicators_a_uniform_drop_alarms_and_says_why() -> None:
    sky = dropped(sky_rows(), 120.0, 180.0, 15.0)
    event = _only_event(table_of(sky, fix_rows(np.arange(0.0, 300.0))))
    assert event["alarm"] and event["rf_verdict"] == "not logged" and "no AGC or noise" in str(event["because"])


def test_the_receivers_jamming_state_alarms_and_unknown_is_not_ok() -> None:
    t = np.arange(0.0, 200.0)
    state = np.where((t >= 50) & (t < 80), 2.0, 1.0)
    meta = {"enum.jamming_state": "u-blox jammingState: 0 unknown or disabled, 1 ok, 2 warning, 3 critical"}
    r = run_interference(table_of(None, fix_rows(t, jamming_state=state), meta))
    assert [(a.start_s, a.end_s) for a in r.alarms] == [(50.0, 79.0)]
    assert "the receiver reported jamming (warning)" in r.findings[0].text
    meaning = jamming_state_meaning(meta)
    off = jamming_monitor(table_of(None, fix_rows(t, jamming_state=0.0)).fixes, meaning)
    ok = jamming_monitor(table_of(None, fix_rows(t, jamming_state=1.0)).fixes, meaning)
    missing = jamming_monitor(table_of(None, fix_rows(t)).fixes, meaning)
    assert off["reported"] == "unknown or monitor off" and ok["reported"].startswith("ok")
    assert missing["reported"] == "not logged"
    px4 = jamming_state_meaning({"enum.jamming_state": "0 unknown, 1 OK, 2 mitigated, 3 detected"})
    assert px4[2] == "mitigated"


def test_the_front_ends_power_alone_needs_two_indicators_together() -> None:
    t = np.arange(0.0, 400.0)
    rng = np.random.default_rng(5)
    on = (t >= 200) & (t < 240)
    agc = 4000.0 + rng.normal(0, 15, len(t)) - 1500.0 * on
    noise = 90.0 + rng.normal(0, 1, len(t)) + 40.0 * on
    both = run_interference(table_of(None, fix_rows(t, agc=agc, noise_per_ms=noise)))
    assert len(both.alarms) == 1 and 199.0 <= both.alarms[0].start_s <= 201.0
    one = run_interference(table_of(None, fix_rows(t, agc=agc, noise_per_ms=90.0 + rng.normal(0, 1, len(t)))))
    assert not one.alarms


def test_a_log_without_any_signal_level_is_not_judged() -> None:
    t = np.arange(0.0, 100.0)
    r = run_interference(table_of(None, fix_rows(t)))
    assert not r.ran and "no C/N0" in r.reason


def test_a_c_n0_that_never_changes_is_said_to_be_one_not_missing() -> None:
    """A 6 s excerpt of a real receiver's NMEA: its GSV carried C/N0 that had not yet changed, and the test
    said the log had no C/N0 at all."""
    t = np.arange(0.0, 5.0)
    steady = sky_rows(5.0).assign(cn0_dbhz=np.tile(40.0 + np.arange(N_SATS), 5))
    r = run_interference(table_of(steady, fix_rows(t)))
    assert not r.ran
    assert r.reason.startswith("the C/N0 of most satellites never changes over the log's 5 epochs")
    # with the front end's gain to judge it runs, and says why its sky gives no C/N0 (it said "from none")
    r = run_interference(table_of(steady, fix_rows(t, agc=np.linspace(3000.0, 3010.0, 5))))
    assert r.ran and "C/N0 from none (each satellite's C/N0 the same throughout" in r.reason


def test_the_verdict_keeps_interference_apart_from_spoofing() -> None:
    from spooflens.detectors.base import Alarm, DetectorResult
    from spooflens.pipeline.verdict import decide

    spoof = [
        DetectorResult("a", True, alarms=[Alarm(130.0, 200.0, 9.0, 131.0, onset_s=130.0)], evidence=Evidence.INERTIAL),
        DetectorResult("b", True, alarms=[Alarm(131.0, 200.0, 9.0, 132.0, onset_s=131.0)], evidence=Evidence.RECEIVER),
    ]
    jam = DetectorResult(
        "interference",
        True,
        alarms=[Alarm(100.0, 129.0, 15.0, 100.0, onset_s=100.0)],
        evidence=Evidence.INTERFERENCE,
    )
    verdict = decide([*spoof, jam])
    assert [(i.start_s, i.is_spoofing) for i in verdict.incidents] == [(100.0, False), (130.0, True)]
    assert verdict.incidents[1].onset_s == 130.0  # the jamming before it did not move its onset
    alone = decide([copy.deepcopy(jam)])
    assert not alone.spoofed and alone.incidents[0].confidence == "low"
