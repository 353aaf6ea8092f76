"""Batched torch Newton–Euler vs a per-sample loop over pinocchio, on the KUKA LWR4+ (7 joints).

Run: ``python bench/rnea.py [--samples 5000] [--sets 64] [--repeats 5] [--threads 0]``.
Prints one table measured in one run: best-of-``repeats`` wall time per call (the machine may be
shared: the minimum is the least noisy estimate), and speed-ups against the pinocchio loop.
Needs ``pin`` (pinocchio) and the KUKA URDF in ``../shared/data/kuka-lwr4`` (not part of the repo).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from idkit.robots.urdf import URDFRobot

KUKA_URDF = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kuka-lwr4" / "kuka_lwr4.urdf"


def best_time(function: Callable[[], object], repeats: int) -> float:
    """Minimum wall time (s) of ``repeats`` calls after one warm-up call."""
    function()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def rnea_once(robot: URDFRobot, params: torch.Tensor, q, qd, qdd) -> torch.Tensor:
    """One parameter set on states the robot has not kept: the direct Newton–Euler pass."""
    robot._regressor_cache = None
    return robot.inverse_dynamics(params, q, qd, qdd)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=5000)
    parser.add_argument("--sets", type=int, default=64, help="parameter sets for the batched rows")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    args = parser.parse_args()
    if not KUKA_URDF.is_file():
        raise SystemExit(f"KUKA URDF not found at {KUKA_URDF} (it is not part of this repository)")
    import pinocchio as pin

    if args.threads:
        torch.set_num_threads(args.threads)
    robot = URDFRobot(str(KUKA_URDF))
    q, qd, qdd = robot.random_states(args.samples, torch.Generator().manual_seed(0))
    params = robot.nominal_params()
    lower, upper = robot.bounds()
    gen = torch.Generator().manual_seed(1)
    swarm = lower + (upper - lower) * torch.rand(
        args.sets, robot.n_params, generator=gen, dtype=torch.float64
    )

    model = pin.buildModelFromUrdf(str(KUKA_URDF))
    data = model.createData()
    order = [model.joints[model.getJointId(name)].idx_v for name in robot.joint_names]
    q_pin, qd_pin, qdd_pin = (np.ascontiguousarray(x.numpy()[:, np.argsort(order)]) for x in (q, qd, qdd))

    def pin_loop() -> np.ndarray:
        return np.stack(
            [pin.rnea(model, data, a, b, c) for a, b, c in zip(q_pin, qd_pin, qdd_pin, strict=True)]
        )

    def pin_regressor_loop() -> np.ndarray:
        return np.stack(
            [
                pin.computeJointTorqueRegressor(model, data, a, b, c)
                for a, b, c in zip(q_pin, qd_pin, qdd_pin, strict=True)
            ]
        )

    def cold(batch: torch.Tensor) -> torch.Tensor:
        robot._regressor_cache = None  # new states: the regressor is built inside the timed call
        return robot.inverse_dynamics(batch, q, qd, qdd)

    with torch.no_grad():
        check = robot.inverse_dynamics(params, q, qd, qdd).numpy()
        error = np.abs(check - pin_loop()[:, order]).max()
        robot.inverse_dynamics(swarm, q, qd, qdd)  # keeps the regressor for the warm row
        s = args.sets
        rows = [
            ("pinocchio rnea, Python loop over samples", 1, pin_loop),
            ("pinocchio joint-torque regressor, Python loop", 1, pin_regressor_loop),
            (
                "idkit RNEA, 1 parameter set (Newton-Euler pass)",
                1,
                lambda: rnea_once(robot, params, q, qd, qdd),
            ),
            (f"idkit batched, {s} sets, new states (builds Y)", s, lambda: cold(swarm)),
            (
                f"idkit batched, {s} sets, same states (Y kept)",
                s,
                lambda: robot.inverse_dynamics(swarm, q, qd, qdd),
            ),
            ("idkit base regressor Y[N, n, B]", 1, lambda: robot.regressor(q, qd, qdd)),
        ]
        results = [(name, sets, best_time(fn, args.repeats)) for name, sets, fn in rows]
    reference = results[0][2]
    print(
        f"KUKA LWR4+ ({robot.n_joints} joints, B = {len(robot.base_param_names)} base parameters), "
        f"N = {args.samples} samples, torch threads = {torch.get_num_threads()}, "
        f"best of {args.repeats}; max |idkit - pinocchio| torque = {error:.1e} N·m"
    )
    print(f"| {'computation':<52} | {'time (ms)':>10} | {'per set (ms)':>12} | {'vs pinocchio loop':>17} |")
    print(f"|{'-' * 54}|{'-' * 11}:|{'-' * 13}:|{'-' * 18}:|")
    for name, sets, seconds in results:
        per_set = seconds / sets
        ratio = reference / per_set
        print(f"| {name:<52} | {seconds * 1e3:>10.2f} | {per_set * 1e3:>12.3f} | {ratio:>16.1f}× |")


if __name__ == "__main__":
    main()
