"""The paper's reported PSO estimate: "the mean estimate of ten PSO runs, omitting all estimates
with cost functions that are relatively too large" (section IV), as an explicit rule; and the
paper's final estimate, the average of several estimates (``average_estimates``: its one home).

``KeepRule`` decides which runs count; ``aggregate`` averages their parameters. The rule and the
kept runs are recorded in every estimate's ``details``, because "relatively too large" is a choice
the paper leaves open:

- ``"relative"`` (default): keep runs with ``cost <= (1 + tol) · best``;
- ``"mad"``: keep runs with ``cost <= median + k · 1.4826 · MAD`` (a robust z-score), plus the best
  run, so a rule that degenerates (MAD = 0) still keeps the runs that tie with the median;
- ``"best"``: keep only the best run; ``"all"``: the plain mean.

Costs are non-negative (they are norms), so ``(1 + tol) · best`` is the intended scale.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import torch
from torch import Tensor

from idkit.estimate import Estimate
from idkit.estimators.objective import Objective, cost_label
from idkit.interfaces import Cost
from idkit.problem import Problem

RULES = ("relative", "mad", "best", "all")


@dataclass(frozen=True)
class KeepRule:
    """Which runs are "relatively" good enough to average.

    Args:
        kind: one of ``RULES``.
        tol: relative slack of ``"relative"``.
        k: width of ``"mad"`` in robust standard deviations.
    """

    kind: str = "relative"
    tol: float = 0.05
    k: float = 3.0

    def __post_init__(self) -> None:
        if self.kind not in RULES:
            raise ValueError(f"unknown keep rule {self.kind!r}; use one of {', '.join(RULES)}")
        if self.tol < 0 or self.k < 0:
            raise ValueError(f"keep rule needs tol >= 0 and k >= 0, got tol={self.tol}, k={self.k}")

    @classmethod
    def parse(cls, rule: KeepRule | dict[str, Any] | str) -> KeepRule:
        """Accept a rule, a dict of its fields (a config section) or just its kind."""
        if isinstance(rule, KeepRule):
            return rule
        if isinstance(rule, str):
            return cls(kind=rule)
        return cls(**dict(rule))

    def keep(self, costs: Tensor) -> Tensor:
        """Boolean mask ``[..., R]`` of the runs to keep given final costs ``[..., R]``.

        Non-finite costs are never kept; if no run is finite the mask is all false.
        """
        finite = torch.isfinite(costs)
        safe = torch.where(finite, costs, torch.inf)
        best = safe.amin(dim=-1, keepdim=True)
        if self.kind == "all":
            return finite
        if self.kind == "best":
            index = safe.argmin(dim=-1, keepdim=True)
            return torch.zeros_like(finite).scatter(-1, index, True) & finite
        if self.kind == "relative":
            return finite & (safe <= (1 + self.tol) * best)
        finite_only = torch.where(finite, costs, torch.nan)  # statistics of the finite runs only
        median = finite_only.nanmedian(dim=-1, keepdim=True).values
        mad = (finite_only - median).abs().nanmedian(dim=-1, keepdim=True).values
        return finite & ((safe <= median + self.k * 1.4826 * mad) | (safe == best))

    def describe(self) -> dict[str, Any]:
        return asdict(self)


def aggregate(values: Tensor, costs: Tensor, rule: KeepRule) -> tuple[Tensor, Tensor]:
    """Mean of the kept runs.

    Args:
        values: per-run results ``[..., R, P]`` (parameters).
        costs: final cost of each run ``[..., R]``.
        rule: which runs to keep.

    Returns:
        ``(mean[..., P], kept[..., R])``; the mean is NaN where no run was kept.
    """
    kept = rule.keep(costs)
    weights = kept.to(values.dtype).unsqueeze(-1)
    total = (values * weights).nan_to_num().sum(dim=-2)
    return total / weights.sum(dim=-2), kept


def average_estimates(
    problem: Problem,
    parts: Sequence[Estimate],
    costs: Sequence[Cost],
    label: str,
    space: str | None = None,
    use_regressor: bool | None = None,
) -> Estimate:
    """The mean of ``parts`` (e.g. PSO-f13 and PSO-f14 of one problem) in their search space.

    The paper's final estimate (section V). Parts are averaged in the space they searched
    (physical parameters, or base parameters for robots that search there), so the average of
    two estimates of a base-space search is again consistent. ``Estimate.cost`` is
    ``problem.cost`` at the average (``None`` without one); each part's criterion at the average
    is in ``details["costs_at_average"]`` and the parts themselves in ``details["parts"]``.

    Args:
        problem: the problem the parts were fitted on.
        parts: the estimates to average, e.g. ``fit_costs(problem, costs)`` of ``pso``/``adam``.
        costs: the criterion of each part (reported at the average).
        label: the estimator label of the average.
        space, use_regressor: as given to the estimator that made the parts.
    """
    from idkit.estimators.search_result import make_estimate  # it imports this module

    started = time.perf_counter()
    objective = Objective(problem, costs, space=space, use_regressor=use_regressor)
    robot = problem.robot
    base = objective.space == "base"
    names = robot.base_param_names if base else robot.param_names
    average = torch.tensor(
        [[(part.base_params if base else part.params)[name] for name in names] for part in parts],
        dtype=objective.lower.dtype,
        device=objective.lower.device,
    ).mean(dim=0)
    measured = objective.measured[0]
    error = objective.error(average) if base else problem.error(average)
    details = {
        "parts": {part.estimator: part.to_dict() for part in parts},
        "costs_at_average": {cost_label(c): float(c(error, measured)) for c in costs},
        **{key: parts[0].details[key] for key in ("threads", "device", "dtype") if key in parts[0].details},
    }
    cost = None if problem.cost is None else float(problem.cost(error, measured))
    wall = sum(part.wall_time_s for part in parts) + time.perf_counter() - started
    return make_estimate(problem, objective, label, average, cost, wall, details)
