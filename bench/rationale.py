"""The measurements behind a few design choices whose docstrings point to ``docs/speed.md``.

Run: ``python bench/rationale.py``. Each row times one thing the code was shaped around, on this
machine, with the load average printed beside the table (times are the median of repeated calls,
wall clock; the first call of each is a warm-up):

- an SVD of the paper's observation matrix, and a paper-sized PSO fit on the eager engine, with
  torch's default intra-op pool against one thread (``idkit.runtime``, the estimators' ``threads``);
- an eager elementwise swarm update (``x·w + r·(b − x)``, float64) per element on ``[500, 20, 4]``
  against ``[10,000, 20, 4]`` (``idkit.estimators.trials.CHUNK_ELEMENTS``);
- torch's CPU generator against numpy's SFC64 ``Generator.random`` in float64 (``idkit.optim.swarm.
  Uniform``);
- the cylindrical robot's ``base_params`` in torch on one tile of swarms (10 runs × 20 particles),
  what each move would pay without the kernel's tape (``idkit.optim.base_map``);
- RLS's secular-equation root find on Python floats, one trial of the paper's problem
  (``idkit.estimators.linear.robust_ls``);
- the first ``torch.optim.Adam`` step of a fresh process, CPU seconds (it imports
  ``torch._dynamo``; ``idkit.excitation.optimize`` writes Adam out instead).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable

import numpy as np
import torch

from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators.linear.observation import linear_system
from idkit.estimators.linear.robust_ls import secular_root
from idkit.estimators.pso import ParticleSwarm
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot


def median_wall(call: Callable[[], object], repeat: int) -> float:
    """Median wall seconds of ``repeat`` calls after one warm-up call."""
    call()
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        call()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def load() -> str:
    return "{:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


def paper_system() -> tuple[torch.Tensor, torch.Tensor]:
    """``W[M, B]`` and ``τ[M]`` of the paper's problem (``torque_noise``, seed 0)."""
    robot = CylindricalRobot()
    system = linear_system(Problem(robot, simulate(robot, "torque_noise", seed=0), None, seed=0))
    return system.W, system.tau


def svd_rows() -> list[str]:
    W, _ = paper_system()
    found = {}
    for threads in (torch.get_num_threads(), 1):
        torch.set_num_threads(threads)
        found[threads] = median_wall(lambda: torch.linalg.svd(W, full_matrices=False), 200)
    default = max(found)
    return [
        f"| SVD of a {tuple(W.shape)[0]} × {tuple(W.shape)[1]} matrix, default pool ({default} threads) "
        f"| {found[default] * 1e6:.1f} µs | one thread | {found[1] * 1e6:.1f} µs |"
    ]


def pool_rows() -> list[str]:
    robot = CylindricalRobot()
    problem = Problem(robot, simulate(robot, "torque_noise", seed=0), paper.f13(), seed=0)
    found = {}
    for threads in (os.cpu_count() or 1, 1):
        pso = ParticleSwarm(engine="eager", threads=threads, history=False)
        found[threads] = median_wall(lambda pso=pso: pso.fit(problem), 5)
    default = max(found)
    return [
        f"| eager PSO fit, f13, 10 runs, {default} torch threads | {found[default] * 1e3:.0f} ms "
        f"| one thread | {found[1] * 1e3:.0f} ms |"
    ]


def elementwise_rows() -> list[str]:
    torch.set_num_threads(1)
    per_element = {}
    for runs in (500, 10_000):
        x, b, r = (torch.rand(runs, 20, 4, dtype=torch.float64) for _ in range(3))
        per_element[runs] = median_wall(lambda x=x, b=b, r=r: x * 0.7 + r * (b - x), 50) / x.numel()
    return [
        f"| eager swarm update per element, [500, 20, 4] | {per_element[500] * 1e9:.2f} ns "
        f"| [10,000, 20, 4] | {per_element[10_000] * 1e9:.2f} ns |"
    ]


def generator_rows() -> list[str]:
    count = 10_000_000
    torch_gen = torch.Generator().manual_seed(0)
    numpy_gen = np.random.Generator(np.random.SFC64(0))
    torch_time = median_wall(lambda: torch.rand(count, dtype=torch.float64, generator=torch_gen), 5)
    numpy_time = median_wall(lambda: numpy_gen.random(count), 5)
    return [
        f"| uniform doubles, torch's CPU generator | {count / torch_time / 1e6:.0f} M/s "
        f"| numpy SFC64 `Generator.random` | {count / numpy_time / 1e6:.0f} M/s |"
    ]


def base_map_rows() -> list[str]:
    torch.set_num_threads(1)
    robot = CylindricalRobot()
    low, high = robot.bounds()
    x = low + (high - low) * torch.rand(200, low.shape[-1], dtype=torch.float64)
    seconds = median_wall(lambda: robot.base_params(x), 500)
    return [f"| `base_params` in torch, 200 particles (one tile, one move) | {seconds * 1e6:.1f} µs | | |"]


def secular_rows() -> list[str]:
    W, tau = paper_system()
    u, s, _ = torch.linalg.svd(W, full_matrices=False)
    b = (u.T @ tau).tolist()
    beta = float(torch.linalg.vector_norm(tau - u @ (u.T @ tau)))
    rho = float(torch.linalg.svdvals(torch.cat([W, tau[:, None]], 1))[-1])
    seconds = median_wall(lambda: secular_root(s.tolist(), b, beta, rho), 500)
    return [f"| RLS secular root find, one trial ({len(s)} singular values) | {seconds * 1e6:.1f} µs | | |"]


def adam_rows() -> list[str]:
    code = (
        "import time, torch; p = torch.zeros(4, requires_grad=True); "
        "t = time.process_time(); o = torch.optim.Adam([p]); p.sum().backward(); o.step(); "
        "print(time.process_time() - t)"
    )
    seconds = [
        float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)
        for _ in range(3)
    ]
    return [f"| first `torch.optim.Adam` step in a fresh process (CPU) | {min(seconds):.2f} s | | |"]


def main() -> None:
    before = load()
    rows = [
        *svd_rows(),
        *pool_rows(),
        *elementwise_rows(),
        *generator_rows(),
        *base_map_rows(),
        *secular_rows(),
        *adam_rows(),
    ]
    print(f"load average before: {before}; after: {load()} ({os.cpu_count()} cores)\n")
    print("| measurement | value | against | value |\n| --- | ---: | --- | ---: |")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
