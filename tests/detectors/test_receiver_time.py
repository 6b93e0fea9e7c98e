"""receiver_time: steps of the receiver's time against the log's own clock."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from paths import real_log
from px4_support import BOOT_UTC_US, current_log, flight
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

from readers import read_log
from spooflens.attacks import apply_attack
from spooflens.attacks.spec import parse_attack
from spooflens.baseline.format import Baseline
from spooflens.cli import main
from spooflens.detectors.receiver_time import run_receiver_time
from spooflens.pipeline.evidence import Evidence
from spooflens.pipeline.run import analyze_table
from spooflens.pipeline.verdict import Kind


def _fixes(t: np.ndarray, offset: np.ndarray) -> pd.DataFrame:
    return pd.DataFrame({"t_s": t, "receiver_id": "gps", "time_offset_s": offset})


def _logger(seconds: float = 1800.0, rate_hz: float = 5.0, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A logger's view of a healthy receiver: 30 ppm of crystal drift, 20 ms of latency jitter and a
    message now and then 150 ms late."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / rate_hz)
    x = 30e-6 * t + rng.normal(0.0, 0.02, len(t))
    late = rng.random(len(t)) < 0.01
    return t, x - np.where(late, 0.15, 0.0)


def test_a_healthy_receiver_raises_nothing() -> None:
    t, x = _logger()
    result = run_receiver_time(_fixes(t, x))
    assert result.ran and result.evidence == Evidence.LOG_CLOCK
    assert not result.alarms and not result.findings
    assert "robust sigma 2" in result.reason and "alarm level 0.250 s" in result.reason  # 8 x 20 ms < 0.25 s


@pytest.mark.parametrize("step", [0.4, -2.7, 3600.0, -86_400.3])
def test_a_spoofer_clock_is_an_alarm_from_the_step_to_the_return(step: float) -> None:
    t, x = _logger()
    attacked = (t >= 600.0) & (t < 900.0)
    result = run_receiver_time(_fixes(t, x + step * attacked))
    assert len(result.alarms) == 1  # the return to the old time is no second step
    a = result.alarms[0]
    assert a.onset_interval_s == (pytest.approx(599.8), pytest.approx(600.0))
    assert a.start_s == pytest.approx(600.4)  # three fixes on the new time
    assert a.end_s == pytest.approx(899.8)
    assert a.receiver_id == "gps"
    assert result.extras["gps/steps_s"] == [pytest.approx(step, abs=0.01)]
    (finding,) = result.findings
    assert "against the log's own clock at 600.0 s, until 899.8 s" in finding.text


def test_utc_back_by_a_second_early_in_the_log_is_the_leap_seconds_being_learned() -> None:
    t, x = _logger()
    result = run_receiver_time(_fixes(t, x - 1.0 * (t >= 300.0)))
    assert not result.alarms
    (finding,) = result.findings
    assert "exactly -1 s at 300.0 s" in finding.text and "not counted" in finding.text
    # after the 15 minutes in which broadcast UTC parameters arrive, or forward (no default is ahead of
    # today's 18 leap seconds), or 5 s, it is not that
    for step, at in ((-1.0, 1200.0), (1.0, 300.0), (-5.0, 300.0)):
        late = run_receiver_time(_fixes(t, x + step * (t >= at)))
        assert len(late.alarms) == 1 and late.alarms[0].onset_s == pytest.approx(at)


def test_a_step_of_the_loggers_own_clock_is_not_the_receivers() -> None:
    t, x = _logger()
    stepped = t >= 700.0
    # the host's clock is set 5.3 s ahead (NTP): the rows move on, the receiver's time does not
    result = run_receiver_time(_fixes(t + 5.3 * stepped, x - 5.3 * stepped))
    assert not result.alarms
    (finding,) = result.findings
    assert (
        "logger's clock stepped by +5.2" in finding.text
        and "at 705.3 s while the receiver's time ran on" in finding.text
    )


def test_against_a_boot_clock_a_time_that_ran_on_across_a_gap_is_the_receivers_step() -> None:
    """The fixes stop for 8 s (the takeover) and the spoofer resumes at the time of the last real fix: a
    host clock's step would look the same, a monotonic boot clock cannot step."""
    t, x = _logger()
    keep = (t < 700.0) | (t >= 708.0)
    t, x = t[keep], x[keep] - 8.0 * (t[keep] >= 708.0)  # the first fix after the gap one period on
    host = run_receiver_time(_fixes(t, x))
    assert not host.alarms and "logger's clock stepped" in host.findings[0].text
    boot = run_receiver_time(_fixes(t, x), clock="TimeUS, the autopilot's boot clock", monotonic=True)
    (alarm,) = boot.alarms
    assert alarm.onset_interval_s == (pytest.approx(699.8), pytest.approx(708.0))
    assert (
        "moved -7.98" in boot.findings[0].text and "against TimeUS, the autopilot's boot clock" in boot.findings[0].text
    )


@pytest.mark.parametrize(
    "relative",
    [
        "ardupilot_dataflash/flightdata_center_0003.bin",
        "android_gnsslogger/gnss_lib_py/pixel6.txt",
        "android_gnsslogger/gnss_lib_py/pixel6.nmea",
    ],
)
def test_real_logs_have_the_offset_and_no_alarm(relative: str) -> None:
    table = read_log(real_log(relative))
    x = table.fixes["time_offset_s"].to_numpy(dtype=float)
    assert np.isfinite(x).mean() > 0.9 and np.nanmax(np.abs(x)) < 0.07  # latency jitter only
    result = run_receiver_time(table.fixes)
    assert result.ran and not result.alarms and not result.findings


def test_px4_table_with_the_spoofers_utc(tmp_path: Path) -> None:
    f = flight(np.round(np.arange(1.0, 240.0, 0.2), 6))
    t_us = np.round(f["t_s"] * 1e6).astype(np.int64)
    jump = np.where(f["t_s"] >= 100.0, 3_600_000_000, 0)
    pd.DataFrame(
        {
            "timestamp": t_us,
            "lat": f["lat_deg"],
            "lon": f["lon_deg"],
            "alt_ellipsoid": f["height_m"],
            "vel_n_m_s": f["vel_n_mps"],
            "vel_e_m_s": f["vel_e_mps"],
            "fix_type": 3,
            "time_utc_usec": BOOT_UTC_US + t_us + jump,
            "timestamp_time_relative": 0,
        }
    ).to_csv(tmp_path / "gps.csv", index=False)
    fixes = read_log(tmp_path / "gps.csv").fixes
    x = fixes["time_offset_s"].to_numpy()  # less its median: the spoofed time fills most of this log
    np.testing.assert_allclose(x - x[0], np.where(f["t_s"] >= 100.0, 3600.0, 0.0))
    (alarm,) = run_receiver_time(fixes).alarms
    # t_s counts from the first row (boot 1.0 s): boot 100 s is 99 s into the log
    assert alarm.onset_interval_s == (pytest.approx(98.8), pytest.approx(99.0))


def test_real_ardupilot_log_with_a_spoofer_clock_injected(tmp_path: Path) -> None:
    """The real flight's GPS messages rewritten by `inject` (GWk/GMS moved with the position): the
    receiver's time makes an independent class. Without it the capture is spoofing on what its copy
    carries beside the step (the receiver's inflated accuracies, HDOP and lost satellites in GPS/GPA),
    medium and over once the step's alarms end; with it, high and to the end of the log."""
    src = real_log("ardupilot_dataflash/flightdata_center_0003.bin")
    verdicts = {}
    for clock in (0.0, 3600.5):
        out = tmp_path / f"clock{clock:g}.bin"
        attack = f"capture:start=20,drag=step,offset=300,clock={clock}"
        assert main(["inject", str(src), "--attack", attack, "-o", str(out)]) == 0
        report = tmp_path / f"clock{clock:g}.json"
        main(["analyze", str(out), "-o", str(tmp_path / "x.rrd"), "--json", str(report), "--quiet"])
        verdicts[clock] = json.loads(report.read_text())
    assert verdicts[0.0]["metadata"]["time_offset.monotonic"] == "yes"
    clean, spoofed = verdicts[0.0]["verdict"], verdicts[3600.5]["verdict"]
    assert not any("log_clock" in i["evidence"] for i in clean["incidents"])
    assert all(i["confidence"] != "high" and not i["ongoing_at_end"] for i in clean["incidents"])
    assert spoofed["spoofed"]
    incident = spoofed["incidents"][0]
    assert incident["confidence"] == "high" and incident["evidence"] == ["gnss_only", "receiver", "log_clock"]
    assert incident["onset_s"] == pytest.approx(24.0, abs=0.3) and incident["ongoing_at_end"]
    assert any(
        "time moved +3600.5" in str(f) and "against the autopilot's boot clock (TimeUS; TimeMS before 2015)" in str(f)
        for f in spoofed["findings"]
    )


def test_px4_ulog_inject_writes_the_spoofers_time(tmp_path: Path) -> None:
    src, out = tmp_path / "clean.ulg", tmp_path / "spoofed.ulg"
    current_log(src, attack_s=None)
    assert run_receiver_time(read_log(src).fixes).findings == []
    assert main(["inject", str(src), "--attack", "capture:start=20,clock=-7.25", "-o", str(out)]) == 0
    result = run_receiver_time(read_log(out).fixes)
    (alarm,) = result.alarms
    assert alarm.onset_s == pytest.approx(24.0)  # captured after the 4 s takeover
    assert "time moved -7.250 s against the log's own clock at 24.0 s, to the end of the log" in result.findings[0].text


def _navsat_bag(path: Path, spoof_from_s: float, clock_s: float) -> None:
    """nmea_navsat_driver's topics at 1 Hz for 10 min: /fix and /time_reference (the sentence's UTC beside
    the host's time it came at), the host 0.35 s behind GNSS and 10 ms of serial latency jitter."""
    ts = get_typestore(Stores.ROS1_NOETIC)
    Header, Time = ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    Fix, Status = ts.types["sensor_msgs/msg/NavSatFix"], ts.types["sensor_msgs/msg/NavSatStatus"]
    Ref = ts.types["sensor_msgs/msg/TimeReference"]
    rng = np.random.default_rng(5)
    t0 = 1_700_000_000
    with Writer(path) as w:
        fix_conn = w.add_connection("/gps/fix", "sensor_msgs/msg/NavSatFix", typestore=ts)
        ref_conn = w.add_connection("/gps/time_reference", "sensor_msgs/msg/TimeReference", typestore=ts)
        for k in range(600):
            host_ns = (t0 + k) * 10**9 + int(rng.normal(0.0, 0.01) * 1e9)
            gnss_ns = (t0 + k) * 10**9 + 350_000_000 + (int(clock_s * 1e9) if k >= spoof_from_s else 0)
            header = Header(seq=k, stamp=Time(sec=host_ns // 10**9, nanosec=host_ns % 10**9), frame_id="gps")
            fix = Fix(header, Status(0, 1), 42.0 + k * 1e-6, -71.0, 30.0, np.zeros(9), 0)
            w.write(fix_conn, host_ns, ts.serialize_ros1(fix, "sensor_msgs/msg/NavSatFix"))
            ref = Ref(header, Time(sec=gnss_ns // 10**9, nanosec=gnss_ns % 10**9), "gps")
            w.write(ref_conn, host_ns, ts.serialize_ros1(ref, "sensor_msgs/msg/TimeReference"))


def test_ros_time_reference_is_the_receivers_time(tmp_path: Path) -> None:
    clean, spoofed = tmp_path / "clean.bag", tmp_path / "spoofed.bag"
    _navsat_bag(clean, spoof_from_s=1e9, clock_s=0.0)
    _navsat_bag(spoofed, spoof_from_s=300, clock_s=-41.7)
    table = read_log(clean)
    assert next(s for s in table.streams if s.topic == "/gps/time_reference").receiver == "/gps/fix"
    x = table.fixes["time_offset_s"].to_numpy()
    assert np.isfinite(x).all() and np.abs(x).max() < 0.05
    assert not run_receiver_time(table.fixes).alarms
    (alarm,) = run_receiver_time(read_log(spoofed).fixes).alarms
    assert alarm.onset_interval_s == (pytest.approx(299.0, abs=0.05), pytest.approx(300.0, abs=0.05))
    # inject moves the time references with the fixes they belong to
    injected = tmp_path / "injected.bag"
    assert main(["inject", str(clean), "--attack", "capture:start=200,clock=5", "-o", str(injected)]) == 0
    result = run_receiver_time(read_log(injected).fixes)
    (alarm,) = result.alarms
    assert alarm.onset_s == pytest.approx(204.0, abs=0.05)
    assert result.extras["/gps/fix/steps_s"] == [pytest.approx(5.0, abs=0.01)]


def test_real_phone_log_with_a_spoofer_clock_injected(tmp_path: Path) -> None:
    """The Pixel 6's Fix lines rewritten with UnixTimeMillis 30.5 s back from the capture on: the fixes stay
    where the phone's clock put them, the time they carry is the alarm."""
    src = real_log("android_gnsslogger/gnss_lib_py/pixel6.txt")
    out = tmp_path / "pixel6_spoofed.txt"
    assert main(["inject", str(src), "--attack", "capture:start=200,clock=-30.5", "-o", str(out)]) == 0
    clean, spoofed = read_log(src), read_log(out)
    np.testing.assert_allclose(spoofed.fixes["t_s"], clean.fixes["t_s"])
    result = run_receiver_time(spoofed.fixes)
    (alarm,) = result.alarms
    assert alarm.onset_interval_s == (pytest.approx(198.0, abs=0.05), pytest.approx(204.0, abs=0.05))
    assert result.extras["phone/steps_s"] == [pytest.approx(-30.5, abs=0.01)]


def _coarse(
    seconds: float = 900.0, cycle_s: float = 1.0055, resolution_s: float = 1.0, seed: int = 4
) -> tuple[np.ndarray, np.ndarray]:
    """A gateway that sends the receiver's last time to the whole second on a cycle of its own (1.0055 s, not
    locked to GNSS seconds), 4 ms of latency jitter: the offset saws, -5.5 ms/s then back by 1 s."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, cycle_s) + 0.3
    receiver = np.floor(t / resolution_s) * resolution_s  # the GNSS time when the message is assembled
    return t + rng.normal(0.0, 0.004, len(t)), receiver


def test_a_time_to_the_whole_second_read_on_a_cycle_of_its_own_is_a_sawtooth_not_a_step() -> None:
    t, receiver = _coarse()
    x = receiver - t
    result = run_receiver_time(_fixes(t, x))
    assert not result.alarms
    (finding,) = result.findings
    assert "whole steps of 1 s" in finding.text and "wraps back by 1 s (5 time(s))" in finding.text
    assert "alarm level 1.250 s (raised by its time's resolution, 1 s)" in result.reason
    # ten messages a second, each with the second it was assembled in: the offset falls 1 s/s, 900 wraps
    t10, r10 = _coarse(cycle_s=0.1)
    assert not run_receiver_time(_fixes(t10, r10 - t10)).alarms
    # a receiver whose messages come at its own seconds (1 Hz, whole seconds) has no sawtooth: 0.25 s holds
    t1 = np.arange(0.0, 900.0, 1.0) + 0.3
    steady = run_receiver_time(_fixes(t1, np.floor(t1) - t1 + 0.4 * (t1 >= 500.0)))
    assert "raised" not in steady.reason and steady.alarms[0].onset_s == pytest.approx(500.3)


@pytest.mark.parametrize("clock", [30.0, -2.0, 30.5, 3600.0])
def test_a_spoofer_clock_on_a_sawtooth_is_still_an_alarm(clock: float) -> None:
    """A spoofer's time moves the whole band of the sawtooth and keeps it moved; wraps of one step undone by
    the drift are the sawtooth's own. Half a second off, the spoofer's time is on another phase of the
    seconds after its takeover (most of the log still on one)."""
    t, receiver = _coarse()
    x = receiver - t + clock * (t >= 600.0)
    result = run_receiver_time(_fixes(t, x))
    (alarm,) = result.alarms
    assert alarm.onset_s == pytest.approx(600.0, abs=1.1)
    assert any("a spoofer's clock" in f.text for f in result.findings)


def test_the_real_n2k_gateways_sawtooth_is_no_spoofing_and_a_time_attack_on_it_is() -> None:
    """The Aava's NMEA 2000 capture (clean sky): its 129029 carries the GNSS time to the whole second, sent
    every 1.005 s of the logger's clock, so the time minus the logger's saws -5 ms/s and wraps back by 1 s at
    106.6, 279.5 and 448.4 s (it was SPOOFING on the log clock, four incidents). The same capture with a
    spoofer 30 s off GNSS time from 200 s (inject cannot write NMEA 2000: the table is attacked) is SPOOFING
    from the takeover, the log clock and the GNSS-only class together."""
    table = read_log(real_log("corpus/signalk/aava-n2k.data"))
    result = run_receiver_time(table.fixes)
    assert not result.alarms and result.extras["N2K/160/steps_s"] == []
    assert "wraps back by 1 s (3 time(s))" in result.findings[0].text
    clean = analyze_table(table).verdict
    assert not clean.spoofed and not any(i.kind == Kind.SPOOFING for i in clean.incidents)
    assert not any(Evidence.LOG_CLOCK in i.evidence for i in clean.incidents)
    for clock in (30.0, -2.0):
        spoofed, _ = apply_attack(table, parse_attack(f"capture:start=200,drag=step,offset=300,clock={clock}"))
        verdict = analyze_table(spoofed).verdict
        assert verdict.spoofed
        (incident,) = [i for i in verdict.incidents if i.kind == Kind.SPOOFING]
        assert incident.confidence == "high" and Evidence.LOG_CLOCK in incident.evidence
        assert 200.0 <= incident.onset_s <= 206.0


def _clock_baseline(n: int = 3) -> Baseline:
    from baseline_support import measurement

    from spooflens.baseline.learn import aggregate

    return aggregate([measurement(k, {"hdop": (0.8, 0.05)}) for k in range(n)])


def test_a_baseline_caps_the_jitter_a_spoofers_clock_would_teach() -> None:
    """A spoofer's clock jittering 100 ms from the first fix raises the log's own alarm level above a
    0.5 s step; the clean logs' jitter (20 ms, twice allowed) keeps it at 0.32 s."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 900.0, 0.2)
    x = rng.normal(0.0, 0.1, len(t)) + 0.5 * (t >= 400.0)
    fixes = _fixes(t, x).assign(receiver_id="gps")
    assert not run_receiver_time(fixes, clock="boot clock", monotonic=True).alarms
    with_baseline = run_receiver_time(fixes, clock="boot clock", monotonic=True, baseline=_clock_baseline())
    onset = with_baseline.alarms[0].onset_s if with_baseline.alarms else None
    assert onset is not None and 399.0 <= onset <= 401.0
    assert "jitter scale at most 40.0 ms" in str(with_baseline.extras["from_baseline"])
    # another kind of clock than the baseline's: its numbers do not apply
    assert not run_receiver_time(fixes, clock="host clock", monotonic=False, baseline=_clock_baseline()).alarms


def test_a_clock_running_at_another_rate_than_the_vehicles_is_a_finding() -> None:
    t, x = _logger()
    fixes = _fixes(t, x).assign(receiver_id="gps")
    clean = run_receiver_time(fixes, clock="boot clock", monotonic=True, baseline=_clock_baseline())
    assert not clean.findings and not clean.alarms
    fast = _fixes(t, x + 250e-6 * t).assign(receiver_id="gps")
    result = run_receiver_time(fast, clock="boot clock", monotonic=True, baseline=_clock_baseline())
    (finding,) = result.findings
    assert "ran +279.6 ppm" in finding.text and "+31.0 ppm (3 log(s))" in finding.text and not result.alarms


@pytest.mark.parametrize(("start_s", "length_s"), [(0.0, 1e9), (78.2, 400.0), (200.0, 300.0), (105.3, 180.0)])
def test_a_gateways_coarse_time_is_known_on_any_stretch_of_it(start_s: float, length_s: float) -> None:
    """The Aava's NMEA 2000 gateway stamps whole seconds on a 1.005 s cycle: its offset saws, a wrap of 1 s
    every 170 s. Cut to 78.2-478.2 s the stretch holds three wraps; the median rate (5.0 ms/s) said two
    steps drifted, the wraps were one too many for a coarse time, and the three wraps were three clock steps
    (SPOOFING, medium). The drift is now the offset's change end to end with the wraps taken out. Cut to
    105.3-285.3 s (`bench windows --seed 25`) the stretch runs from 1 s before one wrap to 6 s after the next:
    two wraps over 0.971 steps of drift, short of the 1 + 1 a sawtooth allows by the drift of its end samples,
    and the second wrap was a clock step at the log's end (SPOOFING, medium); each wrap's tolerance is now
    allowed on the count."""
    fixes = read_log(real_log("corpus/signalk/aava-n2k.data")).between(start_s, start_s + length_s).fixes
    result = run_receiver_time(fixes)
    assert result.ran and not result.alarms and "raised by its time's resolution, 1 s" in result.reason
