"""The excitation criteria against an independent numpy computation on a numpy-built regressor."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from idkit.excitation.criterion import (
    excitation_criterion,
    log_det_information,
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
    with pytest.raises(ValueError, match="unknown excitation criterion 'aopt'; use one of cond, logdet"):
        excitation_criterion(cylindrical, "aopt", *states)
