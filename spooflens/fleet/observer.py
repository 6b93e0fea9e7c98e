"""Seed 004's distributed secure state observer (eqs. 3-13) with the corrected error dynamics (eq. 26).

In depth: docs/methods/fleet.md."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, optimize, signal

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Decomposition:
    """One agent's observability decomposition with respect to its secure output."""

    gamma_o: FloatArray  # (q, r) orthonormal basis of the observable subspace
    gamma_obar: FloatArray  # (q, q - r) orthonormal basis of the unobservable subspace
    A_o: FloatArray
    A_obar: FloatArray
    A_tilde: FloatArray  # coupling of the observable part into the unobservable one
    C_o: FloatArray
    Ca_o: FloatArray
    Ca_obar: FloatArray
    singular_values: FloatArray  # of the observability matrix (empty without a secure output)
    residual: float  # ||Gamma_o^T A Gamma_obar||: zero for an exact decomposition

    @property
    def n_o(self) -> int:
        return int(self.gamma_o.shape[1])

    @property
    def n_obar(self) -> int:
        return int(self.gamma_obar.shape[1])

    @property
    def gamma(self) -> FloatArray:
        """Gamma_i = [Gamma^obar^T; Gamma^o^T]: xi = Gamma x."""
        out: FloatArray = np.vstack([self.gamma_obar.T, self.gamma_o.T])
        return out


def observability_matrix(A: FloatArray, C: FloatArray) -> FloatArray:
    q = A.shape[0]
    blocks, M = [], np.asarray(C, dtype=float)
    for _ in range(q):
        blocks.append(M)
        M = M @ A
    return np.vstack(blocks)


def decompose(A: FloatArray, C: FloatArray | None, Ca: FloatArray, rtol: float = 1e-2) -> Decomposition:
    """Observability decomposition of (A, C): the observable subspace is the row space of the
    observability matrix, its rank the number of singular values above `rtol` times the largest (the
    paper's matrices are rounded to three decimals, so the small singular values are 1e-3, not 0)."""
    A = np.asarray(A, dtype=float)
    Ca = np.atleast_2d(np.asarray(Ca, dtype=float))
    q = A.shape[0]
    if C is None or np.size(C) == 0:
        go, gobar, sv = np.zeros((q, 0)), np.eye(q), np.zeros(0)
    else:
        C = np.atleast_2d(np.asarray(C, dtype=float))
        _, sv, vt = np.linalg.svd(observability_matrix(A, C))
        r = int(np.sum(sv > rtol * sv[0]))
        go, gobar = vt[:r].T, vt[r:].T
    Cs = np.zeros((0, q)) if C is None or np.size(C) == 0 else np.atleast_2d(np.asarray(C, dtype=float))
    return Decomposition(
        go,
        gobar,
        go.T @ A @ go,
        gobar.T @ A @ gobar,
        gobar.T @ A @ go,
        Cs @ go,
        Ca @ go,
        Ca @ gobar,
        sv,
        float(np.linalg.norm(go.T @ A @ gobar)) if go.size and gobar.size else 0.0,
    )


def place_observer_gain(A_o: FloatArray, C_o: FloatArray, poles: Sequence[float]) -> FloatArray:
    """L with eig(A_o - L C_o) = poles (pole placement on the dual system)."""
    res = signal.place_poles(A_o.T, C_o.T, np.asarray(poles, dtype=float))
    out: FloatArray = res.gain_matrix.T
    return out


def spectral_radius(M: FloatArray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(M)))) if M.size else 0.0


def upsilon(P: FloatArray, s: int) -> FloatArray:
    """Upsilon_s = (P - I) kron I_s."""
    weights = np.asarray(P, dtype=float)
    out: FloatArray = np.kron(weights - np.eye(len(weights)), np.eye(s)).astype(float)
    return out


def error_matrix(decs: Sequence[Decomposition], N: Sequence[FloatArray], P: FloatArray) -> FloatArray:
    """Eq. (26): A^obar + N (P - I kron I_s) C^{a,obar}, block-diagonal A, N, C over the agents."""
    s = decs[0].Ca_obar.shape[0]
    Ab = linalg.block_diag(*[d.A_obar for d in decs])
    Nb = linalg.block_diag(*[np.reshape(n, (d.n_obar, s)) for d, n in zip(decs, N, strict=True)])
    Cb = linalg.block_diag(*[d.Ca_obar for d in decs])
    out: FloatArray = Ab + Nb @ upsilon(P, s) @ Cb
    return out


def theorem2_matrix(decs: Sequence[Decomposition], N: Sequence[FloatArray], P: FloatArray) -> FloatArray:
    """Theorem 2 as printed: A^obar + N (I - P kron I) C^{a,obar} (the sign is wrong; for comparison)."""
    s = decs[0].Ca_obar.shape[0]
    Ab = linalg.block_diag(*[d.A_obar for d in decs])
    Nb = linalg.block_diag(*[np.reshape(n, (d.n_obar, s)) for d, n in zip(decs, N, strict=True)])
    Cb = linalg.block_diag(*[d.Ca_obar for d in decs])
    out: FloatArray = Ab - Nb @ upsilon(P, s) @ Cb
    return out


@dataclass(frozen=True)
class Agents:
    """The multi-agent system of eqs. (3)-(5); C[i] None for an agent without a secure output."""

    A: tuple[FloatArray, ...]
    C: tuple[FloatArray | None, ...]
    Ca: tuple[FloatArray, ...]
    P: FloatArray  # consensus weights p_ij, rows sum to 1

    @property
    def s(self) -> int:
        return int(np.atleast_2d(self.Ca[0]).shape[0])


@dataclass(frozen=True)
class Gains:
    L: tuple[FloatArray, ...]  # (n_o, p) per agent; (0, 0) without a secure output
    N: tuple[FloatArray, ...]  # (n_obar, s) per agent


def full_error_matrix(agents: Agents, decs: Sequence[Decomposition], gains: Gains) -> FloatArray:
    """The exact error dynamics of (10)-(13) in x coordinates, stacked over agents (no decomposition
    approximation): e(k+1) = [diag(A_i - Gamma_i^o L_i C_i) + diag(Gamma_i^obar N_i) Upsilon_s C^a] e."""
    s = agents.s
    blocks = []
    for A, C, d, L in zip(agents.A, agents.C, decs, gains.L, strict=True):
        corr = d.gamma_o @ L @ np.atleast_2d(C) if C is not None and d.n_o else np.zeros_like(A)
        blocks.append(np.asarray(A, float) - corr)
    GN = linalg.block_diag(*[d.gamma_obar @ np.reshape(n, (d.n_obar, s)) for d, n in zip(decs, gains.N, strict=True)])
    Ca = linalg.block_diag(*[np.atleast_2d(c) for c in agents.Ca])
    out: FloatArray = linalg.block_diag(*blocks) + GN @ upsilon(agents.P, s) @ Ca
    return out


def design_n(
    decs: Sequence[Decomposition],
    P: FloatArray,
    fixed: dict[int, FloatArray] | None = None,
    seed: int = 0,
    starts: int = 12,
) -> tuple[tuple[FloatArray, ...], str]:
    """N = diag(N_i) for eq. (26); agents in `fixed` keep the given N_i. Returns (N, how it was found).

    First the 2-norm is minimised (convex in N: an affine map inside a norm, so one start finds the
    optimum); below 1, the paper's bound applies. Otherwise the spectral radius is minimised (not convex:
    `starts` seeded random starts, each first on the smooth ||M^16||_F^(1/16), which bounds it, then on the
    radius itself); convergence then holds without the paper's bound.
    """
    fixed = fixed or {}
    s = decs[0].Ca_obar.shape[0]
    free = [i for i, d in enumerate(decs) if i not in fixed and d.n_obar]
    sizes = [decs[i].n_obar * s for i in free]

    def unpack(v: FloatArray) -> list[FloatArray]:
        out = [
            np.asarray(fixed.get(i, np.zeros((d.n_obar, s))), float).reshape(d.n_obar, s) for i, d in enumerate(decs)
        ]
        pos = 0
        for i, n in zip(free, sizes, strict=True):
            out[i] = v[pos : pos + n].reshape(decs[i].n_obar, s)
            pos += n
        return out

    def matrix(v: FloatArray) -> FloatArray:
        return error_matrix(decs, unpack(v), P)

    if not sizes:
        return tuple(unpack(np.zeros(0))), "none free"

    def two_norm(v: FloatArray) -> float:
        return float(np.linalg.norm(matrix(v), 2))

    def power_norm(v: FloatArray) -> float:  # a smooth stand-in for the spectral radius, to start from
        return float(np.linalg.norm(np.linalg.matrix_power(matrix(v), 16), "fro") ** (1.0 / 16.0))

    def radius(v: FloatArray) -> float:
        return float(spectral_radius(matrix(v)))

    r = optimize.minimize(
        two_norm, np.zeros(sum(sizes)), method="Nelder-Mead", options={"maxiter": 4000, "xatol": 1e-9, "fatol": 1e-12}
    )
    if r.fun < 1.0:
        return tuple(unpack(r.x)), "minimum 2-norm"
    rng = np.random.default_rng(seed)
    best: tuple[float, FloatArray] = (np.inf, np.asarray(r.x, dtype=np.float64))
    for _ in range(starts):
        start = optimize.minimize(
            power_norm, rng.normal(0.0, 2.0, sum(sizes)), method="Nelder-Mead", options={"maxiter": 1500}
        ).x
        r = optimize.minimize(radius, start, method="Nelder-Mead", options={"maxiter": 1500})
        if r.fun < best[0]:
            best = (float(r.fun), np.asarray(r.x, dtype=np.float64))
    return tuple(unpack(best[1])), "minimum spectral radius"


def lyapunov_certificate(M: FloatArray) -> tuple[FloatArray, float]:
    """Psi solving M^T Psi M - Psi = -I, and the smallest eigenvalue of [[Psi, Psi M], [M^T Psi, Psi]]
    (positive: the corrected matrix inequality holds, so M is Schur stable)."""
    Psi = np.asarray(linalg.solve_discrete_lyapunov(M.T, np.eye(len(M))), dtype=np.float64)
    Psi = 0.5 * (Psi + Psi.T)
    lmi = np.block([[Psi, Psi @ M], [M.T @ Psi, Psi]])
    return Psi, float(np.min(np.linalg.eigvalsh(0.5 * (lmi + lmi.T))))


def error_bound(decs: Sequence[Decomposition], N: Sequence[FloatArray], P: FloatArray, eps: float) -> float:
    """Theorem 2's bound varpi eps / (1 - sigma), varpi = ||Gamma|| ||N Upsilon_p||, sigma the 2-norm of
    the eq. (26) matrix; inf when sigma >= 1 (the bound does not apply)."""
    s = decs[0].Ca_obar.shape[0]
    sigma = float(np.linalg.norm(error_matrix(decs, N, P), 2))
    if sigma >= 1.0:
        return float("inf")
    Nb = linalg.block_diag(*[np.reshape(n, (d.n_obar, s)) for d, n in zip(decs, N, strict=True)])
    gamma = linalg.block_diag(*[d.gamma for d in decs])
    varpi = float(np.linalg.norm(gamma, 2) * np.linalg.norm(Nb @ upsilon(P, s), 2))
    return varpi * eps / (1.0 - sigma)


@dataclass(frozen=True)
class ObserverRun:
    k: NDArray[np.int64]
    x: FloatArray  # (K, n_agents, q)
    x_hat: FloatArray
    a_hat: FloatArray  # (K, n_agents, s) final attack estimates (11)
    a_tilde: FloatArray  # (K, n_agents, s) intermediate attack estimates (10)
    a: FloatArray  # (K, s)

    @property
    def e_x(self) -> FloatArray:
        out: FloatArray = self.x - self.x_hat
        return out

    @property
    def e_a(self) -> FloatArray:
        out: FloatArray = self.a[:, None, :] - self.a_hat
        return out


def simulate_observer(
    agents: Agents,
    decs: Sequence[Decomposition],
    gains: Gains,
    attack: Callable[[int], FloatArray],
    steps: int,
    x0: FloatArray,
    x_hat0: FloatArray | None = None,
    eps: Callable[[int, int], FloatArray] | None = None,
) -> ObserverRun:
    """Eqs. (3)-(5) and (10)-(13) literally, u = 0 (B and u are not printed; they cancel in the error)."""
    n, q, s = len(agents.A), agents.A[0].shape[0], agents.s
    x = np.asarray(x0, dtype=float).reshape(n, q).copy()
    xh = np.zeros((n, q)) if x_hat0 is None else np.asarray(x_hat0, dtype=float).reshape(n, q).copy()
    xs, xhs, ahs, ats, As = [], [], [], [], []
    for k in range(steps):
        a = np.atleast_1d(attack(k)).astype(float)
        ya = [np.atleast_2d(agents.Ca[i]) @ x[i] + a + (eps(k, i) if eps else 0.0) for i in range(n)]
        a_tilde = np.array([ya[i] - np.atleast_2d(agents.Ca[i]) @ xh[i] for i in range(n)])  # (10)
        a_hat = agents.P @ a_tilde  # (11)
        xs.append(x.copy())
        xhs.append(xh.copy())
        ahs.append(a_hat.copy())
        ats.append(a_tilde.copy())
        As.append(a)
        new_x = np.array([agents.A[i] @ x[i] for i in range(n)])
        new_xh = np.empty_like(xh)
        for i, (d, L, N) in enumerate(zip(decs, gains.L, gains.N, strict=True)):
            step = agents.A[i] @ xh[i]
            C = agents.C[i]
            if C is not None and d.n_o:
                y, y_hat = np.atleast_2d(C) @ x[i], np.atleast_2d(C) @ xh[i]
                step = step + d.gamma_o @ (L @ (y - y_hat))
            ya_hat = np.atleast_2d(agents.Ca[i]) @ xh[i] + a_hat[i]  # (13)
            step = step + d.gamma_obar @ (np.reshape(N, (d.n_obar, s)) @ (ya[i] - ya_hat))  # (12)
            new_xh[i] = step
        x, xh = new_x, new_xh
    return ObserverRun(np.arange(steps), np.array(xs), np.array(xhs), np.array(ahs), np.array(ats), np.array(As))
