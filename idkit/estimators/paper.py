"""``pso_f13_f14``: the paper's recommended final estimate (section V), as a composition.

"An average of the results of PSO-f13 and PSO-f14 can be taken as the final estimation": one
``ParticleSwarm`` (configured by the ``pso`` option, exactly as ``estimator=pso`` would be) runs
both costs in one batched ``fit_costs`` call, then ``average_estimates`` (the one home of the
average, ``idkit.estimators.aggregate``) averages the two estimates in the search space.
``problem.cost`` is ignored — the criteria are f13 and f14 — except that, when set,
``Estimate.cost`` is its value at the average; otherwise ``Estimate.cost`` is ``None`` and the
values of f13 and f14 at the average are in ``details["costs_at_average"]``.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

from idkit.costs.paper import f13, f14
from idkit.estimate import Estimate
from idkit.estimators.aggregate import average_estimates, average_label
from idkit.estimators.pso import ParticleSwarm
from idkit.interfaces import Cost, Estimator
from idkit.problem import Problem
from idkit.relative import DEFAULT_FLOOR

LABEL = average_label(("f13", "f14"))


class PaperFinalEstimate(Estimator):
    """Mean of PSO-f13 and PSO-f14 (label ``"PSO-f13/f14"``).

    Args:
        pso: options of the ``ParticleSwarm`` that runs both costs (``None``: its defaults), e.g.
            ``{"preset": "paper", "runs": 10}``; on the command line ``+estimator.pso.runs=5``.
        floor: near-zero torque floor of the relative costs (``idkit.relative``).
    """

    conformance_options: ClassVar[dict[str, Any]] = {"pso": {"runs": 3, "particles": 6, "iterations": 15}}

    def __init__(self, pso: Mapping[str, Any] | None = None, floor: float = DEFAULT_FLOOR) -> None:
        self.pso = pso
        self.floor = floor
        self.resolve()  # a bad option is refused now; every fit resolves again (idkit.hyperparameters)

    def resolve(self) -> ParticleSwarm:
        """The configured PSO, its options checked (a new instance: building it has no side effects)."""
        if self.pso is not None and not isinstance(self.pso, Mapping):
            raise ValueError(f"pso_f13_f14 option pso must be a mapping of PSO options, got {self.pso!r}")
        if not (isinstance(self.floor, numbers.Real) and math.isfinite(self.floor) and self.floor >= 0):
            raise ValueError(f"pso_f13_f14 option floor must be a finite number >= 0, got {self.floor!r}")
        return ParticleSwarm(**dict(self.pso or {}))

    def costs(self) -> list[Cost]:
        return [f13(self.floor), f14(self.floor)]

    def fit(self, problem: Problem) -> Estimate:
        return self.fit_trials([problem])[0][0]

    def fit_trials(
        self, problems: Sequence[Problem], costs: Sequence[Cost] | None = None, chunk: int | None = None
    ) -> list[list[Estimate]]:
        """The average of every trial, its two PSOs batched over trials (``ParticleSwarm.fit_trials``).

        ``costs`` must be ``None`` (the criteria are fixed); one estimate per trial.
        """
        if costs is not None:
            raise ValueError("pso_f13_f14 fixes its criteria (f13, f14); fit_trials takes no costs")
        pso, criteria = self.resolve(), self.costs()
        parts = pso.fit_trials(problems, criteria, chunk=chunk)
        return [
            [average_estimates(problem, pair, criteria, LABEL)]
            for problem, pair in zip(problems, parts, strict=True)
        ]
