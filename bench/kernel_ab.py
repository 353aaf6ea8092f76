"""The fast kernel of another revision against this one, interleaved in one process.

Run: ``python bench/kernel_ab.py [REVISION] [--runs 1 10 200] [--rounds 30]`` (default ``main``). Both
versions of ``idkit/optim/kernel.py`` — ``git show REVISION:idkit/optim/kernel.py`` and the working
tree's — are loaded as standalone modules (compiled by numba in a new temporary folder: about half
a minute per version), checked to give bitwise the same history on the benchmark's problem (f13 on
``torque_noise``, paper preset, 20 particles × 300 iterations, one thread), and timed in rounds: each
round calls every version once per batch size in turn, so the machine's load falls on both alike.
CPU time per call (``time.process_time``: other jobs on a shared machine count less), median and
minimum over the rounds, and nanoseconds per evaluation. The kernel alone: no estimator around it.
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
from pathlib import Path

import numpy as np
import torch

from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators.objective import Objective
from idkit.estimators.pso import ParticleSwarm
from idkit.optim import codes
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot

ROOT = Path(__file__).resolve().parents[1]


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("revision", nargs="?", default="main")
    parser.add_argument("--runs", type=int, nargs="+", default=[1, 10, 200])
    parser.add_argument("--rounds", type=int, default=30)
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
    cost = paper.f13()
    robot = CylindricalRobot()
    objective = Objective(Problem(robot, simulate(robot, "torque_noise", seed=0), cost, seed=0), [cost])
    rules = ParticleSwarm(preset="paper").resolve().rules
    spec = objective.spec()
    linear, offset = spec.linear.contiguous().numpy(), spec.offset.contiguous().numpy()
    factor_codes, parameters = (
        np.array([[codes.FORMS[name] for name in cost.norms] + [0, 0]]),
        np.zeros((1, 4)),
    )
    lower, upper = objective.lower.numpy(), objective.upper.numpy()
    weights = np.array([rules.weight(m) for m in range(299)])
    load = os.getloadavg()[0]
    print(
        "| runs | kernel | CPU per call, median (min) | ns per evaluation (min) |\n| --- | --- | --- | --- |"
    )
    for runs in args.runs:
        start = lower + (upper - lower) * np.random.default_rng(0).random((runs, 20, 4))
        fixed = (
            linear, offset, np.zeros(runs, dtype=np.int64), factor_codes, parameters, 3, lower, upper,
            np.array([rules.c1, rules.c2, 0.0]), np.array([codes.CLAMP, 0, codes.MAP_TAPE], dtype=np.int64),
            spec.tape.ops, spec.tape.constants, spec.tape.outputs, np.zeros((0, 0, 0)),
        )  # fmt: skip

        def call(kernel, start=start, runs=runs, fixed=fixed):  # noqa: ANN001, ANN202
            x = start.copy()
            history = np.empty((300, runs))
            kernel(
                np.random.Generator(np.random.SFC64(1)), 0, runs, weights, True, history, x, np.zeros_like(x),
                x.copy(), np.full((runs, 20), np.inf), np.empty((runs, 4)), *fixed,
            )  # fmt: skip
            return history

        histories = [call(kernel) for kernel in kernels.values()]
        if not all(np.array_equal(histories[0], h) for h in histories[1:]):
            sys.exit(f"runs={runs}: the kernels give different histories")
        times: dict[str, list[float]] = {name: [] for name in kernels}
        repeat = max(1, 2000 // (runs * 20))
        for _ in range(args.rounds):
            for name, kernel in kernels.items():
                started = time.process_time()
                for _ in range(repeat):
                    call(kernel)
                times[name].append((time.process_time() - started) / repeat)
        for name, spent in times.items():
            print(
                f"| {runs} | {name} | {statistics.median(spent) * 1e3:.3f} ms ({min(spent) * 1e3:.3f}) "
                f"| {min(spent) / (runs * 6000) * 1e9:.1f} |"
            )
    print(f"\nSame histories, bitwise. Load average {load:.1f} before, {os.getloadavg()[0]:.1f} after.")


if __name__ == "__main__":
    main()
