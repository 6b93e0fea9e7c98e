"""ArduPilot DataFlash logs (`.bin`) into an EpochTable.

**Fixes.** `GPS` rows (instance `I`: `GPS[0]`, `GPS[1]`; an older log's `GPS2` message is `GPS[1]`;
instance 2, the autopilot's blended solution, is not a receiver and is skipped). Lat/Lng as logged;
height above the ellipsoid from `GPA.AEl` (4.5+) or `GPS.Alt - GPA.Und` (ArduPilot's undulation is
h_msl - h_ellipsoid); without either the AMSL `Alt` is kept and the metadata says so. Velocity ENU from
ground speed, course and `VZ` (down): ve = Spd sin(GCrs), vn = Spd cos(GCrs), vu = -VZ. `NSats`,
`HDop` (99.99 = unknown), `Status` -> FixType (0-1 no fix: dropped, 2 2D, 3 3D, 4 DGPS, 5-6 RTK).
`GPA` (same instance and TimeUS) gives `VDop`, `HAcc`, `VAcc`, `SAcc`. `UBX1` (u-blox MON-HW) gives
`noise_per_ms` (noisePerMS), `jamming_indicator` (jamInd) and `agc` (agcCnt): the latest report of
the same receiver at or before the fix, within 5 s.

**Receiver status.** Every `UBX1` report is also a row of the `receiver_status` frame (receiver
`GPS[<Instance>]`), with or without a fix: a jammer that costs the fix still shows in them.

**IMU.** `IMU` rows per instance (`IMU[0]`, `IMU[1]`, ...; older logs `IMU`, `IMU2`, `IMU3`), body
frame FRD (the autopilot has applied the board orientation). The primary is instance 0, the IMU
ArduPilot uses while it is healthy, unless `--topic imu=IMU[1]` names another; it is listed first, so
the navigation uses it (metadata `imu.primary`). `ATT` roll/pitch/yaw (NED Euler angles of the FRD
body, degrees) become the quaternion columns: q = q(ENU<-NED) * qz(yaw) * qy(pitch) * qx(roll), with
q(ENU<-NED) = (0, 1/sqrt2, 1/sqrt2, 0), so q rotates FRD body vectors into ENU; interpolated (nlerp)
to the IMU stamps within 0.5 s of an ATT row.

**Raw observations.** `GRXH`/`GRXS` (u-blox RXM-RAWX logged by the autopilot): pseudorange, carrier
phase, Doppler, C/N0 per satellite of valid pseudoranges (trkStat bit 0); a carrier only with cpValid, one
the receiver says is not continuous marked (half-cycle unresolved or its correction toggled, lock time
restarted: `carrier_arc_start`, `readers.carrier_arcs`, counted as flagged); stamped with the receiver's
own time (GRXH week and rcvTime) when the log has the GPS clock; satellite states from a navigation
file given with `--topic nav=FILE`.

**The autopilot's EKF.** `XKF3`/`XKF4` (EKF3) and `NKF3`/`NKF4` (EKF2) innovations and test ratios
per core go to the `autopilot_ekf` frame (source `EKF3 core 0`, ...), in SI units.

**Time.** TimeUS is time since boot. The GPS rows' week (`GWk`) and ms of week (`GMS`) give the GPS
clock: the log goes on it with the median offset between the two clocks over 3D fixes. A log whose
GPS rows never carry a week (GWk 0, as some do) stays on the boot clock.

**Metadata.** Firmware (`VER.FWS`, else the first `MSG` naming the vehicle), board and receivers
(`MSG` lines), and the choices above.

**PX4 sdlog2** (`.px4log`, PX4 2013-2017) is the same container, read here as one more revision of its
fields (`readers.dataflash_eras`): format `px4_sdlog2`, streams labelled `px4_sdlog2/...`. Its `GPS` (and
`DGPS`, the second receiver: `GPS[1]`) carries its own accuracies `EPH`/`EPV` (h_acc_m, v_acc_m), noise
`N` and jamming indicator `J` (u-blox MON-HW, as UBX1's) and mean `SNR` (cn0_mean_dbhz; 0 = not
reported), and no DOP; its `Alt` is AMSL (sdlog2 logs no undulation). `IMU`, `IMU1`, `IMU2` are
`IMU[0..2]`; `ATT` angles are radians. `VER` (`Arch`, `FwGit`) and `PARM` `SYS_AUTOSTART` (the airframe)
are the metadata. The autopilot's estimates `GPOS`/`LPOS` are positions, not the innovations and test
ratios of the `autopilot_ekf` frame: skipped, counted.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from readers import NothingToJudgeError, ReaderFormat
from readers.carrier_arcs import CP_VALID, PR_VALID, arc_starts, ublox_breaks
from readers.dataflash import Columns, DataFlash, is_dataflash
from readers.dataflash_text import TextDataFlash, is_dataflash_text, open_any_dataflash
from readers.raw_states import add_satellite_states, nav_stream, navigation_for
from readers.rinex import NavFile
from readers.ubx.messages import sv_ids
from spooflens.epoch_table import EpochTable, Skipped, StreamInfo, build_table, log_clock, time_offset_s
from spooflens.errors import ReaderError
from spooflens.gnss.ephemeris import C_MPS, SECONDS_PER_WEEK
from spooflens.navigation.rotations import quat_multiply
from spooflens.schema import FixType

Progress = Callable[[int, int], None]
FloatArray = NDArray[np.float64]

# ArduPilot GPS_Status: 0 no GPS, 1 no fix, 2 2D, 3 3D, 4 3D DGPS, 5 RTK float, 6 RTK fixed
_FIX = {2: FixType.FIX_2D, 3: FixType.FIX_3D, 4: FixType.DGNSS, 5: FixType.RTK_FLOAT, 6: FixType.RTK_FIXED}
BLENDED_INSTANCE = 2  # GPS_MAX_RECEIVERS: the blended solution is logged as this instance
UBX_MAX_AGE_S = 5.0
UBX3_MAX_AGE_US = 100_000  # UBX3 is written with its fix, a few ms before it
ATT_MAX_GAP_S = 0.5
Q_ENU_NED = np.array([0.0, np.sqrt(0.5), np.sqrt(0.5), 0.0])
# the fields each message must have to be read at all (a damaged FMT text can rename any of them)
GPS_FIELDS = ("TimeUS", "Status", "Lat", "Lng", "Alt", "Spd", "GCrs", "HDop", "NSats")  # VZ since 2014
IMU_FIELDS = ("TimeUS", "AccX", "AccY", "AccZ", "GyrX", "GyrY", "GyrZ")
ATT_FIELDS = ("TimeUS", "Roll", "Pitch", "Yaw")
UBX1_FIELDS = ("TimeUS", "noisePerMS", "jamInd", "agcCnt")
UBX3_FIELDS = ("TimeUS", "hAcc", "vAcc", "sAcc")  # u-blox NAV-POSLLH/VELNED accuracies, before GPA (2016)
GRXH_FIELDS = ("TimeUS", "week", "rcvTime")
GRXS_FIELDS = ("TimeUS", "gnss", "sv", "freq", "prMes", "cpMes", "doMes", "cno", "trk")
# u-blox gnssId -> RINEX system letter
_L1_HZ = {"G": 1575.42e6, "S": 1575.42e6, "E": 1575.42e6, "J": 1575.42e6, "C": 1561.098e6, "I": 1176.45e6}


def _instance(cols: Columns, key: str = "I") -> NDArray[np.int64]:
    n = len(cols["TimeUS"])
    return cols[key].astype(np.int64) if key in cols else np.zeros(n, dtype=np.int64)


def _f(cols: Columns | None, name: str, n: int) -> FloatArray:
    if cols is None or name not in cols:
        return np.full(n, np.nan)
    return cols[name].astype(np.float64)


def gps_rows(log: DataFlash, skipped: list[Skipped]) -> pd.DataFrame | None:
    """Every GPS row with its instance (GPS2 messages as instance 1), GPA and UBX1 columns joined."""
    parts = []
    receivers = (("GPS", None), ("DGPS", 1)) if log.sdlog2 else (("GPS", None), ("GPS2", 1))
    for name, inst in receivers:
        cols = log.columns(name, GPS_FIELDS)
        if cols is None:
            continue
        df = pd.DataFrame({k: v for k, v in cols.items() if v.dtype.kind != "S" and k != "_ofs"})
        df["inst"] = inst if inst is not None else _instance(cols)
        df["msg"] = name
        df["ofs"] = cols["_ofs"]  # where each row sits in the file (inject patches it there)
        parts.append(df)
    if not parts:
        return None
    gps = pd.concat(parts, ignore_index=True)
    blended = gps["inst"] == BLENDED_INSTANCE
    if blended.any():
        skipped.append(Skipped("GPS[2]", "the autopilot's blended GPS solution (not a receiver)", int(blended.sum())))
        gps = gps[~blended]
    gpa_parts = []
    for name, inst in (("GPA", None), ("GPA2", 1)):
        cols = log.columns(name, ("TimeUS",))
        if cols is None:
            continue
        g = pd.DataFrame({k: v for k, v in cols.items() if v.dtype.kind != "S" and k not in ("I", "_ofs")})
        g["inst"] = inst if inst is not None else _instance(cols)
        g["ofs"] = cols["_ofs"]  # `gpa_ofs` once prefixed: inject patches the GPA row joined to each fix there
        gpa_parts.append(g.add_prefix("gpa_").rename(columns={"gpa_TimeUS": "TimeUS", "gpa_inst": "inst"}))
    if gpa_parts:
        gpa = pd.concat(gpa_parts, ignore_index=True).drop_duplicates(["TimeUS", "inst"])
        gps = gps.merge(gpa, on=["TimeUS", "inst"], how="left")
    # the receiver's noise, jamming indicator and AGC (UBX1, u-blox only), the latest one not older than
    # UBX_MAX_AGE_S
    ubx1 = {"noisePerMS": "ubx_noise", "jamInd": "ubx_jam", "agcCnt": "ubx_agc"}
    gps = _join_receiver_message(log, gps, "UBX1", UBX1_FIELDS, ubx1, int(UBX_MAX_AGE_S * 1e6))
    if log.sdlog2:
        # PX4's GPS message carries the receiver's accuracies, noise and jamming indicator itself: joined as
        # GPA's and UBX1's would be, from the same message (`gpa_ofs`: inject writes them back there)
        sdlog2 = {"HAcc": "gpa_HAcc", "VAcc": "gpa_VAcc", "ofs": "gpa_ofs", "N": "ubx_noise", "J": "ubx_jam"}
        for src, dst in sdlog2.items():
            if src in gps and dst not in gps:
                gps[dst] = gps[src]
    elif not gpa_parts:
        # before GPA (2016), u-blox receivers' accuracies came as UBX3, logged with each fix: joined as GPA's
        ubx3 = {"hAcc": "gpa_HAcc", "vAcc": "gpa_VAcc", "sAcc": "gpa_SAcc"}
        gps = _join_receiver_message(log, gps, "UBX3", UBX3_FIELDS, ubx3, UBX3_MAX_AGE_US)
    return gps.sort_values(["inst", "TimeUS"], kind="stable").reset_index(drop=True)


def ubx1_reports(log: DataFlash, offset_ns: int) -> pd.DataFrame | None:
    """Every UBX1 (u-blox MON-HW) report as a `receiver_status` row of its receiver (`GPS[<Instance>]`, as
    its fixes are named), plus `ofs`, where it sits in the file (inject patches it there). The reports
    come whether the receiver has a fix or not: a jammer that costs the fix is seen through them."""
    found = log.columns("UBX1", UBX1_FIELDS)
    if found is None:
        return None
    inst = _instance(found, "Instance")
    return pd.DataFrame(
        {
            "t_ns": found["TimeUS"].astype(np.int64) * 1000 + offset_ns,
            "receiver_id": np.array([f"GPS[{i}]" for i in inst], dtype=object),
            "noise_per_ms": found["noisePerMS"].astype(float),
            "jamming_indicator": found["jamInd"].astype(float),
            "agc": found["agcCnt"].astype(float),
            "ofs": found["_ofs"].astype(np.int64),
        }
    )


def _join_receiver_message(
    log: DataFlash, gps: pd.DataFrame, name: str, fields: tuple[str, ...], columns: dict[str, str], max_age_us: int
) -> pd.DataFrame:
    """`gps` with the `columns` of message `name` (renamed) of the same instance joined to each fix: the
    latest one logged at or before it and not more than `max_age_us` older. `<name>_ofs` (lower case) is
    where the joined message sits in the file, so inject writes the attacked values back to the same one."""
    found = log.columns(name, fields)
    if found is None:
        return gps
    u = pd.DataFrame(
        {"TimeUS": found["TimeUS"].astype(np.int64), "inst": _instance(found, "Instance")}
        | {new: found[old].astype(float) for old, new in columns.items()}
        | {f"{name.lower()}_ofs": found["_ofs"].astype(np.int64)}
    ).sort_values("TimeUS")
    gps["TimeUS"] = gps["TimeUS"].astype(np.int64)
    return pd.merge_asof(
        gps.sort_values("TimeUS"), u, on="TimeUS", by="inst", direction="backward", tolerance=max_age_us
    )


WEEK_MS = 604_800_000


def gps_time_ns(gps: pd.DataFrame) -> NDArray[np.int64]:
    """Each GPS row's own time (GPS week `GWk` and ms of week `GMS`), ns since the GPS epoch."""
    return (gps["GWk"].to_numpy(np.int64) * WEEK_MS + gps["GMS"].to_numpy(np.int64)) * 1_000_000


def gps_clock(gps: pd.DataFrame | None) -> tuple[str, int, str]:
    """(time reference, offset ns added to TimeUS * 1000, how it was found)."""
    if gps is None or "GWk" not in gps or "GMS" not in gps:
        return "boot", 0, "no GPS week/ms in the log: boot clock (TimeUS)"
    ok = (gps["GWk"] > 0) & (gps["Status"] >= 3)
    if not ok.any():
        return "boot", 0, "GPS rows carry no week number (GWk 0): boot clock (TimeUS)"
    ok_rows = ok.to_numpy()
    gps_ns = gps_time_ns(gps)[ok_rows]
    offset = int(np.median(gps_ns - gps["TimeUS"].to_numpy(np.int64)[ok_rows] * 1000))
    return "gps", offset, f"GPS clock from GPS week/ms of {int(ok.sum())} 3D fixes (median offset to TimeUS)"


def _time_offsets(gps: pd.DataFrame) -> FloatArray:
    """`time_offset_s` per receiver instance: its GPS week/ms against TimeUS (the boot clock)."""
    receiver_ns = gps_time_ns(gps)
    clock_ns = gps["TimeUS"].to_numpy(np.int64) * 1000
    valid = (gps["GWk"].to_numpy(np.int64) > 0) & (gps["Status"].to_numpy(np.int64) >= 3)
    out = np.full(len(gps), np.nan)
    inst = gps["inst"].to_numpy(np.int64)
    for i in np.unique(inst):
        mine = inst == i
        out[mine] = time_offset_s(receiver_ns[mine], clock_ns[mine], valid[mine])
    return out


def gps_fixes(gps: pd.DataFrame, offset_ns: int, skipped: list[Skipped], meta: dict[str, str]) -> pd.DataFrame:
    """Fix rows (schema columns, t_ns) of the GPS rows with a fix, plus `msg` and `ofs`: the message each
    row came from and its offset in the file."""
    n = len(gps)
    status = gps["Status"].to_numpy(np.int64)
    fix_type = np.full(n, FixType.NO_FIX, dtype=np.int8)
    for code, mapped in _FIX.items():
        fix_type[status == code] = mapped
    alt = gps["Alt"].to_numpy(float)
    ael = gps["gpa_AEl"].to_numpy(float) if "gpa_AEl" in gps else np.full(n, np.nan)
    und = gps["gpa_Und"].to_numpy(float) if "gpa_Und" in gps else np.full(n, np.nan)
    ael_ok = np.isfinite(ael) & (ael != 0) & (ael != alt)
    und_ok = np.isfinite(und) & (und != 0)
    height = np.where(ael_ok, ael, np.where(und_ok, alt - und, alt))
    amsl = ~(ael_ok | und_ok)
    meta["height"] = (
        "ellipsoidal: GPA.AEl"
        if ael_ok.all()
        else "ellipsoidal: GPS.Alt - GPA.Und (ArduPilot undulation = h_msl - h_ellipsoid)"
        if (ael_ok | und_ok).all()
        else f"{int(amsl.sum())} of {n} GPS rows have no undulation: their height_m is AMSL (GPS.Alt)"
    )
    spd, crs = gps["Spd"].to_numpy(float), np.radians(gps["GCrs"].to_numpy(float))
    hdop = gps["HDop"].to_numpy(float)
    names = np.array([f"GPS[{i}]" for i in gps["inst"].to_numpy(np.int64)], dtype=object)
    cols: dict[str, object] = {
        "t_ns": gps["TimeUS"].to_numpy(np.int64) * 1000 + offset_ns,
        "receiver_id": names,
        "lat_deg": gps["Lat"].to_numpy(float),
        "lon_deg": gps["Lng"].to_numpy(float),
        "height_m": height,
        "vel_e_mps": spd * np.sin(crs),
        "vel_n_mps": spd * np.cos(crs),
        "vel_u_mps": -gps["VZ"].to_numpy(float) if "VZ" in gps else np.full(n, np.nan),
        "sats_used": gps["NSats"].to_numpy(float),
        "hdop": np.where(hdop >= 99.99, np.nan, hdop),
        "fix_type": fix_type,
        "msg": gps["msg"].to_numpy(),
        "ofs": gps["ofs"].to_numpy(np.int64),
    }
    for col, src in (
        ("vdop", "gpa_VDop"),
        ("h_acc_m", "gpa_HAcc"),
        ("v_acc_m", "gpa_VAcc"),
        ("vel_acc_mps", "gpa_SAcc"),
        ("noise_per_ms", "ubx_noise"),
        ("jamming_indicator", "ubx_jam"),
        ("agc", "ubx_agc"),
    ):
        if src in gps:
            cols[col] = gps[src].to_numpy(float)
    if "SNR" in gps and "GPSTime" in gps:  # PX4 sdlog2: the receiver's mean C/N0, 0 when it reports none
        snr = gps["SNR"].to_numpy(float)
        cols["cn0_mean_dbhz"] = np.where(snr > 0, snr, np.nan)
    if "GWk" in gps and "GMS" in gps:
        cols["time_offset_s"] = _time_offsets(gps)
        meta |= log_clock("the autopilot's boot clock (TimeUS; TimeMS before 2015)", True)
    fixes = pd.DataFrame(cols)
    no_fix = fix_type == FixType.NO_FIX
    for rid in dict.fromkeys(names[no_fix]):
        skipped.append(Skipped(str(rid), "GPS Status 0-1 (no fix)", int((names[no_fix] == rid).sum())))
    return fixes[~no_fix].reset_index(drop=True)


def attitude_quaternion(roll_deg: FloatArray, pitch_deg: FloatArray, yaw_deg: FloatArray) -> FloatArray:
    """ArduPilot's NED Euler angles (ZYX, degrees) -> quaternion (w, x, y, z) rotating FRD body to ENU."""
    r, p, y = (np.radians(np.asarray(a, dtype=float)) / 2 for a in (roll_deg, pitch_deg, yaw_deg))
    z = np.zeros_like(r)
    qx = np.stack([np.cos(r), np.sin(r), z, z], axis=-1)
    qy = np.stack([np.cos(p), z, np.sin(p), z], axis=-1)
    qz = np.stack([np.cos(y), z, z, np.sin(y)], axis=-1)
    q_ned_frd = quat_multiply(quat_multiply(qz, qy), qx)
    return quat_multiply(np.broadcast_to(Q_ENU_NED, q_ned_frd.shape), q_ned_frd)


def attitude_at(att: Columns | None, t_us: NDArray[np.int64]) -> FloatArray:
    """ATT attitude at the IMU stamps (normalised linear interpolation), NaN far from any ATT row."""
    out = np.full((len(t_us), 4), np.nan)
    if att is None or not len(att["TimeUS"]):
        return out
    ta = att["TimeUS"].astype(np.int64)
    order = np.argsort(ta, kind="stable")
    ta = ta[order]
    q = attitude_quaternion(att["Roll"][order], att["Pitch"][order], att["Yaw"][order])
    # one hemisphere along the track, so neighbours interpolate the short way
    flip = np.cumprod(np.where(np.sum(q[1:] * q[:-1], axis=1) < 0, -1.0, 1.0))
    q[1:] *= flip[:, None]
    k = np.clip(np.searchsorted(ta, t_us), 1, max(len(ta) - 1, 1))
    if len(ta) == 1:
        near = np.abs(t_us - ta[0]) <= ATT_MAX_GAP_S * 1e6
        out[near] = q[0]
        return out
    lo, hi = k - 1, k
    span = (ta[hi] - ta[lo]).astype(float)
    w = np.clip((t_us - ta[lo]) / np.where(span > 0, span, 1.0), 0.0, 1.0)
    qi = q[lo] * (1 - w)[:, None] + q[hi] * w[:, None]
    qi /= np.linalg.norm(qi, axis=1, keepdims=True)
    gap = np.minimum(np.abs(t_us - ta[lo]), np.abs(t_us - ta[hi]))
    ok = gap <= ATT_MAX_GAP_S * 1e6
    out[ok] = qi[ok]
    return out


def _imu(
    log: DataFlash, offset_ns: int, primary: str | None, skipped: list[Skipped], meta: dict[str, str]
) -> tuple[pd.DataFrame | None, list[StreamInfo]]:
    """Every IMU instance (primary first) with the ATT attitude as its quaternion columns."""
    parts: dict[str, Columns] = {}
    label = _label(log)
    if log.sdlog2:  # PX4 numbers its IMU messages IMU, IMU1, IMU2
        for name, iid in (("IMU", "IMU[0]"), ("IMU1", "IMU[1]"), ("IMU2", "IMU[2]")):
            cols = log.columns(name, IMU_FIELDS)
            if cols is not None:
                parts[iid] = cols
    for name in () if log.sdlog2 else ("IMU", "IMU2", "IMU3"):
        cols = log.columns(name, IMU_FIELDS)
        if cols is None:
            continue
        if name == "IMU" and "I" in cols:
            inst = _instance(cols)
            for i in np.unique(inst):
                parts[f"IMU[{i}]"] = {k: v[inst == i] for k, v in cols.items()}
        else:
            parts[f"IMU[{int(name[3:] or 1) - 1}]"] = cols
    if not parts:
        return None, []
    ids = sorted(parts)
    first = primary if primary in parts else ids[0]
    if primary and primary not in parts:
        skipped.append(Skipped(f"<{label}>", f"--topic imu={primary} is not in the log (IMUs {ids})", 1))
    ids = [first, *[i for i in ids if i != first]]
    meta["imu.primary"] = (
        f"{first} (named with --topic imu=)"
        if primary == first
        else f"{first} (PX4's first IMU)"
        if log.sdlog2
        else f"{first} (ArduPilot's first IMU, primary while healthy)"
    )
    att = log.columns("ATT", ATT_FIELDS)
    frames, streams = [], []
    for iid in ids:
        c = parts[iid]
        t_us = c["TimeUS"].astype(np.int64)
        q = attitude_at(att, t_us)
        frames.append(
            pd.DataFrame(
                {
                    "t_ns": t_us * 1000 + offset_ns,
                    "imu_id": iid,
                    "ax_mps2": c["AccX"].astype(float),
                    "ay_mps2": c["AccY"].astype(float),
                    "az_mps2": c["AccZ"].astype(float),
                    "wx_radps": c["GyrX"].astype(float),
                    "wy_radps": c["GyrY"].astype(float),
                    "wz_radps": c["GyrZ"].astype(float),
                    "qw": q[:, 0],
                    "qx": q[:, 1],
                    "qy": q[:, 2],
                    "qz": q[:, 3],
                }
            )
        )
        streams.append(StreamInfo("imu", iid, "IMU", f"{label}/IMU", len(t_us), body_frame="FRD"))
    return pd.concat(frames, ignore_index=True), streams


_EKF_FIELDS = {
    "IVN": ("vel_innov_n_mps", 1.0),
    "IVE": ("vel_innov_e_mps", 1.0),
    "IVD": ("vel_innov_d_mps", 1.0),
    "IPN": ("pos_innov_n_m", 1.0),
    "IPE": ("pos_innov_e_m", 1.0),
    "IPD": ("pos_innov_d_m", 1.0),
    "IMX": ("mag_innov_x_ut", 0.1),  # mGauss -> uT
    "IMY": ("mag_innov_y_ut", 0.1),
    "IMZ": ("mag_innov_z_ut", 0.1),
    "IYAW": ("yaw_innov_rad", np.pi / 180),
    "IVT": ("airspeed_innov_mps", 1.0),
    "SV": ("vel_test_ratio", 1.0),
    "SP": ("pos_test_ratio", 1.0),
    "SH": ("hgt_test_ratio", 1.0),
    "SM": ("mag_test_ratio", 1.0),
    "SVT": ("airspeed_test_ratio", 1.0),
    "errRP": ("tilt_error_rad", 1.0),
    "FS": ("fault_status", 1.0),
    "TS": ("timeout_status", 1.0),
    "SS": ("solution_status", 1.0),
    "GPS": ("gps_check_status", 1.0),
    "PI": ("primary_core", 1.0),
}


def _ekf(log: DataFlash, offset_ns: int) -> tuple[pd.DataFrame | None, list[StreamInfo]]:
    frames, streams = [], []
    # EKF1 is ArduPilot's first EKF (AP_NavEKF, 2014-2017): its innovations EKF3, test ratios EKF4
    for filt, innov, ratio in (("EKF3", "XKF3", "XKF4"), ("EKF2", "NKF3", "NKF4"), ("EKF1", "EKF3", "EKF4")):
        parts = []
        for name in (innov, ratio):
            cols = log.columns(name, ("TimeUS",))
            if cols is None:
                continue
            df = pd.DataFrame({"TimeUS": cols["TimeUS"].astype(np.int64), "core": _instance(cols, "C")})
            for src, (dst, scale) in _EKF_FIELDS.items():
                if src in cols:
                    df[dst] = cols[src].astype(float) * scale
            per_axis = [cols[k].astype(float) for k in ("SMX", "SMY", "SMZ") if k in cols]
            if per_axis and "SM" not in cols:  # EKF1 logged one magnetometer ratio per axis
                df["mag_test_ratio"] = np.max(per_axis, axis=0)
            parts.append(df.drop_duplicates(["TimeUS", "core"]))
        if not parts:
            continue
        df = parts[0] if len(parts) == 1 else parts[0].merge(parts[1], on=["TimeUS", "core"], how="outer")
        df = df.sort_values(["core", "TimeUS"], kind="stable")
        df["source"] = [f"{filt} core {c}" for c in df["core"]]
        df["t_ns"] = df["TimeUS"].to_numpy(np.int64) * 1000 + offset_ns
        frames.append(df.drop(columns=["TimeUS", "core"]))
        for src in dict.fromkeys(df["source"]):
            n = int((df["source"] == src).sum())
            streams.append(StreamInfo("autopilot_ekf", src, f"{innov}/{ratio}", f"{_label(log)}/{innov}+{ratio}", n))
    if not frames:
        return None, []
    return pd.concat(frames, ignore_index=True), streams


def grxs_rows(log: DataFlash, offset_ns: int, reference: str, skipped: list[Skipped]) -> pd.DataFrame | None:
    """GRXH/GRXS (u-blox RXM-RAWX as logged) -> observation rows of receiver GPS[0], without satellite
    states, and `ofs`: where each row's GRXS message sits in the file (inject patches it there)."""
    hdr, sat = log.columns("GRXH", GRXH_FIELDS), log.columns("GRXS", GRXS_FIELDS)
    if hdr is None or sat is None:
        return None
    h_ofs, s_ofs = hdr["_ofs"], sat["_ofs"]
    # each GRXS belongs to the GRXH written just before it in the file
    k = np.searchsorted(h_ofs, s_ofs, side="right") - 1
    orphan = k < 0
    if orphan.any():
        skipped.append(Skipped("GRXS", "raw measurement before any GRXH header", int(orphan.sum())))
    k = np.where(orphan, 0, k)
    # GRXS is the receiver's RXM-RAWX relayed: u-blox (gnssId, svId) pairs
    sv_id, known = sv_ids(sat["gnss"].astype(np.int64), sat["sv"].astype(np.int64))
    system = np.where(known, np.char.ljust(sv_id, 1).astype("U1"), "")
    pr_valid = (sat["trk"].astype(np.int64) & PR_VALID) != 0
    keep = ~orphan & pr_valid & known & np.isfinite(sat["prMes"]) & (sat["prMes"] > 0)
    if (~pr_valid & ~orphan).any():
        skipped.append(Skipped("GRXS", "pseudorange not valid (trkStat bit 0 clear)", int((~pr_valid & ~orphan).sum())))
    if reference == "gps":
        t_gps_ns = np.round(
            (hdr["week"].astype(np.int64)[k] * SECONDS_PER_WEEK + hdr["rcvTime"].astype(float)[k]) * 1e9
        ).astype(np.int64)
    else:
        t_gps_ns = hdr["TimeUS"].astype(np.int64)[k] * 1000 + offset_ns
    freq = np.array([_L1_HZ.get(s, np.nan) for s in system])
    glo = system == "R"
    freq[glo] = 1602.0e6 + (sat["freq"].astype(float)[glo] - 7.0) * 0.5625e6
    doppler = sat["doMes"].astype(float)
    cp_valid = (sat["trk"].astype(np.int64) & CP_VALID) != 0
    carrier = np.where(cp_valid, sat["cpMes"].astype(float), np.nan)
    arc_start = _carrier_arc_starts(sv_id, t_gps_ns, sat, carrier, keep, skipped)
    return pd.DataFrame(
        {
            "t_ns": t_gps_ns,
            "receiver_id": "GPS[0]",
            "sv_id": sv_id,
            "pseudorange_m": sat["prMes"].astype(float),
            "pseudorange_rate_mps": -doppler * C_MPS / freq,
            "doppler_hz": doppler,
            "carrier_phase_cycles": carrier,
            "carrier_arc_start": arc_start,
            "carrier_freq_hz": freq,
            "cn0_dbhz": sat["cno"].astype(float),
            "ofs": s_ofs,
        }
    )[keep].reset_index(drop=True)


def _carrier_arc_starts(
    sv_id: NDArray[np.str_],
    t_ns: NDArray[np.int64],
    sat: Columns,
    carrier: FloatArray,
    keep: NDArray[np.bool_],
    skipped: list[Skipped],
) -> FloatArray:
    """GRXS `carrier_arc_start`: the carriers the receiver says are not continuous (`readers.carrier_arcs`: the
    u-blox trkStat half-cycle bits and lock time). GRXS logs no sigId: the signals of one satellite in an
    epoch are told apart by their order, as the rewriter tells them apart."""
    rows = pd.DataFrame({"t": t_ns[keep], "sv": sv_id[keep]})
    nth = rows.groupby(["t", "sv"], sort=False).cumcount().astype(str).to_numpy()
    key = np.char.add(np.char.add(sv_id[keep].astype(str), "/"), nth)
    lock = sat["lock"][keep] if "lock" in sat else None
    out = np.full(len(carrier), np.nan)
    out[keep] = arc_starts("GPS[0]", carrier[keep], ublox_breaks(key, t_ns[keep], sat["trk"][keep], lock), skipped)
    return out


def _raw_observations(
    log: DataFlash,
    offset_ns: int,
    reference: str,
    topics: Mapping[str, str] | None,
    skipped: list[Skipped],
) -> tuple[pd.DataFrame | None, list[StreamInfo], NavFile | None]:
    """GRXH/GRXS -> observation rows of receiver GPS[0] with their satellites' states."""
    found = grxs_rows(log, offset_ns, reference, skipped)
    if found is None:
        return None, [], None
    rows = found.drop(columns="ofs")
    nav = None
    if len(rows) and reference == "gps":
        nav = navigation_for(log.path, topics, rows["t_ns"].to_numpy() / 1e9, skipped)
        rows = add_satellite_states(rows, nav.ephemerides if nav else None, "GPS[0]", skipped)
    elif len(rows):
        skipped.append(Skipped("GPS[0]", "raw observations on the boot clock: no satellite states", len(rows)))
    epochs = int(rows["t_ns"].nunique())
    return (
        rows,
        [StreamInfo("observations", "GPS[0]", "GRXH/GRXS", f"{_label(log)}/GRXS (u-blox RXM-RAWX)", epochs)],
        nav,
    )


def _label(log: DataFlash) -> str:
    """The format the log is in, as streams and the table name it: `px4_sdlog2`, `ardupilot` or
    `ardupilot_text` (a DataFlash log saved as text)."""
    return "px4_sdlog2" if log.sdlog2 else "ardupilot_text" if isinstance(log, TextDataFlash) else "ardupilot"


def _sdlog2_metadata(log: DataFlash, meta: dict[str, str], skipped: list[Skipped]) -> None:
    """VER and PARM of a PX4 sdlog2 log; its estimates (GPOS, LPOS) skipped, counted."""
    meta["log_format"] = "PX4 sdlog2 (.px4log): DataFlash container, PX4's messages timed by TIME.StartTime"
    fw, arch = log.strings("VER", "FwGit"), log.strings("VER", "Arch")
    meta["firmware"] = f"PX4 sdlog2, git {fw[0]}" if fw and fw[0] else "PX4 sdlog2 (no VER message)"
    if arch and arch[0]:
        meta["board"] = arch[0]
    parm = log.columns("PARM")
    if parm is not None and "Name" in parm and "Value" in parm:
        names = log.strings("PARM", "Name")
        airframe = [v for n, v in zip(names, parm["Value"], strict=True) if n == "SYS_AUTOSTART"]
        if airframe:
            meta["airframe"] = f"SYS_AUTOSTART {int(airframe[-1])}"
    for name, what in (("GPOS", "global"), ("LPOS", "local")):
        if log.count(name):
            reason = f"the autopilot's {what} position estimate (autopilot_ekf holds innovations and test ratios)"
            skipped.append(Skipped(name, reason, log.count(name)))


def _metadata(log: DataFlash, meta: dict[str, str]) -> None:
    for key, note in log.notes.items():
        meta[f"dataflash.{key}"] = note
    if log.sdlog2:
        return
    messages = log.strings("MSG", "Message")
    fws = log.strings("VER", "FWS")
    vehicle = next((m for m in messages if m.startswith("Ardu")), "")
    if not vehicle:  # a 2013 log names its firmware only in the banner the board printed before it
        vehicle = next((b for b in log.banner if b.startswith("Ardu") and " V" in b), "")
    if fws and fws[0]:
        meta["firmware"] = fws[0]
    elif vehicle:
        meta["firmware"] = vehicle
    if vehicle and vehicle in messages:
        i = messages.index(vehicle)
        board = [m for m in messages[i + 1 : i + 3] if not m.startswith(("ChibiOS", "Param", "RC"))]
        if board:
            meta["board"] = board[0]
    gps_lines = [m for m in messages if m.startswith(("GPS ", "u-blox", "GPS:"))]
    if gps_lines:
        meta["receivers"] = "; ".join(gps_lines)


def read_ardupilot(path: Path, topics: Mapping[str, str] | None = None, progress: Progress | None = None) -> EpochTable:
    path = Path(path)
    log = open_any_dataflash(path)
    label = _label(log)
    skipped: list[Skipped] = []
    meta: dict[str, str] = {}
    gps = gps_rows(log, skipped)
    reference, offset_ns, how = gps_clock(gps)
    if gps is not None and reference == "boot" and set(gps["msg"]) & log.on_receiver_clock:
        reference, how = "relative", "the GPS messages' time of week (this revision logs no boot time and no week)"
    meta["clock"] = how
    frames: dict[str, pd.DataFrame] = {}
    streams: list[StreamInfo] = []
    if gps is not None:
        fixes = gps_fixes(gps, offset_ns, skipped, meta)
        frames["fixes"] = fixes.drop(columns=["msg", "ofs"])
        source = "px4_sdlog2/GPS" if log.sdlog2 else f"{label}/GPS+GPA"
        for rid in dict.fromkeys(gps["inst"]):
            name = f"GPS[{rid}]"
            streams.append(StreamInfo("fix", name, "GPS", source, int((fixes["receiver_id"] == name).sum())))
    status = ubx1_reports(log, offset_ns)
    if status is not None:
        frames["receiver_status"] = status.drop(columns="ofs")
        for rid in dict.fromkeys(status["receiver_id"]):
            n = int((status["receiver_id"] == rid).sum())
            streams.append(StreamInfo("receiver_status", rid, "UBX1", f"{label}/UBX1 (u-blox MON-HW)", n))
    if progress:
        progress(1, 4)
    primary = (topics or {}).get("imu")
    imu, imu_streams = _imu(log, offset_ns, primary, skipped, meta)
    if imu is not None:
        frames["imu"] = imu
        streams += imu_streams
    elif log.count("ATT"):
        skipped.append(
            Skipped("ATT", "attitude without a raw IMU message to attach it to (IMU not logged)", log.count("ATT"))
        )
    if progress:
        progress(2, 4)
    ekf, ekf_streams = _ekf(log, offset_ns)
    if ekf is not None:
        frames["autopilot_ekf"] = ekf
        streams += ekf_streams
    obs, obs_streams, nav = _raw_observations(log, offset_ns, reference, topics, skipped)
    if obs is not None and len(obs):
        frames["observations"] = obs
        streams += obs_streams
    if progress:
        progress(3, 4)
    if log.count("UBX2"):
        skipped.append(Skipped("UBX2", "u-blox I/Q imbalance (no schema column)", log.count("UBX2")))
    _metadata(log, meta)
    if isinstance(log, TextDataFlash):
        meta["log_format"] = (
            f"ArduPilot DataFlash saved as text (Mission Planner / APM Planner), '{log.delimiter}' delimited"
        )
    if log.sdlog2:
        _sdlog2_metadata(log, meta, skipped)
    unknown = sorted(set(topics or {}) - {"imu", "nav"})
    if unknown:
        skipped.append(
            Skipped(f"<{label}>", f"--topic ignored for DataFlash logs except imu=, nav= ({unknown})", len(unknown))
        )
    if not frames:
        what = "PX4 sdlog2" if log.sdlog2 else "DataFlash"
        for name in log.names():  # decoded, so that a message cut or unusable among them is counted
            log.columns(name)
        losses = [*log.skipped, *skipped]
        held = sorted(((n, log.count(n)) for n in log.names() if n != "FMT"), key=lambda kv: (-kv[1], kv[0]))
        if any(s.action == "lost" for s in losses) or not held:  # a damaged stretch may have held the GPS
            raise ReaderError(path, f"no GPS, IMU or EKF message in this {what} log (messages: {sorted(log.names())})")
        # sound: a log of other messages alone (a bench session's, logging while disarmed)
        listed = ", ".join(f"{n} x{c}" for n, c in held[:6]) + (
            f" and {len(held) - 6} more kinds" if len(held) > 6 else ""
        )
        raise NothingToJudgeError(path, f"{what} log without a GPS, IMU or EKF message ({listed})", label, losses)
    table = build_table(path, label, reference, frames, streams, [*log.skipped, *skipped], metadata=meta)
    if nav is not None:
        table.ephemerides = nav.ephemerides
        table.streams.append(nav_stream(nav, table.t0_ns))
    if progress:
        progress(4, 4)
    return table


# (message, first columns) only PX4's sdlog2 defines, in FMTs near the start of its log (IMU is the third);
# ArduPilot's IMU has GyrX, its TIME none, and its GPSTime is a CAM field
SDLOG2_FMTS = ((b"IMU", b"AccX,AccY,AccZ,GyroX"), (b"GPS", b"GPSTime,"), (b"TIME", b"StartTime"))
FMT_BYTES = 89  # A3 95 80, type, length, name[4], format[16], columns[64]


def _is_sdlog2(path: Path, head: bytes) -> bool:
    if not is_dataflash(head):
        return False
    pos = head.find(b"\xa3\x95\x80")
    while 0 <= pos <= len(head) - FMT_BYTES:
        name, columns = head[pos + 5 : pos + 9].rstrip(b"\0"), head[pos + 25 : pos + FMT_BYTES]
        if any(name == n and columns.startswith(c) for n, c in SDLOG2_FMTS):
            return True
        pos = head.find(b"\xa3\x95\x80", pos + 3)
    return False


def _is_dataflash(path: Path, head: bytes) -> bool:
    return is_dataflash(head) and not _is_sdlog2(path, head)


def _is_dataflash_text(path: Path, head: bytes) -> bool:
    return is_dataflash_text(head)


FORMATS = (
    ReaderFormat(
        "px4_sdlog2",
        "PX4 sdlog2 log (.px4log, PX4 2013-2017)",
        read_ardupilot,
        _is_sdlog2,
        rewrite="spooflens.writers.dataflash_rewrite:rewrite_dataflash",
    ),
    ReaderFormat(
        "ardupilot",
        "ArduPilot DataFlash log (.bin)",
        read_ardupilot,
        _is_dataflash,
        rewrite="spooflens.writers.dataflash_rewrite:rewrite_dataflash",
    ),
    ReaderFormat(
        "ardupilot_text",
        "ArduPilot DataFlash text log (.log, Mission Planner / APM Planner)",
        read_ardupilot,
        _is_dataflash_text,
        rewrite="spooflens.writers.dataflash_rewrite:rewrite_dataflash",
    ),
)
