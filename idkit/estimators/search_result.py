"""Turning one batched multi-start search (PSO swarms, Adam starts) into one ``Estimate`` per cost.

Both search estimators end with the same tensors — each run's final position and cost, the kept
runs, their mean and its exact cost — so they share how those become estimates and what the
per-run record in ``Estimate.details`` holds.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor

from idkit.estimate import Estimate, to_python
from idkit.estimators.aggregate import KeepRule
from idkit.estimators.bounds import at_bounds, near_bounds, sides, warn_at_bounds
from idkit.estimators.objective import Objective, cost_label
from idkit.interfaces import Cost, Robot
from idkit.problem import Problem


def common_details(
    problem: Problem, objective: Objective, costs: Sequence[Cost], keep: KeepRule, threads: int, wall: float
) -> dict[str, Any]:
    """What every estimate of one batched call records besides its own runs."""
    return {
        "keep_rule": keep.describe(),
        "space": objective.space,
        "use_regressor": objective.use_regressor,
        "threads": threads,
        "device": str(problem.device),
        "dtype": str(problem.torch_dtype).removeprefix("torch."),
        "seed": problem.seed,
        "batched_costs": [cost_label(c) for c in costs],
        "batch_wall_time_s": wall,
    }


def per_cost_estimates(
    problem: Problem,
    objective: Objective,
    costs: Sequence[Cost],
    label: str,
    position: Tensor,
    run_costs: Tensor,
    kept: Tensor,
    mean: Tensor,
    values: Sequence[float | Tensor],
    history: Tensor | None,
    common: dict[str, Any],
) -> list[Estimate]:
    """One estimate per cost.

    Args:
        label: ``"<prefix>-{cost}"`` format string, e.g. ``"PSO-{cost}"``, or a fixed label.
        position: ``[C, R, D]`` each run's final search position; ``run_costs``, ``kept``: ``[C, R]``.
        mean: ``[C, D]`` the reported positions; ``values``: their exact costs.
        history: ``[T, C, R]`` best cost per iteration, or ``None``.
        common: ``common_details(...)`` plus estimator-specific settings.
    """
    wall = common["batch_wall_time_s"] / len(costs)
    # Python lists for all costs at once: a study makes tens of thousands of estimates, and a
    # tensor per field and estimate costs more in conversions than the fit itself.
    all_costs, all_params, all_kept = (t.tolist() for t in (run_costs, objective.params(position), kept))
    runs_at = runs_at_bounds(search_names(problem.robot, objective.space), position, kept, objective)
    estimates = []
    for c, cost in enumerate(costs):
        details = dict(common)
        details.update(
            run_costs=all_costs[c],
            run_params=all_params[c],
            kept=all_kept[c],
            n_kept=sum(all_kept[c]),
        )
        if history is not None:
            details["history"] = history[:, c].T  # [R, T]
        name = label.format(cost=cost_label(cost))
        estimate = make_estimate(problem, objective, name, mean[c], float(values[c]), wall, details)
        estimate.details = {**estimate.details, "at_bound": {**runs_at[c], **estimate.details["at_bound"]}}
        estimates.append(estimate)
    return estimates


def runs_at_bounds(names: Sequence[str], position: Tensor, kept: Tensor, objective: Objective) -> list[dict]:
    """Per cost, ``{name: side}`` of the parameters at which any kept run of ``position[C, R, D]``
    (``kept[C, R]``) ended at a bound: the reported mean of runs some of which the box stopped is
    the box's doing too, though it may lie inside."""
    low, high = near_bounds(position, objective.lower, objective.upper)
    per_cost = ((mask & kept[..., None]).any(-2).tolist() for mask in (low, high))  # [C, D] each
    return [sides(names, lows, highs) for lows, highs in zip(*per_cost, strict=True)]


def make_estimate(
    problem: Problem,
    objective: Objective,
    label: str,
    position: torch.Tensor,
    cost: float | None,
    wall_time_s: float,
    details: dict[str, Any],
) -> Estimate:
    """An ``Estimate`` from a search position ``[D]``: physical and (where defined) base params."""
    robot = problem.robot
    params = objective.params(position)
    names = search_names(robot, objective.space)
    details = {**details, "at_bound": at_bounds(names, position, objective.lower, objective.upper)}
    base = None
    if robot.has_regressor:
        alpha = objective.base(position)
        base = dict(zip(robot.base_param_names, alpha.tolist(), strict=True))
    return Estimate(
        estimator=label,
        params=dict(zip(robot.param_names, params.tolist(), strict=True)),
        cost=cost,
        wall_time_s=wall_time_s,
        base_params=base,
        details=to_python(details),
    )


def search_names(robot: Robot, space: str) -> tuple[str, ...]:
    """The names of the searched coordinates: base parameters or the robot's own."""
    return tuple(robot.base_param_names if space == "base" else robot.param_names)


def warn_search_bounds(problem: Problem, estimates: Sequence[Estimate]) -> list[Estimate]:
    """Say, one line per estimate, which searched parameters ended at a bound (``details["at_bound"]``,
    :mod:`idkit.estimators.bounds`); the estimates are returned unchanged."""
    robot = problem.robot
    for estimate in estimates:
        space = estimate.details["space"]
        lower, upper = robot.base_bounds() if space == "base" else robot.bounds()
        names = search_names(robot, space)
        warn_at_bounds(
            estimate.estimator, estimate.details["at_bound"], names, lower, upper, "the robot's bounds"
        )
    return list(estimates)
