"""The excitation criteria against an independent numpy computation on a numpy-built regressor:
cond and logdet (SVD as reported, Gram matrix as searched) and the expected LS error under noise."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from idkit.excitation.criterion import (
    NoiseModel,
    excitation_criterion,
    gram_condition_number,
    gram_log_det,
    log_det_information,
    make_criterion,
    observation_matrix,
    scaled_condition_number,
)
from idkit.excitation.fourier import FourierExcitation
from idkit.robots.urdf import URDFRobot

G = 9.81


def cylindrical_w_numpy(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """Eq. (23) typed from the paper, stacked sample-major: ``W[3N, 4]``."""
    rows = []
    for (_, _, d3), (th_d, _, d3_d), (th_dd, d2_dd, d3_dd) in zip(q, qd, qdd, strict=True):
        rows.append([th_dd, 0.0, 2 * d3 * d3_d * th_d + d3**2 * th_dd, 2 * d3_d * th_d + 2 * d3 * th_dd])
        rows.append([0.0, d2_dd + G, d2_dd + G, 0.0])
        rows.append([0.0, 0.0, d3_dd - d3 * th_d**2, -(th_d**2)])
    return np.array(rows)


def numpy_criteria(w: np.ndarray) -> tuple[float, float]:
    """``(cond of the unit-column W, log det WᵀW)`` with numpy's own routines."""
    return float(np.linalg.cond(w / np.linalg.norm(w, axis=0))), float(np.linalg.slogdet(w.T @ w)[1])


def random_states(batch: tuple[int, ...], n_samples: int, n_joints: int, seed: int) -> list[torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    return [torch.randn(*batch, n_samples, n_joints, generator=g, dtype=torch.float64) for _ in range(3)]


def test_cylindrical_criteria_equal_numpy_on_eq39(cylindrical):
    t = torch.arange(1, 11, dtype=torch.float64)
    states = cylindrical.excitation(t)
    cond, logdet = numpy_criteria(cylindrical_w_numpy(*(x.numpy() for x in states)))
    assert float(excitation_criterion(cylindrical, "cond", *states)) == pytest.approx(cond, rel=1e-12)
    assert float(excitation_criterion(cylindrical, "logdet", *states)) == pytest.approx(logdet, rel=1e-12)
    assert cond == pytest.approx(36.11, abs=0.01)  # the "≈ 36" of eq. (39) at t = 1, ..., 10 s


def test_batched_criteria_equal_numpy_per_candidate(cylindrical):
    states = random_states((2, 3), 10, 3, seed=4)
    cond = excitation_criterion(cylindrical, "cond", *states)
    logdet = excitation_criterion(cylindrical, "logdet", *states)
    assert cond.shape == logdet.shape == (2, 3)
    for i in range(2):
        for j in range(3):
            ref = numpy_criteria(cylindrical_w_numpy(*(x[i, j].numpy() for x in states)))
            assert (float(cond[i, j]), float(logdet[i, j])) == pytest.approx(ref, rel=1e-11)


def test_urdf_criteria_equal_numpy_on_its_regressor():
    robot = URDFRobot("cylindrical", friction=True)
    t = torch.linspace(0.5, 10.0, 40, dtype=torch.float64)
    states = FourierExcitation(3, offset=[0.0, 0.5, 0.5])(t)
    w = observation_matrix(robot, *states)
    y = robot.regressor(*states).numpy()  # [N, n, B]
    assert np.array_equal(w.numpy(), y.reshape(-1, y.shape[-1]))
    cond, logdet = numpy_criteria(y.reshape(-1, y.shape[-1]))
    assert float(scaled_condition_number(w)) == pytest.approx(cond, rel=1e-10)
    assert float(log_det_information(w)) == pytest.approx(logdet, rel=1e-10)


def test_an_unexcited_parameter_gives_an_infinite_condition_number(cylindrical):
    q, qd, qdd = (torch.zeros(5, 3, dtype=torch.float64) for _ in range(3))  # at rest: only gravity
    assert torch.isinf(excitation_criterion(cylindrical, "cond", q, qd, qdd))


def test_unknown_criterion_lists_the_known_ones(cylindrical):
    states = random_states((), 5, 3, seed=0)
    with pytest.raises(
        ValueError, match="unknown excitation criterion 'aopt'; use one of cond, logdet, ls_error"
    ):
        excitation_criterion(cylindrical, "aopt", *states)


def test_the_searched_gram_forms_equal_the_reported_svd_forms():
    """On tall matrices like a real arm's (700 × 64) and on badly scaled columns, to 1e-9."""
    g = torch.Generator().manual_seed(5)
    w = torch.randn(6, 700, 64, generator=g, dtype=torch.float64) + torch.randn(
        6, 1, 64, generator=g, dtype=torch.float64
    )
    w = w * torch.logspace(-3, 3, 64, dtype=torch.float64)  # units differ by 10⁶
    torch.testing.assert_close(gram_condition_number(w), scaled_condition_number(w), rtol=1e-9, atol=0)
    torch.testing.assert_close(gram_log_det(w), log_det_information(w), rtol=1e-9, atol=0)
    cond = scaled_condition_number(w)
    assert (cond > 1.5).all() and (cond < 1e3).all()  # a range where the comparison means something


def test_the_gram_forms_score_unexcited_and_non_finite_matrices_as_worst():
    w = torch.randn(3, 20, 4, dtype=torch.float64)
    w[0, :, 2] = 0.0  # an unexcited parameter
    w[1, 3, 1] = float("nan")
    w[2, :, 3] = w[2, :, 0]  # two identical columns: rank deficient
    cond, logdet = gram_condition_number(w), gram_log_det(w)
    assert torch.isinf(cond[:2]).all() and (cond[2] > 1e7)
    assert torch.isneginf(logdet[:2]).all()


def ls_error_numpy(robot, states, noise: NoiseModel) -> float:
    """The expected LS error typed again: per draw, noisy states and torques, numpy lstsq, the mean
    relative error of the nonzero base parameters; then the mean over draws (same draws)."""
    q, qd, qdd = (x.numpy() for x in states)
    n_samples, n = q.shape
    u = noise.errors(n_samples, n).numpy()  # [K, 4, N, n]
    truth = robot.base_params(robot.nominal_params()).numpy()
    tau = np.einsum("snb,b->sn", robot.regressor(*states).numpy(), truth)
    errors = []
    for draw in u:
        noisy = [torch.from_numpy(x * (1 + e)) for x, e in zip((q, qd, qdd), draw[:3], strict=True)]
        w = robot.regressor(*noisy).numpy().reshape(-1, truth.size)
        estimate = np.linalg.lstsq(w, (tau * (1 + draw[3])).reshape(-1), rcond=None)[0]
        known = truth != 0
        errors.append(np.mean(np.abs(estimate[known] - truth[known]) / np.abs(truth[known])))
    return float(np.mean(errors))


@pytest.mark.parametrize("robot_name", ["cylindrical", "urdf"])
def test_ls_error_equals_a_numpy_monte_carlo_on_the_same_draws(robot_name, cylindrical):
    robot = cylindrical if robot_name == "cylindrical" else URDFRobot("cylindrical", friction=True)
    noise = NoiseModel(state=0.1, torque=0.05, draws=7, seed=3)
    states = FourierExcitation(3, offset=[0.0, 0.5, 0.5])(torch.linspace(1.0, 10.0, 10, dtype=torch.float64))
    found = float(excitation_criterion(robot, "ls_error", *states, noise=noise))
    assert found == pytest.approx(ls_error_numpy(robot, states, noise), rel=1e-9)
    assert 1e-4 < found < 10


def test_ls_error_is_deterministic_batched_and_differentiable(cylindrical):
    noise = NoiseModel(draws=5, seed=1)
    criterion = make_criterion("ls_error", cylindrical, 10, noise)
    family = FourierExcitation(3, offset=[0.0, 0.5, 0.5])
    t = torch.linspace(1.0, 10.0, 10, dtype=torch.float64)
    coefficients = family.to_vector() + 0.05 * torch.randn(2, family.to_vector().numel(), dtype=torch.float64)
    coefficients.requires_grad_(True)
    states = family.evaluate(coefficients, t)
    value = criterion.loss(observation_matrix(cylindrical, *states), states)
    single = [
        excitation_criterion(cylindrical, "ls_error", *family.from_vector(c.detach())(t), noise=noise)
        for c in coefficients
    ]
    torch.testing.assert_close(value.detach(), torch.stack(single), rtol=1e-12, atol=0)
    (gradient,) = torch.autograd.grad(value.sum(), coefficients)
    assert gradient.isfinite().all() and gradient.abs().max() > 0
    # No torque noise and no state noise: LS recovers the parameters exactly.
    exact = make_criterion("ls_error", cylindrical, 10, NoiseModel(state=0.0, torque=0.0, draws=2))
    assert float(exact.value(observation_matrix(cylindrical, *states), states)[0].detach()) < 1e-12


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"state": 1.0}, "state must be a level in"),
        ({"torque": -0.1}, "torque must be a level in"),
        ({"draws": 0}, "draws must be an integer >= 1"),
        ({"seed": -1}, "excitation noise: seed must be an integer in"),
    ],
)
def test_noise_model_refuses_bad_values(options, match):
    with pytest.raises(ValueError, match=match):
        NoiseModel(**options)
