"""Base-parameter standard deviations against formulas computed independently in numpy, and the
long-run variance of an AR(1) mean in closed form."""

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


def driscoll_kraay(W: np.ndarray, tau: np.ndarray, joints: int, lags: int) -> tuple[np.ndarray, np.ndarray]:
    """beta and the Bartlett HAC standard deviations with scores summed over each sample's ``joints``
    rows, by the normal equations and a loop over lags (Newey & West 1987; Driscoll & Kraay 1998),
    each sample's residuals first multiplied by ``(1 − H_ii)⁻¹`` (the jackknife's leverage
    adjustment, ``H_ii = W_i (WᵀW)⁻¹ W_iᵀ``, by ``np.linalg.solve``)."""
    M, B = W.shape
    bread = np.linalg.inv(W.T @ W)
    beta = bread @ W.T @ tau
    residual = (tau - W @ beta).reshape(M // joints, joints)
    rows = W.reshape(M // joints, joints, B)
    adjusted = np.stack(
        [np.linalg.solve(np.eye(joints) - w @ bread @ w.T, e) for w, e in zip(rows, residual, strict=True)]
    )
    g = (rows * adjusted[..., None]).sum(1)
    meat = g.T @ g
    for lag in range(1, lags + 1):
        gamma = sum(np.outer(g[i], g[i + lag]) for i in range(len(g) - lag))
        meat += (1 - lag / (lags + 1)) * (gamma + gamma.T)
    return beta, np.sqrt(np.diag(bread @ meat @ bread))


def andrews_bandwidth(g: np.ndarray) -> int:
    """Andrews' (1991) AR(1) plug-in bandwidth of the Bartlett kernel for scores ``g[N, B]``."""
    rho = np.array([np.dot(c[:-1], c[1:]) / np.dot(c[:-1], c[:-1]) for c in g.T])
    s2 = np.array([np.mean((c[1:] - r * c[:-1]) ** 2) for c, r in zip(g.T, rho, strict=True)])
    a = np.sum(4 * rho**2 * s2**2 / ((1 - rho) ** 6 * (1 + rho) ** 2)) / np.sum(s2**2 / (1 - rho) ** 4)
    return int(np.ceil(1.1447 * (a * len(g)) ** (1 / 3)))


def ar1(rng: np.random.Generator, n: int, rho: float, shape: tuple[int, ...] = ()) -> np.ndarray:
    """``n`` steps of a stationary AR(1) with unit innovations (along the first axis)."""
    e = np.empty((n, *shape))
    e[0] = rng.normal(size=shape) / np.sqrt(1 - rho**2)
    for i in range(1, n):
        e[i] = rho * e[i - 1] + rng.normal(size=shape)
    return e


def test_matches_an_independent_hac_on_badly_scaled_grouped_rows():
    """300 samples of 3 joints, regressors and errors (of three scales) correlated in time: the
    sandwich equals the normal
    equations' Driscoll–Kraay estimate at the same bandwidth, and the bandwidth is Andrews' rule."""
    rng = np.random.default_rng(0)
    W = (1.0 + ar1(rng, 300, 0.9, (3, 5))).reshape(900, 5) * np.array([1e-3, 1.0, 10.0, 1e2, 0.5])
    noise = (ar1(rng, 300, 0.7, (3,)) * np.array([0.1, 1.0, 0.01])).reshape(-1)
    tau = W @ rng.normal(size=5) + noise
    beta, _, s2 = textbook(W, tau)
    result = base_uncertainty(
        torch.as_tensor(W), torch.as_tensor(tau), torch.as_tensor(beta), list("abcde"), joints=3
    )
    scaled = W / np.linalg.norm(W, axis=0)  # the bandwidth rule sees the equilibrated scores
    scores = (scaled * (tau - W @ beta)[:, None]).reshape(300, 3, 5).sum(1)
    assert result.bandwidth == andrews_bandwidth(scores) > 2
    _, std = driscoll_kraay(W, tau, 3, result.bandwidth)  # normal equations: 1e-8 of round-off here
    np.testing.assert_allclose(result.std.numpy(), std, rtol=1e-6)
    np.testing.assert_allclose(result.relative_pct.numpy(), 100 * std / np.abs(beta), rtol=1e-6)
    assert result.sigma2 == pytest.approx(s2, rel=1e-12)
    assert (result.rank, result.dof, result.unidentifiable) == (5, 895, ())
    assert result.cond == pytest.approx(np.linalg.cond(scaled), rel=1e-9)


def test_white_noise_of_equal_variance_gives_the_textbook_formula():
    """For independent errors of one variance the sandwich estimates what ``σ² (WᵀW)⁻¹`` does: a
    bandwidth of a few lags and every standard deviation within 10 % of the textbook one (the
    sandwich's own sampling error at 2000 rows)."""
    rng = np.random.default_rng(1)
    W = rng.normal(size=(2000, 4)) * np.array([1e-2, 1.0, 1e2, 3.0])
    tau = W @ rng.normal(size=4) + 0.1 * rng.normal(size=2000)
    beta, std, _ = textbook(W, tau)
    result = base_uncertainty(torch.as_tensor(W), torch.as_tensor(tau), torch.as_tensor(beta), list("abcd"))
    assert result.bandwidth <= 5
    np.testing.assert_allclose(result.std.numpy(), std, rtol=0.1)


@pytest.mark.parametrize("rho", [0.5, 0.9])
def test_the_mean_of_an_ar1_series_gets_its_long_run_variance(rho):
    """The mean of 20,000 steps of an AR(1) with unit innovations has variance ``1 / ((1 − ρ)² N)``;
    the textbook formula says ``1 / ((1 − ρ²) N)``, 1.7× / 4.4× too small in σ. The sandwich with
    Andrews' bandwidth comes within 15 % (Bartlett's kernel is biased low by ~1/L)."""
    rng = np.random.default_rng(2)
    n = 20_000
    tau = 3.0 + ar1(rng, n, rho)
    result = base_uncertainty(
        torch.ones(n, 1, dtype=torch.float64), torch.as_tensor(tau), torch.tensor([tau.mean()]), ["mean"]
    )
    assert float(result.std[0]) == pytest.approx(1 / ((1 - rho) * np.sqrt(n)), rel=0.15)


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
    reported = estimate.details["uncertainty"]
    beta, std = driscoll_kraay(W, samples.tau.reshape(-1).numpy(), robot.n_joints, reported["bandwidth"])
    np.testing.assert_allclose(list(estimate.base_params.values()), beta, rtol=1e-8)
    np.testing.assert_allclose(list(reported["std"].values()), std, rtol=1e-8)
    assert reported["rank"] == 4 and reported["unidentifiable"] == [] and reported["method"] == "hac"


def test_a_pulled_estimate_adds_its_distance_from_least_squares():
    """An estimate moved off least squares by δ (a prior's pull) reports δ and std = sqrt(std_data² + δ²),
    std_data being the sandwich of its own residuals."""
    rng = np.random.default_rng(3)
    W = rng.normal(size=(600, 3)) * np.array([1.0, 1e2, 1e-2])
    tau = W @ np.array([1.0, 0.01, 100.0]) + 0.1 * rng.normal(size=600)
    beta, _, _ = textbook(W, tau)
    shift = np.array([0.0, 1e-4, -3.0])
    args = (torch.as_tensor(W), torch.as_tensor(tau), torch.as_tensor(beta + shift), list("abc"))
    data = base_uncertainty(*args, joints=2)
    pulled = base_uncertainty(*args, joints=2, pulled=True)
    np.testing.assert_allclose(pulled.pull.numpy(), shift, atol=1e-9)
    np.testing.assert_allclose(pulled.std.numpy(), np.hypot(data.std.numpy(), shift), rtol=1e-9)
    assert pulled.to_details()["uncertainty"]["pull"]["c"] == pytest.approx(-3.0)
    assert "pull" not in data.to_details()["uncertainty"]
