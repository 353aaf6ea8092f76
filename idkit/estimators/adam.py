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

Sizes, as for ``pso`` (``idkit.optim.sizes``): ``starts × steps``, plus the steps' own cost
(``ADAM_STEP_EVALUATIONS`` each), is capped at ``MAX_EVALUATIONS`` per cost and trial, a search
that will be long says so before it starts, a batch's memory is checked before anything is allocated, and
``details["history"]`` keeps every ``details["history_stride"]``-th step (and the last), at most
``HISTORY_ROWS`` + 1 per start.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import torch

from idkit.estimate import Estimate
from idkit.estimators.aggregate import KeepRule, aggregate
from idkit.estimators.objective import Objective
from idkit.estimators.search_result import common_details, per_cost_estimates, warn_search_bounds
from idkit.estimators.trials import criteria, fit_in_batches, trial_chunk
from idkit.interfaces import Cost, Estimator
from idkit.optim import sizes
from idkit.optim.swarm import Draws, Uniform, history_rows
from idkit.problem import Problem
from idkit.runtime import resolve_threads, torch_threads


@dataclass(frozen=True)
class AdamSettings:
    """An ``AdamMultiStart``'s settings, checked and resolved at each fit.

    Attributes:
        starts, steps: the budget (integers >= 1, under ``sizes.MAX_EVALUATIONS``).
        lr, lr_final, betas: the step and its schedule (``lr > 0``, ``0 < lr_final <= 1``).
        keep: the rule for omitting starts (``KeepRule``).
        stride: the history keeps every ``stride``-th step (``sizes.history_stride``).
    """

    starts: int
    steps: int
    lr: float
    lr_final: float
    betas: tuple[float, float]
    keep: KeepRule
    stride: int


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
        betas: tuple[float, float] = (0.9, 0.999),
        keep: KeepRule | dict[str, Any] | str = "relative",
        space: Literal["physical", "base"] | None = None,
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
        self.resolve()  # a bad option is refused now; every fit resolves again (idkit.hyperparameters)

    def resolve(self) -> AdamSettings:
        """The options checked and resolved (``ValueError`` naming the option)."""
        for name, value in (("starts", self.starts), ("steps", self.steps)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"adam option {name} must be an integer >= 1, got {value!r}")
        if not self.lr > 0 or not 0 < self.lr_final <= 1:
            raise ValueError(
                f"adam needs lr > 0 and 0 < lr_final <= 1, got lr={self.lr}, lr_final={self.lr_final}"
            )
        betas = tuple(float(b) for b in self.betas)
        if len(betas) != 2 or not all(0 <= b < 1 for b in betas):
            raise ValueError(f"adam option betas must be two numbers in [0, 1), got {self.betas!r}")
        sizes.check_evaluations(
            "adam", {"starts": self.starts, "steps": self.steps}, "steps", sizes.ADAM_STEP_EVALUATIONS
        )
        return AdamSettings(
            starts=self.starts,
            steps=self.steps,
            lr=float(self.lr),
            lr_final=float(self.lr_final),
            betas=betas,
            keep=KeepRule.parse(self.keep),
            stride=sizes.history_stride(self.steps),
        )

    def fit(self, problem: Problem) -> Estimate:
        """Minimise ``problem.cost`` (required)."""
        if problem.cost is None:
            raise ValueError("adam minimises problem.cost, which is None; give the problem a cost (e.g. f1)")
        return self.fit_costs(problem, [problem.cost])[0]

    def fit_costs(self, problem: Problem, costs: Sequence[Cost]) -> list[Estimate]:
        """One estimate per cost; all costs' starts are one batched computation."""
        return warn_search_bounds(problem, self.fit_trials([problem], costs)[0])

    def fit_trials(
        self, problems: Sequence[Problem], costs: Sequence[Cost] | None = None, chunk: int | None = None
    ) -> list[list[Estimate]]:
        """One estimate per trial and cost: trials × costs × starts as one batch per chunk.

        As ``ParticleSwarm.fit_trials``: trial ``t``'s starting points come from its own seed, and
        Adam's update is elementwise, so its estimates equal ``fit_costs(problems[t], costs)``
        whatever ``chunk`` (trials per batch; ``None``: about ``CHUNK_ELEMENTS`` error elements).
        """
        settings = self.resolve()
        problems, costs = list(problems), criteria(problems, costs)
        for problem in problems:
            problem.check_identifiable()
        sizes.announce_long_search(
            "adam",
            settings.starts * settings.steps,
            len(costs),
            [p.samples.tau.numel() for p in problems],
            sizes.ADAM_RESIDUAL_NS,
        )

        def trials_per_batch(problem: Problem) -> int:
            return trial_chunk(
                chunk, len(costs) * settings.starts * problem.robot.n_joints * problem.samples.n_samples
            )

        def fit_batch(batch: list[Problem]) -> list[list[Estimate]]:
            return self._fit_group(batch, costs, settings)

        return fit_in_batches(problems, trials_per_batch, fit_batch)

    def _fit_group(
        self, problems: list[Problem], costs: list[Cost], settings: AdamSettings
    ) -> list[list[Estimate]]:
        """``fit_trials`` of one chunk of trials."""
        trials, count = len(problems), len(costs)
        robot = problems[0].robot
        kept_steps = history_rows(settings.steps, settings.stride) if self.history else []
        dimension = max(len(robot.param_names), len(robot.base_param_names))
        slots = trials * count
        sizes.check_memory(
            f"adam: {trials} trial(s) × {count} cost(s) × starts={settings.starts} "
            f"({len(kept_steps)} history rows)",
            sizes.swarm_bytes(slots, settings.starts, 1, dimension, len(kept_steps))
            # an evaluation's error, its autograd copies and their gradients
            + sizes.error_bytes(slots * settings.starts, problems[0].samples.tau.numel(), copies=8),
            "lower starts, or fit the trials in smaller chunks",
        )
        started = time.perf_counter()
        objective = Objective(problems, costs, space=self.space, use_regressor=self.use_regressor)
        n, samples = objective.shape
        threads = resolve_threads(self.threads, objective.slots * settings.starts * n * samples)
        lower, width = objective.lower, objective.upper - objective.lower
        keep_rows = set(kept_steps)
        with torch_threads(threads):
            draws = Draws([Uniform(p.generator(), lower) for p in problems])
            u = draws.draw((objective.slots, settings.starts, lower.shape[-1]))
            u.requires_grad_(True)
            optimiser = torch.optim.Adam([u], lr=settings.lr, betas=settings.betas, fused=True)
            low = settings.lr * settings.lr_final

            def evaluate() -> torch.Tensor:  # [S, R]
                x = (lower + width * u).view(trials, count, settings.starts, -1)
                values = []
                for t in range(trials):
                    error = objective.error(x[t], t)  # [C, R, n, N], regressor where possible
                    values += [cost(error[c], objective.measured[t]) for c, cost in enumerate(costs)]
                return torch.stack(values)

            history = []
            for step in range(settings.steps):
                optimiser.zero_grad(set_to_none=True)
                value = evaluate()
                value.sum().backward()
                optimiser.step()
                # Cosine decay from lr to lr·lr_final (set directly: cheaper than an LRScheduler).
                progress = (step + 1) / settings.steps
                optimiser.param_groups[0]["lr"] = low + (settings.lr - low) * 0.5 * (
                    1 + math.cos(math.pi * progress)
                )
                with torch.no_grad():
                    u.clamp_(0.0, 1.0)
                if step in keep_rows:
                    history.append(value.detach())
            with torch.no_grad():
                final = evaluate()  # at the projected last iterate
                position = lower + width * u.detach()
                mean, kept = aggregate(position, final, settings.keep)
                values = [objective.exact(s, mean[s]) for s in range(objective.slots)]
        wall = time.perf_counter() - started
        stacked = torch.stack(history) if self.history else None  # [rows, S, R], cost before each kept step
        estimates = []
        for t, problem in enumerate(problems):
            part = slice(t * count, (t + 1) * count)
            common = common_details(problem, objective, costs, settings.keep, threads, wall / trials)
            common.update(
                starts=settings.starts,
                steps=settings.steps,
                lr=settings.lr,
                lr_final=settings.lr_final,
                batched_trials=trials,
                history_stride=settings.stride,
            )
            estimates.append(
                per_cost_estimates(
                    problem,
                    objective,
                    costs,
                    self.label or "Adam-{cost}",
                    position[part],
                    final[part],
                    kept[part],
                    mean[part],
                    values[part],
                    None if stacked is None else stacked[:, part],
                    common,
                )
            )
        return estimates
