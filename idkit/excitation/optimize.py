"""Optimal excitation: coefficients that make the base regressor well conditioned, within limits.

The problem (Swevers et al. 1997; Gautier & Khalil 1992): choose the coefficients ``c`` of an
excitation family (``fourier`` by default) to minimise a criterion of the base regressor stacked
over the ``N`` sample times (``idkit.excitation.criterion``: column-scaled condition number, or
D-optimality), subject to the robot's joint position, velocity and acceleration limits at every
instant.

Constraints are hard, by construction: every candidate goes through ``fit_into_limits``, which
shrinks each joint's motion about its offset until a time grid over ``[0, t_end]`` stays inside the
box (candidates already inside are unchanged). The search therefore needs no penalty weight and
never returns an infeasible motion. The optimiser sees a ``grid_points`` grid; the result is
scaled once more on the ``check_points`` grid, on which it is checked (``excess_after`` is 0).

Search, seeded: the batched particle swarm of ``idkit.optim.swarm`` (``swarms`` independent
swarms of ``particles`` candidates: every candidate of an iteration is one tensor computation),
then Adam through autograd from each swarm's best (``method="pso+adam"``, the default), or either
alone. Both work in the unit cube of the family's ``coefficient_box``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import torch
from torch import Tensor

from idkit.data.trajectory import sample_times
from idkit.excitation.criterion import check_criterion, criterion_value, loss, observation_matrix
from idkit.excitation.feasible import fit_into_limits
from idkit.excitation.spec import build_excitation
from idkit.interfaces import Excitation, Robot
from idkit.limits import MotionLimits
from idkit.optim import swarm
from idkit.runtime import resolve_threads, torch_threads
from idkit.seeds import torch_generator

METHODS = ("pso", "adam", "pso+adam")

#: The swarm's update rule: constriction coefficients with reflecting walls (idkit's PSO default).
RULES = swarm.SwarmRules(c1=1.49618, c2=1.49618, inertia=(0.7298, 0.5, 300), boundary="reflect")


@dataclass(frozen=True)
class ExcitationResult:
    """An optimised excitation and how it compares with the robot's default one.

    Attributes:
        name: registry name of the excitation family (``idkit.excitations``).
        excitation: the optimised member, feasible on ``grid``.
        baseline: the robot's default excitation (what ``simulate`` samples unless told otherwise).
        criterion: ``"cond"`` or ``"logdet"``.
        before, after: the criterion of ``baseline`` and of ``excitation`` at the sample times ``t``.
        t: sample times ``[N]``.
        limits: the box the motion had to respect.
        grid: the dense check grid ``[G]`` over ``[0, t_end]``.
        excess_before, excess_after: worst excursion beyond each limit on ``grid`` ``[3, n]``
            (rows position, velocity, acceleration; 0 inside).
        details: method, budget, seed, the best loss and wall time of each stage.
    """

    name: str
    excitation: Excitation
    baseline: Excitation
    criterion: str
    before: float
    after: float
    t: Tensor
    limits: MotionLimits
    grid: Tensor
    excess_before: Tensor
    excess_after: Tensor
    details: dict[str, Any] = field(default_factory=dict)

    def samples(self) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """``(t[N], q, qd, qdd)`` of the optimised motion at the sample times, each ``[N, n]``."""
        return (self.t, *self.excitation(self.t))


def _check_budget(**values: int) -> None:
    for key, value in values.items():
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"optimize_excitation: {key} must be an integer >= 1, got {value!r}")


def optimize_excitation(
    robot: Robot,
    excitation: str = "fourier",
    options: Mapping[str, Any] | None = None,
    criterion: str = "cond",
    n_samples: int = 10,
    t_end: float = 10.0,
    limits: MotionLimits | None = None,
    method: str = "pso+adam",
    swarms: int = 4,
    particles: int = 64,
    iterations: int = 200,
    adam_steps: int = 200,
    learning_rate: float = 0.01,
    grid_points: int = 1001,
    check_points: int = 10001,
    seed: int = 0,
    device: str = "cpu",
    threads: int | None = None,
) -> ExcitationResult:
    """Choose the coefficients of an excitation family for ``robot`` (module docstring).

    Args:
        robot: a robot with a base regressor; its ``motion_limits()`` unless ``limits`` is given.
        excitation: registry name of the family (``idkit.excitations``).
        options: the family's structural options (e.g. ``harmonics``, ``period``).
        criterion: ``"cond"`` (minimised) or ``"logdet"`` (maximised).
        n_samples, t_end: the sample times ``sample_times(n_samples, t_end)`` of the criterion,
            as the scenarios sample; ``t_end`` also spans the limit grids.
        limits: overrides the robot's motion limits.
        method: ``"pso"``, ``"adam"`` or ``"pso+adam"``.
        swarms, particles, iterations: ``swarms`` independent swarms of ``particles`` candidates
            each, ``iterations`` evaluations per candidate; Adam starts from each swarm's best (or,
            alone, from ``swarms`` uniform points of the box).
        adam_steps, learning_rate: Adam's budget and step in unit-cube coordinates.
        grid_points, check_points: limit grids over ``[0, t_end]`` during the search and for the
            result.
        seed: every random number (swarm, Adam starts) comes from it.
        device: where the candidates are evaluated (``"cpu"``, ``"cuda"``).
        threads: torch intra-op threads (``None``: by problem size).
    """
    check_criterion(criterion)
    if method not in METHODS:
        raise ValueError(f"optimize_excitation: unknown method {method!r}; use one of {', '.join(METHODS)}")
    _check_budget(
        n_samples=n_samples,
        swarms=swarms,
        particles=particles,
        iterations=iterations,
        adam_steps=adam_steps,
        grid_points=grid_points,
        check_points=check_points,
    )
    limits = robot.motion_limits() if limits is None else limits
    if limits.joint_names != tuple(robot.joint_names):
        raise ValueError(
            f"optimize_excitation: limits are for joints {limits.joint_names}, robot has {robot.joint_names}"
        )
    family = build_excitation(excitation, robot, options)
    like = {"device": torch.device(device), "dtype": torch.float64}
    t = sample_times(n_samples, t_end)
    grid = torch.linspace(0.0, t_end, grid_points, **like)
    lower, upper = (x.to(**like) for x in family.coefficient_box(limits))
    t_device = t.to(**like)

    def objective(unit: Tensor) -> Tensor:
        """Loss ``[...]`` of unit-cube points ``[..., C]`` after fitting them into the limits."""
        coefficients = fit_into_limits(family, lower + (upper - lower) * unit, limits, grid)
        w = observation_matrix(robot, *family.evaluate(coefficients, t_device))
        finite = w.isfinite().flatten(-2).all(-1)[..., None, None]
        value = loss(criterion, torch.where(finite, w, 0.0))  # a non-finite W scores as unexcited
        return torch.nan_to_num(value, nan=math.inf)

    generator = torch_generator(seed)
    budget = {
        "swarms": swarms,
        "particles": particles,
        "iterations": iterations,
        "adam_steps": adam_steps,
        "learning_rate": learning_rate,
    }
    work = swarms * particles * (grid_points + n_samples) * robot.n_joints
    with torch_threads(resolve_threads(threads, work)):
        unit, details = _search(objective, lower.numel(), method, budget, generator, like)
    # With the default grids (1,000 and 10,000 intervals) the search grid's points are among the
    # check grid's, so this only shrinks what the finer grid shows beyond a limit.
    check_grid = torch.linspace(0.0, t_end, check_points, dtype=torch.float64)
    best = (lower + (upper - lower) * unit).double().cpu()
    final = family.from_vector(fit_into_limits(family, best, limits, check_grid))
    baseline = robot.default_excitation()
    before, after = (
        float(criterion_value(criterion, observation_matrix(robot, *e(t)))) for e in (baseline, final)
    )
    details.update(seed=int(seed), grid_points=grid_points, check_points=check_points)
    return ExcitationResult(
        name=excitation,
        excitation=final,
        baseline=baseline,
        criterion=criterion,
        before=before,
        after=after,
        t=t,
        limits=limits,
        grid=check_grid,
        excess_before=limits.excess(*baseline(check_grid)),
        excess_after=limits.excess(*final(check_grid)),
        details=details,
    )


def _search(
    objective: Callable[[Tensor], Tensor],
    dims: int,
    method: str,
    budget: dict[str, Any],
    generator: torch.Generator,
    like: dict[str, Any],
) -> tuple[Tensor, dict[str, Any]]:
    """The best unit-cube point ``[C]`` found by ``method``, and each stage's budget, loss and time.

    Args:
        budget: ``swarms``, ``particles``, ``iterations``, ``adam_steps``, ``learning_rate``.
    """
    details: dict[str, Any] = {"method": method, **budget}
    started = time.perf_counter()
    if method == "adam":
        best = torch.rand(budget["swarms"], dims, generator=generator, dtype=torch.float64).to(**like)
    else:
        best = _swarm_search(
            objective, dims, budget["swarms"], budget["particles"], budget["iterations"], generator, like
        )
        details.update(pso_best_loss=float(objective(best).min()), pso_seconds=time.perf_counter() - started)
    if method != "pso":
        started = time.perf_counter()
        best = _adam_search(objective, best, budget["adam_steps"], budget["learning_rate"])
        details.update(
            adam_best_loss=float(objective(best).min()), adam_seconds=time.perf_counter() - started
        )
    with torch.no_grad():
        return best[objective(best).argmin()], details


def _swarm_search(
    objective: Callable[[Tensor], Tensor],
    dims: int,
    swarms: int,
    particles: int,
    iterations: int,
    generator: torch.Generator,
    like: dict[str, Any],
) -> Tensor:
    """Each swarm's best unit-cube point ``[swarms, C]``."""
    lower, upper = torch.zeros(dims, **like), torch.ones(dims, **like)
    with torch.inference_mode():
        uniform = swarm.Draws([swarm.Uniform(generator, lower)])
        state, _ = swarm.run(objective, lower, upper, (swarms,), particles, iterations, RULES, uniform)
    return state.global_position.clone()


def _adam_search(
    objective: Callable[[Tensor], Tensor], starts: Tensor, steps: int, learning_rate: float
) -> Tensor:
    """Adam from ``starts[S, C]`` (independent, projected on the unit cube); each start's best point."""
    unit = starts.clone().requires_grad_(True)
    optimiser = torch.optim.Adam([unit], lr=learning_rate)
    best, best_loss = starts.clone(), torch.full(starts.shape[:1], math.inf, dtype=starts.dtype)
    for step in range(steps + 1):
        value = objective(unit)
        improved = value.detach() < best_loss.to(value.device)
        best = torch.where(improved[:, None], unit.detach(), best)
        best_loss = torch.where(improved, value.detach(), best_loss.to(value.device))
        if step == steps:
            break
        optimiser.zero_grad()
        value[torch.isfinite(value)].sum().backward()
        optimiser.step()
        with torch.no_grad():
            unit.clamp_(0.0, 1.0)
    return best
