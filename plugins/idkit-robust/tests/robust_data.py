"""Shared test data: simulated torques with gross outliers."""

from __future__ import annotations

import torch
from idkit.problem import Problem, Samples


def outlier_problem(robot, n_samples: int = 30, fraction: float = 0.1, seed: int = 0, cost=None) -> Problem:
    """``robot`` on its excitation at its nominal parameters; every torque gets up to 2 % noise
    and each, with probability ``fraction``, a gross ±70 % error (like the paper's outliers)."""
    gen = torch.Generator().manual_seed(seed)
    t = 10 * torch.arange(1, n_samples + 1, dtype=torch.float64) / n_samples
    q, qd, qdd = robot.excitation(t)
    tau = robot.inverse_dynamics(robot.nominal_params(), q, qd, qdd)
    tau = tau * (1 + 0.02 * (2 * torch.rand(tau.shape, generator=gen, dtype=torch.float64) - 1))
    hit = torch.rand(tau.shape, generator=gen, dtype=torch.float64) < fraction
    sign = torch.sign(torch.rand(tau.shape, generator=gen, dtype=torch.float64) - 0.5)
    tau = torch.where(hit, tau * (1 + 0.7 * sign), tau)
    return Problem(robot, Samples(q, qd, qdd, tau), cost=cost)
