"""Eq. (39) and the Fourier excitation: values, exact derivatives, sampling instants."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from idkit.data.trajectory import fourier_excitation, paper_trajectory, sample_times
from idkit.interfaces import Robot


def paper_numpy(t: np.ndarray) -> np.ndarray:
    """Eq. (39) typed in again from the paper, independently of PAPER_TERMS: ``[N, 3]``."""
    s = np.sin
    return np.stack(
        (
            0.43 * s(2.2 * t) + 0.23 * s(1.8 * t) - 3.4 * s(0.06 * t) - 0.36,
            s(0.1 * t) - 0.3 * s(0.07 * t) + 0.35 * s(1.3 * t) - 0.014,
            0.1 * s(0.1 * t) - 0.1 * s(2.7 * t) + 0.06 * s(0.14 * t) + 0.26,
        ),
        axis=1,
    )


def autograd_derivatives(fn, t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """d/dt and d²/dt² of ``fn(t)[0]`` (``[N, n]``) by autograd; rows depend only on their own t."""
    t = t.clone().requires_grad_(True)
    q = fn(t)[0]
    first = torch.stack(
        [torch.autograd.grad(q[:, j].sum(), t, create_graph=True)[0] for j in range(q.shape[1])], 1
    )
    second = torch.stack(
        [torch.autograd.grad(first[:, j].sum(), t, retain_graph=True)[0] for j in range(q.shape[1])], 1
    )
    return first.detach(), second.detach()


TRAJECTORIES = {
    "paper": paper_trajectory,
    "fourier3": lambda t: fourier_excitation(t, 3),
    "fourier7": lambda t: fourier_excitation(t, 7, amplitude=0.3, period=4.0, harmonics=2),
}


def test_paper_trajectory_matches_the_printed_equation():
    t = np.linspace(0.0, 10.0, 101)
    q, _, _ = paper_trajectory(torch.from_numpy(t))
    np.testing.assert_allclose(q.numpy(), paper_numpy(t), rtol=0, atol=1e-14)


@pytest.mark.parametrize("name", TRAJECTORIES)
def test_derivatives_match_autograd(name):
    fn = TRAJECTORIES[name]
    t = torch.linspace(0.0, 10.0, 57, dtype=torch.float64)
    _, qd, qdd = fn(t)
    first, second = autograd_derivatives(fn, t)
    torch.testing.assert_close(qd, first, rtol=0, atol=1e-12)
    torch.testing.assert_close(qdd, second, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", TRAJECTORIES)
def test_derivatives_match_central_differences(name):
    fn = TRAJECTORIES[name]
    t = torch.linspace(0.3, 9.7, 41, dtype=torch.float64)
    h = 1e-4
    q_plus, qd_plus, _ = fn(t + h)
    q_minus, qd_minus, _ = fn(t - h)
    q, qd, qdd = fn(t)
    # Central differences are O(h²) accurate: |error| <= h²/6 · max|q'''| ≈ 1e-8 here.
    torch.testing.assert_close((q_plus - q_minus) / (2 * h), qd, rtol=0, atol=1e-7)
    torch.testing.assert_close((qd_plus - qd_minus) / (2 * h), qdd, rtol=0, atol=1e-7)
    torch.testing.assert_close((q_plus - 2 * q + q_minus) / h**2, qdd, rtol=0, atol=1e-5)


def test_trajectory_follows_dtype_and_shapes():
    t = torch.linspace(0.0, 10.0, 5, dtype=torch.float32)
    for fn in TRAJECTORIES.values():
        out = fn(t)
        assert all(x.dtype == torch.float32 and x.shape[0] == 5 for x in out)
    assert [x.shape for x in paper_trajectory(t)] == [(5, 3)] * 3


def test_fourier_excitation_bounds_periodicity_and_distinct_joints():
    t = torch.linspace(0.0, 10.0, 2001, dtype=torch.float64)
    q, qd, qdd = fourier_excitation(t, 7)
    w = 2 * math.pi / 10.0
    k = np.arange(1, 6)
    # The documented bounds: sums of the term amplitudes.
    assert q.abs().max() <= 0.5 * (1 / k).sum()
    assert qd.abs().max() <= 0.5 * w * len(k) + 1e-12
    assert qdd.abs().max() <= 0.5 * w**2 * k.sum() + 1e-12
    for a, b in zip(fourier_excitation(t + 10.0, 7), (q, qd, qdd), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=1e-12)
    # Joints move differently: no two joint trajectories are (nearly) collinear.
    corr = torch.corrcoef(q.T)
    assert (corr - torch.eye(7)).abs().max() < 0.99


def test_fourier_excitation_rejects_bad_arguments():
    with pytest.raises(ValueError, match="n_joints"):
        fourier_excitation(torch.zeros(3), 0)


def test_robot_default_excitation_is_the_fourier_series(cylindrical):
    class Point(Robot):
        joint_names = ("a", "b")
        param_names = ("m",)

        def bounds(self):
            return torch.zeros(1), torch.ones(1)

        def inverse_dynamics(self, params, q, qd, qdd):
            return params[..., 0, None, None] * qdd

    t = sample_times(10)
    for a, b in zip(Point().excitation(t), fourier_excitation(t, 2), strict=True):
        assert torch.equal(a, b)
    for a, b in zip(cylindrical.excitation(t), paper_trajectory(t), strict=True):
        assert torch.equal(a, b)


def test_sample_times_uniform_period_ending_at_t_end():
    assert sample_times(10).tolist() == [float(i) for i in range(1, 11)]
    torch.testing.assert_close(sample_times(20), torch.arange(1, 21, dtype=torch.float64) / 2)
    assert sample_times(1, t_end=3.0).tolist() == [3.0]
    with pytest.raises(ValueError, match="n_samples"):
        sample_times(0)
    with pytest.raises(ValueError, match="t_end"):
        sample_times(5, t_end=0.0)
