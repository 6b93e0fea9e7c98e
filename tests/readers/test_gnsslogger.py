"""Android GnssLogger logs: real v1.4 (2016) and v3 (2023) logs from ../shared/real/android_gnsslogger/."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from paths import REAL, real_log

from readers import read_log, sniff_format
from readers.gnsslogger import _orientation_quaternion
from readers.rinex import read_rinex
from spooflens.cli import main
from spooflens.geodesy import geodetic_to_enu
from spooflens.gnss.single_point import solve_logged
from spooflens.gnss.solved_fixes import with_solved_fixes
from spooflens.navigation.alignment import TO_FLU, flu_axes
from spooflens.navigation.rotations import quat_to_matrix

ANDROID = REAL / "android_gnsslogger"
GMT = ANDROID / "gps-measurement-tools"
JUNE = GMT / "pseudoranges_log_2016_06_30_21_26_07.txt"
AUGUST = GMT / "pseudoranges_log_2016_08_22_14_45_50.txt"
PIXEL = ANDROID / "gnss_lib_py" / "pixel6.txt"


def spp_vs_phone(path: Path) -> tuple[float, float, int]:
    """Median horizontal distance (m) between our single-point solution of the Raw lines and the phone's
    nearest Fix, the distance between the two mean positions, and the epochs solved."""
    t = read_log(path)
    obs = t.observations[np.isfinite(t.observations["sv_x_m"])]
    sol = solve_logged(t, obs)
    lat, lon, h = sol.geodetic()
    fx = t.fixes
    ref = [float(fx[c].median()) for c in ("lat_deg", "lon_deg", "height_m")]
    ours = geodetic_to_enu(lat, lon, h, *ref)
    phone = geodetic_to_enu(fx["lat_deg"], fx["lon_deg"], fx["height_m"], *ref)
    k = np.abs(fx["t_s"].to_numpy()[None, :] - sol.t_s[:, None]).argmin(axis=1)
    horizontal = np.hypot(*(ours[:, :2] - phone[k, :2]).T)
    mean_gap = float(np.hypot(*(np.nanmean(ours[:, :2], axis=0) - phone[:, :2].mean(axis=0))))
    return float(np.nanmedian(horizontal)), mean_gap, int(sol.ok.sum())


def test_2016_logs_solve_within_10_m_of_the_phones_fixes() -> None:
    """The README figure: SPP of the phone's own pseudoranges with the hour*.16n broadcast orbits."""
    for path, nav, epochs in ((JUNE, "hour1820.16n", 223), (AUGUST, "hour2350.16n", 200)):
        t = read_log(path)
        assert t.stream("nav", nav) is not None  # found beside the log by its time coverage
        median_m, mean_gap_m, solved = spp_vs_phone(path)
        print(
            f"{path.name}: {solved} epochs, median horizontal {median_m:.1f} m, mean positions {mean_gap_m:.1f} m apart"
        )
        assert solved == epochs
        assert median_m < 10.0 and mean_gap_m < 5.0
    # the phone logged its own fixes: with_solved_fixes adds no second receiver
    t = read_log(JUNE)
    assert with_solved_fixes(t).receivers() == ["phone"]


def test_v14_log_counts_clock_and_units() -> None:
    t = read_log(JUNE)
    assert sniff_format(JUNE) == "gnsslogger" and t.format == "gnsslogger"
    assert t.time_reference == "gps" and t.metadata["firmware"].startswith("1.4.0.0")
    fix, obs = t.stream("fix", "phone"), t.stream("observations", "phone")
    assert fix is not None and obs is not None and fix.count == 216
    assert obs.count == 223 and obs.rate_hz == pytest.approx(1.0, abs=0.01)
    # 1379 Raw lines, 3 above the 500 ns time uncertainty
    assert len(t.observations) == 1379 - 3
    assert [s.count for s in t.skipped if "Uncertainty" in s.reason] == [3]
    o = t.observations
    assert set(o["sv_id"].str[0]) == {"G"} and o["pseudorange_m"].between(1.9e7, 2.6e7).all()
    np.testing.assert_allclose(o["doppler_hz"], -o["pseudorange_rate_mps"] * 1575.42e6 / 299792458.0)
    # the first epoch: TimeNanos - FullBiasNanos - BiasNanos as GPS time, 2016-06-30 21:26:08 UTC + 17 s
    assert t.absolute_iso(0.0).startswith("2016-06-30T21:26:08.397")
    fx = t.fixes
    assert fx["lat_deg"].iloc[0] == 37.422541 and fx["height_m"].iloc[0] == -33.0 and fx["h_acc_m"].iloc[0] == 3.0


def test_v3_log_providers_sensors_and_receiver_indicators() -> None:
    t = read_log(PIXEL)
    assert "Pixel 7" in t.metadata["firmware"]
    fix = t.stream("fix", "phone")
    assert fix is not None and fix.count == 94
    skipped = {s.stream: s.count for s in t.skipped}
    assert skipped["Fix/FLP"] == 95 and skipped["Fix/NLP"] == 54
    # L5/E5a rows left out, one L1 signal per satellite; GPS, GLONASS and Galileo ids
    assert [s.count for s in t.skipped if "L1 band" in s.reason] == [310]
    assert set(t.observations["sv_id"].str[0]) == {"G", "R", "E"}
    assert not t.observations.duplicated(["t_s", "sv_id"]).any()
    # C/N0 and AGC of the raw epochs land on the fixes (AgcDb in dB)
    assert t.fixes["cn0_mean_dbhz"].notna().sum() >= 25 and t.fixes["agc"].between(0, 80).any()
    imu = t.stream("imu", "phone_imu")
    assert imu is not None and imu.body_frame == "ANDROID" and imu.count == 9
    g = np.linalg.norm(t.imu[["ax_mps2", "ay_mps2", "az_mps2"]].to_numpy(), axis=1)
    assert abs(np.median(g) - 9.8) < 1.0  # a walking user: single samples swing by +-3 m/s^2
    assert t.imu[["qw", "qx", "qy", "qz"]].notna().all(axis=1).sum() >= 8


def test_v3_fixes_match_the_phones_nmea_and_pseudoranges_its_rinex() -> None:
    """Independent outputs of the same phone: GGA sentences and the logger's own RINEX file."""
    t = read_log(PIXEL)
    gga = []
    for line in (ANDROID / "gnss_lib_py" / "pixel6.nmea").read_text().splitlines():
        f = line.split(",")
        if len(f) > 12 and f[1].endswith("GGA"):
            lat = int(f[3][:2]) + float(f[3][2:]) / 60
            lon = -(int(f[5][:3]) + float(f[5][3:]) / 60)
            gga.append((int(f[-1]), lat, lon, float(f[10]) + float(f[12])))
    gga_df = pd.DataFrame(gga, columns=["unix_ms", "lat", "lon", "h"])
    unix_ns = t.unix_ns(t.fixes["t_s"].to_numpy())
    assert unix_ns is not None
    unix = unix_ns // 1_000_000
    lat = np.interp(gga_df["unix_ms"], unix, t.fixes["lat_deg"])
    lon = np.interp(gga_df["unix_ms"], unix, t.fixes["lon_deg"])
    d = geodetic_to_enu(
        lat, lon, np.zeros(len(lat)), gga_df["lat"].iloc[0], gga_df["lon"].iloc[0], 0
    ) - geodetic_to_enu(
        gga_df["lat"], gga_df["lon"], np.zeros(len(lat)), gga_df["lat"].iloc[0], gga_df["lon"].iloc[0], 0
    )
    assert np.median(np.hypot(d[:, 0], d[:, 1])) < 5.0
    # pseudoranges vs the RINEX GnssLogger wrote (epochs a few seconds apart: propagated by the rate, the
    # receiver clock removed per epoch); a wrong time-of-week scale or ms ambiguity would be >= 300 km
    r = read_rinex(ANDROID / "gnss_lib_py" / "pixel6.23o")
    a = t.observations.assign(abs_s=t.absolute_ns(t.observations["t_s"].to_numpy()) / 1e9)
    b = r.observations.assign(abs_s=r.absolute_ns(r.observations["t_s"].to_numpy()) / 1e9)
    tb_all = np.unique(b["abs_s"])
    diffs = []
    for ta, ga in a.groupby("abs_s"):
        tb = tb_all[np.argmin(np.abs(tb_all - ta))]
        m = ga.merge(b[b["abs_s"] == tb], on="sv_id", suffixes=("", "_r"))
        d = m["pseudorange_m"] + m["pseudorange_rate_mps"] * (tb - ta) - m["pseudorange_m_r"]
        diffs.append(pd.DataFrame({"sys": m["sv_id"].str[0], "d": d - d.median()}))
    diff = pd.concat(diffs)
    assert set(diff["sys"]) == {"G", "R", "E"}
    assert diff["d"].abs().max() < 100.0 and diff.groupby("sys")["d"].apply(lambda x: x.abs().median()).max() < 10.0


def test_orientation_inverts_android_get_orientation() -> None:
    """SensorManager.getOrientation: azimuth = atan2(R01, R11), pitch = asin(-R21), roll = atan2(-R20, R22)."""
    rng = np.random.default_rng(5)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    R = quat_to_matrix(q)
    azimuth = np.degrees(np.arctan2(R[:, 0, 1], R[:, 1, 1]))
    pitch = np.degrees(np.arcsin(-R[:, 2, 1]))
    roll = np.degrees(np.arctan2(-R[:, 2, 0], R[:, 2, 2]))
    back = quat_to_matrix(_orientation_quaternion(azimuth, roll, pitch))
    np.testing.assert_allclose(back, R, atol=1e-9)


def test_android_body_frame_is_rfu_when_lying_flat() -> None:
    # flat, screen up, top of the phone forward: the gravity reaction reads +z, the top edge is forward
    def to_flu(row: list[float]) -> np.ndarray:
        return np.stack(flu_axes(np.array([row]), "ANDROID"), axis=1)

    np.testing.assert_allclose(to_flu([0.0, 0.0, 9.81]), [[0.0, 0.0, 9.81]])
    np.testing.assert_allclose(to_flu([0.0, 1.0, 0.0]), [[1.0, 0.0, 0.0]])
    np.testing.assert_allclose(to_flu([1.0, 0.0, 0.0]), [[0.0, -1.0, 0.0]])  # right
    assert np.linalg.det(TO_FLU["ANDROID"]) == pytest.approx(1.0)


@pytest.mark.parametrize("log", [JUNE, AUGUST, PIXEL], ids=["june2016", "august2016", "pixel"])
def test_inspect_and_analyze(log: Path, tmp_path: Path) -> None:
    assert main(["inspect", str(log)]) == 0
    summary = tmp_path / "s.json"
    assert main(["analyze", str(log), "-o", str(tmp_path / "a.rrd"), "--json", str(summary), "--quiet"]) == 0
    assert not json.loads(summary.read_text())["verdict"]["spoofed"]


def test_bad_input(tmp_path: Path) -> None:
    text = JUNE.read_text()
    cut = tmp_path / "cut.txt"
    cut.write_text(text[: len(text) // 2 + 11])  # ends inside a line
    t = read_log(cut)
    assert any(s.action == "lost" and "fields" in s.reason for s in t.skipped)
    assert 100 < len(t.fixes) < 216
    assert main(["inspect", str(cut)]) == 3
    lines = text.splitlines(keepends=True)
    mixed = tmp_path / "mixed.txt"
    mixed.write_text("".join(lines[:40]) + "garbage,1,2,3\n\x00\x01junk\nRaw,1,2\n" + "".join(lines[40:]))
    t = read_log(mixed)
    lost = {s.reason for s in t.skipped if s.action == "lost"}
    assert any("no GnssLogger record" in r for r in lost) and any(
        "Raw" in s.stream for s in t.skipped if s.action == "lost"
    )
    assert len(t.observations) == 1379 - 3
    nav = tmp_path / "x.16n"
    nav.write_text("not a navigation file\n")
    assert main(["inspect", str(JUNE), "--topic", f"nav={nav}"]) == 2


def test_inject_rewrites_the_gps_fix_lines(tmp_path: Path) -> None:
    out = tmp_path / "spoofed.txt"
    assert main(["inject", str(AUGUST), "--attack", "step:offset=50,axes=e,start=100", "-o", str(out)]) == 0
    # the copy lies elsewhere: its navigation file is named with --topic nav=
    a, b = read_log(AUGUST), read_log(out, topics={"nav": str(GMT / "hour2350.16n")})
    pd.testing.assert_frame_equal(a.observations, b.observations)
    late = a.fixes["t_s"].to_numpy() >= 100
    d = np.array(
        [
            geodetic_to_enu(lb, ob, hb, la, oa, ha)
            for lb, ob, hb, la, oa, ha in zip(
                b.fixes["lat_deg"],
                b.fixes["lon_deg"],
                b.fixes["height_m"],
                a.fixes["lat_deg"],
                a.fixes["lon_deg"],
                a.fixes["height_m"],
                strict=True,
            )
        ]
    )
    np.testing.assert_allclose(d[late, 0], 50.0, atol=0.01)
    np.testing.assert_allclose(d[~late], 0.0, atol=0.01)
    # a counterfeit satellite is written into its Raw lines' ReceivedSvTimeNanos (300 m later: 1,000.7 ns earlier)
    delayed = tmp_path / "delayed.txt"
    assert main(["inject", str(AUGUST), "--attack", "pr_delay:delay=300,svs=G05", "-o", str(delayed)]) == 0
    c = read_log(delayed, topics={"nav": str(GMT / "hour2350.16n")})
    moved = c.observations["pseudorange_m"].to_numpy() - a.observations["pseudorange_m"].to_numpy()
    g05 = (a.observations["sv_id"] == "G05").to_numpy()
    np.testing.assert_allclose(moved[g05], 300.0, atol=0.3)  # whole nanoseconds: 0.3 m
    np.testing.assert_allclose(moved[~g05], 0.0, atol=1e-6)


def test_nav_records_give_the_satellite_states_the_navigation_file_gives(tmp_path: Path) -> None:
    """The real 2016-06-30 log without its navigation file, but with GnssLogger `Nav` lines carrying
    that file's records as GPS L1 C/A subframes (encoded from IS-GPS-200): the same satellite states."""
    from ubx_support import lnav_subframes

    from readers.rinex import read_rinex_nav_file

    folder = ANDROID / "gps-measurement-tools"
    log, nav_file = folder / "pseudoranges_log_2016_06_30_21_26_07.txt", folder / "hour1820.16n"
    if not (log.exists() and nav_file.exists()):
        pytest.skip("the GnssLogger log or its navigation file is not present")
    with_file = read_log(log)
    eph = read_rinex_nav_file(nav_file).ephemerides
    t_first = float(np.asarray(with_file.gps_seconds(0.0)))
    lines = log.read_text().splitlines()
    first_raw = next(i for i, ln in enumerate(lines) if ln.startswith("Raw,"))
    nav_lines = ["# Nav,Svid,Type,Status,MessageId,Sub-messageId,Data(Bytes)"]
    sent = 30.0 * (t_first // 30.0) - 30.0
    for i in range(len(eph)):
        toe = float(eph.toe_s[i])
        if abs(toe - t_first) > 2 * 3600:
            continue
        rec = {k: getattr(eph, k)[i].item() for k in ("sv_id", "week", "toe_sow", "toc_s", "health", "iode")}
        rec |= {k: getattr(eph, k)[i].item() for k in QUANTA}
        for k, words in enumerate(lnav_subframes(rec, sent)):
            data = b"".join(w.to_bytes(4, "big") for w in words)
            signed = ",".join(str(b - 256 if b > 127 else b) for b in data)
            nav_lines.append(f"Nav,{int(rec['sv_id'][1:])},257,1,1,{k + 1},{signed}")
    out = tmp_path / "phone.txt"
    out.write_text("\n".join(lines[: first_raw + 1] + nav_lines + lines[first_raw + 1 :]) + "\n")
    table = read_log(out)  # no navigation file beside it
    assert any(s.role == "nav" and s.msgtype.startswith("gnsslogger/Nav") for s in table.streams)
    assert table.ephemerides is not None and np.isfinite(table.ephemerides.received_s).all()
    key = ["t_s", "sv_id"]
    cols = ["sv_x_m", "sv_y_m", "sv_z_m", "sv_clock_bias_m"]
    a = table.observations[key + cols].assign(t_s=lambda d: d["t_s"].round(3))
    b = with_file.observations[key + cols].assign(t_s=lambda d: d["t_s"].round(3))
    both = a.merge(b, on=key, suffixes=("_nav", "_file")).dropna()
    assert len(both) > 0.9 * len(with_file.observations)
    for c in cols:
        assert np.abs(both[f"{c}_nav"] - both[f"{c}_file"]).max() < 0.05, c


QUANTA = (
    "af0", "af1", "af2", "tgd", "crs", "crc", "cuc", "cus", "cic", "cis", "e", "sqrt_a", "m0", "omega0",
    "i0", "omega", "delta_n", "omega_dot", "idot",
)  # fmt: skip


@pytest.mark.skipif(not PIXEL.exists(), reason="real GnssLogger logs not present")
def test_status_records_give_the_satellites_frame(tmp_path: Path) -> None:
    """GnssStatus lines (GnssLogger v3) -> one row per satellite and time: its L1-band signal (the L5 of
    a dual-frequency phone left out), GLONASS known only by its frequency channel counted and left out,
    UsedInFix as 1/0 or true/false, the UTC time on the table's clock like the fixes'."""
    header = (
        "# Status,UnixTimeMillis,SignalCount,SignalIndex,ConstellationType,Svid,CarrierFrequencyHz,Cn0DbHz,"
        "AzimuthDegrees,ElevationDegrees,UsedInFix,HasAlmanacData,HasEphemerisData,BasebandCn0DbHz\n"
    )
    lines = PIXEL.read_text().splitlines(keepends=True)
    fixes = [line.split(",") for line in lines if line.startswith("Fix,GPS,")]
    times = [f[8] for f in fixes[:20]]
    status = []
    for ms in times:
        status += [
            f"Status,{ms},5,0,1,5,1575420030,41.5,120.0,35.0,1,1,1,38.0\n",
            f"Status,{ms},5,1,1,5,1176450050,33.0,120.0,35.0,1,1,1,30.0\n",  # G05's L5
            f"Status,{ms},5,2,6,11,1575420030,29.0,300.0,12.5,false,1,1,26.0\n",
            f"Status,{ms},5,3,4,194,1575420030,36.0,10.0,70.0,true,1,1,33.0\n",  # QZSS J02
            f"Status,{ms},5,4,3,93,1602000000,30.0,200.0,20.0,0,1,1,27.0\n",  # GLONASS by channel
        ]
    status.append("Status,,5,0,1,7,1575420030,40.0,10.0,10.0,1,1,1,37.0\n")
    log = tmp_path / "with_status.txt"
    log.write_text("".join(lines[:5]) + header + "".join(lines[5:]) + "".join(status))
    table = read_log(log)
    sky = table.satellites
    assert sorted(set(sky["sv_id"])) == ["E11", "G05", "J02"] and len(sky) == 3 * 20
    g05 = sky[sky["sv_id"] == "G05"]
    assert (g05["cn0_dbhz"] == 41.5).all() and (g05["elevation_deg"] == 35.0).all()
    assert list(sky.groupby("sv_id")["used"].first()) == [0.0, 1.0, 1.0]
    gps_fix_t = table.fixes["t_s"].to_numpy()[:20]
    # the same clock as the fixes: theirs is when the phone made them (elapsedRealtimeNanos), a few ms off
    # the time they carry, which these Status lines were given
    np.testing.assert_allclose(np.unique(sky["t_s"]), gps_fix_t, atol=0.01)
    counted = {s.reason: s.count for s in table.skipped if s.stream == "Status"}
    assert counted == {"no UnixTimeMillis": 1, "no satellite id (constellation, svid)": 20}
    assert next(s for s in table.streams if s.role == "satellites").count == 20


def test_a_header_naming_a_column_twice_reads_the_first(tmp_path: Path) -> None:
    """GnssLogger v2.0.0.x writes `CarrierFrequencyHz` twice in its Raw header (a Samsung S10's log of 2020):
    read as the first of the two, said once, never an internal error."""
    original = real_log("android_gnsslogger/gnss_lib_py/pixel6.txt")
    lines = original.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("# Raw,"))
    k = lines[header].split(",").index("CarrierFrequencyHz")
    doubled = [
        line + ",CarrierFrequencyHz,UserLatitude"
        if i == header
        else line + f",{line.split(',')[k]},NaN"
        if line.startswith("Raw,")
        else line
        for i, line in enumerate(lines)
    ]
    copy = tmp_path / "v2001.txt"
    copy.write_text("\n".join(doubled) + "\n")
    table = read_log(copy)
    pd.testing.assert_frame_equal(table.observations, read_log(original).observations)
    (said,) = [s for s in table.skipped if "twice" in s.reason]
    assert said.stream == "Raw" and said.reason == "header names CarrierFrequencyHz twice: the first column read"


def test_a_doubled_hash_before_the_version_still_names_the_phone(tmp_path: Path) -> None:
    """A Xiaomi MI 8's v2.0.0.1 log writes `# # Version: ...`: the phone and app were lost from the metadata."""
    original = real_log("android_gnsslogger/gnss_lib_py/pixel6.txt")
    text = original.read_text().replace("# Version:", "# # Version:", 1)
    copy = tmp_path / "doubled.txt"
    copy.write_text(text)
    assert read_log(copy).metadata["firmware"] == read_log(original).metadata["firmware"]


# a Samsung S8's log (nnanthi/android_rinex `SensorLog20171005.txt`) stopped seconds after the phone began
# tracking: State 17 (code lock, no time of week yet) on every measurement, so no pseudorange can be formed
S8_ACQUIRING = (
    "# \n"
    "# Header Description:\n"
    "# \n"
    "# Version: v2.0.0.1 Platform: 7.0 Manufacturer: samsung Model: SM-G950F\n"
    "# \n"
    "# Raw,ElapsedRealtimeMillis,TimeNanos,LeapSecond,TimeUncertaintyNanos,FullBiasNanos,BiasNanos,BiasUn"
    "certaintyNanos,DriftNanosPerSecond,DriftUncertaintyNanosPerSecond,HardwareClockDiscontinuityCount,Sv"
    "id,TimeOffsetNanos,State,ReceivedSvTimeNanos,ReceivedSvTimeUncertaintyNanos,Cn0DbHz,PseudorangeRateM"
    "etersPerSecond,PseudorangeRateUncertaintyMetersPerSecond,AccumulatedDeltaRangeState,AccumulatedDelta"
    "RangeMeters,AccumulatedDeltaRangeUncertaintyMeters,CarrierFrequencyHz,CarrierCycles,CarrierPhase,Car"
    "rierPhaseUncertainty,MultipathIndicator,SnrInDb,ConstellationType,AgcDb,CarrierFrequencyHz\n"
    "Raw,5530968,2123000000,,,-1191199253693999999,0.0,5.968969500122643E9,,,0,2,0.0,17,19123676,15,35.62"
    "989807128906,446.5701240515798,0.08057168442293733,4,8.474382443931574,3.4028234663852886E38,,,,,0,,"
    "1,,\n"
    "Raw,5530969,2123000000,,,-1191199253693999999,0.0,5.968969500122643E9,,,0,3,0.0,17,14166631,39,27.51"
    "0974884033203,890.327422966332,0.19896549295536636,4,16.89538740722486,3.4028234663852886E38,,,,,0,,"
    "1,,\n"
    "Raw,5530969,2123000000,,,-1191199253693999999,0.0,5.968969500122643E9,,,0,5,0.0,17,16294234,26,31.15"
    "4491424560547,-444.89766382754897,0.13205398388274375,4,-8.442644936378741,3.4028234663852886E38,,,,"
    ",0,,1,,\n"
    "Raw,5530970,2123000000,,,-1191199253693999999,0.0,5.968969500122643E9,,,0,6,0.0,17,19975255,15,35.44"
    "3382263183594,672.496150427181,0.0823990566011325,4,13.392772426654858,3.4028234663852886E38,,,,,0,,"
    "1,,\n"
    "Raw,5530970,2123000000,,,-1191199253693999999,0.0,5.968969500122643E9,,,0,7,0.0,17,10522288,8,40.561"
    "40899658203,400.69026378059425,0.045610477161056456,4,7.603738807459948,3.4028234663852886E38,,,,,0,"
    ",1,,\n"
    "Raw,5530971,2123000000,,,-1191199253693999999,0.0,5.968969500122643E9,,,0,9,0.0,17,26952278,8,40.910"
    "614013671875,373.91484735907875,0.04684307053254985,4,7.09563233230385,3.4028234663852886E38,,,,,0,,"
    "1,,\n"
)


def test_a_phone_log_stopped_while_acquiring_is_nothing_to_judge_not_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """It was refused (exit 2) with "no Raw, Fix or sensor record could be read", though the reader had said why
    it read none: a sound log with nothing to judge is a NO VERDICT saying what it holds."""
    log = tmp_path / "SensorLog.txt"
    log.write_text(S8_ACQUIRING)
    assert main(["analyze", str(log), "-o", str(tmp_path / "x.rrd")]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "NO VERDICT: no GNSS data to judge: GnssLogger log with no usable fix, measurement or sensor (Raw x6)" in out
    assert "time of week/day not decoded" in out


def _adr_states(path: Path, change: dict[int, int]) -> str:
    """The log's text with AccumulatedDeltaRangeState values replaced (old -> new) on every Raw line."""
    lines = path.read_text().splitlines()
    k = next(line for line in lines if line.startswith("# Raw,"))[2:].split(",").index("AccumulatedDeltaRangeState")
    out = []
    for line in lines:
        if line.startswith("Raw,"):
            f = line.split(",")
            f[k] = str(change.get(int(f[k]), int(f[k])))
            line = ",".join(f)
        out.append(line)
    return "\n".join(out) + "\n"


def test_carriers_with_an_unresolved_half_cycle_are_not_taken_as_continuous(tmp_path: Path) -> None:
    """ADR state HALF_CYCLE_REPORTED (16) without HALF_CYCLE_RESOLVED (8): the phone says the carrier may
    still jump by half a cycle (0.095 m on L1, under the Doppler screen's 0.1 m). The Pixel 7 Pro's log
    has ten such valid carriers (state 17) beside 25 (valid, resolved)."""
    src = real_log("corpus/gnss_lib_py/gsdc2023_pixel7pro_gnss_log.txt")
    table = read_log(src)
    (said,) = [s for s in table.skipped if "half-cycle" in s.reason]
    assert (said.stream, said.count, said.action) == ("phone", 10, "flagged")
    assert int((table.observations["carrier_arc_start"] == 0).sum()) == 86
    copy = tmp_path / "unresolved.txt"
    copy.write_text(_adr_states(src, {25: 17}))  # every valid carrier reported unresolved
    table = read_log(copy)
    assert not (table.observations["carrier_arc_start"] == 0).any()
    (said,) = [s for s in table.skipped if "half-cycle" in s.reason]
    assert said.count == 96 and "every carrier the receiver gave" in said.reason
