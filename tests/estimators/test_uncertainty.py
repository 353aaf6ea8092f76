"""Base-parameter standard deviations vs the textbook formula computed independently in numpy."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from idkit import registry
from idkit.data.scenarios import simulate
from idkit.estimators.linear.uncertainty import base_uncertainty
from idkit.problem import Problem


def textbook(W: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """OLS by the normal equations: beta, sqrt(diag(s² (WᵀW)⁻¹)), s² = RSS / (M − B)."""
    beta = np.linalg.solve(W.T @ W, W.T @ tau)
    residual = tau - W @ beta
    s2 = residual @ residual / (W.shape[0] - W.shape[1])
    return beta, np.sqrt(np.diag(s2 * np.linalg.inv(W.T @ W))), s2


def test_matches_the_normal_equations_on_badly_scaled_columns():
    rng = np.random.default_rng(0)
    W = rng.normal(size=(200, 5)) * np.array([1e-3, 1.0, 10.0, 1e2, 0.5])
    tau = W @ rng.normal(size=5) + 0.1 * rng.normal(size=200)
    beta, std, s2 = textbook(W, tau)
    result = base_uncertainty(torch.as_tensor(W), torch.as_tensor(tau), torch.as_tensor(beta), list("abcde"))
    np.testing.assert_allclose(result.std.numpy(), std, rtol=1e-9)
    np.testing.assert_allclose(result.relative_pct.numpy(), 100 * std / np.abs(beta), rtol=1e-9)
    assert result.sigma2 == pytest.approx(s2, rel=1e-12)
    assert (result.rank, result.dof, result.unidentifiable) == (5, 195, ())
    scaled = W / np.linalg.norm(W, axis=0)
    assert result.cond == pytest.approx(np.linalg.cond(scaled), rel=1e-9)


def test_rank_deficiency_names_the_combination_and_gives_infinite_std():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(2, 100))
    W = np.c_[a, b, a + 2 * b, rng.normal(size=100)]  # column c = a + 2 b
    tau = W[:, [0, 1, 3]] @ np.array([1.0, 2.0, 3.0])
    alpha = np.array([1.0, 2.0, 0.0, 3.0])
    result = base_uncertainty(
        torch.as_tensor(W), torch.as_tensor(tau), torch.as_tensor(alpha), ["a", "b", "c", "d"]
    )
    assert result.rank == 3
    assert np.isinf(result.std.numpy()[:3]).all() and np.isfinite(result.std.numpy()[3])
    (combination,) = result.unidentifiable
    assert all(name in combination for name in ("*a", "*b", "*c")) and "*d" not in combination


def test_ls_reports_the_uncertainty_of_its_fit():
    robot = registry.create("robot", "cylindrical")
    samples = simulate(robot, "torque_noise", seed=0, n_samples=40)
    problem = Problem(robot, samples)
    estimate = registry.create("estimator", "ls").fit(problem)
    W = problem.robot.regressor(samples.q, samples.qd, samples.qdd).reshape(-1, 4).numpy()
    beta, std, _ = textbook(W, samples.tau.reshape(-1).numpy())
    reported = estimate.details["uncertainty"]
    np.testing.assert_allclose(list(estimate.base_params.values()), beta, rtol=1e-8)
    np.testing.assert_allclose(list(reported["std"].values()), std, rtol=1e-8)
    assert reported["rank"] == 4 and reported["unidentifiable"] == []
