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
from collections.abc import Sequence
from typing import Any, ClassVar

import torch

from idkit.costs.paper import f13, f14
from idkit.relative import DEFAULT_FLOOR
from idkit.estimate import Estimate
from idkit.estimators.aggregate import KeepRule
from idkit.estimators.objective import Objective, cost_label
from idkit.estimators.pso import ParticleSwarm
from idkit.estimators.search_result import make_estimate
from idkit.interfaces import Estimator
from idkit.problem import Problem


class PaperFinalEstimate(Estimator):
    """Mean of PSO-f13 and PSO-f14 (label ``"PSO-f13/f14"``).

    Args:
        floor: near-zero torque floor of the relative costs (``idkit.relative``).
        preset … history: passed unchanged to ``ParticleSwarm`` (see there).
    """

    conformance_options: ClassVar[dict[str, Any]] = {"runs": 3, "particles": 6, "iterations": 15}

    def __init__(
        self,
        floor: float = DEFAULT_FLOOR,
        preset: str = "default",
        runs: int = 10,
        particles: int | None = None,
        iterations: int | None = None,
        c1: float | None = None,
        c2: float | None = None,
        inertia: Sequence[float] | None = None,
        boundary: str | None = None,
        velocity_limit: float | None = None,
        per_particle: bool | None = None,
        keep: KeepRule | dict[str, Any] | str = "relative",
        space: str | None = None,
        use_regressor: bool | None = None,
        threads: int | None = None,
        history: bool = True,
    ) -> None:
        self.floor = floor
        self.preset = preset
        self.runs = runs
        self.particles = particles
        self.iterations = iterations
        self.c1 = c1
        self.c2 = c2
        self.inertia = inertia
        self.boundary = boundary
        self.velocity_limit = velocity_limit
        self.per_particle = per_particle
        self.keep = keep
        self.space = space
        self.use_regressor = use_regressor
        self.threads = threads
        self.history = history
        self._pso = ParticleSwarm(
            preset=preset,
            runs=runs,
            particles=particles,
            iterations=iterations,
            c1=c1,
            c2=c2,
            inertia=inertia,
            boundary=boundary,
            velocity_limit=velocity_limit,
            per_particle=per_particle,
            keep=keep,
            space=space,
            use_regressor=use_regressor,
            threads=threads,
            history=history,
        )

    def fit(self, problem: Problem) -> Estimate:
        started = time.perf_counter()
        costs = [f13(self.floor), f14(self.floor)]
        parts = self._pso.fit_costs(problem, costs)
        objective = Objective(problem, costs, space=self.space, use_regressor=self.use_regressor)
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
