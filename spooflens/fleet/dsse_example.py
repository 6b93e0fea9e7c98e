"""Seed 004's three-UAV example (section 4.3) with its printed matrices, our gains, and what the printed
gains do.

The printed L_i and N_i were computed in a basis Gamma_i the paper does not print; an orthonormal basis
of a subspace is fixed only up to the order and signs of its vectors (and any rotation), so the printed
gains are evaluated in every order/sign variant of our SVD basis. UAV 3 has no secure output: its
unobservable part is its whole state (n^obar_3 = 4), so N_3 must be 4x1 and the printed 2x1 N_3 (and an
L_3) cannot be used; N_3 is designed here in either case.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from spooflens.fleet.observer import (
    Agents,
    Decomposition,
    Gains,
    decompose,
    design_n,
    error_matrix,
    full_error_matrix,
    place_observer_gain,
    spectral_radius,
    theorem2_matrix,
)

FloatArray = NDArray[np.float64]

A1 = np.array(
    [
        [1.394, -0.795, 0.072, -0.135],
        [0.298, 0.254, -0.079, 0.075],
        [-0.442, 0.198, 0.047, 0.014],
        [0.289, -0.097, -0.010, 0.106],
    ]
)
A2 = np.array(
    [
        [2.739, -1.196, 0.531, 0.266],
        [1.140, -0.206, 0.077, 0.140],
        [-0.039, -0.235, 0.349, 0.671],
        [-1.107, 1.042, -0.096, 0.794],
    ]
)
A3 = np.array(
    [
        [1.974, -0.690, -0.608, -0.516],
        [0.994, 0.064, -0.820, 0.117],
        [-0.306, 0.439, 0.399, 0.319],
        [-0.316, 0.475, 0.372, 0.402],
    ]
)
C1 = np.array([[-0.874, 0.842, -0.193, 0.727]])
CA1 = np.array([[-0.486, -0.226, 0.797, -0.110]])
C2 = np.array([[-1.281, 0.9216, -0.439, -0.169]])
CA2 = np.array([[-0.563, -0.294, 0.882, 0.368]])
CA3 = np.array([[-0.344, -0.703, 0.215, 0.237]])
# p_ij: 1 listens to 3, 2 to 1, 3 to 2 (a directed cycle 3 -> 1 -> 2 -> 3)
P = np.array([[0.3, 0.0, 0.7], [0.7, 0.3, 0.0], [0.0, 0.2, 0.8]])
PAPER_AGENTS = Agents((A1, A2, A3), (C1, C2, None), (CA1, CA2, CA3), P)

PRINTED_L = (np.array([[0.486], [0.535]]), np.array([[2.375], [0.610]]), np.array([[0.653], [2.215]]))
PRINTED_N = (np.array([[0.218], [0.220]]), np.array([[0.420], [1.303]]), np.array([[0.638], [0.270]]))
RANK_RTOL = 1e-2  # singular values 2.12 / 0.361 / 1.3e-3 / 1e-4 (agent 1): rank 2 at this tolerance
POLES = (0.2, 0.3)  # eig(A_i^o - L_i C_i^o): our choice (the paper's are not printed)


def attack(k: int) -> FloatArray:
    """a(k) = sin(0.2 k), the example's homologous attack."""
    return np.array([np.sin(0.2 * k)])


def decompositions(agents: Agents = PAPER_AGENTS, rtol: float = RANK_RTOL) -> list[Decomposition]:
    return [decompose(A, C, Ca, rtol) for A, C, Ca in zip(agents.A, agents.C, agents.Ca, strict=True)]


def designed_gains(
    agents: Agents, decs: list[Decomposition], poles: tuple[float, ...] = POLES, seed: int = 0, starts: int = 12
) -> tuple[Gains, str]:
    L = tuple(place_observer_gain(d.A_o, d.C_o, poles[: d.n_o]) if d.n_o else np.zeros((0, 0)) for d in decs)
    N, how = design_n(decs, agents.P, seed=seed, starts=starts)
    return Gains(L, N), how


def exact_agents(agents: Agents, decs: list[Decomposition]) -> Agents:
    """The same agents with the rounding-sized coupling Gamma^o^T A Gamma^obar (and C Gamma^obar) set to
    zero, so the decomposition is exact: the system eqs. (19) and (26) describe without approximation."""
    A, C = [], []
    for Ai, Ci, d in zip(agents.A, agents.C, decs, strict=True):
        G = d.gamma
        blocks = G @ Ai @ G.T
        blocks[d.n_obar :, : d.n_obar] = 0.0
        A.append(G.T @ blocks @ G)
        C.append(None if Ci is None else d.C_o @ d.gamma_o.T)
    return replace(agents, A=tuple(A), C=tuple(C))


def basis_variants(gamma: FloatArray) -> list[FloatArray]:
    """Every order and sign choice of the basis vectors (columns)."""
    m = gamma.shape[1]
    out = []
    for order in itertools.permutations(range(m)):
        for signs in itertools.product((1.0, -1.0), repeat=m):
            out.append(gamma[:, order] * np.array(signs))
    return out


@dataclass(frozen=True)
class PrintedGains:
    """What the printed gains do in the order/sign variants of our bases (min, max spectral radius)."""

    l_radius: tuple[tuple[float, float], ...]  # per agent with a secure output
    n_radius_with_designed_n3: tuple[float, float]  # eq. (26) with printed N_1, N_2 and N_3 designed here
    n_radius_theorem2_sign: tuple[float, float]  # the same gains in Theorem 2's printed matrix
    n3_printed_shape: tuple[int, int]
    n3_needed_shape: tuple[int, int]


def evaluate_printed(
    agents: Agents = PAPER_AGENTS,
    rtol: float = RANK_RTOL,
    starts: int = 3,
    pairs: list[tuple[int, int]] | None = None,
) -> PrintedGains:
    """The printed L_i in every basis variant; the printed N_1, N_2 in every pair of variants of the two
    unobservable bases (or the `pairs` of variant indices given), N_3 designed for each (the printed one
    has the wrong shape)."""
    decs = decompositions(agents, rtol)
    l_rad = []
    for A, C, d, L in zip(agents.A, agents.C, decs, PRINTED_L, strict=True):
        if C is None or not d.n_o:
            continue
        r = [spectral_radius(g.T @ A @ g - L @ (C @ g)) for g in basis_variants(d.gamma_o)]
        l_rad.append((min(r), max(r)))
    n_rad, t2_rad = [], []
    v1, v2 = basis_variants(decs[0].gamma_obar), basis_variants(decs[1].gamma_obar)
    for i, j in pairs if pairs is not None else itertools.product(range(len(v1)), range(len(v2))):
        ds = [
            _rebased(decs[0], agents.A[0], agents.Ca[0], v1[i]),
            _rebased(decs[1], agents.A[1], agents.Ca[1], v2[j]),
            decs[2],
        ]
        N, _ = design_n(ds, agents.P, fixed={0: PRINTED_N[0], 1: PRINTED_N[1]}, starts=starts)
        n_rad.append(spectral_radius(error_matrix(ds, N, agents.P)))
        t2_rad.append(spectral_radius(theorem2_matrix(ds, N, agents.P)))
    return PrintedGains(
        tuple(l_rad),
        (min(n_rad), max(n_rad)),
        (min(t2_rad), max(t2_rad)),
        PRINTED_N[2].shape,
        (decs[2].n_obar, 1),
    )


def _rebased(d: Decomposition, A: FloatArray, Ca: FloatArray, gobar: FloatArray) -> Decomposition:
    return replace(d, gamma_obar=gobar, A_obar=gobar.T @ A @ gobar, A_tilde=gobar.T @ A @ d.gamma_o, Ca_obar=Ca @ gobar)


@dataclass(frozen=True)
class ExampleReport:
    singular_values: tuple[tuple[float, ...], ...]
    ranks: tuple[int, ...]
    decomposition_residual: tuple[float, ...]
    open_loop_radius: tuple[float, ...]
    l_radius: tuple[float, ...]
    n_objective: str
    error_radius: float  # eq. (26)
    error_norm: float  # its 2-norm (sigma of the bound)
    theorem2_radius: float  # the printed form with our gains
    full_radius: float  # the exact closed loop of (10)-(13)
    gains: Gains


def example_report(seed: int = 0, starts: int = 12) -> ExampleReport:
    agents = PAPER_AGENTS
    decs = decompositions(agents)
    gains, how = designed_gains(agents, decs, seed=seed, starts=starts)
    M = error_matrix(decs, gains.N, agents.P)
    return ExampleReport(
        tuple(tuple(float(v) for v in d.singular_values) for d in decs),
        tuple(d.n_o for d in decs),
        tuple(d.residual for d in decs),
        tuple(spectral_radius(A) for A in agents.A),
        tuple(spectral_radius(d.A_o - L @ d.C_o) if d.n_o else 0.0 for d, L in zip(decs, gains.L, strict=True)),
        how,
        spectral_radius(M),
        float(np.linalg.norm(M, 2)),
        spectral_radius(theorem2_matrix(decs, gains.N, agents.P)),
        spectral_radius(full_error_matrix(agents, decs, gains)),
        gains,
    )
