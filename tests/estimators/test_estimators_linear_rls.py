"""RLS: the closed-form secular-equation solver against cvxpy and against first principles.

Independent references: a plain cvxpy formulation written here (``cp.norm`` objective, not eq. 18),
the gradient of ``f(α) = ‖Wα − τ‖ + ρ‖[α;1]‖`` evaluated with numpy (zero at the unique minimiser
of this convex function), and ``np.linalg.lstsq``/``np.linalg.svd`` for ρ = 0 and the TLS ρ.
"""

from __future__ import annotations

import math
import warnings

import cvxpy as cp
import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.data.scenarios import simulate
from idkit.estimators.linear import robust_ls
from idkit.estimators.linear.least_squares import LeastSquares, TotalLeastSquares
from idkit.estimators.linear.observation import IdentificationError, IdentificationWarning, linear_system
from idkit.estimators.linear.robust_ls import (
    RobustLeastSquares,
    newton_polish,
    rls_closed_form,
    rls_cvxpy,
    secular_root,
)
from idkit.problem import Problem


def objective(W: np.ndarray, tau: np.ndarray, alpha: np.ndarray, rho: float) -> float:
    return float(np.linalg.norm(W @ alpha - tau) + rho * math.sqrt(1.0 + alpha @ alpha))


def gradient(W: np.ndarray, tau: np.ndarray, alpha: np.ndarray, rho: float) -> np.ndarray:
    r = W @ alpha - tau
    return W.T @ r / np.linalg.norm(r) + rho * alpha / math.sqrt(1.0 + alpha @ alpha)


def plain_cvxpy(W: np.ndarray, tau: np.ndarray, rho: float) -> np.ndarray:
    alpha = cp.Variable(W.shape[1])
    cp.Problem(cp.Minimize(cp.norm(W @ alpha - tau) + rho * cp.norm(cp.hstack([alpha, np.ones(1)])))).solve(
        solver="CLARABEL"
    )
    return alpha.value


def closed_form(W: np.ndarray, tau: np.ndarray, rho: float) -> np.ndarray:
    return rls_closed_form(torch.from_numpy(W), torch.from_numpy(tau), rho).alpha.numpy()


def random_problem(seed: int, m_extra: int, b: int, log_noise: float, log_rho: float):
    """W with column scales over two decades, tau = W a + noise, rho relative to sigma_min(W)."""
    rng = np.random.default_rng(seed)
    W = rng.standard_normal((b + m_extra, b)) * 10 ** rng.uniform(-1, 1, b)
    clean = W @ rng.standard_normal(b)
    tau = clean + 10**log_noise * np.linalg.norm(clean) / math.sqrt(len(clean)) * rng.standard_normal(
        len(clean)
    )
    rho = float(np.linalg.svd(W, compute_uv=False)[-1] * 10**log_rho)
    return W, tau, rho


problems = st.builds(
    random_problem,
    seed=st.integers(0, 2**31 - 1),
    m_extra=st.integers(1, 35),
    b=st.integers(1, 6),
    log_noise=st.floats(-4, 0),
    log_rho=st.floats(-4, 1.5),
)


@settings(max_examples=40, deadline=None)
@given(problem=problems)
def test_closed_form_is_stationary_and_agrees_with_cvxpy(problem):
    W, tau, rho = problem
    alpha = closed_form(W, tau, rho)
    sigma_max = np.linalg.norm(W, 2)
    # first principles: the gradient of the convex objective vanishes (r ≠ 0 here: M > B, noise)
    assert np.linalg.norm(gradient(W, tau, alpha, rho)) <= 1e-9 * (sigma_max + rho)
    # the estimator's cvxpy path (eq. 18 + Newton polish) agrees to 1e-6 relative
    reference = rls_cvxpy(torch.from_numpy(W), torch.from_numpy(tau), rho)[0]
    np.testing.assert_allclose(alpha, reference, rtol=0, atol=1e-6 * np.linalg.norm(alpha))
    # an independent plain-norm SOCP, unpolished: never a better objective, close estimate
    plain = plain_cvxpy(W, tau, rho)
    f = objective(W, tau, alpha, rho)
    assert f <= objective(W, tau, plain, rho) + 1e-12 * f
    np.testing.assert_allclose(alpha, plain, rtol=0, atol=1e-2 * np.linalg.norm(alpha))  # IPM: ~1e-4


@pytest.mark.parametrize("scenario", ["state_noise", "torque_noise", "all_noise", "outliers"])
@pytest.mark.parametrize("relative", [False, True])
def test_closed_form_and_cvxpy_agree_on_scenarios(cylindrical, scenario, relative):
    for seed in range(3):
        problem = Problem(cylindrical, simulate(cylindrical, scenario, seed=seed))
        fast = RobustLeastSquares(relative=relative).fit(problem)
        ref = RobustLeastSquares(relative=relative, solver="cvxpy").fit(problem)
        a, b = (np.array(list(e.base_params.values())) for e in (fast, ref))
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-6 * np.linalg.norm(a))
        assert fast.details["rho"] == ref.details["rho"] > 0
        assert fast.estimator == ref.estimator == ("RLS-rel" if relative else "RLS")
        # raw interior point (no polish) is within its own ~1e-5 accuracy, never better
        raw = RobustLeastSquares(relative=relative, solver="cvxpy", polish=False).fit(problem)
        c = np.array(list(raw.base_params.values()))
        np.testing.assert_allclose(a, c, rtol=0, atol=1e-3 * np.linalg.norm(a))
        assert fast.details["criterion_value"] <= raw.details["criterion_value"] * (1 + 1e-12)


def test_rho_defaults_to_the_tls_rho(cylindrical):
    problem = Problem(cylindrical, simulate(cylindrical, "all_noise", seed=4))
    system = linear_system(problem)
    sigma = np.linalg.svd(np.column_stack([system.W.numpy(), system.tau.numpy()]), compute_uv=False)[-1]
    estimate = RobustLeastSquares().fit(problem)
    assert estimate.details["rho"] == pytest.approx(sigma, rel=1e-10)
    assert estimate.details["rho_source"] == "tls (eq. 14)"
    with warnings.catch_warnings():  # whether a draw's TLS is nearly degenerate depends on the draw
        warnings.simplefilter("ignore", IdentificationWarning)
        tls = TotalLeastSquares().fit(problem)
    assert estimate.details["rho"] == pytest.approx(tls.details["rho"], rel=1e-12)
    with pytest.warns(IdentificationWarning, match="nearly degenerate"):
        TotalLeastSquares(max_cond=tls.details["tls_cond"] / 2).fit(problem)
    given_rho = RobustLeastSquares(rho=0.5).fit(problem)
    assert given_rho.details["rho"] == 0.5 and given_rho.details["rho_source"] == "given"


def test_rls_shrinks_and_its_objective_beats_ls_and_tls(cylindrical):
    for scenario in ("torque_noise", "all_noise", "outliers"):
        problem = Problem(cylindrical, simulate(cylindrical, scenario, seed=1))
        system = linear_system(problem)
        W, tau = system.W.numpy(), system.tau.numpy()
        rls = RobustLeastSquares().fit(problem)
        rho = rls.details["rho"]
        a_rls = np.array(list(rls.base_params.values()))
        assert rls.details["mu"] > 0
        for other in (LeastSquares(), TotalLeastSquares()):
            a = np.array(list(other.fit(problem).base_params.values()))
            assert objective(W, tau, a_rls, rho) < objective(W, tau, a, rho)
        # (WᵀW + μI)α = Wᵀτ with μ > 0 is a ridge solution: shorter than least squares
        assert np.linalg.norm(a_rls) < np.linalg.norm(np.linalg.lstsq(W, tau, rcond=None)[0])


# --- the secular equation's special cases -------------------------------------------------------


def test_rho_zero_is_least_squares():
    W, tau, _ = random_problem(0, 10, 4, -1, 0)
    np.testing.assert_allclose(closed_form(W, tau, 0.0), np.linalg.lstsq(W, tau, rcond=None)[0], rtol=1e-12)


def test_zero_residual_small_rho_keeps_least_squares():
    """β = 0 (τ in range(W)): α_LS is optimal iff g'(0⁺) = √(1+‖α_LS‖²) − ρ‖S⁻²b‖ ≥ 0."""
    s, b = [3.0, 1.0], [1.0, 2.0]  # ‖α_LS‖² = (1/3)² + 2² ; ‖S⁻² b‖² = (1/9)² + 2²
    threshold = math.sqrt(1 + 1 / 9 + 4) / math.sqrt(1 / 81 + 4)
    assert secular_root(s, b, 0.0, 0.999 * threshold) == (0.0, 0)
    mu, _ = secular_root(s, b, 0.0, 1.001 * threshold)
    assert mu > 0


@pytest.mark.parametrize("rho", [0.1, 5.0])
def test_zero_residual_square_system_matches_cvxpy(rho):
    """Square W: r = 0 is reachable, f has a kink there; compare objectives with the plain SOCP."""
    rng = np.random.default_rng(3)
    W = rng.standard_normal((4, 4)) + 3 * np.eye(4)
    tau = W @ rng.standard_normal(4)
    alpha = closed_form(W, tau, rho)
    plain = plain_cvxpy(W, tau, rho)
    f = objective(W, tau, alpha, rho)
    assert f <= objective(W, tau, plain, rho) + 1e-9 * f
    np.testing.assert_allclose(alpha, plain, atol=1e-5 * np.linalg.norm(alpha))


def test_tau_orthogonal_to_range_gives_zero():
    W = np.array([[1.0], [0.0]])
    tau = np.array([0.0, 2.0])
    solution = rls_closed_form(torch.from_numpy(W), torch.from_numpy(tau), 0.3)
    assert solution.alpha.tolist() == [0.0]
    assert solution.mu == pytest.approx(0.3 * 2.0)  # μ = ρ‖r‖/‖[α;1]‖ at α = 0


def test_huge_rho_gives_small_alpha_not_a_failure():
    W, tau, _ = random_problem(1, 20, 3, -2, 0)
    rho = 1e6 * np.linalg.norm(W, 2)
    solution = rls_closed_form(torch.from_numpy(W), torch.from_numpy(tau), rho)
    alpha = solution.alpha.numpy()
    assert 0 < np.linalg.norm(alpha) < 1e-5 * np.linalg.norm(np.linalg.lstsq(W, tau, rcond=None)[0])
    assert solution.mu == pytest.approx(rho * np.linalg.norm(tau), rel=1e-3)
    assert np.linalg.norm(gradient(W, tau, alpha, rho)) <= 1e-9 * rho


def test_newton_polish_does_not_move_the_optimum_and_fixes_a_perturbation():
    W, tau, rho = random_problem(2, 25, 4, -2, -1)
    alpha = closed_form(W, tau, rho)
    np.testing.assert_allclose(newton_polish(W, tau, rho, alpha), alpha, rtol=1e-13)
    rough = alpha * (1 + 1e-4)
    np.testing.assert_allclose(newton_polish(W, tau, rho, rough), alpha, rtol=1e-11)


# --- errors and warnings --------------------------------------------------------------------------


def test_bad_arguments():
    with pytest.raises(ValueError, match="unknown solver 'cvx'"):
        RobustLeastSquares(solver="cvx")
    with pytest.raises(ValueError, match="rho must be None or a finite number >= 0"):
        RobustLeastSquares(rho=-1.0)
    W = torch.eye(3, 2, dtype=torch.float64)
    with pytest.raises(ValueError, match="rho must be a finite number >= 0"):
        rls_closed_form(W, torch.ones(3, dtype=torch.float64), math.nan)
    with pytest.raises(IdentificationError, match="rank deficient and rho = 0"):
        rls_closed_form(torch.zeros(3, 2, dtype=torch.float64), torch.ones(3, dtype=torch.float64), 0.0)


def test_cvxpy_solver_failure_is_an_error(cylindrical):
    problem = Problem(cylindrical, simulate(cylindrical, "torque_noise"))
    with pytest.raises(IdentificationError, match="cvxpy solver failed"):
        RobustLeastSquares(solver="cvxpy", cvxpy_solver="OSQP").fit(problem)  # OSQP has no cones


def test_cvxpy_inaccurate_status_warns_and_is_recorded(cylindrical, monkeypatch):
    problem = Problem(cylindrical, simulate(cylindrical, "torque_noise"))
    real = robust_ls.rls_cvxpy

    def inaccurate(*args, **kwargs):
        values, _, used = real(*args, **kwargs)
        return values, "optimal_inaccurate", used

    monkeypatch.setattr(robust_ls, "rls_cvxpy", inaccurate)
    with pytest.warns(IdentificationWarning, match="optimal_inaccurate"):
        estimate = RobustLeastSquares(solver="cvxpy").fit(problem)
    assert estimate.details["status"] == "optimal_inaccurate"
    assert any("optimal_inaccurate" in w for w in estimate.details["warnings"])


def test_cvxpy_infeasible_status_is_an_error(monkeypatch):
    def infeasible(self, *args, **kwargs):
        return None

    monkeypatch.setattr(cp.Problem, "solve", infeasible)
    monkeypatch.setattr(cp.Problem, "status", property(lambda self: "infeasible"))
    W = torch.eye(3, 2, dtype=torch.float64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(IdentificationError, match="status 'infeasible'"):
            rls_cvxpy(W, torch.ones(3, dtype=torch.float64), 0.1)
