"""Variable projection for the sigmoid friction shapes (``varpro``), on data simulated with the
friction Gaz et al. identified on a Panda (``GAZ_PANDA_FRICTION``).

References: numpy's ``lstsq`` for the projected residual, and ``scipy.optimize.least_squares`` on all
parameters at once for the minimiser (both minimise the same sum of squares).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch
from scipy.optimize import least_squares

from idkit.data.scenarios import simulate
from idkit.estimators.bounds import BoundWarning
from idkit.estimators.varpro import VariableProjection, _solve, projection
from idkit.problem import IdentificationError, Problem, Samples
from idkit.robots.drives import GAZ_PANDA_FRICTION, with_drive_values
from idkit.robots.inertia import min_pseudo_inertia_eigenvalues
from idkit.robots.urdf import URDFRobot
from tests.urdf_cases import TREE_URDF


def sigmoid_robot(urdf: str, **options) -> URDFRobot:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return URDFRobot(urdf, friction="sigmoid", offset=True, **options)


def gaz_truth(robot: URDFRobot) -> torch.Tensor:
    n = robot.n_joints
    values = {
        **GAZ_PANDA_FRICTION,
        "fv": [0.1 + 0.05 * j for j in range(n)],
        "offset": [0.2 - 0.05 * j for j in range(n)],
    }
    return with_drive_values(robot.param_names, robot.joint_names, robot.nominal_params(), values)


def phi_index(robot: URDFRobot, *keys: str) -> list[int]:
    return [robot.param_names.index(f"{j}.{k}") for k in keys for j in robot.joint_names]


def estimate_vector(robot: URDFRobot, estimate) -> torch.Tensor:
    return torch.tensor([estimate.params[name] for name in robot.param_names], dtype=torch.float64)


@pytest.fixture(scope="module")
def tree():
    robot = sigmoid_robot(TREE_URDF)
    truth = gaz_truth(robot)
    return robot, truth, simulate(robot, "clean", seed=0, n_samples=600, params=truth)


def test_the_projected_residual_is_the_least_squares_residual(tree):
    robot, _, samples = tree
    data = projection(robot, samples.q, samples.qd, samples.qdd, samples.tau)
    lower, upper = (bound[phi_index(robot, "phi2", "phi3")] for bound in robot.bounds())
    theta = lower + (upper - lower) * torch.rand(5, len(lower), generator=torch.Generator().manual_seed(0))
    for k in range(5):
        w = data.matrix(theta[k]).numpy()
        tau = data.tau.reshape(-1).numpy()  # rows in the order of the matrix's
        solution, *_ = np.linalg.lstsq(w, tau, rcond=None)
        expected = np.sum((tau - w @ solution) ** 2)
        np.testing.assert_allclose(float(data.residual(theta[k])), expected, rtol=1e-8)
    torch.testing.assert_close(data.residual(theta), torch.stack([data.residual(t) for t in theta]))


def test_varpro_recovers_the_shapes_of_noise_free_data(tree):
    robot, truth, samples = tree
    estimate = VariableProjection(particles=16, iterations=15).fit(Problem(robot, samples, seed=3))
    params = estimate_vector(robot, estimate)
    index = phi_index(robot, "phi1", "phi2", "phi3")
    np.testing.assert_allclose(params[index].numpy(), truth[index].numpy(), rtol=1e-6)
    assert estimate.details["rel_error_train"] < 1e-9
    assert estimate.details["shape"]["j1"] == {
        "phi2": pytest.approx(GAZ_PANDA_FRICTION["phi2"][0]),
        "phi3": pytest.approx(GAZ_PANDA_FRICTION["phi3"][0]),
    }
    again = VariableProjection(particles=16, iterations=15).fit(Problem(robot, samples, seed=3))
    assert again.params == estimate.params  # the seed fixes every number


def test_varpro_finds_the_least_squares_minimiser_of_noisy_data(tree):
    robot, truth, samples = tree
    generator = torch.Generator().manual_seed(1)
    rms = samples.tau.square().mean(0).sqrt()
    noisy = Samples(
        samples.q,
        samples.qd,
        samples.qdd,
        samples.tau + 0.01 * rms * torch.randn(samples.tau.shape, generator=generator, dtype=torch.float64),
    )
    params = estimate_vector(robot, VariableProjection().fit(Problem(robot, noisy)))
    # The same sum of squares minimised by scipy over all parameters, started at the truth.
    data = projection(robot, noisy.q, noisy.qd, noisy.qdd, noisy.tau)
    shapes = phi_index(robot, "phi2", "phi3")
    n = robot.n_joints

    def residual(x: np.ndarray) -> np.ndarray:
        w = data.matrix(torch.as_tensor(x[: 2 * n])).numpy()
        return w @ x[2 * n :] - data.tau.reshape(-1).numpy()

    alpha = robot.base_params(truth).numpy()
    x0 = np.concatenate([truth[shapes].numpy(), alpha[data.fixed + data.scaled]])
    reference = least_squares(residual, x0, x_scale="jac", xtol=1e-14, ftol=1e-14, gtol=1e-14).x
    np.testing.assert_allclose(params[shapes].numpy(), reference[: 2 * n], rtol=1e-5)


def test_refine_with_pcls_keeps_the_shape_and_is_physical(tree):
    robot, truth, samples = tree
    estimate = VariableProjection(particles=16, iterations=15, refine="pcls").fit(Problem(robot, samples))
    params = estimate_vector(robot, estimate)
    shapes = phi_index(robot, "phi2", "phi3")
    np.testing.assert_allclose(params[shapes].numpy(), truth[shapes].numpy(), rtol=1e-5)
    assert float(min_pseudo_inertia_eigenvalues(robot, params).min()) >= -1e-9
    assert (params[phi_index(robot, "phi1", "fv")] >= -1e-9).all()
    assert estimate.details["status"] == "optimal"


def test_varpro_refuses_a_robot_without_shapes():
    robot = URDFRobot("cylindrical", friction=True)
    samples = simulate(robot, "clean", n_samples=50)
    with pytest.raises(IdentificationError, match="varpro: robot URDFRobot has no nonlinear friction shapes"):
        VariableProjection().fit(Problem(robot, samples))


@pytest.mark.parametrize("weight", [-1.0, float("inf"), "often"])
def test_a_prior_weight_pcls_would_refuse_is_refused_before_the_search(weight):
    with pytest.raises(ValueError, match=r"varpro: prior_weight must be a finite number >= 0 or 'auto'"):
        VariableProjection(refine="pcls", prior_weight=weight)


@pytest.mark.kuka
def test_varpro_recovers_gaz_friction_on_the_kuka_arm(kuka_dir):
    robot = sigmoid_robot(str(kuka_dir / "kuka_lwr4.urdf"))
    truth = gaz_truth(robot)
    samples = simulate(robot, "clean", seed=0, n_samples=2000, params=truth)
    params = estimate_vector(robot, VariableProjection().fit(Problem(robot, samples)))
    index = phi_index(robot, "phi1", "phi2", "phi3")
    relative = ((params[index] - truth[index]).abs() / truth[index].abs()).max()
    assert relative < 1e-6  # the judged bound is 2 %


def _on_own_rows(values: torch.Tensor) -> torch.Tensor:
    """Per-joint columns ``values[n, N]`` as a dense ``[n·N, n]`` matrix, joint ``j``'s column on
    joint ``j``'s rows (the projection's joint-major row order)."""
    n, samples = values.shape
    dense = values.new_zeros(n, samples, n)
    for j in range(n):
        dense[j, :, j] = values[j]
    return dense.reshape(-1, n)


def _dense_kaufman(data, theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Kaufman's ``JᵀJ``, ``Jᵀr`` and ``‖r‖²`` formed the slow way: the whole ``W(θ)`` factored, the
    derivative columns built dense and projected off it."""
    n = data.qd.shape[0]
    w = data.matrix(theta)
    q = torch.linalg.qr(w).Q
    tau = data.tau.reshape(-1)
    amplitude = torch.linalg.lstsq(w, tau[:, None], driver="gelsd").solution[-n:, 0]
    steepness, shift = theta[:n, None], theta[n:, None]
    sigma, rest = torch.sigmoid(steepness * (data.qd + shift)), torch.sigmoid(steepness * shift)
    slope, slope_rest = sigma * (1 - sigma), rest * (1 - rest)
    d_steepness = (slope * (data.qd + shift) - slope_rest * shift) * amplitude[:, None]
    d_shift = (slope - slope_rest) * steepness * amplitude[:, None]
    d = torch.cat([_on_own_rows(d_steepness), _on_own_rows(d_shift)], 1)
    jacobian = -(d - q @ (q.T @ d))
    r = tau - q @ (q.T @ tau)
    return jacobian.T @ jacobian, jacobian.T @ r, r @ r


def test_the_linearisation_equals_kaufmans_jacobian_formed_densely(tree):
    robot, _, samples = tree
    data = projection(robot, samples.q, samples.qd, samples.qdd, samples.tau)
    lower, upper = (bound[phi_index(robot, "phi2", "phi3")] for bound in robot.bounds())
    generator = torch.Generator().manual_seed(4)
    shapes = lower + (upper - lower) * torch.rand(3, len(lower), generator=generator, dtype=torch.float64)
    for theta in shapes:
        normal, gradient, value = data.linearised(theta)
        dense_normal, dense_gradient, dense_value = _dense_kaufman(data, theta)
        scale = dense_normal.diagonal().sqrt()
        torch.testing.assert_close(normal / scale / scale[:, None], dense_normal / scale / scale[:, None])
        floor = 1e-9 * float(value.sqrt())  # Jᵀr at r ⊥ J's span: what is left is round-off
        torch.testing.assert_close(gradient / scale, dense_gradient / scale, rtol=1e-7, atol=floor)
        torch.testing.assert_close(value, dense_value, rtol=1e-9, atol=0)


def _residual_vector(data, theta: torch.Tensor) -> torch.Tensor:
    """``r(θ) = τ − W(θ) α*(θ)``, ``α*`` by numpy-independent LAPACK least squares on the whole ``W``."""
    w, tau = data.matrix(theta), data.tau.reshape(-1)
    return tau - w @ torch.linalg.lstsq(w, tau[:, None], driver="gelsd").solution[:, 0]


def test_the_gradient_is_the_derivative_of_the_projected_residual(tree):
    """Kaufman's ``Jᵀr`` is half the exact gradient of ``‖r(θ)‖²`` (the term it drops is orthogonal
    to ``r``): central differences of ``Projection.residual`` agree at random shapes."""
    robot, _, samples = tree
    data = projection(robot, samples.q, samples.qd, samples.qdd, samples.tau)
    lower, upper = (bound[phi_index(robot, "phi2", "phi3")] for bound in robot.bounds())
    generator = torch.Generator().manual_seed(5)
    for theta in lower + (upper - lower) * torch.rand(
        3, len(lower), generator=generator, dtype=torch.float64
    ):
        _, gradient, _ = data.linearised(theta)
        step = 1e-5 * (upper - lower)
        shifted = theta + torch.diag(step)  # one shape moved per row
        lowered = theta - torch.diag(step)
        differences = (data.residual(shifted) - data.residual(lowered)) / (2 * step)
        torch.testing.assert_close(
            2 * gradient, differences, rtol=1e-5, atol=1e-6 * float(differences.abs().max())
        )


def test_the_gauss_newton_matrix_is_the_jacobian_product_at_an_exact_fit(tree):
    """Where the model fits exactly (``r = 0``) Kaufman's ``J`` is the Jacobian of the residual
    vector: ``JᵀJ`` equals the product of its central-difference Jacobian, and Gauss–Newton steps
    from nearby shapes converge quadratically to the true one."""
    robot, truth, samples = tree
    data = projection(robot, samples.q, samples.qd, samples.qdd, samples.tau)
    shapes = phi_index(robot, "phi2", "phi3")
    lower, upper = (bound[shapes] for bound in robot.bounds())
    theta = truth[shapes]
    normal, _, value = data.linearised(theta)
    assert float(value) < 1e-16 * float(samples.tau.square().sum())
    step = 1e-6 * (upper - lower)
    columns = [
        (_residual_vector(data, theta + step[k] * unit) - _residual_vector(data, theta - step[k] * unit))
        / (2 * step[k])
        for k, unit in enumerate(torch.eye(len(theta), dtype=theta.dtype))
    ]
    jacobian = torch.stack(columns, 1)
    scale = normal.diagonal().sqrt()
    torch.testing.assert_close(
        normal / scale / scale[:, None], jacobian.T @ jacobian / scale / scale[:, None], rtol=1e-5, atol=1e-6
    )
    errors = []
    for offset in (1e-3, 1e-4):  # of the box widths, in alternating directions
        start = theta + offset * (upper - lower) * torch.linspace(-1, 1, len(theta), dtype=theta.dtype)
        normal, gradient, _ = data.linearised(start)
        landed = start - torch.linalg.solve(normal, gradient)
        errors.append(float(((landed - theta) / (upper - lower)).abs().max()))
    assert errors[1] < 1e-2 * 1e-4  # a hundredth of the start's offset
    assert errors[1] < errors[0] / 30  # and quadratic: a tenth of the offset leaves ~a hundredth


def test_the_assembled_qr_solve_equals_lstsq(tree):
    """The final solve reuses ``W_fixed``'s QR; it must give numpy's least squares."""
    robot, truth, samples = tree
    data = projection(robot, samples.q, samples.qd, samples.qdd, samples.tau)
    theta = truth[phi_index(robot, "phi2", "phi3")] * 1.3
    solved = _solve(data, theta)
    w = data.matrix(theta).numpy()
    expected, *_ = np.linalg.lstsq(w, data.tau.reshape(-1).numpy(), rcond=None)
    np.testing.assert_allclose(solved.alpha.numpy(), expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())


def noisy_tree(tree, level: float = 0.01, seed: int = 1) -> Samples:
    robot, _, samples = tree
    generator = torch.Generator().manual_seed(seed)
    rms = samples.tau.square().mean(0).sqrt()
    noise = level * rms * torch.randn(samples.tau.shape, generator=generator, dtype=torch.float64)
    return Samples(samples.q, samples.qd, samples.qdd, samples.tau + noise)


def test_the_uncertainty_is_the_sandwich_of_the_whole_jacobian(tree):
    """The std of every linear parameter and shape is the HAC sandwich of the Jacobian of
    ``τ = [W_fixed | S(θ)] α`` in ``(α, θ)`` — formed here densely by autograd, in an independent
    implementation of the sandwich — not the std at a fixed shape, which is smaller for ``φ1``."""
    from tests.estimators.test_uncertainty import driscoll_kraay

    robot, _, _ = tree
    noisy = noisy_tree(tree)
    estimate = VariableProjection().fit(Problem(robot, noisy))
    data = projection(robot, noisy.q, noisy.qd, noisy.qdd, noisy.tau)
    n, samples = data.qd.shape
    shapes = [estimate.params[robot.param_names[k]] for k in phi_index(robot, "phi2", "phi3")]
    linear = [estimate.base_params[robot.base_param_names[k]] for k in data.fixed + data.scaled]
    theta, alpha = (torch.tensor(v, dtype=torch.float64) for v in (shapes, linear))

    def model(x: torch.Tensor) -> torch.Tensor:
        return data.matrix(x[: 2 * n]) @ x[2 * n :]

    x = torch.cat([theta, alpha])
    jacobian = torch.autograd.functional.jacobian(model, x)  # [n·N, 2n + B], rows joint-major
    jacobian = jacobian.reshape(n, samples, -1).transpose(0, 1).reshape(n * samples, -1).numpy()
    measured = data.tau.T.reshape(-1).numpy()  # sample-major
    target = measured - model(x).reshape(n, samples).T.reshape(-1).numpy() + jacobian @ x.numpy()
    reported = estimate.details["uncertainty"]
    assert estimate.details["at_bound"] == {}
    _, std = driscoll_kraay(jacobian, target, n, reported["bandwidth"])
    names = [robot.param_names[k] for k in phi_index(robot, "phi2", "phi3")]
    names += [robot.base_param_names[k] for k in data.fixed + data.scaled]
    assert set(reported["std"]) == set(names)
    np.testing.assert_allclose([reported["std"][name] for name in names], std, rtol=1e-5)
    # at the found shape held fixed, phi1 would look better determined than it is
    fixed = driscoll_kraay(jacobian[:, 2 * n :], target - jacobian[:, : 2 * n] @ theta.numpy(), n, 1)[1]
    amplitudes = [names.index(f"{j}.phi1") - 2 * n for j in robot.joint_names]
    assert (std[2 * n :][amplitudes] > 1.2 * fixed[amplitudes]).any()


def test_a_shape_at_its_bound_is_flagged_said_and_held_out_of_the_uncertainty(tree):
    """The box of phi2 below two joints' true steepness (9.07 and 10.1): the search stops at 8 there."""
    _, truth, samples = tree
    robot = sigmoid_robot(TREE_URDF, steepness_range=(1.0, 8.0), sigmoid_steepness=5.0)
    with pytest.warns(
        BoundWarning, match=r"^VarPro: \d parameter\(s\) ended at a bound .*j2\.phi2 at its upper"
    ):
        estimate = VariableProjection().fit(Problem(robot, samples))
    assert {"j2.phi2": "upper", "j3.phi2": "upper"}.items() <= estimate.details["at_bound"].items()
    assert estimate.params["j2.phi2"] == pytest.approx(8.0)
    assert not set(estimate.details["at_bound"]) & set(estimate.details["uncertainty"]["std"])
    assert "j1.phi2" in estimate.details["uncertainty"]["std"]


def test_the_search_is_sized_before_it_starts(tree):
    with pytest.raises(
        ValueError, match=r"^varpro: particles × iterations = 16 × 1000000000 = 1\.6e\+10 cost"
    ):
        VariableProjection(iterations=10**9)
    said = r"^varpro option iterations must be an integer >= 1, got 1000000000\.0$"
    with pytest.raises(ValueError, match=said):
        VariableProjection(iterations=1e9)
    with pytest.raises(ValueError, match=r"^varpro option polish must be an integer >= 0, got -1"):
        VariableProjection(polish=-1)
    robot, _, samples = tree
    estimate = VariableProjection(particles=2, iterations=2500, polish=0).fit(Problem(robot, samples))
    assert len(estimate.details["history"]) <= 1001 and estimate.details["history_stride"] == 3


def test_a_shape_without_a_friction_step_is_not_identified():
    """A joint whose amplitude phi1 is within 2 std of 0 has no step to shape: its phi2, phi3 get an
    infinite std and are named, whatever the linearisation says."""
    from idkit.estimators.varpro import _shapes_without_amplitude

    details = {
        "uncertainty": {
            "std": {"a.phi1": 0.5, "a.phi2": 3.0, "a.phi3": 0.1, "b.phi1": 0.1, "b.phi2": 2.0},
            "std_rel_pct": {"a.phi2": 30.0, "a.phi3": 10.0, "b.phi2": 5.0},
            "unidentifiable": [],
        }
    }
    found = _shapes_without_amplitude(details, {"a.phi1": 0.6, "b.phi1": 3.0}, ["a", "b"])["uncertainty"]
    assert found["std"]["a.phi2"] == found["std"]["a.phi3"] == float("inf")
    assert found["std"]["b.phi2"] == 2.0  # a step 30 std tall: its shape stands
    assert found["unidentifiable"] == ["a.phi2, a.phi3 (the friction step a.phi1 is within 2 std of 0)"]
