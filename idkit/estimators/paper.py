"""``pso_f13_f14``: the paper's recommended final estimate (section V).

"An average of the results of PSO-f13 and PSO-f14 can be taken as the final estimation": both
PSOs run in one batched ``ParticleSwarm.fit_costs`` call and the two estimates' physical
parameters are averaged (each already the mean of its kept runs). ``problem.cost`` is ignored —
the criteria are f13 and f14 — except that, when set, ``Estimate.cost`` is its value at the
average; otherwise ``Estimate.cost`` is ``None`` (there is no single criterion) and the values of
f13 and f14 at the average are in ``details["costs_at_average"]``.
"""

from __future__ import annotations

import time
from typing import Any

import torch

from idkit.costs.paper import f13, f14
from idkit.costs.relative import DEFAULT_FLOOR
from idkit.estimate import Estimate
from idkit.estimators.objective import Objective, cost_label
from idkit.estimators.pso import ParticleSwarm, make_estimate
from idkit.interfaces import Estimator
from idkit.problem import Problem


class PaperFinalEstimate(Estimator):
    """Mean of PSO-f13 and PSO-f14 (label ``"PSO-f13/f14"``).

    Args:
        floor: near-zero torque floor of the relative costs (``idkit.costs.relative``).
        **pso_options: passed unchanged to ``ParticleSwarm`` (``preset``, ``runs``, ``threads`` …).
    """

    def __init__(self, floor: float = DEFAULT_FLOOR, **pso_options: Any) -> None:
        self.floor = floor
        self.pso_options = pso_options
        for name, value in pso_options.items():  # scikit-learn style: options readable by name
            setattr(self, name, value)
        if "label" in pso_options:
            raise ValueError("pso_f13_f14: 'label' is fixed (PSO-f13/f14); remove it from the options")
        self._pso = ParticleSwarm(**pso_options)

    def fit(self, problem: Problem) -> Estimate:
        started = time.perf_counter()
        costs = [f13(self.floor), f14(self.floor)]
        parts = self._pso.fit_costs(problem, costs)
        objective = Objective(problem, costs, space=self._pso.space, use_regressor=self._pso.use_regressor)
        robot = problem.robot
        names = robot.base_param_names if objective.space == "base" else robot.param_names
        source = "base_params" if objective.space == "base" else "params"
        average = torch.tensor(
            [[getattr(part, source)[name] for name in names] for part in parts],
            dtype=objective.lower.dtype,
            device=objective.lower.device,
        ).mean(dim=0)  # in the search space, like each part's mean over runs
        error = objective.error(average) if objective.space == "base" else problem.error(average)
        at_average = {cost_label(c): float(c(error, objective.measured)) for c in costs}
        cost = None if problem.cost is None else float(problem.cost(error, objective.measured))
        details = {
            "parts": {part.estimator: part.to_dict() for part in parts},
            "costs_at_average": at_average,
            "threads": parts[0].details["threads"],
            "device": parts[0].details["device"],
            "dtype": parts[0].details["dtype"],
        }
        return make_estimate(
            problem, objective, "PSO-f13/f14", average, cost, time.perf_counter() - started, details
        )
