"""Raw GNSS observations from a true trajectory: pseudoranges, pseudorange rates, carrier phase, C/N0.

Satellites come from broadcast ephemerides (a RINEX navigation file) or a synthetic Walker
constellation, through the same orbit code. The receiver has a clock that drifts (bias and drift as
a random walk). Each signal is traced back to its true transmission time, so the observation
equations are those a real receiver obeys: `spooflens.gnss.geometry.expected_pseudorange` plus
noise, and the single-point solver, which uses the same model, finds the truth back to within the
noise. Satellite states are stored the way a reader computes them from a navigation file
(`states_at_transmission`), so downstream code cannot tell a simulated log from a real one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from spooflens.gnss.ephemeris import C_MPS, GPS_L1_HZ, GpsEphemerides, satellite_states, states_at_transmission
from spooflens.gnss.geometry import azimuth_elevation, expected_pseudorange, expected_range_rate, sagnac_range

FloatArray = NDArray[np.float64]
L1_WAVELENGTH_M = C_MPS / GPS_L1_HZ


@dataclass(frozen=True)
class ObservationNoise:
    """Noise and tracking settings of a simulated receiver (defaults: a good single-frequency receiver)."""

    pseudorange_sigma_m: float = 0.5  # at zenith; grows as sqrt(1 + 1/sin^2 el)
    range_rate_sigma_mps: float = 0.03
    phase_sigma_cycles: float = 0.01
    elevation_mask_deg: float = 5.0
    clock_bias_sigma_m: float = 3000.0  # initial receiver clock bias (about 10 us)
    clock_drift_sigma_mps: float = 30.0  # initial drift (1e-7 s/s, a TCXO)
    clock_drift_rw_mps_per_sqrt_s: float = 0.01


def receiver_clock(t_s: FloatArray, noise: ObservationNoise, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """Receiver clock bias and drift, times c (m, m/s): the drift random-walks, the bias integrates it."""
    dt = np.diff(t_s, prepend=t_s[0])
    drift = rng.normal(0.0, noise.clock_drift_sigma_mps) + np.cumsum(
        rng.normal(0.0, 1.0, len(t_s)) * noise.clock_drift_rw_mps_per_sqrt_s * np.sqrt(dt)
    )
    bias = rng.normal(0.0, noise.clock_bias_sigma_m) + np.cumsum(drift * dt)
    return bias, drift


def simulate_observations(
    receiver_id: str,
    t_s: FloatArray,
    t_gps_s: FloatArray,
    rx_ecef: FloatArray,
    rx_vel_ecef: FloatArray,
    eph: GpsEphemerides,
    noise: ObservationNoise,
    rng: np.random.Generator,
) -> pd.DataFrame:
    """Observation rows (epoch-table columns, `t_s` relative) of every satellite above the mask.

    `t_gps_s` is each epoch's tag (GPS time by the receiver's clock), `rx_ecef`/`rx_vel_ecef` the
    antenna's true state at that time.
    """
    bias, drift = receiver_clock(t_s, noise, rng)
    sats = np.array(eph.satellites())
    n_e, n_s = len(t_s), len(sats)
    ep = np.repeat(np.arange(n_e), n_s)
    sv = np.tile(sats, n_e)
    # A receiver measures at round times of its own clock (the epoch tag): the true instant is the tag
    # minus its clock bias, when the antenna was a little behind where it is at the tag.
    t_rx = t_gps_s[ep] - bias[ep] / C_MPS
    rx = rx_ecef[ep] - rx_vel_ecef[ep] * (bias[ep] / C_MPS)[:, None]
    # true transmission time: the signal left when the satellite was one light-time away
    t_tx = t_rx - 0.075
    for _ in range(3):
        st = satellite_states(eph, sv, t_tx)
        t_tx = t_rx - sagnac_range(st.pos_m, rx) / C_MPS
    st = satellite_states(eph, sv, t_tx)
    _, el = azimuth_elevation(st.pos_m, rx)
    seen = st.valid & (el >= np.radians(noise.elevation_mask_deg))
    ep, sv, rx, t_rx, el = ep[seen], sv[seen], rx[seen], t_rx[seen], el[seen]
    pos, vel = st.pos_m[seen], st.vel_mps[seen]
    clk, clk_drift = st.clock_bias_m[seen], st.clock_drift_mps[seen]
    n = len(ep)
    code = expected_pseudorange(pos, clk, rx, bias[ep], t_rx, eph.iono)
    # the carrier travels the same path, but the ionosphere advances it: phase = code - 2 x ionosphere
    iono = code - expected_pseudorange(pos, clk, rx, bias[ep], t_rx, None)
    sin_el = np.sin(np.maximum(el, 0.05))
    pr_sigma = noise.pseudorange_sigma_m * np.sqrt(1.0 + 1.0 / sin_el**2)
    pr = code + rng.normal(0.0, 1.0, n) * pr_sigma
    rate = expected_range_rate(pos, vel, clk_drift, rx, rx_vel_ecef[ep], drift[ep])
    rate = rate + rng.normal(0.0, noise.range_rate_sigma_mps, n)
    # each satellite's arc has its own integer ambiguity
    ambiguity = {s: float(rng.integers(-(10**7), 10**7)) for s in sats}
    phase = (code - 2.0 * iono) / L1_WAVELENGTH_M + np.array([ambiguity[s] for s in sv])
    phase = phase + rng.normal(0.0, noise.phase_sigma_cycles, n)
    cn0 = 32.0 + 16.0 * sin_el + rng.normal(0.0, 1.0, n)
    recorded = states_at_transmission(eph, sv, t_gps_s[ep], pr)  # as any reader computes them from the tag
    return pd.DataFrame(
        {
            "t_s": t_s[ep],
            "receiver_id": receiver_id,
            "sv_id": sv,
            "pseudorange_m": pr,
            "pseudorange_rate_mps": rate,
            "doppler_hz": -rate / L1_WAVELENGTH_M,
            "carrier_phase_cycles": phase,
            "carrier_freq_hz": GPS_L1_HZ,
            "cn0_dbhz": cn0,
            **recorded.columns(),
        }
    )
