"""A jammer as real receivers log it (`jam`), and jamming followed by a spoofer's capture (`jam_spoof`).

The rest of its description: docs/interference.md ("Notes from the code")."""

from __future__ import annotations

import copy
from dataclasses import replace
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from scipy.special import ndtr

from spooflens.attacks.capture import apply_capture
from spooflens.attacks.spec import KINDS, AttackError, AttackSpec, AttackTruth, Kind
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import add_enu_offset
from spooflens.gnss.ephemeris import C_MPS
from spooflens.simulation.gauss_markov import stationary_ar1

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
REACQUIRE_DB = 3.0  # a lost satellite is re-acquired this far above the tracking threshold
MIN_SATELLITES = 4  # fewer tracked: no fix
SKY_SPREAD_DB = 5.0  # spread of the satellites' C/N0 around their mean, for a log with the mean alone
FIX_SMOOTHING_S = 5.0  # a receiver's solution filters its extra noise over a few seconds
CODE_NOISE_M = 0.5  # thermal code noise of a pseudorange at the satellite's own C/N0
DOPPLER_NOISE_MPS = 0.03  # ... and of its range rate
SMOOTHED_EPOCHS = 10.0  # the carrier-aided filter averages the code noise over about this many epochs
NOISE_RISE = 0.5  # noise indicator at full power: this much above its level
JAMMING_INDICATOR_RISE = 150.0  # jamming indicator (0-255) at full power: this much above its level
WARNING_DB = 6.0  # the receiver's monitor says warning from this drop on


def jammer_power(t: FloatArray, start: float, end: float, ramp: float) -> FloatArray:
    """The jammer's power as a fraction of its full power (0 outside [start, end])."""
    if ramp <= 0:
        return ((t >= start) & (t <= end)).astype(float)
    up = np.clip((t - start) / ramp, 0.0, 1.0)
    down = np.clip((end - t) / ramp, 0.0, 1.0)
    return np.where((t >= start) & (t <= end), np.minimum(up, down), 0.0)


def _hit(sv: NDArray[Any], systems: str | None) -> BoolArray:
    ids = np.asarray(sv, dtype=str)
    if not systems:
        return np.ones(len(ids), dtype=bool)
    letters = systems.upper().replace("+", "")
    return np.array([s[:1] in letters for s in ids], dtype=bool)


def _tracking(t: FloatArray, sv: NDArray[Any], cn0: FloatArray, power: FloatArray, threshold: float) -> BoolArray:
    """Per row: still tracked, with hysteresis: lost below `threshold` while the jammer is on, back at
    `threshold` + 3 dB or when it is off (a satellite the receiver tracked below the threshold without
    the jammer keeps being tracked then)."""
    state = np.where(
        power <= 0.0, 0.0, np.where(cn0 < threshold, 1.0, np.where(cn0 >= threshold + REACQUIRE_DB, 0.0, np.nan))
    )
    frame = pd.DataFrame({"t": t, "sv": np.asarray(sv, dtype=str), "lost": state})
    order = frame.sort_values(["sv", "t"], kind="stable").index
    filled = frame.loc[order].groupby("sv")["lost"].ffill().fillna(0.0)
    lost = np.zeros(len(t), dtype=bool)
    lost[order.to_numpy()] = filled.to_numpy() > 0.5
    return ~lost


def _weakest(rows: pd.DataFrame, hit: BoolArray, start: float, count: int) -> set[str]:
    """The `count` weakest hit satellites by their C/N0 over the 30 s before `start`."""
    t = rows["t_s"].to_numpy(float)
    before = hit & (t >= start - 30.0) & (t < start)
    if not before.any():
        before = hit
    med = rows[before].groupby(rows["sv_id"].astype(str)[before])["cn0_dbhz"].median().sort_values()
    return set(med.index[:count])


def _jam_signals(
    rows: pd.DataFrame, p: dict[str, Any], power: FloatArray, lost_override: set[str] | None
) -> tuple[FloatArray, BoolArray]:
    """Per-satellite rows (a sky view or raw observations) jammed: their new C/N0 and which are tracked."""
    sv = rows["sv_id"].astype(str).to_numpy()
    hit = _hit(sv, p.get("systems"))
    cn0 = rows["cn0_dbhz"].to_numpy(float)
    jammed = cn0 - p["cn0"] * power * hit
    if lost_override is not None:
        tracked = ~(np.isin(sv, list(lost_override)) & (power >= 0.5))
    else:
        t = rows["t_s"].to_numpy(float)
        tracked = _tracking(t, sv, np.where(hit, jammed, np.inf), power * hit, p["fix_lost_below"])
    tracked &= np.isfinite(cn0)
    return np.where(tracked, jammed, np.nan), tracked


def _sky_counts(rows: pd.DataFrame, tracked: BoolArray) -> pd.DataFrame:
    """Per epoch of a sky: satellites tracked before and after the jamming, and their mean C/N0 after."""
    before = np.isfinite(rows["cn0_dbhz"].to_numpy(float))
    return (
        pd.DataFrame({"t_s": rows["t_s"].to_numpy(float), "before": before, "after": tracked, "cn0": rows["_cn0"]})
        .groupby("t_s")
        .agg(before=("before", "sum"), after=("after", "sum"), cn0=("cn0", "mean"))
    )


def _smoothed_noise(n: int, dt: float, rng: np.random.Generator) -> FloatArray:
    """(n, 3) unit-variance noise filtered over FIX_SMOOTHING_S: a receiver's solution is not white."""
    return stationary_ar1(rng.normal(0.0, 1.0, (n, 3)), float(np.exp(-dt / FIX_SMOOTHING_S)))


def apply_jam(table: EpochTable, spec: AttackSpec) -> tuple[EpochTable, AttackTruth]:
    """The jammed copy of `table` and the attack's truth."""
    p = spec.params
    start = spec.start_s
    end = min(spec.end_s if spec.end_s is not None else table.duration_s, table.duration_s)
    # a receiver that logged only its monitor reports (no fix yet) is jammed too: the reports are its front end
    frames = (table.fixes, table.observations, table.satellites, table.receiver_status)
    receivers = list(dict.fromkeys(str(r) for f in frames for r in f["receiver_id"].dropna().unique()))
    if not receivers:
        raise AttackError(
            f"{table.source}: no GNSS receiver to jam (no fixes, satellites, observations or monitor reports)"
        )
    targets = [p["receiver"]] if "receiver" in p else receivers
    unknown = [r for r in targets if r not in receivers]
    if unknown:
        raise AttackError(f"{table.source}: no receiver {unknown[0]!r}; receivers are {receivers}")
    acc = float(p["acc"]) if "acc" in p else 10.0 ** (p["cn0"] / 20.0)
    rng = np.random.default_rng(int(p["seed"]))
    truth = AttackTruth(
        spec.kind.value, dict(p), start, end, list(targets), KINDS[spec.kind].seed, str(table.source), table.t0_ns
    )
    sats, obs, fixes = table.satellites.copy(), table.observations.copy(), table.fixes.copy()
    status = table.receiver_status.copy()
    agc_in_db = table.metadata.get("units.agc", "").startswith("dB")
    keep_obs = np.ones(len(obs), dtype=bool)
    keep_fix = np.ones(len(fixes), dtype=bool)
    lost_all: set[str] = set()
    fix_lost: list[list[float]] = []
    for rid in targets:
        sky_rows = np.flatnonzero(sats["receiver_id"].astype(str).to_numpy() == rid) if len(sats) else np.zeros(0, int)
        obs_rows = np.flatnonzero(obs["receiver_id"].astype(str).to_numpy() == rid) if len(obs) else np.zeros(0, int)
        counts = None
        for frame, rows, is_obs in ((sats, sky_rows, False), (obs, obs_rows, True)):
            if not len(rows):
                continue
            sub = frame.iloc[rows]
            t = sub["t_s"].to_numpy(float)
            power = jammer_power(t, start, end, p["ramp"])
            override = (
                _weakest(sub, _hit(sub["sv_id"].astype(str).to_numpy(), p.get("systems")), start, int(p["lost"]))
                if "lost" in p
                else None
            )
            cn0, tracked = _jam_signals(sub, p, power, override)
            lost_all |= set(
                sub["sv_id"].astype(str).to_numpy()[~tracked & np.isfinite(sub["cn0_dbhz"].to_numpy(float))]
            )
            frame.iloc[rows, frame.columns.get_loc("cn0_dbhz")] = cn0
            if is_obs:
                keep_obs[rows[~tracked]] = False
                _noisier_ranges(
                    frame, rows, p["cn0"] * power * _hit(sub["sv_id"].astype(str).to_numpy(), p.get("systems")), rng
                )
            elif "used" in frame:
                used = sub["used"].to_numpy(float)
                frame.iloc[rows, frame.columns.get_loc("used")] = np.where(tracked | ~np.isfinite(used), used, 0.0)
            if counts is None or not is_obs:
                counts = _sky_counts(sub.assign(_cn0=cn0), tracked)
        f_rows = np.flatnonzero(fixes["receiver_id"].astype(str).to_numpy() == rid) if len(fixes) else np.zeros(0, int)
        t = fixes["t_s"].to_numpy(float)[f_rows] if len(f_rows) else np.zeros(0)
        lost_mask = np.zeros(len(f_rows), dtype=bool)
        if len(f_rows):
            lost_mask, offsets = _jam_fixes(fixes, f_rows, counts, p, start, end, acc, agc_in_db, rng)
            keep_fix[f_rows[lost_mask]] = False
            truth.offsets[rid] = np.c_[t, offsets][~lost_mask].round(4).tolist()
            fix_lost += _runs(t, lost_mask)
        _jam_reports(status, rid, t, lost_mask, p, start, end, agc_in_db)
    jammed = copy.copy(table)
    jammed.satellites = pd.DataFrame(sats).reset_index(drop=True)
    jammed.observations = pd.DataFrame(obs[keep_obs]).reset_index(drop=True)
    jammed.fixes = pd.DataFrame(fixes[keep_fix]).reset_index(drop=True)
    jammed.receiver_status = status
    jammed.validate()
    truth.satellites = sorted(lost_all)
    truth.phases = [
        {
            "kind": "jam",
            "start_s": start,
            "end_s": end,
            "cn0_drop_db": p["cn0"],
            "satellites_lost": sorted(lost_all),
            "fix_lost_s": fix_lost,
        }
    ]
    return jammed, truth


def _runs(t: FloatArray, flag: BoolArray) -> list[list[float]]:
    if not flag.any():
        return []
    edges = np.diff(np.r_[0, flag.astype(np.int8), 0])
    return [
        [float(t[a]), float(t[b - 1])]
        for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True)
    ]


def _noisier_ranges(obs: pd.DataFrame, rows: NDArray[np.int64], drop_db: FloatArray, rng: np.random.Generator) -> None:
    """Code and Doppler noise grow as 1/sqrt(C/N0): added to the pseudoranges and rates of the jammed rows
    (0.5 m and 0.03 m/s at the satellite's own level), the Doppler kept as the rate's (-rate / wavelength)."""
    extra = np.sqrt(np.maximum(10.0 ** (drop_db / 10.0) - 1.0, 0.0))
    for col, sigma in (("pseudorange_m", CODE_NOISE_M), ("pseudorange_rate_mps", DOPPLER_NOISE_MPS)):
        x = obs[col].to_numpy(float)[rows]
        obs.iloc[rows, obs.columns.get_loc(col)] = x + rng.normal(0.0, 1.0, len(rows)) * sigma * extra
    rate = obs["pseudorange_rate_mps"].to_numpy(float)[rows]
    freq = obs["carrier_freq_hz"].to_numpy(float)[rows]
    doppler = obs["doppler_hz"].to_numpy(float)[rows]
    with_doppler = np.isfinite(doppler) & np.isfinite(freq) & np.isfinite(rate)
    obs.iloc[rows, obs.columns.get_loc("doppler_hz")] = np.where(with_doppler, -rate * freq / C_MPS, doppler)


def _jam_fixes(
    fixes: pd.DataFrame,
    rows: NDArray[np.int64],
    counts: pd.DataFrame | None,
    p: dict[str, Any],
    start: float,
    end: float,
    acc: float,
    agc_in_db: bool,
    rng: np.random.Generator,
) -> tuple[BoolArray, FloatArray]:
    """The receiver's fixes jammed in place; returns which are lost and the position offsets added."""
    fx = fixes.iloc[rows]
    t = fx["t_s"].to_numpy(float)
    power = jammer_power(t, start, end, p["ramp"])
    drop = p["cn0"] * power
    cols = fixes.columns
    cn0_mean = fx["cn0_mean_dbhz"].to_numpy(float)
    if counts is not None and len(counts):
        k = np.clip(np.searchsorted(counts.index.to_numpy(float), t), 0, len(counts) - 1)
        before, after = counts["before"].to_numpy(float)[k], counts["after"].to_numpy(float)[k]
        fraction = np.where(before > 0, after / np.maximum(before, 1.0), 1.0)
        tracked = after
        sky_mean = counts["cn0"].to_numpy(float)[k]
        new_mean = np.where(np.isfinite(cn0_mean), np.where(np.isfinite(sky_mean), sky_mean, cn0_mean - drop), np.nan)
    else:  # the satellites' C/N0 spread around the logged mean (40 dB-Hz when none is logged)
        mean = np.where(np.isfinite(cn0_mean), cn0_mean, 40.0)
        fraction = 1.0 - ndtr((p["fix_lost_below"] + drop - mean) / SKY_SPREAD_DB)
        if "lost" in p:
            n0 = np.nan_to_num(fx["sats_used"].to_numpy(float), nan=10.0)
            fraction = np.where(power >= 0.5, np.clip(1.0 - p["lost"] / np.maximum(n0, 1.0), 0.0, 1.0), 1.0)
        tracked = np.nan_to_num(fx["sats_used"].to_numpy(float), nan=10.0) * fraction
        new_mean = cn0_mean - drop
    lost = (power > 0) & (np.floor(tracked + 1e-9) < MIN_SATELLITES)
    sats = fx["sats_used"].to_numpy(float)
    new_sats = np.where(np.isfinite(sats), np.round(sats * fraction), sats)
    geometry = np.sqrt(np.where(np.isfinite(sats) & (new_sats > 0), sats / np.maximum(new_sats, 1.0), 1.0))
    inflation = (1.0 + (acc - 1.0) * power) * geometry
    fixes.iloc[rows, cols.get_loc("sats_used")] = new_sats
    fixes.iloc[rows, cols.get_loc("cn0_mean_dbhz")] = new_mean
    for c in ("hdop", "vdop"):
        fixes.iloc[rows, cols.get_loc(c)] = fx[c].to_numpy(float) * geometry
    for c in ("h_acc_m", "v_acc_m", "vel_acc_mps"):
        fixes.iloc[rows, cols.get_loc(c)] = fx[c].to_numpy(float) * inflation
    # the real scatter: only the thermal part of the code and Doppler noise grows (through the geometry the
    # satellites left give), smoothed by the receiver's carrier-aided filter; a receiver's reported accuracy
    # grows faster than its real error does
    thermal = np.sqrt(np.maximum(10.0 ** (drop / 10.0) - 1.0, 0.0))
    hdop = np.where(np.isfinite(fx["hdop"].to_numpy(float)), fx["hdop"].to_numpy(float), 1.0) * geometry
    vdop = np.where(np.isfinite(fx["vdop"].to_numpy(float)), fx["vdop"].to_numpy(float), 1.5) * geometry
    code = CODE_NOISE_M * thermal / np.sqrt(SMOOTHED_EPOCHS)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    sigma = np.c_[hdop * code / np.sqrt(2.0), hdop * code / np.sqrt(2.0), vdop * code]
    dp = _smoothed_noise(len(t), dt, rng) * sigma
    dv = rng.normal(0.0, 1.0, (len(t), 3)) * (DOPPLER_NOISE_MPS * thermal * hdop)[:, None] / np.sqrt(2.0)
    lat, lon, h = (fx[c].to_numpy(float) for c in ("lat_deg", "lon_deg", "height_m"))
    new_lat, new_lon, new_h = add_enu_offset(lat, lon, h, dp)
    fixes.iloc[rows, cols.get_loc("lat_deg")] = new_lat
    fixes.iloc[rows, cols.get_loc("lon_deg")] = new_lon
    fixes.iloc[rows, cols.get_loc("height_m")] = new_h
    for i, c in enumerate(("vel_e_mps", "vel_n_mps", "vel_u_mps")):
        fixes.iloc[rows, cols.get_loc(c)] = fx[c].to_numpy(float) + dv[:, i]
    _jam_front_end(fixes, rows, power, p, agc_in_db, lost)
    return lost, np.where(lost[:, None], 0.0, dp)


def _jam_front_end(
    frame: pd.DataFrame,
    rows: NDArray[np.int64],
    power: FloatArray,
    p: dict[str, Any],
    agc_in_db: bool,
    without_fix: BoolArray,
) -> None:
    """The front end's indicators of these rows (fixes, or the receiver's monitor reports) in place: AGC
    down, noise and jamming indicator up with the jammer's power; a jamming monitor that is on warns, and
    says critical where the receiver has no fix."""
    cols = frame.columns
    at = frame.iloc[rows]
    drop = p["cn0"] * power
    agc = at["agc"].to_numpy(float)
    if agc_in_db:  # the gain itself (Android AgcDb): turned down by the power the jammer adds
        frame.iloc[rows, cols.get_loc("agc")] = agc - drop
    else:
        frame.iloc[rows, cols.get_loc("agc")] = np.round(agc * (1.0 - (1.0 - p["agc"]) * power))
    noise = at["noise_per_ms"].to_numpy(float)
    frame.iloc[rows, cols.get_loc("noise_per_ms")] = np.round(noise * (1.0 + NOISE_RISE * power))
    jam = at["jamming_indicator"].to_numpy(float)
    frame.iloc[rows, cols.get_loc("jamming_indicator")] = np.clip(
        np.round(jam + JAMMING_INDICATOR_RISE * power), 0, 255
    )
    state = at["jamming_state"].to_numpy(float)
    if np.nan_to_num(state, nan=0.0).max() >= 1:  # a monitor that is on says what it sees; one off stays off
        said = np.where(drop >= WARNING_DB, np.where(without_fix, 3.0, 2.0), state)
        frame.iloc[rows, cols.get_loc("jamming_state")] = np.where(np.isfinite(state), np.maximum(state, said), state)


def _nearest(sorted_t: FloatArray, t: FloatArray) -> NDArray[np.int64]:
    """Index of the element of `sorted_t` (not empty) nearest each of `t`."""
    k = np.searchsorted(sorted_t, t)
    lo, hi = np.clip(k - 1, 0, len(sorted_t) - 1), np.clip(k, 0, len(sorted_t) - 1)
    return np.where(np.abs(t - sorted_t[lo]) <= np.abs(sorted_t[hi] - t), lo, hi)


def _jam_reports(
    status: pd.DataFrame,
    rid: str,
    fix_t: FloatArray,
    fix_lost: BoolArray,
    p: dict[str, Any],
    start: float,
    end: float,
    agc_in_db: bool,
) -> None:
    """The receiver's monitor reports (`receiver_status`) jammed in place, as its fixes are: a report
    says what the front end saw when it was logged, fix or no fix. Without a fix is the nearest fix's
    state (lost or kept) for a receiver with fixes; always, for one that has none."""
    rows = np.flatnonzero(status["receiver_id"].astype(str).to_numpy() == rid) if len(status) else np.zeros(0, int)
    if not len(rows):
        return
    t = status["t_s"].to_numpy(float)[rows]
    without_fix = fix_lost[_nearest(fix_t, t)] if len(fix_t) else np.ones(len(rows), dtype=bool)
    _jam_front_end(status, rows, jammer_power(t, start, end, p["ramp"]), p, agc_in_db, without_fix)


def apply_jam_spoof(table: EpochTable, spec: AttackSpec) -> tuple[EpochTable, AttackTruth]:
    """Jamming for `jam` s from `start`, then a capture from where the jamming ends to `end`."""
    p = spec.params
    start = spec.start_s
    end = min(spec.end_s if spec.end_s is not None else table.duration_s, table.duration_s)
    takeover = start + float(p["jam"])
    if takeover >= end:
        raise AttackError(
            f"jam_spoof: {p['jam']:g} s of jamming from {start:g} s leave no time to spoof before {end:.1f} s"
        )
    jam_keys = ("cn0", "ramp", "agc", "lost", "fix_lost_below", "acc", "systems", "seed", "receiver")
    jam_params = {k: p[k] for k in jam_keys if k in p} | {"start": start, "end": takeover}
    jammed, jam_truth = apply_jam(table, AttackSpec(Kind.JAM, jam_params))
    capture_params = (
        {
            "drag": p["drag"],
            "rate": p["rate"],
            "offset": p["offset"],
            "axes": p["axes"],
            "lost": p["reacquire"],
            "jump": p["jump"],
            "acc": 4.0,
            "cn0": p["louder"],
            "clock": p["clock"],
            "seed": p["seed"],
            "start": takeover,
        }
        | ({"end": p["end"]} if "end" in p else {})
        | ({"receiver": p["receiver"]} if "receiver" in p else {})
    )
    spoofed, capture_truth = apply_capture(jammed, AttackSpec(Kind.CAPTURE, capture_params))
    captured = takeover + float(p["reacquire"])
    spoofed = _louder_and_alike(spoofed, capture_truth.receivers, start, (captured, end), float(p["louder"]), p)
    truth = replace(
        capture_truth,
        kind=spec.kind.value,
        params=dict(p),
        start_s=start,
        end_s=end,
        seed_paper=KINDS[spec.kind].seed,
        satellites=jam_truth.satellites,
        phases=[
            jam_truth.phases[0],
            {"kind": "capture", "start_s": takeover, "end_s": end, "captured_s": takeover + float(p["reacquire"])},
        ],
    )
    # the receivers' offsets: the jamming's noise, then the capture's drag
    for rid, rows in capture_truth.offsets.items():
        jam_rows = {r[0]: r[1:] for r in jam_truth.offsets.get(rid, [])}
        truth.offsets[rid] = [
            [r[0], *(np.add(r[1:], jam_rows.get(r[0], [0.0, 0.0, 0.0])).round(4).tolist())] for r in rows
        ]
    return spoofed, truth


def _louder_and_alike(
    table: EpochTable,
    receivers: list[str],
    sky_until: float,
    captured: tuple[float, float],
    louder: float,
    p: dict[str, Any],
) -> EpochTable:
    """While captured, every satellite arrives from the spoofer's one antenna: `louder` dB above the median
    of the sky before the attack (`sky_until`), within about 1 dB of each other (the capture itself moves
    only the fixes)."""
    rng = np.random.default_rng(int(p["seed"]) + 1)
    out = copy.copy(table)
    for name in ("satellites", "observations"):
        frame = getattr(table, name).copy()
        if not len(frame):
            continue
        ids = frame["receiver_id"].astype(str).to_numpy()
        t = frame["t_s"].to_numpy(float)
        cn0 = frame["cn0_dbhz"].to_numpy(float)
        new = cn0.copy()
        for rid in receivers:
            mine = ids == rid
            sky = mine & (t < sky_until) & np.isfinite(cn0)
            if not sky.any():
                continue
            level = float(np.median(cn0[sky])) + louder
            on = mine & (t >= captured[0]) & (t <= captured[1]) & np.isfinite(cn0)
            new[on] = level + rng.normal(0.0, 0.7, int(on.sum()))
        frame["cn0_dbhz"] = new
        setattr(out, name, frame)
    out.validate()
    return out
