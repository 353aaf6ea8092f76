"""Excitation design, measured: the criterion before and after optimisation, limits checked.

Run: ``python bench/excitation.py cylindrical`` (eq. 39 vs an optimised Fourier series within eq. 38,
N = 10 samples at t = 1, ..., 10 s) or ``python bench/excitation.py kuka`` (the ``measurements_1``
recording vs a Fourier series optimised within the URDF's position and velocity limits, the
recording's peak accelerations, and within the recording's own envelope). Prints Markdown tables.
How much the optimised motion helps identification is the study ``idkit +experiment=excitation``.
Options: ``--criterion cond|logdet``, ``--seed``, budget (``--swarms --particles --iterations
--adam-steps``).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
import torch

from idkit.excitation.criterion import excitation_criterion
from idkit.excitation.optimize import optimize_excitation
from idkit.limits import MOTION_VARIABLES, MotionLimits
from idkit.robots.cylindrical import CylindricalRobot
from idkit.robots.urdf import URDFRobot

KUKA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kuka-lwr4"


def budget(args: argparse.Namespace) -> dict[str, int]:
    return {
        "swarms": args.swarms,
        "particles": args.particles,
        "iterations": args.iterations,
        "adam_steps": args.adam_steps,
        "seed": args.seed,
    }


def worst(excess: torch.Tensor) -> str:
    """The largest excursion beyond a limit, ``0`` when inside."""
    return "0 (inside)" if not excess.any() else f"{float(excess.max()):.3g}"


def slack(limits: MotionLimits, excitation, grid: torch.Tensor) -> str:
    """Closest approach of each variable to its limits on ``grid``, over joints (0: touching)."""
    motion = torch.stack(excitation(grid), dim=-3)  # [3, T, n]
    gap = torch.minimum(limits.upper - motion.amax(-2), motion.amin(-2) - limits.lower).amin(-1)
    return ", ".join(f"{v} {float(g):.2g}" for v, g in zip(MOTION_VARIABLES, gap, strict=True))


def cylindrical(args: argparse.Namespace) -> None:
    started = time.perf_counter()
    result = optimize_excitation(CylindricalRobot(), criterion=args.criterion, n_samples=10, **budget(args))
    seconds = time.perf_counter() - started
    print(f"| excitation | {args.criterion} at t = 1..10 s | worst excursion beyond eq. (38) |")
    print("|---|---:|---|")
    print(f"| eq. (39) (`paper`) | {result.before:.4g} | {worst(result.excess_before)} |")
    print(f"| optimised `fourier` | {result.after:.4g} | {worst(result.excess_after)} |")
    print(
        f"\nclosest approach to a limit (optimised): {slack(result.limits, result.excitation, result.grid)}"
    )
    print(f"details: {result.details}; {seconds:.1f} s wall")


def kuka(args: argparse.Namespace) -> None:
    record = np.load(KUKA / "measurements_1.npz")
    states = [torch.from_numpy(record[k]) for k in ("positions", "velocities", "accelerations")]
    duration = float(record["times"][-1] - record["times"][0])
    robot = URDFRobot(str(KUKA / "kuka_lwr4.urdf"), friction=True, offset=True)
    peak = torch.stack([x.abs().amax(0) for x in states])  # [3, n]
    urdf = robot.motion_limits().replace("acceleration", -peak[2], peak[2])
    envelope = MotionLimits(robot.joint_names, -peak, peak)
    step = max(1, len(states[0]) // args.samples)
    recorded = [x[::step][: args.samples] for x in states]
    print(
        f"measurements_1: {len(states[0])} samples over {duration:.2f} s; criterion at {args.samples} samples"
    )
    print(
        f"| excitation | {args.criterion} ({args.samples} samples) | {args.criterion} (all 200 Hz samples) |"
    )
    print("|---|---:|---:|")
    value = float(excitation_criterion(robot, args.criterion, *recorded))
    full = float(excitation_criterion(robot, args.criterion, *states))
    print(f"| measurements_1 (recorded) | {value:.4g} | {full:.4g} |")
    t_full = torch.linspace(0.0, duration, len(states[0]), dtype=torch.float64)
    for label, limits in (
        ("URDF q, qd limits + recorded peak qdd", urdf),
        ("recording's envelope", envelope),
    ):
        started = time.perf_counter()
        result = optimize_excitation(
            robot,
            options={"period": duration},
            criterion=args.criterion,
            n_samples=args.samples,
            t_end=duration,
            limits=limits,
            **budget(args),
        )
        seconds = time.perf_counter() - started
        full = float(excitation_criterion(robot, args.criterion, *result.excitation(t_full)))
        print(f"| optimised `fourier`, {label} | {result.after:.4g} | {full:.4g} |")
        print(
            f"  worst excursion {worst(result.excess_after)}; closest approach to a limit: "
            f"{slack(limits, result.excitation, result.grid)}; {seconds:.1f} s wall"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robot", choices=("cylindrical", "kuka"))
    parser.add_argument("--criterion", default="cond", choices=("cond", "logdet"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--swarms", type=int, default=4)
    parser.add_argument("--particles", type=int, default=64)
    parser.add_argument("--iterations", type=int, default=200)
    parser.add_argument("--adam-steps", type=int, default=200)
    parser.add_argument("--samples", type=int, default=100, help="KUKA: samples of the criterion")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    {"cylindrical": cylindrical, "kuka": kuka}[args.robot](args)


if __name__ == "__main__":
    main()
