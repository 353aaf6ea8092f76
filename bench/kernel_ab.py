"""The fast kernel of another revision against this one, interleaved in one process.

Run: ``python bench/kernel_ab.py [REVISION] [--runs 1 10 200] [--rounds 30] [--costs f13 ...]
[--preset paper|default] [--trials 1]`` (default ``main``, f13, paper preset). Both versions of
``idkit/optim/kernel.py`` — ``git show REVISION:idkit/optim/kernel.py`` and the working tree's — are
loaded as standalone modules (compiled by numba in a new temporary folder: about half a minute per
version), checked to give bitwise the same histories and final states (positions, velocities,
personal bests and their costs, swarm bests) on the benchmark's problem (``torque_noise``, 20
particles × 300 iterations, one thread), and timed in rounds: each round calls every version once
per batch size in turn, so the machine's load falls on both alike. CPU time per call
(``time.process_time``: other jobs on a shared machine count less), median and minimum over the
rounds, and nanoseconds per evaluation. The kernel alone: no estimator around it.

Several ``--costs`` are evaluated side by side as the slots of one call, ``runs`` swarms each, as
the robustness study's PSO does (one kernel call per trial: ``--costs f1 f9 f13 f14 huber trimmed
--preset default --runs 10``); each row also times every cost alone. ``--trials`` calls per timed
round, each on its own noise draw (``seed`` = trial).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from idkit.data.scenarios import simulate
from idkit.estimators.objective import Objective
from idkit.estimators.pso import ParticleSwarm
from idkit.optim import swarm
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot
from idkit.studies.build import build

ROOT = Path(__file__).resolve().parents[1]
PARTICLES, ITERATIONS = 20, 300


def standalone(source: str, name: str, folder: Path):  # noqa: ANN201
    """``source`` (a kernel.py) as module ``name`` with numba's cache in ``folder``, not idkit's."""
    source = re.sub(r"FOLDER, MANIFEST = cache\.prepared\(\n.*?\n\)\n", "", source, flags=re.S)
    for line in (
        "_previous_cache_dir = numba.core.config.CACHE_DIR\n",
        "numba.core.config.CACHE_DIR = str(FOLDER)\n",
        "numba.core.config.CACHE_DIR = _previous_cache_dir\n",
    ):
        source = source.replace(line, "")
    source = source.replace("from idkit.optim import cache, codes\n", "from idkit.optim import codes\n")
    path = folder / f"{name}.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def problem_arrays(costs: list[str], trials: int, rules: swarm.SwarmRules) -> list[tuple]:
    """Per trial, the kernel's fixed arguments for ``costs`` as slots (``idkit.optim.fast.run``'s)."""
    robot = CylindricalRobot()
    found = []
    for trial in range(trials):
        cost_objects = [build("cost", name) for name in costs]
        problem = Problem(robot, simulate(robot, "torque_noise", seed=trial), None, seed=trial)
        objective = Objective(problem, cost_objects)
        spec = objective.spec()
        arrays = spec.arrays
        found.append(
            (
                objective.lower.numpy(),
                objective.upper.numpy(),
                (
                    arrays.linear, arrays.offset, arrays.codes, arrays.parameters, spec.joints,
                    objective.lower.numpy(), objective.upper.numpy(),
                    np.array([rules.c1, rules.c2, rules.velocity_limit or 0.0]),
                    np.array(
                        [swarm.BOUNDARIES.index(rules.boundary), int(rules.per_particle), arrays.mode],
                        dtype=np.int64,
                    ),
                    arrays.tape.ops, arrays.tape.constants, arrays.tape.outputs, np.zeros((0, 0, 0)),
                ),
            )
        )  # fmt: skip
    return found


def same_results(first: list[tuple], second: list[tuple]) -> bool:
    """Whether two kernels' per-trial arrays (histories and final states) are bitwise equal."""
    return all(
        np.array_equal(a, b, equal_nan=True)
        for one, other in zip(first, second, strict=True)
        for a, b in zip(one, other, strict=True)
    )


def interleaved_cpu_times(
    kernels: dict[str, Callable], call: Callable, rounds: int, repeat: int
) -> dict[str, list[float]]:
    """CPU seconds per ``call(kernel)``, each round timing every kernel in turn (``repeat`` calls), so
    that a change of load touches both alike."""
    times: dict[str, list[float]] = {name: [] for name in kernels}
    for _ in range(rounds):
        for name, kernel in kernels.items():
            started = time.process_time()
            for _ in range(repeat):
                call(kernel)
            times[name].append((time.process_time() - started) / repeat)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("revision", nargs="?", default="main")
    parser.add_argument("--runs", type=int, nargs="+", default=[1, 10, 200])
    parser.add_argument("--rounds", type=int, default=30)
    parser.add_argument("--costs", nargs="+", default=["f13"], help="registered cost names, side by side")
    parser.add_argument("--preset", default="paper", help="the PSO preset whose rules are used")
    parser.add_argument("--trials", type=int, default=1, help="calls (noise draws) per timed round")
    args = parser.parse_args()
    torch.set_num_threads(1)
    old = subprocess.run(
        ["git", "show", f"{args.revision}:idkit/optim/kernel.py"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    folder = Path(tempfile.mkdtemp(prefix="idkit-kernel-ab-"))
    kernels = {
        args.revision: standalone(old, "kernel_before", folder).run_trial,
        "this tree": standalone(
            (ROOT / "idkit/optim/kernel.py").read_text(), "kernel_after", folder
        ).run_trial,
    }
    rules = ParticleSwarm(preset=args.preset).resolve().rules
    weights = np.array([rules.weight(m) for m in range(ITERATIONS - 1)])
    groups = {" + ".join(args.costs): args.costs}
    if len(args.costs) > 1:
        groups.update({name: [name] for name in args.costs})
    load = os.getloadavg()[0]
    print(
        f"{args.preset} preset, {args.trials} trial(s) per round, {PARTICLES} particles × {ITERATIONS} "
        "iterations\n\n| costs | runs per cost | kernel | CPU per round, median (min) "
        "| ns per evaluation (min) |\n| --- | --- | --- | --- | --- |"
    )
    for label, costs in groups.items():
        setting = problem_arrays(costs, args.trials, rules)
        for runs in args.runs:
            swarms = runs * len(costs)
            starts = [
                lower + (upper - lower) * np.random.default_rng(trial).random((swarms, PARTICLES, 4))
                for trial, (lower, upper, _) in enumerate(setting)
            ]

            def call(kernel, swarms=swarms, runs=runs, starts=starts, setting=setting):  # noqa: ANN001, ANN202
                found = []
                for trial, (start, (_, _, fixed)) in enumerate(zip(starts, setting, strict=True)):
                    x = start.copy()
                    v, pbest, pcost = np.zeros_like(x), x.copy(), np.full((swarms, PARTICLES), np.inf)
                    history, gpos = np.empty((ITERATIONS, swarms)), np.empty((swarms, 4))
                    slot_of = np.repeat(np.arange(swarms // runs, dtype=np.int64), runs)
                    linear, offset, *rest = fixed
                    kernel(
                        np.random.Generator(np.random.SFC64(trial + 1)), 0, swarms, weights, True, history,
                        x, v, pbest, pcost, gpos, linear, offset, slot_of, *rest,
                    )  # fmt: skip
                    found.append((history, x, v, pbest, pcost, gpos))
                return found

            results = [call(kernel) for kernel in kernels.values()]
            if not same_results(*results):
                sys.exit(f"{label}, runs={runs}: the kernels give different results")
            repeat = max(1, 2000 // (swarms * PARTICLES * args.trials))
            times = interleaved_cpu_times(kernels, call, args.rounds, repeat)
            evaluations = swarms * PARTICLES * ITERATIONS * args.trials
            for name, spent in times.items():
                print(
                    f"| {label} | {runs} | {name} | {statistics.median(spent) * 1e3:.3f} ms "
                    f"({min(spent) * 1e3:.3f}) | {min(spent) / evaluations * 1e9:.1f} |"
                )
    print(
        f"\nSame histories and final states, bitwise. Load average {load:.1f} before, "
        f"{os.getloadavg()[0]:.1f} after."
    )


if __name__ == "__main__":
    main()
