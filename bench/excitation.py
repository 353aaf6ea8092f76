"""Excitation design, measured: the criterion before and after optimisation, limits checked, speed.

Run: ``python bench/excitation.py cylindrical`` (eq. 39 vs an optimised Fourier series within eq. 38,
N = 10 samples at t = 1, ..., 10 s), ``python bench/excitation.py kuka`` (the ``measurements_1``
recording vs a rest-to-rest Fourier series of 20 s optimised within the URDF's position, velocity
and effort limits, the recording's peak accelerations and without self-collision; the criterion at
100 samples), or ``python bench/excitation.py profile`` (where one swarm iteration of the KUKA
search spends its time, each part and its alternatives timed in the same run). Prints Markdown
tables with wall and CPU time, and criterion evaluations per second. How much the optimised motion
helps identification is the robustness study on it (docs/excitation.md).
Options: ``--criterion cond|logdet|ls_error``, ``--seed``, ``--margin`` (default 0.05), budget
(``--swarms --particles --iterations --adam-steps``; default: the task's default budget).
"""

from __future__ import annotations

import argparse
import inspect
import os
import time
from pathlib import Path

import numpy as np
import torch

from idkit.data.trajectory import sample_times
from idkit.excitation.collision import SelfCollision, self_collision
from idkit.excitation.criterion import (
    excitation_criterion,
    gram_condition_number,
    observation_matrix,
    scaled_condition_number,
)
from idkit.excitation.effort import nominal_torques
from idkit.excitation.export import controller_times
from idkit.excitation.feasible import fit_into_limits
from idkit.excitation.fourier import FourierExcitation
from idkit.excitation.optimize import CHUNK_STATES, optimize_excitation
from idkit.limits import MOTION_VARIABLES, MotionLimits
from idkit.robots.cylindrical import CylindricalRobot
from idkit.robots.rnea import rnea_regressor
from idkit.robots.urdf import URDFRobot

KUKA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kuka-lwr4"
DEFAULTS = inspect.signature(optimize_excitation).parameters
BUDGET = ("swarms", "particles", "iterations", "adam_steps")
T_END, SAMPLES = 20.0, 100


def budget(args: argparse.Namespace) -> dict[str, float]:
    return {key: getattr(args, key) for key in (*BUDGET, "seed", "margin")}


def worst(excess: torch.Tensor) -> str:
    """The largest excursion beyond a limit, ``0`` when inside."""
    return "0 (inside)" if not excess.any() else f"{float(excess.max()):.3g}"


def slack(limits: MotionLimits, excitation, grid: torch.Tensor) -> str:
    """Closest approach of each variable to its limits on ``grid``, over joints (0: touching)."""
    motion = torch.stack(excitation(grid), dim=-3)  # [3, T, n]
    gap = torch.minimum(limits.upper - motion.amax(-2), motion.amin(-2) - limits.lower).amin(-1)
    return ", ".join(f"{v} {float(g):.2g}" for v, g in zip(MOTION_VARIABLES, gap, strict=True))


def timed(run):
    """``(result, wall seconds, CPU seconds of this process)``."""
    wall, cpu = time.perf_counter(), time.process_time()
    result = run()
    return result, time.perf_counter() - wall, time.process_time() - cpu


def speed(result, wall: float, cpu: float) -> str:
    d = result.details
    search = sum(d.get(f"{stage}_cpu_seconds", 0.0) for stage in ("pso", "adam"))
    return (
        f"{wall:.1f} s wall, {cpu:.1f} s CPU (search {search:.1f} s CPU); {d['evaluations']} criterion "
        f"evaluations, {d['evaluations'] / search:.0f} per CPU second of search"
    )


def cylindrical(args: argparse.Namespace) -> None:
    result, wall, cpu = timed(
        lambda: optimize_excitation(
            CylindricalRobot(), options={"rest": True}, criterion=args.criterion, n_samples=10, **budget(args)
        )
    )
    print(f"| excitation | {args.criterion} at t = 1..10 s | worst excursion beyond eq. (38) |")
    print("|---|---:|---|")
    print(f"| eq. (39) (`paper`) | {result.before:.4g} | {worst(result.excess_before)} |")
    print(f"| the start (`fourier`'s default, made runnable) | {result.start:.4g} | 0 (inside) |")
    print(
        f"| optimised `fourier`, at rest at both ends | {result.after:.4g} | {worst(result.excess_after)} |"
    )
    print(
        f"\nclosest approach to a limit (optimised): {slack(result.limits, result.excitation, result.grid)}; "
        f"margin {args.margin:g} of each half-range; improved on the start: {result.improved}"
    )
    print(f"{speed(result, wall, cpu)}\ndetails: {result.details}")


def kuka_setup() -> tuple[URDFRobot, MotionLimits, list[torch.Tensor]]:
    """The KUKA model of the KUKA study, its URDF limits with ``measurements_1``'s peak |q̈|, the recording."""
    record = np.load(KUKA / "measurements_1.npz")
    states = [torch.from_numpy(record[k]) for k in ("positions", "velocities", "accelerations")]
    robot = URDFRobot(str(KUKA / "kuka_lwr4.urdf"), friction=True, offset=True)
    peak = states[2].abs().amax(0)
    return robot, robot.motion_limits().replace("acceleration", -peak, peak), states


def kuka(args: argparse.Namespace) -> None:
    robot, limits, states = kuka_setup()
    test = self_collision(robot)
    step = len(states[0]) // SAMPLES
    recorded = [x[::step][:SAMPLES] for x in states]
    print(f"measurements_1: {len(states[0])} samples; criterion {args.criterion} at {SAMPLES} samples")
    print(f"self-collision: {test.status()}")
    print(
        f"| motion | {args.criterion}, {SAMPLES} samples | {args.criterion}, all samples | shrunk by | time |"
    )
    print("|---|---:|---:|---:|---|")
    value = float(excitation_criterion(robot, args.criterion, *recorded))
    full = float(excitation_criterion(robot, args.criterion, *states))
    print(f"| measurements_1 (recorded, 25.1 s) | {value:.4g} | {full:.4g} | — | — |")
    result, wall, cpu = timed(
        lambda: optimize_excitation(
            robot,
            options={"period": T_END, "rest": True},
            criterion=args.criterion,
            n_samples=SAMPLES,
            t_end=T_END,
            limits=limits,
            check_points=controller_times(T_END, 1000.0).numel(),
            collision=test if isinstance(test, SelfCollision) else None,
            **budget(args),
        )
    )
    dense = result.excitation(result.grid)
    full = float(excitation_criterion(robot, args.criterion, *dense))
    print(
        f"| optimised `fourier`, {T_END:g} s, rest to rest | {result.after:.4g} | {full:.4g} (1 kHz) | "
        f"{result.details['shrunk_by']:.3g} | {speed(result, wall, cpu)} |"
    )
    tau = nominal_torques(robot, *dense).abs().amax(0)
    print(f"\nworst excursion beyond the box {worst(result.excess_after)}; closest approach: "
          f"{slack(limits, result.excitation, result.grid)}")  # fmt: skip
    print(f"margin {args.margin:g} of each half-range; start {result.start:.4g}; improved: {result.improved}")
    print(f"peak |tau| / effort per joint: {', '.join(f'{x:.2f}' for x in (tau / result.effort).tolist())}")
    print(f"details: {result.details}")


def profile(args: argparse.Namespace) -> None:
    """Time each part of one swarm iteration of the KUKA search, and the alternatives it replaced."""
    robot, limits, _ = kuka_setup()
    family = FourierExcitation(7, 5, T_END, rest=True)
    lower, upper = family.coefficient_box(limits)
    candidates = args.swarms * args.particles
    unit = torch.rand(
        candidates, lower.numel(), generator=torch.Generator().manual_seed(0), dtype=torch.float64
    )
    grid = torch.linspace(0.0, T_END, DEFAULTS["grid_points"].default, dtype=torch.float64)
    t = sample_times(SAMPLES, T_END)
    coefficients = fit_into_limits(family, lower + (upper - lower) * unit, limits, grid)
    states = family.evaluate(coefficients, t)
    chunk = max(1, CHUNK_STATES // SAMPLES)

    def chunked(f):
        return lambda: [f(*(x[i : i + chunk] for x in states)) for i in range(0, candidates, chunk)]

    def regressor_and(criterion):
        return lambda q, qd, qdd: criterion(observation_matrix(robot, q, qd, qdd))

    parts = {
        f"fit into the box ({grid.numel()}-point grid)": lambda: fit_into_limits(
            family, lower + (upper - lower) * unit, limits, grid
        ),
        f"evaluate the series at the {SAMPLES} samples": lambda: family.evaluate(coefficients, t),
        "base regressor, whole swarm at once": lambda: observation_matrix(robot, *states),
        f"base regressor, chunks of {chunk} candidates": chunked(regressor_and(lambda w: w)),
        "  of which the Newton–Euler recursion (rnea_regressor)": chunked(
            lambda q, qd, qdd: rnea_regressor(
                robot._tree_tensors(q), *(x.reshape(-1, robot.n_joints) for x in (q, qd, qdd)), robot.gravity
            )
        ),
        "regressor + cond by SVD (chunked)": chunked(regressor_and(scaled_condition_number)),
        "regressor + cond by Gram eigenvalues (chunked; the search's)": chunked(
            regressor_and(gram_condition_number)
        ),
    }
    print(f"One swarm iteration of the KUKA search: {candidates} candidates × {SAMPLES} samples, 1 thread")
    print("| part | wall ms | CPU ms |")
    print("|---|---:|---:|")
    for label, run in parts.items():
        run()  # warm up
        _, wall, cpu = timed(lambda run=run: [run() for _ in range(args.repeats)])
        print(f"| {label} | {1e3 * wall / args.repeats:.1f} | {1e3 * cpu / args.repeats:.1f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robot", choices=("cylindrical", "kuka", "profile"))
    parser.add_argument("--criterion", default="cond", choices=("cond", "logdet", "ls_error"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--margin", type=float, default=0.05, help="safety margin of every limit (share)")
    for key in BUDGET:
        parser.add_argument(f"--{key.replace('_', '-')}", type=int, default=DEFAULTS[key].default)
    parser.add_argument("--repeats", type=int, default=3, help="profile: repetitions of each part")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    {"cylindrical": cylindrical, "kuka": kuka, "profile": profile}[args.robot](args)
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
