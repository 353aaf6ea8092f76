"""Where a PSO fit's time goes, per engine and batch size (the profile behind docs/speed.md).

Run: ``python bench/profile_pso.py``. For one run, a 10-run estimate and one chunk of a 10,000-run
batch (436 runs; paper preset, f13, ``torque_noise``, one thread) it prints the CPU time per move
(of the 299 moves of a 300-iteration run; CPU time, because the machine is shared; the fast
engine's averaged over many calls), per particle-move, and its split:

- eager engine: torch ops per move and their summed self time (``torch.profiler``), and the rest
  (Python between ops);
- fast engine: the kernel loop (base map, costs and moves, compiled) and the whole estimator around
  it, split into its parts (CPU time of each, summed over the repeated fits): the engine call
  (``fast.run``: initial draw, kernel, state back to tensors), the exact cost at the mean, the keep
  rule, the estimates and the rest. A repeated fit of the same ``Problem`` reuses the objective
  (``pso.Prepared``), as the benchmark's repeated calls do.
"""

from __future__ import annotations

import collections
import functools
import time

import torch
from torch.profiler import ProfilerActivity, profile

from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators import pso as pso_module
from idkit.estimators.objective import Objective
from idkit.estimators.pso import ParticleSwarm
from idkit.optim import fast, swarm
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot

ITERATIONS = 300


def main() -> None:
    torch.set_num_threads(1)
    robot = CylindricalRobot()
    problem = Problem(robot, simulate(robot, "torque_noise", seed=0), paper.f13(), seed=0)
    objective = Objective(problem, [paper.f13()])
    rules = ParticleSwarm(preset="paper").resolve().rules
    print("| runs | engine | µs CPU per move (ns per particle-move) | split |\n| --- | --- | --- | --- |")
    for runs in (1, 10, 436):  # 436 = the chunk of runs a 10,000-run batch is cut into
        draws = lambda: swarm.Draws([swarm.Uniform(problem.generator(), objective.lower)])  # noqa: E731
        shape = (1, runs)
        # eager: ops per move from the profiler
        swarm.run(objective, objective.lower, objective.upper, shape, 20, ITERATIONS, rules, draws())
        start = time.process_time()
        swarm.run(objective, objective.lower, objective.upper, shape, 20, ITERATIONS, rules, draws())
        wall = time.process_time() - start
        with profile(activities=[ProfilerActivity.CPU]) as prof:
            swarm.run(objective, objective.lower, objective.upper, shape, 20, ITERATIONS, rules, draws())
        events = [e for e in prof.key_averages() if e.key.startswith("aten::")]
        ops = sum(e.count for e in events) / (ITERATIONS - 1)
        op_time = sum(e.self_cpu_time_total for e in events) / (ITERATIONS - 1)
        move = wall / (ITERATIONS - 1)
        print(
            f"| {runs} | eager | {move * 1e6:.0f} ({move / runs / 20 * 1e9:.0f}) | {ops:.0f} aten calls per "
            f"move (views included), {op_time:.0f} µs self time under the profiler |"
        )
        # fast: the kernel loop vs the whole estimator around it
        spec = objective.spec()
        fast.run(spec, objective.lower, objective.upper, runs, 20, ITERATIONS, rules, draws())
        calls = max(3, 300 // runs)
        start = time.process_time()
        for _ in range(calls):
            fast.run(spec, objective.lower, objective.upper, runs, 20, ITERATIONS, rules, draws())
        loop = (time.process_time() - start) / calls
        pso = ParticleSwarm(preset="paper", runs=runs, threads=1, history=False)
        pso.fit(problem)
        fits = max(3, 300 // runs)
        start = time.process_time()
        for _ in range(fits):
            pso.fit(problem)
        whole = (time.process_time() - start) / fits
        parts = _parts(pso, problem, fits)
        move = loop / (ITERATIONS - 1)
        split = ", ".join(f"{name} {seconds * 1e3:.2f}" for name, seconds in parts.items())
        print(
            f"| {runs} | fast | {move * 1e6:.1f} ({move / runs / 20 * 1e9:.0f}) | loop {loop * 1e3:.2f} ms "
            f"(compiled, blocks of moves per call); whole fit {whole * 1e3:.2f} ms CPU; "
            f"its parts (ms, timed apart): {split} |"
        )


def _parts(pso: ParticleSwarm, problem: Problem, fits: int) -> dict[str, float]:
    """CPU seconds per fit of the parts of ``pso.fit(problem)`` (each wrapped with a CPU clock)."""
    spent: collections.Counter[str] = collections.Counter()
    originals = {}

    def timed(owner: object, name: str, label: str) -> None:
        original = getattr(owner, name)
        originals[(owner, name)] = original

        @functools.wraps(original)
        def wrapper(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
            started = time.process_time()
            try:
                return original(*args, **kwargs)
            finally:
                spent[label] += time.process_time() - started

        setattr(owner, name, wrapper)

    timed(fast, "run", "engine call")
    timed(Objective, "exact", "exact cost")
    timed(pso_module, "aggregate", "keep rule")
    timed(pso_module, "per_cost_estimates", "estimates")
    try:
        start = time.process_time()
        for _ in range(fits):
            pso.fit(problem)
        total = time.process_time() - start
    finally:
        for (owner, name), original in originals.items():
            setattr(owner, name, original)
    parts = {label: seconds / fits for label, seconds in spent.items()}
    parts["rest"] = total / fits - sum(parts.values())
    return parts


if __name__ == "__main__":
    main()
