"""One receiver's observations as epoch-by-satellite matrices, and what a reference position predicts.

The raw-observation detectors (seed 001's rate consistency, seed 002's pseudorange changes) difference
each satellite's measurements between consecutive epochs and compare them with what a receiver at a
known place (a station, an INS track) would have measured. Matrices indexed [epoch, satellite] (NaN
where the satellite was not observed) make those differences one numpy expression, and `row` maps
every cell back to the row of the observations frame it came from.

Predictions leave the receiver clock out (it is common to all satellites and estimated by the
detectors): range with Earth rotation, minus the satellite clock, plus the troposphere and, when the
navigation data give the broadcast coefficients, the ionosphere, which delays the code and advances
the carrier (`spooflens.gnss.geometry`, the model the simulator and the single-point solver share).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.epoch_table import EpochTable
from spooflens.geodesy import ecef_to_geodetic, enu_rotation
from spooflens.gnss.ephemeris import C_MPS, GPS_L1_HZ, Klobuchar
from spooflens.gnss.geometry import (
    azimuth_elevation,
    expected_range_rate,
    klobuchar_delay,
    sagnac_range,
    tropospheric_delay,
)

FloatArray = NDArray[np.float64]
SV_POS = ["sv_x_m", "sv_y_m", "sv_z_m"]
SV_VEL = ["sv_vx_mps", "sv_vy_mps", "sv_vz_mps"]


@dataclass(frozen=True)
class ObservationGrid:
    """One receiver's observations: arrays (E, S) over its epochs and satellites, NaN where absent."""

    receiver_id: str
    t_s: FloatArray  # (E,) epoch times, seconds since the log start
    t_gps_s: FloatArray | None  # (E,) GPS seconds (the ionosphere's local time), None without a clock
    sv_id: NDArray[np.str_]  # (S,)
    pseudorange_m: FloatArray
    carrier_m: FloatArray  # carrier phase times the wavelength (same sign as the pseudorange)
    rate_mps: FloatArray  # pseudorange rate: the logged one, else -lambda x Doppler
    wavelength_m: FloatArray
    cn0_dbhz: FloatArray
    sv_pos: FloatArray  # (E, S, 3) ECEF at transmission
    sv_vel: FloatArray  # (E, S, 3)
    sv_clock_bias_m: FloatArray
    sv_clock_drift_mps: FloatArray
    row: NDArray[np.int64]  # (E, S) index of the observations-frame row, -1 where absent
    # (E, S) the receiver says this carrier is not continuous with its signal's previous one (lock lost,
    # half-cycle): no carrier difference into it is a rate
    carrier_arc_start: NDArray[np.bool_] | None = None

    @property
    def n_epochs(self) -> int:
        return len(self.t_s)

    @property
    def usable(self) -> NDArray[np.bool_]:
        """Cells with a pseudorange and a satellite state."""
        return (
            np.isfinite(self.pseudorange_m) & np.isfinite(self.sv_pos).all(axis=-1) & np.isfinite(self.sv_clock_bias_m)
        )

    @property
    def systems(self) -> NDArray[np.str_]:
        """(S,) satellite system letter of each column (G, E, C, R, J, ...)."""
        return np.array([s[:1] for s in self.sv_id.astype(str)])


def observation_grid(table: EpochTable, receiver_id: str) -> ObservationGrid:
    """The receiver's observation rows as matrices (epochs sorted by time, satellites by id)."""
    obs = table.observations
    idx = np.flatnonzero(obs["receiver_id"].astype(str).to_numpy() == receiver_id)
    rows = obs.iloc[idx]
    t_codes, t_uni = pd.factorize(rows["t_s"].to_numpy(float), sort=True)
    s_codes, s_uni = pd.factorize(rows["sv_id"].astype(str).to_numpy(), sort=True)
    E, S = len(t_uni), len(s_uni)

    def grid(values: np.ndarray) -> FloatArray:
        out = np.full((E, S, *values.shape[1:]), np.nan)
        out[t_codes, s_codes] = values
        return out

    freq = rows["carrier_freq_hz"].to_numpy(float)
    lam = C_MPS / np.where(np.isfinite(freq) & (freq > 0), freq, GPS_L1_HZ)
    rate = rows["pseudorange_rate_mps"].to_numpy(float)
    rate = np.where(np.isfinite(rate), rate, -lam * rows["doppler_hz"].to_numpy(float))
    row = np.full((E, S), -1, dtype=np.int64)
    row[t_codes, s_codes] = idx
    t = np.asarray(t_uni, dtype=float)
    t_gps = table.gps_seconds(t)
    return ObservationGrid(
        receiver_id=receiver_id,
        t_s=t,
        t_gps_s=None if t_gps is None else np.asarray(t_gps, dtype=float),
        sv_id=np.asarray(s_uni).astype(str),
        pseudorange_m=grid(rows["pseudorange_m"].to_numpy(float)),
        carrier_m=grid(rows["carrier_phase_cycles"].to_numpy(float) * lam),
        rate_mps=grid(rate),
        wavelength_m=grid(lam),
        cn0_dbhz=grid(rows["cn0_dbhz"].to_numpy(float)),
        sv_pos=grid(rows[SV_POS].to_numpy(float)),
        sv_vel=grid(rows[SV_VEL].to_numpy(float)),
        sv_clock_bias_m=grid(rows["sv_clock_bias_m"].to_numpy(float)),
        sv_clock_drift_mps=grid(rows["sv_clock_drift_mps"].to_numpy(float)),
        row=row,
        # a frame built without the column (older tables, tests) says nothing of its carriers' arcs
        carrier_arc_start=grid(rows["carrier_arc_start"].to_numpy(float)) == 1.0
        if "carrier_arc_start" in rows
        else None,
    )


@dataclass(frozen=True)
class Predicted:
    """What a receiver at the reference would measure, receiver clock left out; (E, S) arrays."""

    code_m: FloatArray
    carrier_m: FloatArray
    elevation_rad: FloatArray
    los_enu: FloatArray  # (E, S, 3) unit vectors receiver -> satellite in the reference's local ENU


def predicted(
    grid: ObservationGrid, rx_ecef: FloatArray, iono: Klobuchar | None, epochs: NDArray[np.int64] | None = None
) -> Predicted:
    """Pseudorange and carrier range of every cell for a receiver at `rx_ecef` (E, 3) (at each epoch of
    `epochs`, default all)."""
    ep = np.arange(grid.n_epochs) if epochs is None else np.asarray(epochs)
    sv = grid.sv_pos[ep]
    rx = np.broadcast_to(np.asarray(rx_ecef, float)[:, None, :], sv.shape)
    geometric = sagnac_range(sv, rx) - grid.sv_clock_bias_m[ep]
    lat_deg, lon_deg, h = ecef_to_geodetic(np.asarray(rx_ecef, float))
    az, el = azimuth_elevation(sv, rx)
    lat_b = np.broadcast_to(np.radians(lat_deg)[:, None], el.shape)
    trop = tropospheric_delay(lat_b, np.broadcast_to(h[:, None], el.shape), el)
    if iono is not None and grid.t_gps_s is not None:
        lon_b = np.broadcast_to(np.radians(lon_deg)[:, None], el.shape)
        t_b = np.broadcast_to(grid.t_gps_s[ep][:, None], el.shape)
        ion = np.nan_to_num(klobuchar_delay(iono, lat_b, lon_b, az, el, t_b))
    else:
        ion = np.zeros_like(el)
    d = sv - rx
    u = d / np.linalg.norm(d, axis=-1, keepdims=True)
    R = enu_rotation(lat_deg, lon_deg)  # (E, 3, 3)
    u_enu = np.einsum("eij,esj->esi", R, u)
    return Predicted(geometric + trop + ion, geometric + trop - ion, el, u_enu)


def predicted_rate(grid: ObservationGrid, rx_ecef: FloatArray, rx_vel_ecef: FloatArray) -> FloatArray:
    """Instantaneous pseudorange rate of every cell for a receiver at `rx_ecef` moving at `rx_vel_ecef`
    (both (E, 3)), receiver clock drift left out."""
    sv = grid.sv_pos
    rx = np.broadcast_to(np.asarray(rx_ecef, float)[:, None, :], sv.shape)
    rv = np.broadcast_to(np.asarray(rx_vel_ecef, float)[:, None, :], sv.shape)
    return expected_range_rate(sv, grid.sv_vel, grid.sv_clock_drift_mps, rx, rv, np.zeros(sv.shape[:2]))


def epoch_change(values: FloatArray) -> FloatArray:
    """values(k) - values(k-1) along the epoch axis; the first epoch NaN."""
    out = np.full_like(values, np.nan)
    out[1:] = values[1:] - values[:-1]
    return out
