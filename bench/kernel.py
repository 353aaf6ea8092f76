"""Nanoseconds per cost evaluation of the fast PSO kernel, per cost, batch size and thread count.

Run: ``python bench/kernel.py [--repeat 3]``. The robustness study's PSO (default preset: 20
particles × 300 iterations, reflecting walls) on the cylindrical robot, ``torque_noise`` samples
(3 joints × 10 samples, 4 base parameters). For each cost it times ``fast.run`` — the whole
engine: initial draw, random numbers, the kernel, the state handed back — on

- the study's chunk: 50 trials × 1 cost × 10 runs in one batch (500 swarms), 1 and 2 threads;
- one 10-run fit (one trial, 10 swarms), 1 thread;

and the whole estimator on the study's chunk with the study's four structured costs
(``ParticleSwarm().fit_trials(50 problems, [f1, f9, f13, f14])``: objective, engine, keep rule,
exact cost, ``Estimate``). Wall time (threads count only in wall time), best of ``--repeat``
calls after a warm-up (10 × ``--repeat`` for the short single fit), divided by the evaluations
(runs × 20 × 300). The machine is shared: the load average before and after is printed with the
table.

``huber`` and ``trimmed`` are the ``idkit-robust`` plugin's costs (delta = 1 N m, trim = 0.1,
absolute error), which declare the kernel's entrywise reductions.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable

import torch
from idkit_robust.costs import HuberCost, TrimmedCost

from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators.objective import Objective
from idkit.estimators.pso import ParticleSwarm
from idkit.interfaces import Cost
from idkit.optim import fast, swarm
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot

TRIALS, RUNS, PARTICLES, ITERATIONS = 50, 10, 20, 300


#: Cost rows: name -> cost (the idkit-robust plugin's declare the kernel's huber and trimmed).
COSTS = {
    "f1": paper.f1(),
    "f9": paper.f9(),
    "f13": paper.f13(),
    "f14": paper.f14(),
    "huber (δ = 1)": HuberCost(delta=1.0),
    "trimmed (10 %)": TrimmedCost(trim=0.1),
}


def best_wall(call: Callable[[], object], repeat: int) -> float:
    """Smallest wall time of ``repeat`` calls after one warm-up call (compiles, caches)."""
    call()
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        call()
        times.append(time.perf_counter() - started)
    return min(times)


def load() -> str:
    return "{:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="timed calls per cell (the best is shown)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    robot = CylindricalRobot()
    problems = [Problem(robot, simulate(robot, "torque_noise", seed=t), None, seed=t) for t in range(TRIALS)]
    pso = ParticleSwarm(history=False)
    rules = pso.resolve().rules
    before = load()

    def engine(trials: list[Problem], cost: Cost, threads: int) -> float:
        """ns per evaluation of ``fast.run`` on ``trials`` × one cost × RUNS runs."""
        objective = Objective(trials, [cost])
        spec = objective.spec()

        def call() -> None:
            draws = swarm.Draws([swarm.Uniform(p.generator(), objective.lower) for p in trials])
            fast.run(
                spec, objective.lower, objective.upper, RUNS, PARTICLES, ITERATIONS, rules, draws, threads
            )

        evaluations = len(trials) * RUNS * PARTICLES * ITERATIONS
        repeat = args.repeat * max(1, TRIALS // len(trials) // 5)  # a short call: more tries against noise
        return best_wall(call, repeat) / evaluations * 1e9

    def ns(value: float) -> str:
        return f"{value:.0f}"

    rows = []
    for name, cost in COSTS.items():
        chunk = [engine(problems, cost, threads) for threads in (1, 2)]
        single = engine(problems[:1], cost, 1)
        rows.append(f"| {name} | {ns(chunk[0])} | {ns(chunk[1])} | {ns(single)} |")
    structured = [paper.f1(), paper.f9(), paper.f13(), paper.f14()]
    evaluations = TRIALS * len(structured) * RUNS * PARTICLES * ITERATIONS
    fits = {t: ParticleSwarm(threads=t, history=False) for t in (1, 2)}
    whole = [best_wall(lambda p=pso: p.fit_trials(problems, structured), 1) for pso in fits.values()]
    whole = [seconds / evaluations * 1e9 for seconds in whole]
    rows.append(f"| whole `fit_trials`, f1 + f9 + f13 + f14 | {ns(whole[0])} | {ns(whole[1])} | |")
    print(f"load average before: {before}; after: {load()} ({os.cpu_count()} cores)")
    print(
        f"\n| ns per evaluation (wall) | {TRIALS} trials × 10 runs, 1 thread | 2 threads "
        "| one 10-run fit, 1 thread |\n| --- | ---: | ---: | ---: |"
    )
    print("\n".join(rows))


if __name__ == "__main__":
    main()
