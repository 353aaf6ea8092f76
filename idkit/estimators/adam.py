"""``adam``: a gradient-based baseline for the PSO — multi-start Adam on the same cost.

``starts`` uniform starting points in the same search box as ``pso`` are one tensor ``[R, D]``;
the loss is the *sum* of their costs, so each start receives exactly its own gradient and the
starts are independent runs of one batched computation. The search runs in the box normalised to
[0, 1]^D (Adam's step is about ``lr`` per coordinate whatever the gradient's scale, so a
normalised box lets one ``lr`` fit parameters of different units) and every step is followed by
a projection (clamp) back into the box. The learning rate decays from ``lr`` to
``lr · lr_final`` on a cosine schedule. The estimate is the mean over kept starts, by the same
``KeepRule`` as the PSO.

Costs are evaluated by their own ``__call__`` (autograd through ``torch.linalg`` where needed)
on the error of ``Objective.error`` (the regressor where the robot has one), with Adam's fused
CPU/GPU kernel.

Non-smooth costs. f3–f8 and f11–f16 contain a max over rows, columns or entries, and every cost
is a norm, non-differentiable where the error vanishes. Autograd then returns one subgradient
(the gradient of the active row/column/entry), and Adam follows it: there is no convergence
guarantee, iterates can zig-zag between active pieces, and only the decaying learning rate makes
them settle, not necessarily at a minimum. The multi-start and the keep rule limit the damage;
compare the final costs with the PSO's before trusting a non-smooth Adam fit.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any, ClassVar

import torch

from idkit.estimate import Estimate
from idkit.estimators.aggregate import KeepRule, aggregate
from idkit.estimators.objective import Objective
from idkit.estimators.search_result import common_details, per_cost_estimates
from idkit.estimators.swarm import Uniform
from idkit.interfaces import Cost, Estimator
from idkit.problem import Problem
from idkit.runtime import resolve_threads, torch_threads


class AdamMultiStart(Estimator):
    """Batched multi-start Adam minimising ``problem.cost`` over the robot's search box.

    Args:
        starts: independent starting points ``R``.
        steps: Adam steps per start (one cost and gradient evaluation each).
        lr: initial learning rate, in box widths (the search box is normalised to [0, 1]^D).
        lr_final: final learning rate as a fraction of ``lr`` (cosine decay).
        betas: Adam's moment decay rates.
        keep: the rule for omitting starts whose final cost is relatively too large (``KeepRule``).
        space, use_regressor, threads, history, label: as for ``pso`` (``label`` default
            ``"Adam-<cost>"``).
    """

    conformance_options: ClassVar[dict[str, Any]] = {"starts": 3, "steps": 20}

    def __init__(
        self,
        starts: int = 10,
        steps: int = 500,
        lr: float = 0.05,
        lr_final: float = 1e-3,
        betas: Sequence[float] = (0.9, 0.999),
        keep: KeepRule | dict[str, Any] | str = "relative",
        space: str | None = None,
        use_regressor: bool | None = None,
        threads: int | None = None,
        history: bool = True,
        label: str | None = None,
    ) -> None:
        self.starts = starts
        self.steps = steps
        self.lr = lr
        self.lr_final = lr_final
        self.betas = betas
        self.keep = keep
        self.space = space
        self.use_regressor = use_regressor
        self.threads = threads
        self.history = history
        self.label = label
        if starts < 1 or steps < 1:
            raise ValueError(f"adam needs starts >= 1 and steps >= 1, got {starts}, {steps}")
        if not lr > 0 or not 0 < lr_final <= 1:
            raise ValueError(f"adam needs lr > 0 and 0 < lr_final <= 1, got lr={lr}, lr_final={lr_final}")
        self._keep = KeepRule.parse(keep)

    def fit(self, problem: Problem) -> Estimate:
        """Minimise ``problem.cost`` (required)."""
        if problem.cost is None:
            raise ValueError("adam minimises problem.cost, which is None; give the problem a cost (e.g. f1)")
        return self.fit_costs(problem, [problem.cost])[0]

    def fit_costs(self, problem: Problem, costs: Sequence[Cost]) -> list[Estimate]:
        """One estimate per cost; all costs' starts are one batched computation."""
        costs = list(costs)
        started = time.perf_counter()
        objective = Objective(problem, costs, space=self.space, use_regressor=self.use_regressor)
        n, samples = objective.shape
        threads = resolve_threads(self.threads, len(costs) * self.starts * n * samples)
        lower, width = objective.lower, objective.upper - objective.lower
        with torch_threads(threads):
            u = Uniform(problem.generator(), lower)((len(costs), self.starts, lower.shape[-1]))
            u.requires_grad_(True)
            optimiser = torch.optim.Adam([u], lr=self.lr, betas=tuple(self.betas), fused=True)
            low = self.lr * self.lr_final

            def evaluate() -> torch.Tensor:  # [C, R]
                error = objective.error(lower + width * u)  # [C, R, n, N], regressor where possible
                return torch.stack([cost(error[c], objective.measured) for c, cost in enumerate(costs)])

            history = []
            for step in range(self.steps):
                optimiser.zero_grad(set_to_none=True)
                value = evaluate()
                value.sum().backward()
                optimiser.step()
                # Cosine decay from lr to lr·lr_final (set directly: cheaper than an LRScheduler).
                progress = (step + 1) / self.steps
                optimiser.param_groups[0]["lr"] = low + (self.lr - low) * 0.5 * (
                    1 + math.cos(math.pi * progress)
                )
                with torch.no_grad():
                    u.clamp_(0.0, 1.0)
                if self.history:
                    history.append(value.detach())
            with torch.no_grad():
                final = evaluate()  # at the projected last iterate
                position = lower + width * u.detach()
                mean, kept = aggregate(position, final, self._keep)
                values = [objective.exact(c, mean[c]) for c in range(len(costs))]
        common = common_details(problem, objective, costs, self._keep, threads, time.perf_counter() - started)
        common.update(starts=self.starts, steps=self.steps, lr=self.lr, lr_final=self.lr_final)
        return per_cost_estimates(
            problem,
            objective,
            costs,
            self.label or "Adam-{cost}",
            position,
            final,
            kept,
            mean,
            values,
            torch.stack(history) if self.history else None,  # [steps, C, R], cost before each step
            common,
        )
