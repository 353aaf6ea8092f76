"""How well a motion excites a robot's base parameters, for a whole batch of motions at once.

``W[..., N·n, B]`` stacks the robot's base regressor over the ``N`` sample times (sample-major,
as the least-squares family builds it, eq. 8). Two classic measures:

* ``"cond"`` — the condition number of ``W`` with unit-norm columns (Gautier & Khalil 1992):
  the column scaling makes it independent of the base parameters' units, and it bounds how much a
  relative error in the torques can grow in the estimate. Smaller is better, 1 is ideal.
* ``"logdet"`` — D-optimality, ``log det(Wᵀ W)`` of the unscaled ``W``: the log volume of the
  information matrix (inverse of the confidence ellipsoid's volume under white torque noise).
  Larger is better; it depends on units and grows with the amplitude and the number of samples.

``loss`` turns each into a number to minimise: ``cond`` itself, ``-logdet``.
"""

from __future__ import annotations

import torch
from torch import Tensor

from idkit.interfaces import Robot

CRITERIA = ("cond", "logdet")


def check_criterion(criterion: str) -> str:
    """``criterion`` if it is one of ``CRITERIA``, else a ``ValueError`` listing them."""
    if criterion not in CRITERIA:
        raise ValueError(f"unknown excitation criterion {criterion!r}; use one of {', '.join(CRITERIA)}")
    return criterion


def observation_matrix(robot: Robot, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
    """Base regressor stacked over samples, ``W[..., N·n, B]``, for states ``[..., N, n]``.

    A regressor row depends on its own sample only, so a batch of trajectories is one call on
    ``[... · N, n]`` states.
    """
    if not robot.has_regressor:
        raise ValueError(f"robot {type(robot).__name__} has no base regressor; excitation design needs one")
    n_samples, n_joints = q.shape[-2:]
    batch = q.shape[:-2]
    y = robot.regressor(q.reshape(-1, n_joints), qd.reshape(-1, n_joints), qdd.reshape(-1, n_joints))
    return y.reshape(*batch, n_samples * n_joints, y.shape[-1])


def scaled_condition_number(w: Tensor) -> Tensor:
    """Condition number ``[...]`` of ``w[..., M, B]`` after scaling its columns to unit norm.

    A zero column (an unexcited parameter) gives ``inf``.
    """
    norm = torch.linalg.vector_norm(w, dim=-2, keepdim=True)
    sigma = torch.linalg.svdvals(w / torch.where(norm > 0, norm, torch.ones_like(norm)))
    return sigma[..., 0] / sigma[..., -1]


def log_det_information(w: Tensor) -> Tensor:
    """``log det(wᵀ w)`` ``[...]`` of ``w[..., M, B]`` as ``2 Σ log σ`` (no squaring of ``w``'s condition)."""
    return 2.0 * torch.log(torch.linalg.svdvals(w)).sum(-1)


def criterion_value(criterion: str, w: Tensor) -> Tensor:
    """The value ``[...]`` of ``criterion`` for ``w[..., M, B]``, as reported."""
    if check_criterion(criterion) == "cond":
        return scaled_condition_number(w)
    return log_det_information(w)


def loss(criterion: str, w: Tensor) -> Tensor:
    """``criterion`` as a number ``[...]`` to minimise (``cond``, or ``-logdet``)."""
    value = criterion_value(criterion, w)
    return value if criterion == "cond" else -value


def excitation_criterion(robot: Robot, criterion: str, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
    """``criterion`` ``[...]`` of sampled states ``[..., N, n]`` (e.g. a recording) on ``robot``."""
    return criterion_value(criterion, observation_matrix(robot, q, qd, qdd))
