"""Would ``torch.compile`` pay for the PSO step? The measurement behind docs/speed.md's answer (no).

Run: ``python bench/compile_trial.py RUNS MOVES`` (e.g. ``1 10`` and ``436 10``). Compiles
``MOVES`` consecutive eager PSO steps (paper preset, f13, ``torque_noise``) as one graph with
``torch.compile(fullgraph=True, dynamic=False)`` (inductor, C++ on the CPU, with its on-disk FX
graph cache), then prints the compile time of this process (cold the first time, from the cache
after) and the time per move of the compiled graph beside the eager engine's.
"""

from __future__ import annotations

import sys
import time

import torch

from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators.objective import Objective
from idkit.estimators.pso import ParticleSwarm
from idkit.optim import swarm
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot


def main() -> None:
    runs, moves = int(sys.argv[1]), int(sys.argv[2])
    torch.set_num_threads(1)
    robot = CylindricalRobot()
    problem = Problem(robot, simulate(robot, "torque_noise", seed=0), paper.f13(), seed=0)
    objective = Objective(problem, [paper.f13()])
    rules = ParticleSwarm(preset="paper").resolve().rules
    lower, upper = objective.lower, objective.upper

    def steps(state: swarm.SwarmState, random: torch.Tensor, weights: torch.Tensor) -> swarm.SwarmState:
        for move in range(moves):
            state = swarm.step(state, objective, weights[move], random[move], lower, upper, rules)
        return state

    with torch.inference_mode():
        draws = swarm.Draws([swarm.Uniform(problem.generator(), lower)])
        state = swarm.init(objective, lower, upper, (1, runs), 20, draws)
        random = draws.draw((moves * 2, runs, 20, 4)).view(moves, 2, 1, runs, 20, 4) * 1.3
        weights = torch.full((moves,), 0.5, dtype=torch.float64)
        started = time.perf_counter()
        compiled = torch.compile(steps, fullgraph=True, dynamic=False)
        compiled(state, random, weights)
        compile_s = time.perf_counter() - started
        calls = 299 // moves
        for label, function in (("compiled", compiled), ("eager", steps)):
            started = time.process_time()
            for _ in range(calls):
                state = function(state, random, weights)
            per_move = (time.process_time() - started) / (calls * moves)
            print(f"{label}: {per_move * 1e6:.0f} µs CPU per move ({runs} runs × 20 particles)")
    print(f"compile (this process): {compile_s:.1f} s")


if __name__ == "__main__":
    main()
