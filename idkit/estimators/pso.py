"""``pso``: the paper's particle swarm estimator, batched over runs and costs on tensors.

``runs`` independent swarms (10, as in the paper) — and with ``fit_costs`` several costs — are one
tensor computation (``idkit.estimators.swarm``); only the iterations are a Python loop. The
reported estimate is the mean over the runs that ``keep`` retains (``idkit.estimators.aggregate``).

Presets (every field can be overridden by its own keyword):

- ``"paper"`` — the paper's algorithm: 20 particles, 300 iterations (6,000 cost evaluations per
  run), c1 = c2 = 1.3, inertia 0.9 → 0.4 linearly over the first 100 moves then 0.4, uniform initial
  positions in the box, zero initial velocities, ``r1``/``r2`` per particle and dimension, no
  velocity limit. The paper does not say how it keeps particles in the box; idkit clamps them to
  the wall and zeroes that velocity component (``"clamp"``), the common textbook rule.
- ``"default"`` — the same budget (20 particles × 300 evaluations per run) and update with Clerc
  and Kennedy's constriction coefficients (ref. [12] of the paper: c1 = c2 = 1.49618, w = 0.7298,
  here lowered linearly to 0.5 over the 300 moves) and reflecting walls. Measured on the
  cylindrical robot (``torque_noise``, f1, 200 runs on each of 6 noise draws, a hit = within 0.1 %
  of the LS cost): ``"paper"`` hits 86–90 % of runs; reflecting walls alone 95–97 %; constriction
  with reflecting walls 100 % (0 misses in 1,200 runs), with or without the lowered inertia. The
  lowered inertia is for precision: on noise-free data, where f1 is a cone at the truth, PSO-f1
  ends within 1e-3 of the true parameters on 10/10 seeds (constant w = 0.7298: 8/10; ``"paper"``:
  median run 7e-2 off). Constriction also reaches the best known value of most other costs more
  often than ``"paper"`` (bench/estimators.py prints the f1 hit rates). A velocity limit made no
  difference with constriction, so there is none.

PSO's update (per-dimension ``r1``/``r2``, walls per dimension) is invariant to an affine rescaling
of each coordinate, so searching a box normalised to [0, 1]^P would change nothing but rounding;
the search runs in the robot's own units.

Engines. ``"eager"`` is the functional torch swarm (``idkit.estimators.swarm``): any cost, any
robot, any device. ``"native"`` runs whole runs as one compiled C call (``idkit.estimators.native``)
for costs that declare a norm structure (``Cost.structure()``, e.g. the paper's 16) on a robot
with a regressor, on the CPU in float64; its compile step (about a second with gcc, per problem
size) happens once per machine and is cached on disk. ``"auto"`` (default) picks ``"native"``
wherever it applies — measured faster at every batch size (``docs/speed.md``) — and ``"eager"``
elsewhere (in a call with several costs, per cost: costs without a structure run eager beside the
others, called as they are, and so do costs declaring a factor the kernel has no code for,
evaluated fused); ``details["engine"]``, ``["engine_build"]`` and ``["engine_compile_s"]`` record
the choice. Both engines use the same random numbers; their trajectories agree to rounding.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any, ClassVar

import torch
from torch import Tensor

from idkit.estimate import Estimate
from idkit.estimators import native, swarm
from idkit.estimators.aggregate import KeepRule, aggregate
from idkit.estimators.objective import Objective
from idkit.estimators.search_result import common_details, per_cost_estimates
from idkit.estimators.trials import CHUNK_ELEMENTS, check_chunk, criteria, fit_in_batches, trial_chunk
from idkit.interfaces import Cost, Estimator
from idkit.problem import Problem
from idkit.runtime import available_cores, resolve_threads, torch_threads

#: ``engine`` values: how the swarm's iterations are computed.
ENGINES = ("auto", "eager", "native")

#: Costs run by one engine: ``(cost indices, their objective, details to record, runner)``.
EngineGroup = tuple[list[int], Objective, dict[str, Any], Callable[..., tuple[swarm.SwarmState, Tensor]]]

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
        threads: threads of the eager engine (torch intra-op) and most threads of the native
            kernel; ``None``: by problem size (``idkit.runtime``) for torch, every core for the
            kernel, which starts a thread only when a call has enough evaluations.
        history: keep each run's best cost per iteration in ``details["history"]``.
        label: estimator label; default ``"PSO-<cost>"`` (e.g. ``PSO-f13``).
        engine: ``"auto"`` (the native kernel where it applies, else eager torch), ``"eager"`` or
            ``"native"`` (an error where it does not apply); see the module docstring.
    """

    conformance_options: ClassVar[dict[str, Any]] = {"runs": 3, "particles": 6, "iterations": 15}

    def __init__(
        self,
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
        label: str | None = None,
        engine: str = "auto",
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
        self.settings()  # validate early: a bad option fails at construction, not mid-sweep

    def settings(self) -> dict[str, Any]:
        """The preset with this instance's overrides applied (``velocity_limit`` may be None).

        Pure: validates and returns, sets nothing. Raises ``ValueError`` naming the bad option.
        """
        if self.preset not in PRESETS:
            raise ValueError(f"unknown PSO preset {self.preset!r}; use one of {', '.join(PRESETS)}")
        if self.engine not in ENGINES:
            raise ValueError(f"unknown PSO engine {self.engine!r}; use one of {', '.join(ENGINES)}")
        resolved = dict(PRESETS[self.preset])
        for name in resolved:
            value = getattr(self, name)
            if value is not None:
                resolved[name] = value
        for name, value in (
            ("runs", self.runs),
            ("particles", resolved["particles"]),
            ("iterations", resolved["iterations"]),
        ):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"pso option {name} must be an integer >= 1, got {value!r}")
        resolved["inertia"] = tuple(resolved["inertia"])
        self.rules(resolved)
        KeepRule.parse(self.keep)
        return resolved

    @staticmethod
    def rules(settings: dict[str, Any]) -> swarm.SwarmRules:
        """The swarm's update rule of resolved ``settings`` (validated by ``SwarmRules``)."""
        inertia = settings["inertia"]
        return swarm.SwarmRules(
            c1=float(settings["c1"]),
            c2=float(settings["c2"]),
            inertia=(float(inertia[0]), float(inertia[1]), int(inertia[2])),
            boundary=settings["boundary"],
            velocity_limit=settings["velocity_limit"],
            per_particle=bool(settings["per_particle"]),
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
        return self.fit_trials([problem], costs)[0]

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
                bound memory; ``None`` picks it from the
                problem size (about ``CHUNK_ELEMENTS`` error elements per chunk).

        Returns:
            ``T`` lists of ``C`` estimates; ``details["batched_trials"]`` says how many trials
            shared the computation and ``details["engine"]`` which engine ran it.
        """
        settings = self.settings()
        problems, costs = list(problems), criteria(problems, costs)
        for problem in problems:
            problem.check_identifiable()
        check_chunk(chunk)

        def per_run(problem: Problem) -> int:
            """Error-tensor elements of one run of every cost on this trial."""
            return len(costs) * settings["particles"] * problem.robot.n_joints * problem.samples.n_samples

        def run_chunk(problem: Problem) -> int:
            """Runs per chunk: big batches run as consecutive chunks of runs whose tensors stay in
            the CPU cache (elementwise ops on [10,000 × 20 × 4] run ~4× slower per element than on
            [500 × 20 × 4])."""
            return max(1, CHUNK_ELEMENTS // per_run(problem))

        def trials_per_batch(problem: Problem) -> int:
            """Small trials are stacked instead, several per batch; a big one is a batch alone."""
            whole = run_chunk(problem) >= self.runs
            return trial_chunk(chunk, per_run(problem) * self.runs if whole else CHUNK_ELEMENTS)

        def fit_batch(batch: list[Problem]) -> list[list[Estimate]]:
            return self._fit_group(batch, costs, settings, run_chunk(batch[0]))

        return fit_in_batches(problems, trials_per_batch, fit_batch)

    def _fit_group(
        self, problems: list[Problem], costs: list[Cost], settings: dict[str, Any], run_chunk: int
    ) -> list[list[Estimate]]:
        """``fit_trials`` of one chunk of trials."""
        started = time.perf_counter()
        rules, keep = self.rules(settings), KeepRule.parse(self.keep)
        objective = Objective(problems, costs, space=self.space, use_regressor=self.use_regressor)
        n, samples = objective.shape
        threads = resolve_threads(
            self.threads, min(objective.slots * self.runs, run_chunk) * settings["particles"] * n * samples
        )
        # torch's pool pays only for big tensors (resolve_threads); the kernel itself starts a
        # thread only for enough evaluations (native.EVALUATIONS_PER_THREAD), so it may use all.
        kernel_threads = self.threads if self.threads is not None else available_cores()
        count, trials = len(costs), len(problems)
        engines: list[dict[str, Any]] = [{} for _ in costs]
        with torch_threads(threads), torch.inference_mode():
            uniform = swarm.Draws([swarm.Uniform(p.generator(), objective.lower) for p in problems])
            position = objective.lower.new_empty((objective.slots, self.runs, objective.dimension))
            run_costs = objective.lower.new_empty((objective.slots, self.runs))
            history = objective.lower.new_empty((settings["iterations"], objective.slots, self.runs))
            for members, part, engine, runner in self._engines(problems, costs, objective):
                if runner is _run_native:  # the kernel splits trials over threads when it pays
                    swarms = part.slots * min(run_chunk, self.runs)
                    used = native.call_threads(
                        part, swarms, settings["particles"], settings["iterations"], kernel_threads
                    )
                    engine = {**engine, "threads": used}
                chunks = [
                    runner(
                        part,
                        (part.slots, min(run_chunk, self.runs - start)),
                        settings,
                        rules,
                        uniform,
                        kernel_threads if runner is _run_native else threads,
                    )
                    for start in range(0, self.runs, run_chunk)
                ]
                slots = torch.tensor([t * count + c for t in range(trials) for c in members])
                position[slots] = torch.cat([state.global_position for state, _ in chunks], dim=1)
                run_costs[slots] = torch.cat([state.global_cost for state, _ in chunks], dim=1)
                history[:, slots] = torch.cat([h for _, h in chunks], dim=2)
                for c in members:
                    engines[c] = engine
            mean, kept = aggregate(position, run_costs, keep)
            values = [objective.exact(s, mean[s]) for s in range(objective.slots)]
        wall = time.perf_counter() - started
        count = len(costs)
        estimates = []
        for t, problem in enumerate(problems):
            part = slice(t * count, (t + 1) * count)
            common = common_details(problem, objective, costs, keep, threads, wall / len(problems))
            common.update(
                preset=self.preset,
                settings=settings,
                evaluations_per_run=settings["particles"] * settings["iterations"],
                batched_trials=len(problems),
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
                estimate.details.update(engine)
        return estimates

    def _engines(self, problems: list[Problem], costs: list[Cost], objective: Objective) -> list[EngineGroup]:
        """Which costs run on which engine, and what ``details`` records about it (module docstring).

        With ``"auto"``, costs whose declared structure the native kernel knows run on it and the
        others on the eager engine (fused where they declare a structure, ``NormProducts``), one
        after the other on the same random streams; with ``"native"`` every cost must suit the
        kernel.
        """

        def subset(members: list[int]) -> Objective:
            if len(members) == len(costs):
                return objective
            chosen = [costs[c] for c in members]
            return Objective(problems, chosen, space=self.space, use_regressor=self.use_regressor)

        def eager(members: list[int], why: str) -> EngineGroup:
            return (
                members,
                subset(members),
                {"engine": "eager", "engine_build": why, "engine_compile_s": 0.0},
                _run_eager,
            )

        everything = list(range(len(costs)))
        if self.engine == "eager":
            return [eager(everything, "engine='eager' was asked for")]
        refusals = {c: native.cost_refusal(costs[c], objective.structures[c]) for c in everything}
        fast = [c for c in everything if refusals[c] is None] if self.engine == "auto" else everything
        part = subset(fast) if fast else None
        if part is None:
            why = "; ".join(sorted(set(refusals.values())))
            reason = f"no cost declares a structure the native kernel knows ({why})"
        else:  # with engine="native", every cost the kernel refuses is named
            reason = "; ".join(sorted({refusals[c] for c in fast} - {None})) or native.supports(part)
        if reason is not None:
            if self.engine == "native":
                raise ValueError(
                    f"engine='native' is impossible here: {reason}; use engine='auto' or 'eager'"
                )
            return [eager(everything, reason)]
        _, how, seconds = native.build(part)
        in_c = native.robot_map(part) is not None
        how += "; base map in C" if in_c else "; base map in torch (not translatable)"
        seconds += native.map_seconds(part)
        groups = [
            (fast, part, {"engine": "native", "engine_build": how, "engine_compile_s": seconds}, _run_native)
        ]
        rest = [c for c in everything if c not in fast]
        if rest:
            groups.append(eager(rest, "; ".join(sorted({refusals[c] for c in rest}))))
        return groups


def _run_eager(
    objective: Objective,
    batch: tuple[int, int],
    settings: dict[str, Any],
    rules: swarm.SwarmRules,
    uniform: swarm.Draws,
    threads: int,
) -> tuple[swarm.SwarmState, Tensor]:
    """The eager engine (torch's intra-op threads are already set to ``threads``)."""
    return swarm.run(
        objective,
        objective.lower,
        objective.upper,
        batch,
        settings["particles"],
        settings["iterations"],
        rules,
        uniform,
    )


def _run_native(
    objective: Objective,
    batch: tuple[int, int],
    settings: dict[str, Any],
    rules: swarm.SwarmRules,
    uniform: swarm.Draws,
    threads: int,
) -> tuple[swarm.SwarmState, Tensor]:
    """The native engine: whole runs per kernel call, trials split over up to ``threads`` threads."""
    return native.run(
        objective, batch, settings["particles"], settings["iterations"], rules, uniform, threads
    )
