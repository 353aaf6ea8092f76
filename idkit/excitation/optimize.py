"""Optimal excitation: coefficients that make the base regressor well conditioned, within limits.

The problem (Swevers et al. 1997; Gautier & Khalil 1992): choose the coefficients ``c`` of an
excitation family (``fourier`` by default) to minimise a criterion of the base regressor stacked
over the ``N`` sample times (``idkit.excitation.criterion``: column-scaled condition number,
D-optimality, or the expected LS error under state and torque noise), subject to the robot's joint
position, velocity and acceleration limits at every instant, its effort limits (the nominal
model's torques) and, optionally, no self-collision. Every limit keeps a safety margin
(``margin``, :mod:`idkit.excitation.margins`: 5 % of its half-range by default): the search and
the final stage see each limit narrowed by its margin, so the check that enforces the margins
passes.

Constraints are hard, without penalty weights:

* the box, by construction: every candidate goes through ``fit_into_limits``, which shrinks each
  joint's motion about its offset until a time grid over ``[0, t_end]`` stays inside (candidates
  already inside are unchanged). The optimiser sees a ``grid_points`` grid;
* effort, when the robot declares effort limits: a candidate whose nominal torques ``W α`` at the
  sample times (free: ``W`` is the criterion's regressor, ``α`` the nominal base parameters) leave
  a limit scores ``inf`` (never kept as a best); with a ``collision`` test, so does a candidate
  whose offset pose (the motion shrunk to nothing) is in contact — the final stage could not make
  it collision-free;
* the result is scaled once more into the box on the ``check_points`` grid, then — if its torques
  on that grid leave an effort limit, or ``collision`` finds a contact there — every joint's motion
  is shrunk by the largest common factor that passes (``largest_feasible_scale``, bisection). So
  the returned motion is inside every limit on the check grid (``excess_after`` is 0) and its
  ``details`` say whether, and by how much, it was shrunk.

Search, seeded: the batched particle swarm of ``idkit.optim.swarm`` (``swarms`` independent
swarms of ``particles`` candidates: every candidate of an iteration is one tensor computation),
then Adam through autograd from each swarm's best (``method="pso+adam"``, the default), or either
alone. Both work in the unit cube of the family's ``coefficient_box``.

**The start.** The family's member with the given options (for ``fourier``, its deterministic
default series, at rest when ``rest``) made runnable by the same final stage is the motion the
optimiser has to beat. If the search ends no better than it (a search can: its candidates are
random, the start is not), the start is returned, ``improved`` is false and the report says that
no improvement was found — an "optimised" motion is never worse than its start.
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
from idkit.excitation.collision import SelfCollision
from idkit.excitation.criterion import Criterion, NoiseModel, make_criterion, observation_matrix
from idkit.excitation.effort import effort_limits, nominal_torques
from idkit.excitation.feasible import fit_into_limits, largest_feasible_scale, offset_indices, scale_motion
from idkit.excitation.margins import Margins
from idkit.excitation.spec import build_excitation
from idkit.interfaces import Excitation, Robot
from idkit.limits import MotionLimits
from idkit.optim import swarm
from idkit.options import positive_number
from idkit.progress import report
from idkit.runtime import resolve_threads, torch_threads
from idkit.seeds import torch_generator

METHODS = ("pso", "adam", "pso+adam")

#: States (candidates × samples, noise draws included) per batch of the objective: small enough
#: that the regressor's intermediate vectors stay in cache (a whole swarm at once was slower per
#: state for the KUKA: docs/excitation.md, "Speed: what bounds the search").
CHUNK_STATES = 4096

#: The swarm's update rule: constriction coefficients with reflecting walls (idkit's PSO default).
RULES = swarm.SwarmRules(c1=1.49618, c2=1.49618, inertia=(0.7298, 0.5, 300), boundary="reflect")


@dataclass(frozen=True)
class ExcitationResult:
    """An optimised excitation and how it compares with the robot's default one.

    Attributes:
        name: registry name of the excitation family (``idkit.excitations``).
        excitation: the optimised member (or the start, when the search did not improve on it),
            feasible on ``grid`` with every margin kept.
        baseline: the robot's default excitation (what ``simulate`` samples unless told otherwise).
        criterion: ``"cond"``, ``"logdet"`` or ``"ls_error"``.
        before, after: the criterion of ``baseline`` and of ``excitation`` at the sample times ``t``.
        t: sample times ``[N]``.
        limits: the box the motion had to respect (the limits themselves; the margins apply within).
        grid: the dense check grid ``[G]`` over ``[0, t_end]``.
        excess_before, excess_after: worst excursion beyond each limit on ``grid`` ``[3, n]``
            (rows position, velocity, acceleration; 0 inside).
        effort: the effort limits ``[n]`` kept, or ``None`` (the robot declares none, or ``effort=False``).
        margins: the safety margins kept inside every limit.
        start: the criterion of the start (module doc), ``None`` if the start could not be made
            runnable (``details["start"]`` says why).
        improved: whether the search found a motion better than the start (``False``: ``excitation``
            is the start).
        details: method, budget, seed, the best loss, wall and CPU time of each stage, the number of
            candidate ``evaluations`` of the criterion, and ``shrunk_by`` (the common scale of the
            final stage, 1 if none was needed) with ``shrunk_for`` and ``criterion_before_shrink``.
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
    effort: Tensor | None = None
    margins: Margins = field(default_factory=Margins)
    start: float | None = None
    improved: bool = True
    details: dict[str, Any] = field(default_factory=dict)

    def samples(self) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """``(t[N], q, qd, qdd)`` of the optimised motion at the sample times, each ``[N, n]``."""
        return (self.t, *self.excitation(self.t))


def _check_budget(t_end: float, learning_rate: float, **values: int) -> None:
    """Refuse a count below 1, or a duration or step that is not a finite number > 0 (``t_end=0``
    divides by zero; a negative learning rate climbs the criterion instead of descending it)."""
    for key, value in values.items():
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"optimize_excitation: {key} must be an integer >= 1, got {value!r}")
    for key, number in (("t_end", t_end), ("learning_rate", learning_rate)):
        if not positive_number(number):
            raise ValueError(f"optimize_excitation: {key} must be a finite number > 0, got {number!r}")


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
    particles: int = 32,
    iterations: int = 100,
    adam_steps: int = 300,
    learning_rate: float = 0.01,
    grid_points: int = 1001,
    check_points: int = 10001,
    seed: int = 0,
    device: str = "cpu",
    threads: int | None = None,
    noise: NoiseModel | None = None,
    effort: bool = True,
    collision: SelfCollision | None = None,
    margin: float | Mapping[str, float] | Margins | None = None,
) -> ExcitationResult:
    """Choose the coefficients of an excitation family for ``robot`` (module docstring).

    Args:
        robot: a robot with a base regressor; its ``motion_limits()`` unless ``limits`` is given.
        excitation: registry name of the family (``idkit.excitations``).
        options: the family's structural options (e.g. ``harmonics``, ``period``, ``rest``).
        criterion: ``"cond"``, ``"ls_error"`` (minimised) or ``"logdet"`` (maximised).
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
        noise: the noise model of ``ls_error`` (default ``NoiseModel()``); ignored by the others.
        effort: keep the nominal torques within the robot's effort limits (if it declares them).
        collision: a self-collision test the result must pass on the check grid (``None``: none).
        margin: the safety margin of every limit, a share of its half-range, or one per quantity
            (``{"position": 0.05, "effort": 0.1}``; :mod:`idkit.excitation.margins`); ``None``: 5 %.
    """
    criterion_ = make_criterion(criterion, robot, n_samples, noise)
    if method not in METHODS:
        raise ValueError(f"optimize_excitation: unknown method {method!r}; use one of {', '.join(METHODS)}")
    _check_budget(
        t_end,
        learning_rate,
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
    margins = Margins.of(margin, "excitation.margin")
    family = build_excitation(excitation, robot, options)
    efforts = effort_limits(robot) if effort else None
    inner, inner_efforts = margins.narrowed(limits), margins.narrowed_effort(efforts)
    like = {"device": torch.device(device), "dtype": torch.float64}
    t = sample_times(n_samples, t_end)
    grid = torch.linspace(0.0, t_end, grid_points, dtype=torch.float64)
    objective = _Objective(robot, family, criterion_, inner, inner_efforts, t, grid, like, collision)
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
        unit, details = _search(objective, objective.dims, method, budget, generator, like)
    check_grid = torch.linspace(0.0, t_end, check_points, dtype=torch.float64)
    final, unshrunk, shrink = _runnable(
        robot, family, objective.coefficients(unit), inner, inner_efforts, collision, check_grid
    )
    baseline = robot.default_excitation()
    before, after = (_value(robot, criterion_, e, t) for e in (baseline, final))
    details.update(
        seed=int(seed),
        grid_points=grid_points,
        check_points=check_points,
        evaluations=objective.evaluations,
        **shrink,
    )
    if unshrunk is not None:
        details["criterion_before_shrink"] = _value(robot, criterion_, unshrunk, t)
    start, start_value, details["start"] = _start(
        robot, family, criterion_, inner, inner_efforts, collision, check_grid, t
    )
    improved = start is None or start_value is None or _better(criterion_, after, start_value)
    if start is not None and start_value is not None and not improved:
        details["search_result"] = after
        final, after = start, start_value
        for key in ("shrunk_by", "shrunk_for", "criterion_before_shrink"):
            details.pop(key, None)
        details.update(details["start"]["shrink"])
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
        effort=efforts,
        margins=margins,
        start=start_value,
        improved=improved,
        details=details,
    )


def _better(criterion: Criterion, value: float, than: float) -> bool:
    """Whether ``value`` of ``criterion`` is strictly better than ``than``."""
    return value > than if criterion.better == "larger" else value < than


def _start(
    robot: Robot,
    family: Excitation,
    criterion: Criterion,
    limits: MotionLimits,
    efforts: Tensor | None,
    collision: SelfCollision | None,
    grid: Tensor,
    t: Tensor,
) -> tuple[Excitation | None, float | None, dict[str, Any]]:
    """The start (module doc) made runnable, its criterion, and ``details["start"]``; ``(None, None,
    {"runnable": False, "why": …})`` when it cannot be (its rest pose fails the effort or collision
    test). An offset outside a joint's position range (``fourier``'s default 0 for a joint whose
    range excludes 0) is moved to the middle of the range: scaling cannot move an offset."""
    vector = family.to_vector().clone()
    where = offset_indices(family)
    low, high = limits.lower[0], limits.upper[0]
    offsets = vector[where]
    outside = (offsets < low) | (offsets > high)
    middle = torch.where(torch.isfinite(low + high), (low + high) / 2, offsets.clamp(low, high))
    vector[where] = torch.where(outside, middle, offsets)
    try:
        start, _, shrink = _runnable(robot, family, vector, limits, efforts, collision, grid)
    except ValueError as exc:
        return None, None, {"runnable": False, "why": str(exc)}
    value = _value(robot, criterion, start, t)
    moved = [name for name, out in zip(limits.joint_names, outside.tolist(), strict=True) if out]
    return start, value, {"runnable": True, "criterion": value, "shrink": shrink, "offsets_centred": moved}


def _value(robot: Robot, criterion: Criterion, excitation: Excitation, t: Tensor) -> float:
    """The reported criterion of ``excitation`` sampled at ``t``."""
    states = excitation(t)
    return float(criterion.value(observation_matrix(robot, *states), states))


class _Objective:
    """The search's loss ``[...]`` of unit-cube points ``[..., C]``: fitted into the box on the
    search grid, scored by the criterion at the sample times, ``inf`` where the nominal torques at
    the sample times leave an effort limit or the offset pose is in contact. Evaluated in chunks of
    ``CHUNK_STATES`` states."""

    def __init__(
        self,
        robot: Robot,
        family: Excitation,
        criterion: Criterion,
        limits: MotionLimits,
        efforts: Tensor | None,
        t: Tensor,
        grid: Tensor,
        like: dict[str, Any],
        collision: SelfCollision | None = None,
    ) -> None:
        self.robot, self.family, self.criterion, self.limits = robot, family, criterion, limits
        self.collision = collision
        self.offsets = offset_indices(family)
        self.t, self.grid = t.to(**like), grid.to(**like)
        self.lower, self.upper = (x.to(**like) for x in family.coefficient_box(limits))
        self.dims = self.lower.numel()
        self.efforts = None if efforts is None else efforts.to(**like)
        nominal = robot.nominal_params() if efforts is not None else None
        self.alpha = None if nominal is None else robot.base_params(torch.as_tensor(nominal)).to(**like)
        self.chunk = max(1, CHUNK_STATES // (t.numel() * criterion.states_per_sample))
        self.evaluations = 0  # candidates scored so far

    def coefficients(self, unit: Tensor) -> Tensor:
        """Family coefficients ``[..., C]`` of unit-cube points ``[..., C]`` (before any fitting)."""
        return self.lower + (self.upper - self.lower) * unit

    def __call__(self, unit: Tensor) -> Tensor:
        flat = unit.reshape(-1, self.dims)
        self.evaluations += flat.shape[0]
        losses = [self._chunk(part) for part in flat.split(self.chunk)]
        return torch.cat(losses).reshape(unit.shape[:-1])

    def _chunk(self, unit: Tensor) -> Tensor:
        coefficients = fit_into_limits(self.family, self.coefficients(unit), self.limits, self.grid)
        states = self.family.evaluate(coefficients, self.t)
        w = observation_matrix(self.robot, *states)
        value = torch.nan_to_num(self.criterion.loss(w, states), nan=math.inf)
        if self.efforts is not None and self.alpha is not None:
            tau = (w @ self.alpha).unflatten(-1, (-1, self.robot.n_joints))  # [c, N, n]
            over = (tau.abs() > self.efforts).flatten(-2).any(-1)
            value = torch.where(over, torch.full_like(value, math.inf), value)
        if self.collision is not None:
            pose = coefficients[..., self.offsets.to(coefficients.device)].detach().cpu().numpy()
            touching = torch.from_numpy(self.collision.in_contact(pose)).to(value.device)
            value = torch.where(touching, torch.full_like(value, math.inf), value)
        return value


def _runnable(
    robot: Robot,
    family: Excitation,
    coefficients: Tensor,
    limits: MotionLimits,
    efforts: Tensor | None,
    collision: SelfCollision | None,
    grid: Tensor,
) -> tuple[Excitation, Excitation | None, dict[str, Any]]:
    """``coefficients[C]`` made runnable on ``grid`` (module docstring, last point).

    Returns:
        The member inside ``limits`` with its nominal torques within ``efforts`` and no contact
        found by ``collision``; the member before shrinking (``None`` if it was not shrunk); and
        ``shrunk_by`` (1 if not shrunk) with ``shrunk_for``, the tests that made it shrink.
    """
    inside = fit_into_limits(family, coefficients.double().cpu(), limits, grid)

    tests: dict[str, Callable[[Tensor], bool]] = {}
    if efforts is not None:

        def torques_within(c: Tensor) -> bool:
            return bool((nominal_torques(robot, *family.evaluate(c, grid)).abs() <= efforts).all())

        tests["effort"] = torques_within
    if collision is not None:

        def collision_free(c: Tensor) -> bool:
            return not collision.contacts(family.evaluate(c, grid)[0].numpy(), first_only=True)

        tests["self-collision"] = collision_free
    failing = [name for name, test in tests.items() if not test(inside)]
    if not failing:
        return family.from_vector(inside), None, {"shrunk_by": 1.0}
    try:
        scale = largest_feasible_scale(family, inside, lambda c: all(test(c) for test in tests.values()))
    except ValueError as exc:
        raise ValueError(
            f"optimize_excitation: the optimised motion fails the {' and '.join(failing)} test, and {exc}"
        ) from None
    shrunk = scale_motion(family, inside, torch.full((family.n_joints,), scale, dtype=torch.float64))
    return family.from_vector(shrunk), family.from_vector(inside), {"shrunk_by": scale, "shrunk_for": failing}


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
    started, cpu = time.perf_counter(), time.process_time()
    if method == "adam":
        best = torch.rand(budget["swarms"], dims, generator=generator, dtype=torch.float64).to(**like)
    else:
        # one evaluation of every swarm per iteration, the start's included
        best = _swarm_search(
            counted(objective, "search (particle swarm)", budget["iterations"]),
            dims,
            budget["swarms"],
            budget["particles"],
            budget["iterations"],
            generator,
            like,
        )
        details.update(
            pso_best_loss=float(objective(best).min()),
            pso_seconds=time.perf_counter() - started,
            pso_cpu_seconds=time.process_time() - cpu,
        )
    if method != "pso":
        started, cpu = time.perf_counter(), time.process_time()
        polish = counted(objective, "polish (Adam)", budget["adam_steps"] + 1)
        best = _adam_search(polish, best, budget["adam_steps"], budget["learning_rate"])
        details.update(
            adam_best_loss=float(objective(best).min()),
            adam_seconds=time.perf_counter() - started,
            adam_cpu_seconds=time.process_time() - cpu,
        )
    with torch.no_grad():
        return best[objective(best).argmin()], details


def counted(objective: Callable[[Tensor], Tensor], stage: str, of: int) -> Callable[[Tensor], Tensor]:
    """``objective``, saying on every call (one per iteration) how far ``stage`` is and the lowest
    value so far, to a study that listens (:func:`idkit.progress.report`; nothing otherwise)."""
    calls, best = 0, math.inf

    def call(unit: Tensor) -> Tensor:
        nonlocal calls, best
        value = objective(unit)
        calls += 1
        finite = value.detach()[torch.isfinite(value.detach())]
        best = min(best, float(finite.min())) if finite.numel() else best
        report(stage, calls, of, best if math.isfinite(best) else None, "best loss")
        return value

    return call


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


#: Adam's moment decay rates and denominator guard (Kingma & Ba's defaults, as ``torch.optim.Adam``).
ADAM_BETAS, ADAM_EPS = (0.9, 0.999), 1e-8


def _adam_search(
    objective: Callable[[Tensor], Tensor], starts: Tensor, steps: int, learning_rate: float
) -> Tensor:
    """Adam from ``starts[S, C]`` (independent, projected on the unit cube); each start's best point.

    The update is written out (``torch.optim.Adam``'s algorithm, tested equal to it): the
    optimiser module imports ``torch._dynamo`` on the first call, which costs seconds of CPU
    (docs/speed.md, "Measurements behind design choices").
    """
    unit = starts.clone().requires_grad_(True)
    (beta1, beta2), moment, square = ADAM_BETAS, torch.zeros_like(starts), torch.zeros_like(starts)
    best, best_loss = starts.clone(), torch.full(starts.shape[:1], math.inf, dtype=starts.dtype)
    for step in range(steps + 1):
        value = objective(unit)
        improved = value.detach() < best_loss.to(value.device)
        best = torch.where(improved[:, None], unit.detach(), best)
        best_loss = torch.where(improved, value.detach(), best_loss.to(value.device))
        if step == steps:
            break
        (gradient,) = torch.autograd.grad(value[torch.isfinite(value)].sum(), unit, allow_unused=True)
        gradient = torch.zeros_like(starts) if gradient is None else gradient
        with torch.no_grad():
            moment.mul_(beta1).add_(gradient, alpha=1 - beta1)
            square.mul_(beta2).addcmul_(gradient, gradient, value=1 - beta2)
            denominator = (square.sqrt() / math.sqrt(1 - beta2 ** (step + 1))).add_(ADAM_EPS)
            unit.addcdiv_(moment, denominator, value=-learning_rate / (1 - beta1 ** (step + 1)))
            unit.clamp_(0.0, 1.0)
    return best
