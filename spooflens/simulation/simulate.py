"""Simulated logs: a scenario (trajectory, sensor grades, rates) -> an EpochTable with its truth.

Deterministic for a seed. The table is built through `build_table`, like a reader's, so everything
downstream treats a simulated log as a real one; `spooflens.writers.write_log` puts it in any format.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from spooflens.epoch_table import EpochTable, StreamInfo, build_table, gps_seconds_of_unix_ns, unix_ns_of_gps_seconds
from spooflens.geodesy import add_enu_offset, geodetic_to_ecef
from spooflens.gnss.ephemeris import (
    GpsEphemerides,
    galileo_constellation,
    satellite_states,
    synthetic_constellation,
)
from spooflens.navigation.imu_models import ImuGrade, grade
from spooflens.navigation.rotations import matrix_to_quat, rotvec_to_matrix
from spooflens.schema import FixType
from spooflens.simulation.observations import ObservationNoise
from spooflens.simulation.sensors import (
    CompassModel,
    GnssNoise,
    ReceiverModel,
    compass_readings,
    gnss_errors,
    noisy_imu,
    receiver_fix_errors,
)
from spooflens.simulation.sky import sky_reports
from spooflens.simulation.trajectories import PROFILES, Profile, Truth, generate

# 2026-03-01T12:00:00Z: a fixed start so simulated logs are byte-for-byte reproducible
T0_UNIX_NS = 1_772_366_400_000_000_000
SYNTHETIC_CONSTELLATIONS = ("synthetic", "synthetic_gps_galileo")


@dataclass(frozen=True)
class Scenario:
    name: str
    profile: Profile
    imu_hz: float
    gnss_hz: float
    imu_grade: ImuGrade
    gnss: GnssNoise = field(default_factory=GnssNoise)
    second_receiver_lever_m: tuple[float, float, float] | None = None  # FLU offset of antenna 2
    imu_orientation: bool = True  # an AHRS quaternion in the IMU messages, as many ROS IMUs publish
    orientation_noise_deg: tuple[float, float] = (0.5, 3.0)  # roll/pitch, yaw (yaw drifts: magnetometer)
    # Raw observations: with noise settings, each receiver logs pseudoranges, rates, carrier phase and
    # C/N0, and its fixes are its own single-point solution of them (as a real receiver's are).
    observations: ObservationNoise | None = None
    # "synthetic" (GPS-like), "synthetic_gps_galileo" (and Galileo's), or the path of a RINEX navigation file
    # (the log then starts in its span)
    constellation: str = "synthetic"
    # A receiver as real ones behave (correlated errors, misstated accuracies, indicators); None: the
    # plain `gnss` noise model with honest accuracies
    receiver: ReceiverModel | None = None
    # a vessel's compass and speed log (and the water it moves through): the `headings` frame
    compass: CompassModel | None = None
    # the receiver (a `receiver` model) reports its sky: per-satellite C/N0, elevation, azimuth, used (the
    # `satellites` frame, `spooflens.simulation.sky`), its satellites used and mean C/N0 following it
    satellite_reports: bool = False


SCENARIOS: dict[str, Scenario] = {
    "seed000": Scenario("seed000", PROFILES["seed000"], 160.0, 1.0, grade("seed000"), GnssNoise((3.7, 3.7, 6.0), 0.1)),
    "aircraft": Scenario(
        "aircraft",
        PROFILES["aircraft"],
        200.0,
        10.0,
        grade("tactical"),
        GnssNoise((1.5, 1.5, 3.0), 0.05, correlation_s=0.0),
    ),
    "ship": Scenario("ship", PROFILES["ship"], 100.0, 1.0, grade("tactical"), GnssNoise((2.0, 2.0, 4.0), 0.05)),
    "ground": Scenario(
        "ground", PROFILES["ground"], 100.0, 10.0, grade("consumer_mems"), GnssNoise((1.5, 1.5, 3.0), 0.08)
    ),
    "ground_raw": Scenario(
        "ground_raw",
        PROFILES["ground"],
        100.0,
        1.0,
        grade("consumer_mems"),
        observations=ObservationNoise(),
    ),
    "multirotor": Scenario(
        "multirotor",
        PROFILES["multirotor"],
        200.0,
        5.0,
        grade("consumer_mems"),
        receiver=ReceiverModel(),
    ),
    "dual_receiver": Scenario(
        "dual_receiver",
        PROFILES["ground"],
        100.0,
        5.0,
        grade("consumer_mems"),
        GnssNoise((1.5, 1.5, 3.0), 0.08),
        second_receiver_lever_m=(0.0, 1.2, 0.0),
    ),
}


@dataclass(frozen=True)
class Simulated:
    table: EpochTable
    truth: Truth  # at the IMU rate
    imu_gyro_bias: np.ndarray  # (N, 3) biases actually in the IMU samples
    imu_accel_bias: np.ndarray


def scenario(name: str) -> Scenario:
    try:
        return SCENARIOS[name]
    except KeyError:
        raise KeyError(f"unknown scenario {name!r}; scenarios are {sorted(SCENARIOS)}") from None


def simulate(spec: str | Scenario, seed: int = 0, duration_s: float | None = None) -> Simulated:
    sc = scenario(spec) if isinstance(spec, str) else spec
    profile = sc.profile
    if duration_s is not None:
        profile = _truncated(profile, duration_s)
    rng = np.random.default_rng(seed)
    truth = generate(profile, sc.imu_hz)
    imu = noisy_imu(truth, sc.imu_grade, rng)
    eph, t0_unix_ns = _constellation(sc, rng) if sc.observations is not None else (None, T0_UNIX_NS)
    t_ns = t0_unix_ns + np.round(truth.t * 1e9).astype(np.int64)
    n = len(truth.t)
    imu_cols: dict[str, object] = {"t_ns": t_ns, "imu_id": "/imu/data"}
    for i, a in enumerate("xyz"):
        imu_cols[f"a{a}_mps2"] = imu.f_b[:, i]
        imu_cols[f"w{a}_radps"] = imu.w_b[:, i]
    if sc.imu_orientation:
        rp, yaw = np.radians(sc.orientation_noise_deg)
        err = rng.normal(0.0, 1.0, (n, 3)) * [rp, rp, 0.0]
        err[:, 2] = rng.normal(0.0, yaw) + np.cumsum(rng.normal(0.0, yaw / np.sqrt(n), n))
        q = matrix_to_quat(rotvec_to_matrix(err) @ truth.C)
        imu_cols |= {"qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3]}
    step = max(1, round(sc.imu_hz / sc.gnss_hz))
    g_idx = np.arange(0, n, step)
    receivers: list[tuple[str, np.ndarray | None]] = [("/gps/fix", None)]
    if sc.second_receiver_lever_m is not None:
        receivers.append(("/gps2/fix", np.asarray(sc.second_receiver_lever_m)))
    fix_frames = []
    obs_frames = []
    sky_frames = []
    # the sky has a generator of its own: the rest of the log is the same with or without it
    sky_rng = np.random.default_rng((seed, 0x5C))
    sky_eph = _sky_constellation(sky_rng) if sc.receiver is not None and sc.satellite_reports else None
    for rid, lever in receivers:
        if eph is not None and sc.observations is not None:
            obs, fixes = _raw_receiver(rid, truth, lever, g_idx, t_ns, eph, sc.observations, rng)
            obs_frames.append(obs)
            fix_frames.append(fixes)
            continue
        lat, lon, h = (
            truth.offset_geodetic(lever)
            if lever is not None
            else (np.degrees(truth.lat), np.degrees(truth.lon), truth.h)
        )
        if sc.receiver is not None:
            dpos, dvel, reported = receiver_fix_errors(len(g_idx), step / sc.imu_hz, sc.receiver, rng)
            if sky_eph is not None:
                rx = truth.ecef(lever)[g_idx]
                t_gps = gps_seconds_of_unix_ns(t_ns[g_idx])
                sky = sky_reports(rid, truth.t[g_idx], t_gps, rx, sky_eph, sc.receiver.cn0_dbhz, sky_rng)
                per_epoch = sky.groupby("t_s").agg(used=("used", "sum"), cn0=("cn0_dbhz", "mean"))
                per_epoch = per_epoch.reindex(truth.t[g_idx])
                reported["sats_used"] = per_epoch["used"].fillna(0.0).to_numpy(float)
                reported["cn0_mean_dbhz"] = per_epoch["cn0"].to_numpy(float)
                sky.insert(0, "t_ns", t0_unix_ns + np.round(sky.pop("t_s").to_numpy() * 1e9).astype(np.int64))
                sky_frames.append(sky)
        else:
            dpos, dvel = gnss_errors(len(g_idx), step / sc.imu_hz, sc.gnss, rng)
            sig = np.asarray(sc.gnss.sigma_enu_m)
            reported = {
                "h_acc_m": np.full(len(g_idx), float(np.sqrt(0.5 * (sig[0] ** 2 + sig[1] ** 2)))),
                "v_acc_m": np.full(len(g_idx), float(sig[2])),
                "vel_acc_mps": np.full(len(g_idx), sc.gnss.sigma_vel_mps),
                "sats_used": (9.0 + (np.arange(len(g_idx)) // 200) % 3).astype(np.float64),
            }
        lat_g, lon_g, h_g = add_enu_offset(lat[g_idx], lon[g_idx], h[g_idx], dpos)
        v = truth.v_enu[g_idx] + dvel
        fix_frames.append(
            pd.DataFrame(
                {
                    "t_ns": t_ns[g_idx],
                    "receiver_id": rid,
                    "lat_deg": lat_g,
                    "lon_deg": lon_g,
                    "height_m": h_g,
                    "vel_e_mps": v[:, 0],
                    "vel_n_mps": v[:, 1],
                    "vel_u_mps": v[:, 2],
                    **reported,
                    "fix_type": np.full(len(g_idx), FixType.FIX_3D, dtype=np.int8),
                }
            )
        )
    truth_frame = pd.DataFrame(
        {
            "t_ns": t_ns[g_idx],
            "lat_deg": np.degrees(truth.lat[g_idx]),
            "lon_deg": np.degrees(truth.lon[g_idx]),
            "height_m": truth.h[g_idx],
            "vel_e_mps": truth.v_enu[g_idx, 0],
            "vel_n_mps": truth.v_enu[g_idx, 1],
            "vel_u_mps": truth.v_enu[g_idx, 2],
            "roll_rad": truth.roll[g_idx],
            "pitch_rad": truth.pitch[g_idx],
            "yaw_rad": truth.yaw[g_idx],
        }
    )
    streams = [
        StreamInfo("imu", "/imu/data", "/imu/data", "sensor_msgs/msg/Imu", n, body_frame="FLU", frame_id="imu_link")
    ]
    streams += [
        StreamInfo("fix", rid, rid, "sensor_msgs/msg/NavSatFix", len(g_idx), frame_id="gnss") for rid, _ in receivers
    ]
    streams += (
        [
            StreamInfo("observations", rid, rid, "simulated raw GNSS", len(g_idx), frame_id="gnss")
            for rid, _ in receivers
        ]
        if obs_frames
        else []
    )
    streams.append(StreamInfo("truth", "truth", "/truth/fix", "simulation", len(g_idx)))
    frames = {"imu": pd.DataFrame(imu_cols), "fixes": pd.concat(fix_frames, ignore_index=True), "truth": truth_frame}
    if obs_frames:
        frames["observations"] = pd.concat(obs_frames, ignore_index=True)
    if sky_frames:
        frames["satellites"] = pd.concat(sky_frames, ignore_index=True)
        streams += [
            StreamInfo("satellites", rid, f"{rid}/satellites", "simulated sky report", len(g_idx), frame_id="gnss")
            for rid, _ in receivers
        ]
    if sc.compass is not None:
        heading, log = compass_readings(truth.t[g_idx], truth.v_enu[g_idx, :2], sc.compass, rng)
        hid = f"{sc.compass.talker}{'HDT' if sc.compass.talker == 'HE' else 'HDG'}"
        frames["headings"] = pd.DataFrame(
            {
                "t_ns": t_ns[g_idx],
                "heading_id": hid,
                "heading_deg": heading,
                "talker": sc.compass.talker,
                "water_speed_mps": log,
            }
        )
        streams.append(StreamInfo("heading", hid, hid, f"NMEA {hid[-3:]} with VHW", len(g_idx)))
    table = build_table(
        Path(f"simulated_{sc.name}_seed{seed}"), "simulation", "unix", frames, streams, [], t0_ns=t0_unix_ns
    )
    table.ephemerides = eph
    return Simulated(table, truth, imu.gyro_bias, imu.accel_bias)


def write_with_truth(table: EpochTable, path: Path, fmt: str) -> Path:
    """Write a simulated log with its true trajectory beside it (`<path>.truth.csv`), not inside it.

    A log is what a vehicle recorded; the truth is what the investigator never has, so it is kept apart.
    Returns the truth file's path.
    """
    from spooflens.writers import write_log

    log = copy.copy(table)
    log.truth = table.truth.iloc[:0]
    write_log(log, path, fmt)
    truth_path = Path(str(path).rstrip("/") + ".truth.csv")
    table.truth.to_csv(truth_path, index=False, float_format="%.10f")
    return truth_path


def _sky_constellation(rng: np.random.Generator) -> GpsEphemerides:
    """GPS and Galileo's nominal constellations at the fixed start, for a receiver's sky report."""
    start_gps = float(gps_seconds_of_unix_ns(T0_UNIX_NS))
    return GpsEphemerides.combined(
        [synthetic_constellation(start_gps, rng=rng), galileo_constellation(start_gps, rng=rng)]
    )


def _constellation(sc: Scenario, rng: np.random.Generator) -> tuple[GpsEphemerides, int]:
    """The satellites and the log's start (UNIX ns): a synthetic constellation at the fixed start, or a
    navigation file's satellites with the log starting when the vehicle can see enough of them."""
    if sc.constellation in SYNTHETIC_CONSTELLATIONS:
        start_gps = float(gps_seconds_of_unix_ns(T0_UNIX_NS))
        gps = synthetic_constellation(start_gps, rng=rng)
        if sc.constellation == "synthetic":
            return gps, T0_UNIX_NS
        return GpsEphemerides.combined([gps, galileo_constellation(start_gps, rng=rng)]), T0_UNIX_NS
    from readers.rinex import read_rinex_nav

    eph = read_rinex_nav(Path(sc.constellation))
    return eph, int(unix_ns_of_gps_seconds(_first_sky(eph, sc)))


def _first_sky(eph: GpsEphemerides, sc: Scenario, wanted: int = 6, step_s: float = 600.0) -> float:
    """The first time (GPS s, from the earliest toe on a `step_s` grid) at which `wanted` satellites of
    the file are above the solver's elevation mask at the trajectory's start.

    A station's navigation file holds only the satellites it tracked, when it tracked them: seen from
    a vehicle elsewhere, much of the file's day may have too few of them to solve.
    """
    from spooflens.gnss.geometry import azimuth_elevation
    from spooflens.gnss.single_point import SinglePointOptions

    rx = geodetic_to_ecef(sc.profile.lat_deg, sc.profile.lon_deg, sc.profile.height_m)
    sats = np.array(eph.satellites())
    mask = np.radians(SinglePointOptions().elevation_mask_deg)  # what the receiver solves with, not tracks
    start = float(np.ceil(float(np.min(eph.toe_s)) / step_s) * step_s)
    best, best_n = start, -1
    for t in np.arange(start, float(np.max(eph.toe_s)) + step_s, step_s):
        st = satellite_states(eph, sats, np.full(len(sats), t))
        _, el = azimuth_elevation(st.pos_m, np.broadcast_to(rx, st.pos_m.shape))
        n = int(np.sum(st.valid & (el > mask)))
        if n >= wanted:
            return float(t)
        if n > best_n:
            best, best_n = float(t), n
    return best


def _raw_receiver(
    rid: str,
    truth: Truth,
    lever: np.ndarray | None,
    g_idx: np.ndarray,
    t_ns: np.ndarray,
    eph: GpsEphemerides,
    noise: ObservationNoise,
    rng: np.random.Generator,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """One receiver's observations (t_ns-stamped) and the fixes it computes from them."""
    from spooflens.gnss.single_point import SinglePointOptions, solve
    from spooflens.simulation.observations import simulate_observations

    t_s = truth.t[g_idx]
    t_gps = gps_seconds_of_unix_ns(t_ns[g_idx])
    rx = truth.ecef(lever)[g_idx]
    obs = simulate_observations(rid, t_s, t_gps, rx, truth.ecef_velocity()[g_idx], eph, noise, rng)
    t0_gps = float(gps_seconds_of_unix_ns(t_ns[0])) - truth.t[0]
    sol = solve(obs, t0_gps + obs["t_s"].to_numpy(), SinglePointOptions(iono=eph.iono))
    cols = sol.fixes_columns()
    fixes = pd.DataFrame(cols)
    fixes["h_acc_m"] = noise.pseudorange_sigma_m * 2.0 * sol.hdop[sol.ok]
    fixes["v_acc_m"] = noise.pseudorange_sigma_m * 2.0 * sol.vdop[sol.ok]
    fixes["vel_acc_mps"] = noise.range_rate_sigma_mps * sol.pdop[sol.ok]
    start = int(t_ns[0])
    for frame in (obs, fixes):
        frame.insert(0, "t_ns", start + np.round(frame.pop("t_s").to_numpy() * 1e9).astype(np.int64))
    return obs, fixes


def _truncated(profile: Profile, duration_s: float) -> Profile:
    """The profile cut (or its last segment extended) to `duration_s`."""
    segs, total = [], 0.0
    for s in profile.segments:
        if total + s.duration_s >= duration_s:
            segs.append(replace(s, duration_s=duration_s - total))
            break
        segs.append(s)
        total += s.duration_s
    else:
        segs[-1] = replace(segs[-1], duration_s=segs[-1].duration_s + duration_s - total)
    return replace(profile, segments=tuple(segs))
