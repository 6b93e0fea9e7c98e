"""A spoofer takeover as real receivers log it (`capture`), for validating detectors without tuning them
to one recorded file.

Real captures (an SDR spoofer switched on near a drone, a counterfeit-signal generator near a ship)
share a signature: while the counterfeit signals overpower the real ones the receiver loses and
re-acquires satellites over a few seconds (the fix may drop out), its reported accuracies and DOP
inflate, its noise and jamming indicators rise and the C/N0 first falls; once locked on the spoofer,
the C/N0 sits above its old level (a spoofer is louder than the sky) and the velocity jumps before the
spoofer starts dragging the position. The drag itself is a ramp, a step or a pull, with the reported
velocity consistent with the false track (the spoofer controls the Doppler too). When the spoofer
switches off, the receiver loses and re-acquires the real sky once more. A spoofer whose time is not
GNSS time (`clock` s off) moves the receiver's time against the log's clock while it is captured.
Indicators the log does not have (NaN columns) stay NaN.
"""

from __future__ import annotations

import copy

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.attacks.spec import KINDS, AttackError, AttackSpec, AttackTruth
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import add_enu_offset, geodetic_to_enu

FloatArray = NDArray[np.float64]
# indicator: (how it moves during the takeover at its worst, how it sits while captured); multiplicative
# factors except where marked additive
_INDICATORS = {
    "sats_used": ("drop", 0.55, 0.85),
    "hdop": ("scale", 2.5, 1.2),
    "vdop": ("scale", 2.5, 1.2),
    "noise_per_ms": ("scale", 1.5, 1.15),
    "jamming_indicator": ("add", 80.0, 25.0),
    "agc": ("scale", 0.75, 0.9),
}


def _bump(tau: FloatArray, length: float) -> FloatArray:
    """0 outside [0, length], rising to 1 in the middle and back (sin^2)."""
    inside = (tau >= 0) & (tau <= length)
    return np.where(inside, np.sin(np.pi * np.clip(tau, 0, length) / length) ** 2, 0.0)


def _drag(spec: AttackSpec, tau: FloatArray, axes: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Position and velocity offsets of the drag, tau s after the takeover (0 before)."""
    p = spec.params
    on = tau > 0
    if p["drag"] == "ramp":
        return np.clip(tau, 0, None)[:, None] * p["rate"] * axes, np.where(on[:, None], p["rate"] * axes, 0.0)
    if p["drag"] == "step":
        return np.where(on[:, None], p["offset"] * axes, 0.0), np.zeros((len(tau), 3))
    frac = np.clip(tau / 60.0, 0.0, 1.0)[:, None]
    rate = np.where((on & (tau < 60.0))[:, None], p["offset"] / 60.0 * axes, 0.0)
    return frac * p["offset"] * axes, rate


def _indicator(column: str, x: FloatArray, transient: FloatArray, during: NDArray[np.bool_]) -> FloatArray:
    """A receiver indicator moved by the takeover's `transient` and while `during` the capture."""
    how, worst, captured = _INDICATORS[column]
    if how == "add":
        return x + worst * transient + captured * during
    if how == "drop":
        return np.maximum(np.round(x * (1.0 - (1.0 - worst) * transient) * np.where(during, captured, 1.0)), 3)
    return x * (1.0 + (worst - 1.0) * transient) * np.where(during, captured, 1.0)


def _capture_reports(status: pd.DataFrame, rid: str, start: float, end: float, lost: float, duration: float) -> None:
    """The receiver's monitor reports (`receiver_status`) moved in place as its fixes' indicators are: the
    front end sees the spoofer whether the receiver has a fix or not."""
    rows = np.flatnonzero(status["receiver_id"].astype(str).to_numpy() == rid) if len(status) else np.zeros(0, int)
    if not len(rows):
        return
    t = status["t_s"].to_numpy(dtype=float)[rows]
    release = _bump(t - end, lost / 2.0) if end < duration else np.zeros_like(t)
    transient = np.maximum(_bump(t - start, lost), release)
    during = (t >= start + lost) & (t <= end)
    for c in ("noise_per_ms", "jamming_indicator", "agc"):
        x = status[c].to_numpy(dtype=float)[rows]
        status.iloc[rows, status.columns.get_loc(c)] = _indicator(c, x, transient, during)


def apply_capture(table: EpochTable, spec: AttackSpec) -> tuple[EpochTable, AttackTruth]:
    receivers = table.receivers()
    if not receivers:
        raise AttackError(f"{table.source}: no GNSS fixes to attack")
    targets = [spec.params["receiver"]] if "receiver" in spec.params else receivers
    unknown = [r for r in targets if r not in receivers]
    if unknown:
        raise AttackError(f"{table.source}: no receiver {unknown[0]!r}; receivers are {receivers}")
    p = spec.params
    start = spec.start_s
    end = spec.end_s if spec.end_s is not None else table.duration_s
    if start >= table.duration_s:
        raise AttackError(f"capture: start={start:g} s is after the log's end ({table.duration_s:.1f} s)")
    lost = float(p["lost"])
    captured_at = start + lost
    axes = np.array([1.0 if a in spec.axes else 0.0 for a in "enu"])
    rng = np.random.default_rng(int(p["seed"]))
    direction = rng.normal(0.0, 1.0, 2)
    direction = np.r_[direction / np.linalg.norm(direction), 0.0]
    truth = AttackTruth(
        spec.kind.value, dict(p), start, end, list(targets), KINDS[spec.kind].seed, str(table.source), table.t0_ns
    )
    keep = np.ones(len(table.fixes), dtype=bool)
    fixes = table.fixes.copy()
    status = table.receiver_status.copy()
    for rid in targets:
        rows = np.flatnonzero(fixes["receiver_id"].to_numpy() == rid)
        fx = fixes.iloc[rows]
        t = fx["t_s"].to_numpy(dtype=float)
        takeover = _bump(t - start, lost)
        release = _bump(t - end, lost / 2.0) if end < table.duration_s else np.zeros_like(t)
        transient = np.maximum(takeover, release)
        during = (t >= captured_at) & (t <= end)
        lat, lon, h = (fx[c].to_numpy(dtype=float) for c in ("lat_deg", "lon_deg", "height_m"))
        p_enu = geodetic_to_enu(lat, lon, h, lat[0], lon[0], h[0])
        dp, dv = _drag(spec, np.where(t <= end, t - captured_at, 0.0), axes)
        # the receiver's solution wanders while it re-acquires, and its velocity jumps
        wander = np.cumsum(rng.normal(0.0, 1.0, (len(t), 3)), axis=0) * [1.0, 1.0, 2.0] * takeover[:, None]
        dp = dp + wander
        dv = (
            dv
            + p["jump"]
            * np.sin(np.pi * np.clip((t - start) / lost, 0, 1))[:, None]
            * direction
            * ((t >= start) & (t <= captured_at))[:, None]
        )
        new_lat, new_lon, new_h = add_enu_offset(lat, lon, h, dp)
        cols = fixes.columns
        fixes.iloc[rows, cols.get_loc("lat_deg")] = new_lat
        fixes.iloc[rows, cols.get_loc("lon_deg")] = new_lon
        fixes.iloc[rows, cols.get_loc("height_m")] = new_h
        v = fx[["vel_e_mps", "vel_n_mps", "vel_u_mps"]].to_numpy(dtype=float)
        for i, c in enumerate(("vel_e_mps", "vel_n_mps", "vel_u_mps")):
            fixes.iloc[rows, cols.get_loc(c)] = v[:, i] + dv[:, i]
        for c, factor in (("h_acc_m", p["acc"]), ("v_acc_m", p["acc"]), ("vel_acc_mps", 2.5 * p["acc"])):
            x = fx[c].to_numpy(dtype=float)
            fixes.iloc[rows, cols.get_loc(c)] = x * (1.0 + (factor - 1.0) * transient) * np.where(during, 1.3, 1.0)
        for c in _INDICATORS:
            fixes.iloc[rows, cols.get_loc(c)] = _indicator(c, fx[c].to_numpy(dtype=float), transient, during)
        if "time_offset_s" in cols:  # the receiver keeps the spoofer's time while it is captured
            off = fx["time_offset_s"].to_numpy(dtype=float)
            fixes.iloc[rows, cols.get_loc("time_offset_s")] = off + p["clock"] * during
        cn0 = fx["cn0_mean_dbhz"].to_numpy(dtype=float)
        fixes.iloc[rows, cols.get_loc("cn0_mean_dbhz")] = cn0 - 8.0 * transient + p["cn0"] * during
        # the fix drops out in the middle of each transient
        gap = (transient > 0.85) & (np.abs(np.diff(np.r_[0.0, transient])) < 0.5)
        keep[rows[gap]] = False
        actual = geodetic_to_enu(new_lat, new_lon, new_h, lat[0], lon[0], h[0]) - p_enu
        truth.offsets[rid] = np.c_[t, actual][~gap].round(4).tolist()
        _capture_reports(status, rid, start, end, lost, table.duration_s)
    spoofed = copy.copy(table)
    spoofed.fixes = pd.DataFrame(fixes[keep]).reset_index(drop=True)
    spoofed.receiver_status = status
    spoofed.validate()
    return spoofed, truth
