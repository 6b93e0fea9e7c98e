"""Seed 003's single-antenna spoofer on raw observations, eq. (7g): one transmitting antenna feeds every
receiver in reach the same signals, so each receiver's pseudoranges are the spoofer's plus its own
distance to the spoofer's antenna (D1, D2: a constant per receiver, absorbed as clock bias) plus its own
tracking noise.

Used to synthesise the spoofed mode on a real receiver pair (the paper's authors had no spoofer either):
from `start_s` on, receiver `b` logs receiver `a`'s pseudoranges (the spoofer re-broadcasts what its
antenna, at a's site, receives) shifted by D_b - D_a and with independent noise of `noise_m`; both
receivers' fixes are then their own single-point solutions, so they coincide up to that noise.
Not an `inject` kind: it needs two receivers' observations of one log and is a bench and test tool.
"""

from __future__ import annotations

import copy

import numpy as np
import pandas as pd

from spooflens.attacks.spec import AttackError
from spooflens.constants import SPEED_OF_LIGHT_MPS
from spooflens.epoch_table import EpochTable
from spooflens.gnss.solved_fixes import with_solved_fixes


def single_antenna_observations(
    table: EpochTable,
    a: str,
    b: str,
    start_s: float,
    noise_m: float = 0.2,
    distance_difference_m: float = 150.0,
    seed: int = 0,
) -> EpochTable:
    """`table` with receiver b's observations from `start_s` on replaced per eq. (7g); fixes re-solved.

    `table` must hold observations of both receivers (fixes, if any, are dropped and solved again).
    Carrier phase and Doppler follow the pseudorange (the spoofer's signal is one signal).
    """
    obs = table.observations
    rid = obs["receiver_id"].astype(str)
    missing = [r for r in (a, b) if not (rid == r).any()]
    if missing:
        raise AttackError(f"{table.source}: no observations of receiver(s) {missing}")
    rng = np.random.default_rng(seed)
    t_b = np.sort(obs.loc[rid == b, "t_s"].unique())
    keep_b = (rid == b) & (obs["t_s"] < start_s)
    src = obs[(rid == a) & (obs["t_s"] >= start_s)].copy()
    # receiver b keeps its own epoch tags: each of a's epochs goes to b's nearest epoch
    if len(t_b):
        near = t_b[np.clip(np.searchsorted(t_b, src["t_s"].to_numpy(float)), 0, len(t_b) - 1)]
        src["t_s"] = np.where(np.abs(near - src["t_s"].to_numpy(float)) < 0.5, near, src["t_s"].to_numpy(float))
    shift = distance_difference_m + rng.normal(0.0, noise_m, len(src))
    src["pseudorange_m"] = src["pseudorange_m"].to_numpy(float) + shift
    if "carrier_phase_cycles" in src:
        lam = SPEED_OF_LIGHT_MPS / src["carrier_freq_hz"].to_numpy(float)
        src["carrier_phase_cycles"] = src["carrier_phase_cycles"].to_numpy(float) + np.where(
            np.isfinite(lam), shift / lam, 0.0
        )
    src["receiver_id"] = b
    new_obs = pd.concat([obs[(rid != b)], obs[keep_b], src], ignore_index=True)
    new_obs = new_obs.sort_values(["t_s", "receiver_id", "sv_id"], kind="stable").reset_index(drop=True)
    out = copy.copy(table)
    out.observations = new_obs
    out.fixes = table.fixes.iloc[:0]
    out.skipped = list(table.skipped)
    out.streams = [s for s in table.streams if s.role != "fix"]
    return with_solved_fixes(out)
