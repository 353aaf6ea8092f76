"""``pso``: the paper's particle swarm estimator, batched over runs and costs on tensors.

The estimator builds the objective (``idkit.estimators.objective``), hands the search to the
array-level swarm (``idkit.optim``: the eager torch engine, or the fast compiled kernel) and reads
the result back into an ``Estimate``: the mean over the runs that ``keep`` retains
(``idkit.estimators.aggregate``). ``runs`` independent swarms (10, as in the paper) — and with
``fit_costs`` several costs, with ``fit_trials`` several trials — are one batched computation.

Presets (every field can be overridden by its own keyword):

- ``"paper"`` — the paper's algorithm: 20 particles, 300 iterations (6,000 cost evaluations per
  run), c1 = c2 = 1.3, inertia 0.9 → 0.4 linearly over the first 100 moves then 0.4, uniform initial
  positions in the box, zero initial velocities, ``r1``/``r2`` per particle and dimension, no
  velocity limit. The paper does not say how it keeps particles in the box; idkit clamps them to
  the wall and zeroes that velocity component (``"clamp"``), the common textbook rule.
- ``"default"`` — the same budget (20 particles × 300 evaluations per run) and update with Clerc
  and Kennedy's constriction coefficients (ref. [12] of the paper: c1 = c2 = 1.49618, w = 0.7298,
  here lowered linearly to 0.5 over the 300 moves) and reflecting walls: its runs reach the least
  squares cost's minimum of f1 far more often than ``"paper"``'s, and the lowered inertia ends
  them closer to it (the measurements: docs/estimators.md, "The PSO presets";
  ``bench/estimators.py`` prints the hit rates). A velocity limit made no difference with
  constriction, so there is none.

PSO's update (per-dimension ``r1``/``r2``, walls per dimension) is invariant to an affine rescaling
of each coordinate, so searching a box normalised to [0, 1]^P would change nothing but rounding;
the search runs in the robot's own units.

Engines. ``"eager"`` is the functional torch swarm (``idkit.optim.swarm``): any cost, any robot,
any device. ``"native"`` runs the fast compiled kernel (``idkit.optim.fast``) for costs that
declare a norm structure (``Cost.structure()``, e.g. the paper's 16) on a robot with a regressor,
on the CPU in float64. ``"auto"`` (default) picks ``"native"`` wherever it applies and
``"eager"`` elsewhere (in a call with several costs, per cost). ``details["engine"]`` and
``["engine_build"]`` record the choice; ``["engine_build_s"]`` the one-time seconds this process
spent loading or compiling the kernel and translating the base map (not part of ``wall_time_s``).
When ``"auto"`` has to take the slower eager engine, a ``SlowEngineWarning`` says why, once per
reason and process. Both engines draw the same random numbers; their trajectories agree to
rounding, and the same seed gives identical numbers for a given engine.

Sizes (``idkit.optim.sizes``). ``runs × particles × iterations``, plus the iterations' own cost
(``PSO_STEP_EVALUATIONS`` each), is capped at ``MAX_EVALUATIONS`` per cost and trial (a bigger
request is refused when the estimator is built), a search that will be long (a big recording,
many trials) says so in one line before it starts, the memory a batch
needs is checked against the machine's before anything is allocated, and the history kept in
``details["history"]`` has at most ``HISTORY_ROWS`` + 1 rows per run: every
``details["history_stride"]``-th iteration from the first, and the last.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any, ClassVar, Literal, get_args

import torch
from torch import Tensor

from idkit.estimate import Estimate
from idkit.estimators.aggregate import KeepRule, aggregate
from idkit.estimators.objective import Objective, fast_structure
from idkit.estimators.search_result import common_details, per_cost_estimates, warn_search_bounds
from idkit.estimators.trials import CHUNK_ELEMENTS, check_chunk, criteria, fit_in_batches, trial_chunk
from idkit.interfaces import Cost, Estimator
from idkit.optim import fast, sizes, swarm
from idkit.problem import SAMPLE_ARRAYS, Problem
from idkit.runtime import available_cores, resolve_threads, torch_threads

Preset = Literal["default", "paper"]
Engine = Literal["auto", "eager", "native"]
Space = Literal["physical", "base"]

PRESETS: dict[str, dict[str, Any]] = {
    "paper": {
        "particles": 20,
        "iterations": 300,
        "c1": 1.3,
        "c2": 1.3,
        "inertia": (0.9, 0.4, 100),
        "boundary": "clamp",
        "velocity_limit": None,
        "per_particle": False,
    },
    "default": {
        "particles": 20,
        "iterations": 300,
        "c1": 1.49618,
        "c2": 1.49618,
        "inertia": (0.7298, 0.5, 300),
        "boundary": "reflect",
        "velocity_limit": None,
        "per_particle": False,
    },
}


class SlowEngineWarning(UserWarning):
    """``engine="auto"`` runs the eager engine where the fast one was hoped for; says why."""


_WARNED: set[str] = set()


def _warn_slow(reason: str) -> None:
    if reason not in _WARNED:
        _WARNED.add(reason)
        warnings.warn(f"pso runs the slower eager engine: {reason}", SlowEngineWarning, stacklevel=4)


@dataclass(frozen=True)
class SwarmSettings:
    """A ``ParticleSwarm``'s settings, resolved at each fit: the preset's values with the overrides.

    Attributes:
        preset: the preset the values came from.
        runs, particles, iterations: the budget (checked: integers >= 1, under ``MAX_EVALUATIONS``).
        rules: the update rule (``swarm.SwarmRules``).
        keep: the rule for omitting runs (``KeepRule``).
        engine: ``"auto"``, ``"eager"`` or ``"native"``.
        stride: the history keeps every ``stride``-th iteration (``sizes.history_stride``).
    """

    preset: Preset
    runs: int
    particles: int
    iterations: int
    rules: swarm.SwarmRules
    keep: KeepRule
    engine: Engine
    stride: int

    def describe(self) -> dict[str, Any]:
        """The preset's fields as resolved (``details["settings"]``)."""
        rules = self.rules
        return {
            "particles": self.particles,
            "iterations": self.iterations,
            "c1": rules.c1,
            "c2": rules.c2,
            "inertia": rules.inertia,
            "boundary": rules.boundary,
            "velocity_limit": rules.velocity_limit,
            "per_particle": rules.per_particle,
        }


class ParticleSwarm(Estimator):
    """Batched global-best PSO minimising ``problem.cost`` over the robot's search box.

    Args:
        preset: ``"default"`` or ``"paper"`` (module docstring); fills every option left ``None``.
        runs: independent swarms per cost; the estimate averages the kept ones.
        particles, iterations: swarm size ``K`` and evaluations per particle (the first is the
            initial population), so ``K · iterations`` cost evaluations per run.
        c1, c2, inertia, boundary, velocity_limit, per_particle: see ``swarm.SwarmRules``.
        keep: the rule for "omitting runs whose cost is relatively too large": a ``KeepRule``, its
            fields as a dict, or its kind (``"relative"``, ``"mad"``, ``"best"``, ``"all"``).
        space: ``"physical"``/``"base"`` search space; ``None`` follows ``robot.search_space``.
        use_regressor: predict torques through the regressor (``None``: when the robot has one).
        threads: threads of the eager engine (torch intra-op) and most threads of the fast
            kernel; ``None``: by problem size (``idkit.runtime``) for torch, every core for the
            kernel, which uses a thread only when a call has enough evaluations.
        history: keep each run's best cost per iteration in ``details["history"]`` (at most
            ``sizes.HISTORY_ROWS`` + 1 rows; module docstring).
        label: estimator label; default ``"PSO-<cost>"`` (e.g. ``PSO-f13``).
        engine: ``"auto"`` (the fast kernel where it applies, else eager torch), ``"eager"`` or
            ``"native"`` (an error where it does not apply); see the module docstring.
    """

    conformance_options: ClassVar[dict[str, Any]] = {"runs": 3, "particles": 6, "iterations": 15}

    def __init__(
        self,
        preset: Preset = "default",
        runs: int = 10,
        particles: int | None = None,
        iterations: int | None = None,
        c1: float | None = None,
        c2: float | None = None,
        inertia: tuple[float, float, int] | None = None,
        boundary: swarm.Boundary | None = None,
        velocity_limit: float | None = None,
        per_particle: bool | None = None,
        keep: KeepRule | dict[str, Any] | str = "relative",
        space: Space | None = None,
        use_regressor: bool | None = None,
        threads: int | None = None,
        history: bool = True,
        label: str | None = None,
        engine: Engine = "auto",
    ) -> None:
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
        self.label = label
        self.engine = engine
        self.resolve()  # a bad option is refused now; every fit resolves again (idkit.hyperparameters)

    def resolve(self) -> SwarmSettings:
        """The preset with this instance's overrides applied, checked (``ValueError`` naming the option)."""
        if self.preset not in PRESETS:
            raise ValueError(f"unknown PSO preset {self.preset!r}; use one of {', '.join(PRESETS)}")
        engines = get_args(Engine)
        if self.engine not in engines:
            raise ValueError(f"unknown PSO engine {self.engine!r}; use one of {', '.join(engines)}")
        values = dict(PRESETS[self.preset])
        for name in values:
            if getattr(self, name) is not None:
                values[name] = getattr(self, name)
        for name, value in (
            ("runs", self.runs),
            ("particles", values["particles"]),
            ("iterations", values["iterations"]),
        ):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"pso option {name} must be an integer >= 1, got {value!r}")
        sizes.check_evaluations(
            "pso",
            {"runs": self.runs, "particles": values["particles"], "iterations": values["iterations"]},
            "iterations",
            sizes.PSO_STEP_EVALUATIONS,
        )
        inertia = tuple(values["inertia"])
        if len(inertia) != 3:
            raise ValueError(f"pso option inertia must be (w_start, w_end, ramp), got {values['inertia']!r}")
        rules = swarm.SwarmRules(
            c1=float(values["c1"]),
            c2=float(values["c2"]),
            inertia=(float(inertia[0]), float(inertia[1]), int(inertia[2])),
            boundary=values["boundary"],
            velocity_limit=values["velocity_limit"],
            per_particle=bool(values["per_particle"]),
        )
        return SwarmSettings(
            preset=self.preset,
            runs=self.runs,
            particles=values["particles"],
            iterations=values["iterations"],
            rules=rules,
            keep=KeepRule.parse(self.keep),
            engine=self.engine,
            stride=sizes.history_stride(values["iterations"]),
        )

    def fit(self, problem: Problem) -> Estimate:
        """Minimise ``problem.cost`` (required)."""
        if problem.cost is None:
            raise ValueError("pso minimises problem.cost, which is None; give the problem a cost (e.g. f13)")
        return self.fit_costs(problem, [problem.cost])[0]

    def fit_costs(self, problem: Problem, costs: Sequence[Cost]) -> list[Estimate]:
        """One estimate per cost, all costs' runs in one batched computation.

        The swarms of cost ``c`` draw their random numbers from the same generator as the others,
        so a cost's result depends on which costs share the call (still reproducible: same seed,
        same cost list → identical estimates). ``wall_time_s`` is the call's time divided by the
        number of costs; the total is in ``details["batch_wall_time_s"]``.
        """
        return warn_search_bounds(problem, self.fit_trials([problem], costs)[0])

    def fit_trials(
        self, problems: Sequence[Problem], costs: Sequence[Cost] | None = None, chunk: int | None = None
    ) -> list[list[Estimate]]:
        """One estimate per trial and cost: trials × costs × runs as one batched swarm per chunk.

        Each trial is a ``Problem`` of the same robot, sample count, device and dtype (a study's
        noise draws); its runs draw from its own seed (``problem.seed``), so trial ``t``'s
        estimates equal ``fit_costs(problems[t], costs)`` and never depend on the other trials or
        on ``chunk``.

        Args:
            problems: ``T`` trials (their ``cost`` is ignored).
            costs: ``C`` costs, each fitted on every trial (``None``: the problems' shared cost).
            chunk: trials per batched computation (trials of equal sample counts share one), to
                bound memory; ``None`` picks it from the problem size (about ``CHUNK_ELEMENTS``
                error elements per chunk).

        Returns:
            ``T`` lists of ``C`` estimates; ``details["batched_trials"]`` says how many trials
            shared the computation and ``details["engine"]`` which engine ran it.
        """
        settings = self.resolve()
        problems, costs = list(problems), criteria(problems, costs)
        for problem in problems:
            problem.check_identifiable()
        check_chunk(chunk)
        sizes.announce_long_search(
            "pso",
            settings.runs * settings.particles * settings.iterations,
            len(costs),
            [p.samples.tau.numel() for p in problems],
            sizes.PSO_RESIDUAL_NS,
        )

        def per_run(problem: Problem) -> int:
            """Error-tensor elements of one run of every cost on this trial."""
            return len(costs) * settings.particles * problem.robot.n_joints * problem.samples.n_samples

        def run_chunk(problem: Problem) -> int:
            """Runs per chunk: big batches run as consecutive chunks of runs whose tensors stay in
            the CPU cache (elementwise ops on big tensors are much slower per element: docs/speed.md,
            "Measurements behind design choices")."""
            return max(1, CHUNK_ELEMENTS // per_run(problem))

        def trials_per_batch(problem: Problem) -> int:
            """Small trials are stacked instead, several per batch; a big one is a batch alone."""
            whole = run_chunk(problem) >= settings.runs
            return trial_chunk(chunk, per_run(problem) * settings.runs if whole else CHUNK_ELEMENTS)

        def fit_batch(batch: list[Problem]) -> list[list[Estimate]]:
            return self._fit_group(batch, costs, run_chunk(batch[0]), settings)

        return fit_in_batches(problems, trials_per_batch, fit_batch)

    def _fit_group(
        self, problems: list[Problem], costs: list[Cost], run_chunk: int, settings: SwarmSettings
    ) -> list[list[Estimate]]:
        """``fit_trials`` of one chunk of trials."""
        count, trials = len(costs), len(problems)
        robot = problems[0].robot
        rows = len(swarm.history_rows(settings.iterations, settings.stride))
        chunk_runs = min(run_chunk, settings.runs)
        dimension = max(len(robot.param_names), len(robot.base_param_names))
        sizes.check_memory(
            f"pso: {trials} trial(s) × {count} cost(s) × runs={settings.runs} of "
            f"particles={settings.particles} ({rows} history rows)",
            sizes.swarm_bytes(trials * count, settings.runs, settings.particles, dimension, rows)
            + sizes.error_bytes(
                trials * count * chunk_runs * settings.particles, problems[0].samples.tau.numel()
            ),
            "lower runs or particles, or fit the trials in smaller chunks",
        )
        started = time.perf_counter()
        prepared = self._prepared(problems, costs)
        objective = prepared.objective if prepared is not None else self._objective(problems, costs)
        n, samples = objective.shape
        threads = resolve_threads(
            self.threads, objective.slots * chunk_runs * settings.particles * n * samples
        )
        # torch's pool pays only for big tensors (resolve_threads); the kernel uses a thread only
        # for enough evaluations (fast.EVALUATIONS_PER_THREAD), so it may use every core.
        kernel_threads = self.threads if self.threads is not None else available_cores()
        engines: list[dict[str, Any]] = [{} for _ in costs]
        with torch_threads(threads), torch.inference_mode():
            if prepared is None:
                groups = self._engines(problems, costs, objective)
                build_seconds = sum(group.details["engine_build_s"] for group in groups)
                self._keep_prepared(problems, costs, objective, groups)
            else:
                groups, build_seconds = prepared.groups, 0.0
            uniform = swarm.Draws([swarm.Uniform.seeded(p.seed, objective.lower) for p in problems])
            parts = []
            for group in groups:
                used = kernel_threads if group.fast else threads
                chunks = [
                    group.run(min(run_chunk, settings.runs - start), settings, uniform, used)
                    for start in range(0, settings.runs, run_chunk)
                ]
                if group.fast:  # the threads its kernel calls used
                    swarms = len(group.members) * trials * chunk_runs
                    used = fast.thread_count(used, trials, swarms, settings.particles, settings.iterations)
                for c in group.members:
                    engines[c] = {**group.details, "threads": used}
                parts.append(
                    [
                        torch.cat(part, dim=axis) if len(part) > 1 else part[0]
                        for part, axis in (
                            ([state.global_position for state, _ in chunks], 1),
                            ([state.global_cost for state, _ in chunks], 1),
                            ([h for _, h in chunks], 2),
                        )
                    ]
                )
            if len(groups) == 1:  # every slot in its place already
                position, run_costs, history = parts[0]
            else:
                position = objective.lower.new_empty((objective.slots, settings.runs, objective.dimension))
                run_costs = objective.lower.new_empty((objective.slots, settings.runs))
                history = objective.lower.new_empty((rows, objective.slots, settings.runs))
                for group, (group_position, group_costs, group_history) in zip(groups, parts, strict=True):
                    slots = torch.tensor([t * count + c for t in range(trials) for c in group.members])
                    position[slots], run_costs[slots] = group_position, group_costs
                    history[:, slots] = group_history
            mean, kept = aggregate(position, run_costs, settings.keep)
            values = [objective.exact(s, mean[s]) for s in range(objective.slots)]
        # The one-time kernel build and base-map translation are recorded apart (engine_build_s).
        wall = time.perf_counter() - started - build_seconds
        estimates = []
        for t, problem in enumerate(problems):
            part = slice(t * count, (t + 1) * count)
            common = common_details(problem, objective, costs, settings.keep, threads, wall / trials)
            common.update(
                preset=settings.preset,
                settings=settings.describe(),
                evaluations_per_run=settings.particles * settings.iterations,
                batched_trials=trials,
                history_stride=settings.stride,
            )
            estimates.append(
                per_cost_estimates(
                    problem,
                    objective,
                    costs,
                    self.label or "PSO-{cost}",
                    position[part],
                    run_costs[part],
                    kept[part],
                    mean[part],
                    values[part],
                    history[:, part] if self.history else None,
                    common,
                )
            )
            for estimate, engine in zip(estimates[-1], engines, strict=True):
                estimate.details = {**estimate.details, **engine}
        return estimates

    def _objective(self, problems: list[Problem], costs: list[Cost]) -> Objective:
        return Objective(problems, costs, space=self.space, use_regressor=self.use_regressor)

    def _prepared(self, problems: list[Problem], costs: list[Cost]) -> Prepared | None:
        """The objective and engine groups of the previous fit if it had the same trials and costs,
        unchanged since (``Prepared``); else ``None``."""
        kept = getattr(self, "_last_prepared", None)
        if kept is None or kept.key != self._prepared_key(problems, costs):
            return None
        if any(a is not b for a, b in zip((*kept.problems, *kept.costs), (*problems, *costs), strict=True)):
            return None
        return kept if kept.versions == _versions(problems, costs) else None

    def _prepared_key(self, problems: list[Problem], costs: list[Cost]) -> tuple:
        ids = tuple(id(p) for p in problems), tuple(id(c) for c in costs)
        return (*ids, self.space, self.use_regressor, self.engine)

    def _keep_prepared(
        self, problems: list[Problem], costs: list[Cost], objective: Objective, groups: list[EngineGroup]
    ) -> None:
        self._last_prepared = Prepared(
            self._prepared_key(problems, costs),
            tuple(problems),
            tuple(costs),
            _versions(problems, costs),
            objective,
            groups,
        )

    def __getstate__(self) -> dict[str, Any]:
        """Pickled without the prepared objective (tensors of the last problems fitted)."""
        return {k: v for k, v in self.__dict__.items() if k != "_last_prepared"}

    def _engines(self, problems: list[Problem], costs: list[Cost], objective: Objective) -> list[EngineGroup]:
        """Which costs run on which engine, and what ``details`` records about it (module docstring).

        With ``"auto"``, costs whose declared structure the fast kernel knows run on it and the
        others on the eager engine (fused where they declare a structure), one after the other on
        the same random streams; with ``"native"`` every cost must suit the kernel.
        """

        def subset(members: list[int]) -> Objective:
            if len(members) == len(costs):
                return objective
            return self._objective(problems, [costs[c] for c in members])

        def eager(members: list[int], why: str) -> EngineGroup:
            if self.engine == "auto":
                _warn_slow(why)
            part = subset(members)
            details = {"engine": "eager", "engine_build": why, "engine_build_s": 0.0}
            return EngineGroup(members, details, partial(_run_eager, part), fast=False)

        everything = list(range(len(costs)))
        if self.engine == "eager":
            return [eager(everything, "engine='eager' was asked for")]

        def refused(reason: str) -> list[EngineGroup]:
            if self.engine == "native":
                raise ValueError(
                    f"engine='native' is impossible here: {reason}; use engine='auto' or 'eager'"
                )
            return [eager(everything, reason)]

        refusals = {c: _cost_refusal(objective, c) for c in everything}
        chosen = [c for c in everything if refusals[c] is None] if self.engine == "auto" else everything
        if not chosen:
            return refused("; ".join(sorted({why for why in refusals.values() if why is not None})))
        # with engine="native", every cost the kernel refuses is named
        named = "; ".join(sorted({why for c in chosen if (why := refusals[c]) is not None}))
        if named:
            return refused(named)
        started = time.perf_counter()
        part = subset(chosen)
        spec = part.spec()  # traces the base map, or reads it from the cache
        reason = fast.refusal(spec)  # loads (or compiles) the kernel
        build_seconds = time.perf_counter() - started
        built = fast.kernel()  # loaded by refusal(): the reason, or the kernel
        if reason is not None or isinstance(built, str):
            return refused(reason or str(built))
        where = "base map in the kernel" if spec.tape is not None else "base map in torch (not translatable)"
        details = {
            "engine": "native",
            "engine_build": f"{built.how}; {where}",
            "engine_build_s": build_seconds,
        }
        groups = [EngineGroup(chosen, details, partial(_run_fast, part, spec), fast=True)]
        rest = [c for c in everything if c not in chosen]
        if rest:
            groups.append(
                eager(rest, "; ".join(sorted({why for c in rest if (why := refusals[c]) is not None})))
            )
        return groups


@dataclass(frozen=True)
class Prepared:
    """What a fit builds before its first random number — the objective (regressor, divided
    torques, fused norms) and which engine runs which cost (with the kernel's spec and base-map
    tape) — kept by the estimator for its next fit. It depends only on the trials and costs, so a
    repeated fit of the same ``Problem`` objects (a benchmark, an interactive session, the
    one-run fits of a sweep) reuses it; the versions of the samples' tensors (bumped by any
    in-place change) and the costs' declared structures must be unchanged, or it is rebuilt."""

    key: tuple
    problems: tuple[Problem, ...]  # held, so that the ids in ``key`` stay theirs
    costs: tuple[Cost, ...]
    versions: tuple
    objective: Objective
    groups: list[EngineGroup]


def _versions(problems: list[Problem], costs: list[Cost]) -> tuple:
    """What must not have changed for a ``Prepared`` to be reused: each sample tensor's version
    counter (torch bumps it on every in-place change) and each cost's declared structure."""
    tensors = tuple(getattr(p.samples, name)._version for p in problems for name in SAMPLE_ARRAYS)
    return tensors, tuple(fast_structure(cost) for cost in costs)


@dataclass(frozen=True)
class EngineGroup:
    """Costs run by one engine: their indices, what ``details`` records, and the runner
    ``run(runs, settings, draws, threads) -> (state, history)``."""

    members: list[int]
    details: dict[str, Any]
    run: Callable[[int, SwarmSettings, swarm.Draws, int], tuple[swarm.SwarmState, Tensor]]
    fast: bool


def _cost_refusal(objective: Objective, c: int) -> str | None:
    """Why the fast kernel cannot run cost ``c`` of ``objective`` whatever the batch, or ``None``."""
    cost, structure = objective.costs[c], objective.structures[c]
    name = type(cost).__name__
    if structure is None:
        return f"{name}: the cost declares no norm structure (Cost.structure)"
    if not objective.use_regressor:
        return "the fast kernel needs the regressor (use_regressor)"
    try:
        fast.factor_codes([structure], objective.shape[0] * objective.shape[1])
    except ValueError as error:
        return f"{name}: {error} (eager engine, fused)"
    return None


def _run_eager(
    objective: Objective, runs: int, settings: SwarmSettings, uniform: swarm.Draws, threads: int
) -> tuple[swarm.SwarmState, Tensor]:
    """The eager engine (torch's intra-op threads are already set to ``threads``)."""
    return swarm.run(
        objective,
        objective.lower,
        objective.upper,
        (objective.slots, runs),
        settings.particles,
        settings.iterations,
        settings.rules,
        uniform,
        settings.stride,
    )


def _run_fast(
    objective: Objective,
    spec: fast.ProductSpec,
    runs: int,
    settings: SwarmSettings,
    uniform: swarm.Draws,
    threads: int,
) -> tuple[swarm.SwarmState, Tensor]:
    """The fast kernel: trials spread over up to ``threads`` threads."""
    return fast.run(
        spec,
        objective.lower,
        objective.upper,
        runs,
        settings.particles,
        settings.iterations,
        settings.rules,
        uniform,
        threads,
        settings.stride,
    )
