"""Seed 004's distributed secure state observer: decomposition, the corrected error dynamics (eq. 26)
against a literal simulation of eqs. (10)-(13), gains and their conditions, the printed gains."""

from __future__ import annotations

import numpy as np
import pytest

from spooflens.fleet import dsse_example as ex
from spooflens.fleet.observer import (
    Agents,
    Gains,
    decompose,
    error_bound,
    error_matrix,
    full_error_matrix,
    lyapunov_certificate,
    simulate_observer,
    spectral_radius,
    theorem2_matrix,
)


@pytest.fixture(scope="module")
def designed():
    decs = ex.decompositions()
    gains, how = ex.designed_gains(ex.PAPER_AGENTS, decs, starts=2)
    return decs, gains, how


def test_decomposition_of_the_printed_example():
    decs = ex.decompositions()
    assert [d.n_o for d in decs] == [2, 2, 0]  # UAV 3 has no secure output: its whole state is unobservable
    assert [d.n_obar for d in decs] == [2, 2, 4]
    sv1, sv2 = decs[0].singular_values, decs[1].singular_values
    assert sv1[:2] == pytest.approx([2.12, 0.361], abs=0.005) and max(sv1[2:]) < 2e-3
    assert sv2[:2] == pytest.approx([10.33, 0.577], abs=0.01) and max(sv2[2:]) < 1e-3
    for d in decs:
        G = d.gamma
        assert np.abs(G @ G.T - np.eye(4)).max() < 1e-12  # orthonormal, Gamma^-1 = Gamma^T
        assert d.residual < 5e-3  # the lower-left block of Gamma A Gamma^T: rounding of the printed A
    assert [spectral_radius(A) for A in ex.PAPER_AGENTS.A] == pytest.approx([0.862, 1.777, 1.476], abs=1e-3)


def test_designed_gains_meet_the_conditions(designed):
    decs, gains, _ = designed
    for d, L in zip(decs[:2], gains.L[:2], strict=True):
        assert spectral_radius(d.A_o - L @ d.C_o) == pytest.approx(0.3, abs=1e-9)  # poles placed at 0.2, 0.3
    assert gains.N[2].shape == (4, 1)  # N_3 is 4x1, not the printed 2x1
    M = error_matrix(decs, gains.N, ex.P)
    assert spectral_radius(M) < 1.0
    Psi, lmi_min = lyapunov_certificate(M)
    assert np.min(np.linalg.eigvalsh(Psi)) > 0 and lmi_min > 0  # the corrected matrix inequality holds
    assert spectral_radius(full_error_matrix(ex.PAPER_AGENTS, decs, gains)) < 1.0  # exact closed loop too
    assert spectral_radius(theorem2_matrix(decs, gains.N, ex.P)) > 1.0  # the printed sign would diverge


def test_literal_simulation_follows_the_exact_error_dynamics(designed):
    decs, gains, _ = designed
    rng = np.random.default_rng(1)
    x0 = rng.normal(0.0, 1.0, (3, 4))
    run = simulate_observer(ex.PAPER_AGENTS, decs, gains, ex.attack, 25, x0)
    M = full_error_matrix(ex.PAPER_AGENTS, decs, gains)
    e = x0.ravel().copy()
    for k in range(25):
        scale = max(1.0, float(np.abs(run.x[k]).max()))  # the unstable agents' states grow; compare relatively
        assert run.e_x[k].ravel() == pytest.approx(e, abs=1e-9 * scale)
        e = M @ e


def test_eq26_is_the_error_dynamics_and_theorem2_is_not(designed):
    decs, gains, _ = designed
    exact = ex.exact_agents(ex.PAPER_AGENTS, decs)
    decs_x = [decompose(A, C, Ca, ex.RANK_RTOL) for A, C, Ca in zip(exact.A, exact.C, exact.Ca, strict=True)]
    for d in decs_x:
        assert d.residual < 1e-12
    rng = np.random.default_rng(2)
    x0 = rng.normal(0.0, 1.0, (3, 4))
    e_obar0 = [rng.normal(0.0, 1.0, d.n_obar) for d in decs_x]
    # start with the observable errors at zero, so the unobservable ones evolve by eq. (26) alone
    x_hat0 = np.array([x0[i] - d.gamma_obar @ e_obar0[i] for i, d in enumerate(decs_x)])
    run = simulate_observer(exact, decs_x, gains, ex.attack, 20, x0, x_hat0)
    M26, Mt2 = error_matrix(decs_x, gains.N, ex.P), theorem2_matrix(decs_x, gains.N, ex.P)
    e26 = et2 = np.concatenate(e_obar0)
    miss = 0.0
    for k in range(20):
        sim = np.concatenate([d.gamma_obar.T @ run.e_x[k, i] for i, d in enumerate(decs_x)])
        # relative to the larger of the states and the errors (the unobservable errors of the unstable
        # agents outgrow the states: 5e7 against 2e5 by epoch 20, equal to 6e-15 of themselves)
        scale = max(1.0, float(np.abs(run.x[k]).max()), float(np.abs(e26).max()))
        assert sim == pytest.approx(e26, abs=1e-12 * scale)
        miss = max(miss, float(np.abs(sim - et2).max()))
        e26, et2 = M26 @ e26, Mt2 @ et2
    assert miss > 0.5


def test_errors_converge_and_the_attack_is_recovered(designed):
    decs, gains, _ = designed
    M = full_error_matrix(ex.PAPER_AGENTS, decs, gains)
    e0 = np.random.default_rng(3).normal(0.0, 1.0, 12)
    e = np.linalg.matrix_power(M, 300) @ e0
    assert np.linalg.norm(e) < 1e-6 * np.linalg.norm(e0)
    # the attack estimates' error is -(P kron I)(C^a e^x) without noise: it goes with e^x
    Ca = np.vstack([np.pad(c, ((0, 0), (4 * i, 8 - 4 * i))) for i, c in enumerate(ex.PAPER_AGENTS.Ca)])
    assert np.abs(ex.P @ Ca @ e).max() < 1e-6
    # a short literal run (the unstable agents' states grow as 1.78^k, so x - x^ loses digits after ~30
    # steps): the estimates close in on a(k) = sin(0.2k)
    run = simulate_observer(ex.PAPER_AGENTS, decs, gains, ex.attack, 25, np.ones((3, 4)))
    assert np.abs(run.e_a[-1]).max() < 0.1 * np.abs(run.e_a[0]).max()
    assert run.e_a[-1].ravel() == pytest.approx(-(ex.P @ Ca @ run.e_x[-1].ravel()), abs=1e-8)


def test_the_bound_holds_when_the_two_norm_is_below_one():
    # one-dimensional agents, both attacked outputs, no secure output: eq. (26) is then 2x2 and sigma < 1
    agents = Agents(
        (np.array([[0.5]]), np.array([[0.6]])),
        (None, None),
        (np.array([[1.0]]), np.array([[0.8]])),
        np.array([[0.5, 0.5], [0.5, 0.5]]),
    )
    decs = [decompose(A, C, Ca) for A, C, Ca in zip(agents.A, agents.C, agents.Ca, strict=True)]
    gains = Gains((np.zeros((0, 0)), np.zeros((0, 0))), (np.array([[0.3]]), np.array([[-0.2]])))
    sigma = np.linalg.norm(error_matrix(decs, gains.N, agents.P), 2)
    assert sigma < 1.0
    eps_bar = 0.1
    bound = error_bound(decs, gains.N, agents.P, eps_bar)
    rng = np.random.default_rng(4)
    noise = rng.uniform(-eps_bar / np.sqrt(2), eps_bar / np.sqrt(2), (2000, 2))
    run = simulate_observer(
        agents, decs, gains, ex.attack, 2000, np.zeros((2, 1)), eps=lambda k, i: noise[k, i : i + 1]
    )
    assert np.linalg.norm(run.e_x.reshape(2000, -1), axis=1).max() <= bound
    sigma_bad = Gains(gains.L, (np.array([[3.0]]), np.array([[3.0]])))
    assert error_bound(decs, sigma_bad.N, agents.P, eps_bar) == float("inf")


def test_printed_gains_depend_on_the_unprinted_basis():
    # `spooflens bench fleet` tries all 64 pairs of N bases (radius 0.56 to 2.1); two of them here
    rep = ex.evaluate_printed(starts=2, pairs=[(3, 5), (4, 4)])
    (l1_lo, l1_hi), (l2_lo, l2_hi) = rep.l_radius
    assert l1_lo == pytest.approx(0.38, abs=0.02) and l1_hi == pytest.approx(1.57, abs=0.02)
    assert l2_lo == pytest.approx(1.55, abs=0.05) and l2_hi == pytest.approx(5.7, abs=0.1)
    assert rep.n3_printed_shape == (2, 1) and rep.n3_needed_shape == (4, 1)
    lo, hi = rep.n_radius_with_designed_n3  # N_3 re-designed: the printed N_1, N_2 work in one basis only
    assert lo < 1.0 < hi
