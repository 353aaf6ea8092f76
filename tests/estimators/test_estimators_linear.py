"""LS and TLS (plain and relative), the observation matrix and the bad-system policy.

References are independent numpy formulations (``np.linalg.lstsq``, ``np.linalg.svd``, eq. 15 by
``np.linalg.solve``) and the costs of ``idkit.costs`` (f1, f9), never the estimators themselves.
"""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit import registry
from idkit.costs.paper import f1, f9
from idkit.data.scenarios import simulate
from idkit.estimators.linear.least_squares import LeastSquares, TotalLeastSquares, total_least_squares
from idkit.estimators.linear.observation import IdentificationError, IdentificationWarning, linear_system
from idkit.estimators.linear.robust_ls import RobustLeastSquares
from idkit.interfaces import Robot
from idkit.problem import Problem, Samples
from idkit.relative import RelativeFloorWarning

TRUE = np.array([5.0, 3.0, -0.5, 3.0])

ESTIMATORS = {
    "LS": lambda: LeastSquares(),
    "LS-rel": lambda: LeastSquares(relative=True),
    "TLS": lambda: TotalLeastSquares(),
    "TLS-rel": lambda: TotalLeastSquares(relative=True),
    "RLS": lambda: RobustLeastSquares(),
    "RLS-rel": lambda: RobustLeastSquares(relative=True),
    "RLS/cvxpy": lambda: RobustLeastSquares(solver="cvxpy"),
    "RLS-rel/cvxpy": lambda: RobustLeastSquares(relative=True, solver="cvxpy"),
}


def random_states(n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """States uniform within the paper's bounds (eq. 38), ``[n, 3]`` each."""
    g = torch.Generator().manual_seed(seed)

    def uniform(lo, hi):
        lo, hi = torch.tensor(lo, dtype=torch.float64), torch.tensor(hi, dtype=torch.float64)
        return lo + (hi - lo) * torch.rand(n, 3, generator=g, dtype=torch.float64)

    q = uniform((-math.pi, 0.0, 0.0), (math.pi, 1.0, 1.0))
    qd = uniform((-4.0, -2.0, -1.5), (4.0, 2.0, 1.5))
    qdd = uniform((-3.0, -2.0, -1.0), (3.0, 2.0, 1.0))
    return q, qd, qdd


def problem_from_states(robot, q, qd, qdd, noise: float = 0.0, seed: int = 0, **kwargs) -> Problem:
    tau = robot.inverse_dynamics(robot.nominal_params(), q, qd, qdd)
    if noise:
        g = torch.Generator().manual_seed(seed + 10_000)
        tau = tau * (1 + noise * (2 * torch.rand(tau.shape, generator=g, dtype=torch.float64) - 1))
    return Problem(robot, Samples(q, qd, qdd, tau), **kwargs)


def numpy_system(problem: Problem) -> tuple[np.ndarray, np.ndarray]:
    """W (eq. 8) and tau_s (eq. 9) assembled sample by sample, as the paper writes them."""
    s = problem.samples
    Y = problem.robot.regressor(s.q, s.qd, s.qdd).numpy()
    W = np.vstack([Y[i] for i in range(Y.shape[0])])
    tau = np.concatenate([s.tau[i].numpy() for i in range(Y.shape[0])])
    return W, tau


def numpy_relative(W: np.ndarray, tau: np.ndarray, n_joints: int, floor: float = 1e-3):
    """Eqs. (36)-(37) with idkit's near-zero policy: |tau| < floor x joint RMS becomes ±floor x RMS."""
    T = tau.reshape(-1, n_joints)
    limit = floor * np.sqrt((T**2).mean(axis=0))
    d = np.where(np.abs(T) < limit, np.where(T < 0, -1.0, 1.0) * limit, T).reshape(-1)
    return W / d[:, None], tau / d


def base_vector(estimate) -> np.ndarray:
    return np.array(list(estimate.base_params.values()))


# --- the observation matrix -------------------------------------------------------------------


def test_system_matches_paper_layout_and_dynamics(cylindrical):
    problem = problem_from_states(cylindrical, *random_states(7, 0))
    system = linear_system(problem)
    W, tau = numpy_system(problem)
    np.testing.assert_array_equal(system.W.numpy(), W)
    np.testing.assert_array_equal(system.tau.numpy(), tau)
    alpha = cylindrical.base_params(cylindrical.nominal_params()).numpy()
    np.testing.assert_allclose(W @ alpha, tau, rtol=0, atol=1e-12 * np.abs(tau).max())


def test_relative_system_is_eqs_36_37(cylindrical):
    problem = problem_from_states(cylindrical, *random_states(7, 1))
    W, tau = numpy_system(problem)
    system = linear_system(problem, relative=True)
    np.testing.assert_allclose(system.W.numpy(), W / tau[:, None], rtol=1e-15)
    np.testing.assert_allclose(system.tau.numpy(), np.ones_like(tau), rtol=1e-15)


def test_relative_system_floors_zero_torque_like_the_relative_costs(cylindrical):
    q, qd, qdd = random_states(6, 2)
    qd[0, 0] = qdd[0, 0] = 0.0  # sample 0: tau_1 = 0 exactly
    problem = problem_from_states(cylindrical, q, qd, qdd, noise=0.1, cost=f9())
    with pytest.warns(RelativeFloorWarning):
        estimate = LeastSquares(relative=True).fit(problem)
    assert any("RelativeFloorWarning" in w for w in estimate.details["warnings"])
    # LS-rel minimises exactly f9 = ||E_rel||_F under the shared near-zero policy
    assert estimate.cost == pytest.approx(estimate.details["criterion_value"], rel=1e-12)


@pytest.mark.parametrize(("relative", "cost"), [(False, f1), (True, f9)])
def test_ls_criterion_is_the_paper_cost(cylindrical, relative, cost):
    """LS minimises f1 = ||E||_F, LS-rel f9 = ||E_rel||_F: the costs agree with the criterion."""
    problem = Problem(cylindrical, simulate(cylindrical, "all_noise", seed=3), cost=cost())
    estimate = LeastSquares(relative=relative).fit(problem)
    assert estimate.cost == pytest.approx(estimate.details["criterion_value"], rel=1e-12)
    # and the estimate is a minimiser of that cost over the physical parameters
    best = torch.tensor(estimate.vector(), dtype=torch.float64)
    g = torch.Generator().manual_seed(0)
    perturbed = best * (1 + 1e-4 * torch.randn(64, 4, generator=g, dtype=torch.float64))
    assert bool((problem.evaluate(perturbed) > problem.evaluate(best)).all())


# --- noise-free recovery, every estimator -------------------------------------------------------


@pytest.mark.parametrize("name", list(ESTIMATORS))
def test_clean_data_recovers_true_parameters(cylindrical, name):
    for problem in (
        Problem(cylindrical, simulate(cylindrical, "clean")),
        problem_from_states(cylindrical, *random_states(10, 5)),
    ):
        estimate = ESTIMATORS[name]().fit(problem)
        assert estimate.estimator == name.split("/")[0]
        np.testing.assert_allclose(estimate.vector(), TRUE, rtol=1e-9, atol=0)
        assert list(estimate.params) == list(cylindrical.param_names)
        assert list(estimate.base_params) == list(cylindrical.base_param_names)


# --- LS and TLS against independent numpy ---------------------------------------------------------


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1), n=st.integers(2, 40), noise=st.floats(1e-4, 0.5), relative=st.booleans()
)
def test_ls_matches_numpy_lstsq(seed, n, noise, relative):
    from idkit.robots.cylindrical import CylindricalRobot

    robot = CylindricalRobot()
    problem = problem_from_states(robot, *random_states(n, seed), noise=noise, seed=seed)
    W, tau = numpy_system(problem)
    if relative:
        W, tau = numpy_relative(W, tau, 3)
    expected = np.linalg.lstsq(W, tau, rcond=None)[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentificationWarning)
        warnings.simplefilter("ignore", RelativeFloorWarning)
        got = base_vector(LeastSquares(relative=relative).fit(problem))
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())


def numpy_tls(W: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, float]:
    _, s, vt = np.linalg.svd(np.column_stack([W, tau]))
    v = vt[-1]
    return -v[:-1] / v[-1], s[-1]


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1), n=st.integers(2, 40), noise=st.floats(1e-4, 0.3), relative=st.booleans()
)
def test_tls_matches_numpy_svd_and_eq_15(seed, n, noise, relative):
    from idkit.robots.cylindrical import CylindricalRobot

    robot = CylindricalRobot()
    problem = problem_from_states(robot, *random_states(n, seed), noise=noise, seed=seed)
    W, tau = numpy_system(problem)
    if relative:
        W, tau = numpy_relative(W, tau, 3)
    expected, sigma = numpy_tls(W, tau)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentificationWarning)
        warnings.simplefilter("ignore", RelativeFloorWarning)
        estimate = TotalLeastSquares(relative=relative).fit(problem)
    got = base_vector(estimate)
    np.testing.assert_allclose(got, expected, rtol=1e-8)
    assert estimate.details["rho"] == pytest.approx(sigma, rel=1e-10, abs=1e-14 * np.linalg.norm(tau))
    # eq. (15): (WᵀW − σ²I)⁻¹ Wᵀτ — a solve with the squared condition number, whose forward error
    # is bounded by κ·eps (near-degenerate TLS draws reach κ ≈ 1e10), hence the scaled tolerance
    shifted = W.T @ W - sigma**2 * np.eye(W.shape[1])
    eq15 = np.linalg.solve(shifted, W.T @ tau)
    np.testing.assert_allclose(got, eq15, rtol=max(1e-6, 10 * np.linalg.cond(shifted) * np.finfo(float).eps))


def test_tls_perturbation_has_norm_rho_and_makes_the_system_consistent():
    """Eqs. (12)–(14): Δ = −σ u vᵀ, ‖Δ‖_F = ρ, and (W + ΔW) α = τ + Δτ exactly."""
    rng = np.random.default_rng(0)
    W = rng.standard_normal((20, 3))
    tau = W @ rng.standard_normal(3) + 0.1 * rng.standard_normal(20)
    sol = total_least_squares(torch.from_numpy(W), torch.from_numpy(tau))
    C = np.column_stack([W, tau])
    u, s, vt = np.linalg.svd(C, full_matrices=False)
    delta = -s[-1] * np.outer(u[:, -1], vt[-1])
    assert np.linalg.norm(delta) == pytest.approx(sol.rho, rel=1e-12)
    alpha = sol.alpha.numpy()
    np.testing.assert_allclose((W + delta[:, :3]) @ alpha, tau + delta[:, 3], atol=1e-12)


def test_tls_without_a_unique_solution_is_an_error():
    W = torch.tensor([[2.0, 0.0], [0.0, 1.0], [0.0, 0.0]], dtype=torch.float64)
    tau = torch.tensor([0.0, 0.0, 3.0], dtype=torch.float64)  # σ_min([W|τ]) = σ_min(W) = 1
    with pytest.raises(IdentificationError, match="no unique solution"):
        total_least_squares(W, tau)


# --- the estimate, the registry, dtypes -----------------------------------------------------------


def test_estimate_fields_and_json(cylindrical):
    problem = Problem(cylindrical, simulate(cylindrical, "torque_noise", seed=1))
    estimate = TotalLeastSquares(relative=True).fit(problem)
    assert estimate.estimator == "TLS-rel"
    assert estimate.cost == estimate.details["criterion_value"] == estimate.details["rho"]
    assert estimate.details["rank"] == 4 and estimate.details["cond"] > 1
    assert estimate.details["dtype"] == "float64" and estimate.details["device"] == "cpu"
    assert estimate.wall_time_s > 0
    back = type(estimate).from_json(estimate.to_json())
    assert back.params == estimate.params and back.details == json.loads(json.dumps(estimate.details))


def test_estimate_cost_is_the_problem_cost_when_given(cylindrical):
    problem = Problem(cylindrical, simulate(cylindrical, "outliers", seed=2), cost=f1())
    estimate = TotalLeastSquares().fit(problem)
    expected = float(problem.evaluate(torch.tensor(estimate.vector(), dtype=torch.float64)))
    assert estimate.cost == pytest.approx(expected, rel=1e-12)
    assert estimate.cost != pytest.approx(estimate.details["criterion_value"])


@pytest.mark.parametrize(
    ("name", "cls"), [("ls", LeastSquares), ("tls", TotalLeastSquares), ("rls", RobustLeastSquares)]
)
def test_registry_builds_the_estimators(name, cls):
    estimator = registry.create("estimator", name, relative=True)
    assert isinstance(estimator, cls) and estimator.relative is True


def test_float32_problem(cylindrical):
    problem = Problem(cylindrical, simulate(cylindrical, "clean"), dtype="float32")
    for make in (LeastSquares, TotalLeastSquares, RobustLeastSquares):
        estimate = make().fit(problem)
        assert estimate.details["dtype"] == "float32"
        np.testing.assert_allclose(estimate.vector(), TRUE, rtol=2e-4)


# --- the bad-system policy ------------------------------------------------------------------------


class NoRegressorRobot(Robot):
    joint_names = ("j",)
    param_names = ("m",)

    def bounds(self):
        return torch.zeros(1), torch.ones(1)

    def inverse_dynamics(self, params, q, qd, qdd):
        return params[..., None, :] * qdd


@pytest.mark.parametrize("make", [LeastSquares, TotalLeastSquares, RobustLeastSquares])
def test_robot_without_regressor_is_a_clear_error(make):
    samples = Samples(*(torch.ones(5, 1, dtype=torch.float64) for _ in range(4)))
    with pytest.raises(IdentificationError, match="NoRegressorRobot has no linear regressor"):
        make().fit(Problem(NoRegressorRobot(), samples))


def test_too_few_equations(cylindrical):
    problem = problem_from_states(cylindrical, *random_states(1, 0))
    with pytest.raises(IdentificationError, match="3 equations .* cannot identify 4"):
        LeastSquares().fit(problem)


@pytest.mark.parametrize("make", [LeastSquares, TotalLeastSquares, RobustLeastSquares])
def test_unexcited_parameters_are_named(cylindrical, make):
    q, qd, qdd = random_states(10, 3)
    qd[:, 0] = qdd[:, 0] = 0.0  # theta1 at rest: the inertia columns vanish
    with pytest.raises(IdentificationError, match=r"rank 2 < 4.*zero columns\): I\+m3\*s3z\^2, m3\*s3z"):
        make().fit(problem_from_states(cylindrical, q, qd, qdd))


def test_inseparable_parameters_are_named(cylindrical):
    q, qd, qdd = random_states(10, 4)
    q[:, 2] = qdd[:, 2] = 0.0  # d3 = 0 and never accelerated: m3 acts only through the lift, like m2
    with pytest.raises(IdentificationError, match=r"rank 3 < 4.*[+-]1\*m2 [+-]1\*m3") as info:
        LeastSquares().fit(problem_from_states(cylindrical, q, qd, qdd))
    assert "I+m3" not in str(info.value)


def test_ill_conditioned_system_warns_and_records(cylindrical):
    q, qd, qdd = random_states(10, 4)
    q[:, 2] *= 1e-9
    qdd[:, 2] *= 1e-9  # m2 and m3 barely separable
    problem = problem_from_states(cylindrical, q, qd, qdd)
    with pytest.warns(IdentificationWarning, match="ill-conditioned"):
        estimate = LeastSquares().fit(problem)
    assert estimate.details["cond"] > estimate.details["max_cond"]
    assert any("ill-conditioned" in w for w in estimate.details["warnings"])


def test_max_cond_option(cylindrical):
    problem = Problem(cylindrical, simulate(cylindrical, "clean"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        LeastSquares().fit(problem)  # the paper's trajectory is well conditioned
    with pytest.warns(IdentificationWarning):
        LeastSquares(max_cond=1.0).fit(problem)
