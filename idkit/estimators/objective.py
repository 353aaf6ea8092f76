"""Many costs of many parameter sets in one call: the hot loop of the search-based estimators.

``Objective(problem, costs)`` maps search positions ``x[C, ..., D]`` (one slice per cost) to
``cost[C, ...]``. It precomputes everything that depends only on the samples, once:

- the search space: the robot's physical parameters in ``bounds()`` (the paper's way) or, for
  robots with ``search_space == "base"``, the base parameters in ``base_bounds()``;
- the torque prediction: ``inverse_dynamics`` in general (``Problem.error``'s path); for a robot
  with a regressor, ``Y @ base_params(x)`` as one ``[..., B] × [B, n·N]`` matmul — exact, because
  ``tau = Y(q, qd, qdd) · alpha`` is the definition of the regressor (tests check both agree);
- each cost as ``error[..., n, N] → value[...]`` with ``measured`` bound. For the built-in norm
  products (``idkit.costs.paper``) the relative denominator (eq. 27 with its near-zero floor) is
  computed once instead of in every call; the value is computed by the same operations.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import torch
from torch import Tensor

from idkit.costs.norms import NORMS
from idkit.costs.paper import NormProductCost, RelativeNormProductCost
from idkit.costs.relative import relative_denominator
from idkit.interfaces import Cost
from idkit.problem import Problem

SPACES = ("physical", "base")


def bound_cost(cost: Cost, measured: Tensor) -> Callable[[Tensor], Tensor]:
    """``error[..., n, N] → value[...]`` for ``cost`` with ``measured[n, N]`` fixed."""
    if type(cost).__call__ is NormProductCost.__call__ and type(cost).error_matrix in (
        NormProductCost.error_matrix,
        RelativeNormProductCost.error_matrix,
    ):
        norms = [NORMS[name] for name in cost.norms]
        if isinstance(cost, RelativeNormProductCost):
            denominator = relative_denominator(measured, cost.floor)
            return lambda error: math.prod(norm(error / denominator) for norm in norms)
        return lambda error: math.prod(norm(error) for norm in norms)
    return lambda error: cost(error, measured)


def cost_label(cost: Cost) -> str:
    """Short name of a cost for estimator labels: the class name (``f13`` for the paper's)."""
    return type(cost).__name__


class Objective:
    """Batched costs of search positions for one problem.

    Args:
        problem: robot, samples, device and dtype (its ``cost`` is not used here).
        costs: ``C`` costs; positions carry a leading dimension of size ``C``, slice ``c`` is
            evaluated with ``costs[c]``.
        space: ``"physical"`` or ``"base"``; ``None`` follows ``robot.search_space``.
        use_regressor: predict torques by the regressor (requires one); ``None`` uses it when the
            robot has one.
    """

    def __init__(
        self,
        problem: Problem,
        costs: Sequence[Cost],
        space: str | None = None,
        use_regressor: bool | None = None,
    ) -> None:
        robot = problem.robot
        self.problem = problem
        self.costs = list(costs)
        if not self.costs:
            raise ValueError("Objective needs at least one cost")
        self.space = robot.search_space if space is None else space
        if self.space not in SPACES:
            raise ValueError(f"unknown search space {self.space!r}; use one of {', '.join(SPACES)}")
        if use_regressor is None:
            use_regressor = robot.has_regressor
        if self.space == "base" and not use_regressor:
            raise ValueError(
                "searching in base space predicts torques by the regressor; use_regressor=False is impossible"
            )
        if (use_regressor or self.space == "base") and not robot.has_regressor:
            raise ValueError(
                f"{type(robot).__name__} has no regressor: search in base space / use_regressor=True "
                "is impossible"
            )
        self.use_regressor = bool(use_regressor)
        dtype, device = problem.torch_dtype, problem.device
        box = robot.base_bounds() if self.space == "base" else robot.bounds()
        self.lower, self.upper = (b.to(device=device, dtype=dtype) for b in box)
        if not bool((self.lower < self.upper).all()):
            raise ValueError(f"{type(robot).__name__}: empty search box {self.lower} .. {self.upper}")
        s = problem.tensors()
        self.samples = s
        self.measured = s.measured_matrix()  # [n, N]
        self.shape = tuple(self.measured.shape)
        if self.use_regressor:
            y = robot.regressor(s.q, s.qd, s.qdd)  # [N, n, B]
            # [B, n·N] so that alpha[..., B] @ it is the prediction in the joints × samples layout.
            self.regressor_t = y.permute(2, 1, 0).reshape(y.shape[-1], -1).contiguous()
            self.measured_flat = self.measured.reshape(-1)
        self.bound = [bound_cost(c, self.measured) for c in self.costs]

    @property
    def dimension(self) -> int:
        return self.lower.shape[-1]

    def params(self, x: Tensor) -> Tensor:
        """Physical parameters ``[..., P]`` of search positions ``x[..., D]``."""
        if self.space == "base":
            return self.problem.robot.params_from_base(x)
        return x

    def base(self, x: Tensor) -> Tensor:
        """Base parameters ``[..., B]`` of search positions ``x[..., D]`` (needs a regressor)."""
        return x if self.space == "base" else self.problem.robot.base_params(x)

    def error(self, x: Tensor) -> Tensor:
        """Torque error ``E[..., n, N] = measured − predicted`` at search positions ``x[..., D]``."""
        if self.use_regressor:
            predicted = self.base(x) @ self.regressor_t
            return (self.measured_flat - predicted).unflatten(-1, self.shape)
        s = self.samples
        predicted = self.problem.robot.inverse_dynamics(x, s.q, s.qd, s.qdd)
        return (s.tau - predicted).transpose(-1, -2)

    def __call__(self, x: Tensor) -> Tensor:
        """``cost[C, ...]`` of positions ``x[C, ..., D]``: slice ``c`` by cost ``c``."""
        if x.shape[0] != len(self.bound):
            raise ValueError(f"positions have {x.shape[0]} cost slices, the objective has {len(self.bound)}")
        error = self.error(x)
        if len(self.bound) == 1:
            return self.bound[0](error[0]).unsqueeze(0)
        return torch.stack([f(e) for f, e in zip(self.bound, error.unbind(0), strict=True)])
