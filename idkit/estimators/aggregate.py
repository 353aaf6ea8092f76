"""The paper's reported PSO estimate: "the mean estimate of ten PSO runs, omitting all estimates
with cost functions that are relatively too large" (section IV), as an explicit rule; and the
paper's final estimate, the average of several estimates — its one home (``average_params``,
``average_estimates``), for the ``pso_f13_f14`` estimator and the studies alike.

The average is taken **in the space the parts searched** (``details["space"]``): physical
parameters for the paper's cylindrical robot (what the paper averages and prints), base parameters
for a robot that searches there (a URDF arm). Averaging physical parameters instead would be wrong
there: they are one representative of each part's base parameters (``params_from_base``), and the
mean of two representatives is in general not the representative of the mean — for a nonlinear map
it does not even predict the mean torque (``τ = Y α`` is linear in the base parameters, not in the
physical ones). The physical parameters of the average are ``params_from_base`` of it.

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
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import torch
from torch import Tensor

from idkit.estimate import Estimate
from idkit.estimators.objective import Objective, cost_label
from idkit.interfaces import Cost, Robot
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


def average_label(costs: Sequence[str]) -> str:
    """``PSO-f13/f14`` for ``("f13", "f14")``: the label of the average of those PSO estimates."""
    return "PSO-" + "/".join(costs)


def mean_params(params: Sequence[Mapping[str, float]]) -> dict[str, float]:
    """Per name, the mean over ``params`` (each a ``name -> value`` map with the same names)."""
    if not params:
        raise ValueError("mean_params: nothing to average")
    return {k: sum(p[k] for p in params) / len(params) for k in params[0]}


def search_average(parts: Sequence[Estimate], robot: Robot) -> tuple[str, Tensor]:
    """The mean of ``parts`` in the space they searched: ``(space, position[D])`` (float64).

    Raises:
        ValueError: parts that searched different spaces, or a base-space part without base
            parameters.
    """
    spaces = {part.details.get("space", "physical") for part in parts}
    if len(spaces) != 1:
        raise ValueError(f"cannot average estimates that searched different spaces: {sorted(spaces)}")
    (space,) = spaces
    if space == "base":
        bases = [part.base_params for part in parts if part.base_params is not None]
        if len(bases) < len(parts):
            raise ValueError("a base-space estimate without base parameters cannot be averaged")
        mean = mean_params(bases)
        names = robot.base_param_names
    else:
        mean = mean_params([part.params for part in parts])
        names = robot.param_names
    return space, torch.tensor([mean[name] for name in names], dtype=torch.float64)


def average_params(parts: Sequence[Estimate], robot: Robot) -> dict[str, float]:
    """The physical parameters of the average of ``parts`` (module docstring): what a study records."""
    space, position = search_average(parts, robot)
    physical = robot.params_from_base(position) if space == "base" else position
    return dict(zip(robot.param_names, (float(v) for v in physical), strict=True))


def average_estimates(
    problem: Problem,
    parts: Sequence[Estimate],
    costs: Sequence[Cost],
    label: str,
) -> Estimate:
    """The mean of ``parts`` (e.g. PSO-f13 and PSO-f14 of one problem) in their search space.

    The paper's final estimate (section V; module docstring). ``Estimate.cost`` is ``problem.cost``
    at the average (``None`` without one); each part's criterion at the average is in
    ``details["costs_at_average"]`` and the parts themselves in ``details["parts"]``.

    Args:
        problem: the problem the parts were fitted on.
        parts: the estimates to average, e.g. ``fit_costs(problem, costs)`` of ``pso``/``adam``
            (their ``details["space"]`` and ``["use_regressor"]`` say how they searched).
        costs: the criterion of each part (reported at the average).
        label: the estimator label of the average.
    """
    from idkit.estimators.search_result import make_estimate  # it imports this module

    started = time.perf_counter()
    space, position = search_average(parts, problem.robot)
    use_regressor = parts[0].details.get("use_regressor")
    objective = Objective(problem, costs, space=space, use_regressor=use_regressor)
    average = position.to(dtype=objective.lower.dtype, device=objective.lower.device)
    measured = objective.measured[0]
    error = objective.error(average) if space == "base" else problem.error(average)
    details: dict[str, Any] = {
        "parts": {part.estimator: part.to_dict() for part in parts},
        "costs_at_average": {cost_label(c): float(c(error, measured)) for c in costs},
        "space": space,
        **{key: parts[0].details[key] for key in ("threads", "device", "dtype") if key in parts[0].details},
    }
    cost = None if problem.cost is None else float(problem.cost(error, measured))
    wall = sum(part.wall_time_s for part in parts) + time.perf_counter() - started
    return make_estimate(problem, objective, label, average, cost, wall, details)
