"""Sigmoid friction of a 7-joint arm: idkit's variable projection beside ``scipy.optimize.least_squares``.

Run: ``python bench/varpro.py [--samples 2000] [--noise 0 0.01] [--repeats 5]``. One simulated problem:
the KUKA LWR4+ URDF's rigid body (its CAD inertials) with the friction of Gaz et al. (RA-L 2019,
their Panda's identified ``φ1, φ2, φ3`` per joint) plus viscous friction and a torque offset, on
idkit's default Fourier excitation (period 10 s), torques with Gaussian noise of ``noise`` × each
joint's RMS (one table per level). The held-out data are another motion (period 7 s, same noise).
Every method
starts from the same information: the CAD base parameters, and the reference sigmoid shape (``φ2 =
10 s/rad``, ``φ3 = 0``) inside the robot's box ``φ2 ∈ [1, 100]``, ``φ3 ∈ ±0.2``.

Rows (one thread each, torch and numpy's BLAS alike, so the machine's load does not favour one;
times are the median of ``repeats`` rounds in this process — each round runs every method once,
in turn, so a change of the machine's load falls on all of them —, each fit from samples to
parameters, the regressor included):

* ``varpro`` — idkit's estimator: a 16-particle swarm over the 14 shapes (one particle at the
  reference shape) with the linear parameters projected out, on every 8th sample, then
  Levenberg–Marquardt with Kaufman's Jacobian, first on those samples, then on all;
* ``least_squares`` on all parameters (base + shapes) with each of scipy's methods: ``trf`` (its
  default) with its finite-difference Jacobian (``2-point``) and with the exact one (the regressor
  and the sigmoid's derivatives), ``dogbox`` with the exact Jacobian, and MINPACK's ``lm`` with the
  exact Jacobian — the fastest here, though it cannot take the shape box (it ignores it; the
  others keep the shapes in the box);
* the exact-Jacobian variants again from the middle of the shape box (``φ2 = 50.5 s/rad``,
  ``φ3 = 0``): the start a user without a reference shape would pick.

After each table: the fastest peer, and the median time of the regressor alone (every method computes
it once, so it bounds how far any ratio can go).

Columns: wall time, the ratio to varpro's, held-out ‖E‖/‖T‖, the largest relative error of any
``φ1`` or ``φ2`` and the largest absolute error of any ``φ3`` (the true shifts are 0.004–0.046 rad/s,
so a relative figure would say little), and the residual evaluations (``nfev``; the swarm's count
each particle).
"""

# ruff: noqa: E402  (the BLAS thread count is set before numpy is imported)
from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # numpy's BLAS too
    os.environ.setdefault(_variable, "1")

import argparse
import statistics
import time
import warnings
from pathlib import Path

import numpy as np
import torch
from scipy.optimize import least_squares

from idkit.data.scenarios import simulate
from idkit.estimators.varpro import VariableProjection
from idkit.excitation.fourier import FourierExcitation
from idkit.model import IdentifiedModel
from idkit.problem import Problem, Samples
from idkit.robots.drives import GAZ_PANDA_FRICTION, with_drive_values
from idkit.robots.urdf import URDFRobot
from idkit.studies.validation import validate

KUKA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kuka-lwr4" / "kuka_lwr4.urdf"


def truth_of(robot: URDFRobot) -> torch.Tensor:
    """The CAD rigid body, Gaz et al.'s Panda friction, viscous friction and offsets."""
    n = robot.n_joints
    values = {
        **GAZ_PANDA_FRICTION,
        "fv": [0.1 + 0.05 * j for j in range(n)],
        "offset": [0.2 - 0.05 * j for j in range(n)],
    }
    return with_drive_values(robot.param_names, robot.joint_names, robot.nominal_params(), values)


def noisy(samples: Samples, level: float, seed: int) -> Samples:
    generator = torch.Generator().manual_seed(seed)
    rms = samples.tau.square().mean(0).sqrt()
    noise = level * rms * torch.randn(samples.tau.shape, generator=generator, dtype=torch.float64)
    return Samples(samples.q, samples.qd, samples.qdd, samples.tau + noise)


def phi_errors(robot: URDFRobot, params: torch.Tensor) -> tuple[float, float]:
    """Largest relative error of any ``φ1``, ``φ2``, and largest absolute error of any ``φ3`` (rad/s)."""
    truth = truth_of(robot)

    def index(*keys: str) -> list[int]:
        return [robot.param_names.index(f"{j}.{k}") for k in keys for j in robot.joint_names]

    scaled = index("phi1", "phi2")
    relative = float(((params[scaled] - truth[scaled]).abs() / truth[scaled].abs()).max())
    return relative, float((params[index("phi3")] - truth[index("phi3")]).abs().max())


def fit_varpro(robot: URDFRobot, train: Samples) -> tuple[torch.Tensor, int]:
    estimator = VariableProjection(threads=1)
    estimate = estimator.fit(Problem(robot, train))
    return IdentifiedModel(robot, estimate).vector, estimate.details["evaluations"]


def fit_least_squares(
    robot: URDFRobot, train: Samples, analytic: bool, centre: bool = False, method: str = "trf"
) -> tuple[torch.Tensor, int]:
    """scipy's ``method`` on ``x = (base parameters but φ1, φ1, φ2, φ3)`` from CAD and the reference
    shape (``centre``: the middle of the shape box instead); ``lm`` without the box (it takes none)."""
    n = robot.n_joints
    regressor = robot.regressor(train.q, train.qd, train.qdd).numpy()  # [N, n, B]
    amplitude = [robot.base_param_names.index(f"{j}.phi1") for j in robot.joint_names]
    fixed = [k for k in range(len(robot.base_param_names)) if k not in amplitude]
    w_fixed = regressor[..., fixed].reshape(-1, len(fixed))
    tau, qd = train.tau.numpy().reshape(-1), train.qd.numpy()
    shapes = [robot.param_names.index(f"{j}.{k}") for k in ("phi2", "phi3") for j in robot.joint_names]
    lower, upper = (bound[shapes].numpy() for bound in robot.bounds())
    start_alpha = robot.base_params(robot.nominal_params()).numpy()
    start_shape = (lower + upper) / 2 if centre else robot.nominal_params()[shapes].numpy()
    x0 = np.concatenate([start_alpha[fixed], start_alpha[amplitude], start_shape])
    L = len(fixed)

    def parts(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        steepness, shift = x[L + n : L + 2 * n], x[L + 2 * n :]
        z = steepness * (qd + shift)
        return x[L : L + n], steepness, shift, z

    def residual(x: np.ndarray) -> np.ndarray:
        phi1, steepness, shift, z = parts(x)
        friction = phi1 * (1 / (1 + np.exp(-z)) - 1 / (1 + np.exp(-steepness * shift)))
        return w_fixed @ x[:L] + friction.reshape(-1) - tau

    def jacobian(x: np.ndarray) -> np.ndarray:
        phi1, steepness, shift, z = parts(x)
        sig, sig0 = 1 / (1 + np.exp(-z)), 1 / (1 + np.exp(-steepness * shift))
        slope, slope0 = sig * (1 - sig), sig0 * (1 - sig0)
        columns = [
            sig - sig0,
            phi1 * (slope * (qd + shift) - slope0 * shift),
            phi1 * (slope - slope0) * steepness,
        ]
        jac = np.zeros((tau.size, L + 3 * n))
        jac[:, :L] = w_fixed
        rows = np.arange(tau.size)
        for k, column in enumerate(columns):  # joint j's entry on joint j's rows (sample-major)
            jac[rows, L + k * n + rows % n] = column.reshape(-1)
        return jac

    inf = np.full(L + n, np.inf)
    box = (
        (np.concatenate([-inf, lower]), np.concatenate([inf, upper])) if method != "lm" else (-np.inf, np.inf)
    )
    solution = least_squares(
        residual, x0, jac=jacobian if analytic else "2-point", bounds=box, method=method, x_scale="jac"
    )
    alpha = np.empty(len(robot.base_param_names))
    alpha[fixed], alpha[amplitude] = solution.x[:L], solution.x[L : L + n]
    params = robot.params_from_base(torch.as_tensor(alpha)).clone()
    params[shapes] = torch.as_tensor(solution.x[L + n :])
    return params, int(solution.nfev)


def table(robot: URDFRobot, samples: int, noise: float, repeats: int) -> None:
    """Print one table: every method on the same training and held-out data."""
    truth = truth_of(robot)
    train = noisy(simulate(robot, "clean", n_samples=samples, params=truth), noise, seed=1)
    other = FourierExcitation(robot.n_joints, period=7.0)
    held_out = noisy(simulate(robot, "clean", n_samples=samples, params=truth, excitation=other), noise, 2)
    methods = {
        "varpro": lambda: fit_varpro(robot, train),
        "least_squares trf (2-point)": lambda: fit_least_squares(robot, train, analytic=False),
        "least_squares trf (analytic J)": lambda: fit_least_squares(robot, train, analytic=True),
        "least_squares dogbox (analytic J)": lambda: fit_least_squares(robot, train, True, method="dogbox"),
        "least_squares lm (analytic J, no box)": lambda: fit_least_squares(robot, train, True, method="lm"),
        "least_squares trf (analytic J), box-centre start": lambda: fit_least_squares(
            robot, train, True, True
        ),
        "least_squares dogbox (analytic J), box-centre start": lambda: fit_least_squares(
            robot, train, True, True, "dogbox"
        ),
        "least_squares lm (analytic J, no box), box-centre start": lambda: fit_least_squares(
            robot, train, True, True, "lm"
        ),
    }
    times: dict[str, list[float]] = {label: [] for label in methods}
    regressor_times = []  # the part every method shares: one regressor of the training samples
    results = {}
    for _ in range(repeats):  # rounds: every method once per round, in turn
        for label, fit in methods.items():
            started = time.perf_counter()
            results[label] = fit()
            times[label].append(time.perf_counter() - started)
        started = time.perf_counter()
        robot.regressor(train.q, train.qd, train.qdd)
        regressor_times.append(time.perf_counter() - started)
    rows = []
    for label in methods:
        params, evaluations = results[label]
        held = validate(robot, held_out, params).rel_all
        rows.append((label, statistics.median(times[label]), held, *phi_errors(robot, params), evaluations))
    print(
        f"\nKUKA LWR4+ URDF, Gaz sigmoid + viscous + offset, {samples} samples x 7 joints, torque noise "
        f"{100 * noise:g} % of joint RMS; held-out: another motion; wall time: median of {repeats} rounds; "
        f"load average {os.getloadavg()[0]:.1f}"
    )
    columns = [
        "method",
        "wall time",
        "vs varpro",
        "held-out ‖E‖/‖T‖",
        "max φ1, φ2 rel. error",
        "max φ3 error",
    ]
    print("| " + " | ".join([*columns, "evaluations"]) + " |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for label, seconds, held, scaled, shift, evaluations in rows:
        cells = [label, f"{seconds:.3f} s", f"{seconds / rows[0][1]:.1f}×", f"{100 * held:.4f} %"]
        print(
            "| "
            + " | ".join([*cells, f"{100 * scaled:.2g} %", f"{shift:.2g} rad/s", str(evaluations)])
            + " |"
        )
    fastest = min(rows[1:], key=lambda row: row[1])
    shared = statistics.median(regressor_times)
    print(
        f"\nFastest peer: {fastest[0]}, {fastest[1] / rows[0][1]:.1f}× varpro's time "
        f"(held-out {100 * fastest[2]:.4f} % against varpro's {100 * rows[0][2]:.4f} %).\n"
        f"The regressor of the training samples, which every method computes once: {shared:.3f} s "
        f"({100 * shared / rows[0][1]:.0f} % of varpro's time); without it the fastest peer takes "
        f"{(fastest[1] - shared) / (rows[0][1] - shared):.1f}× varpro's time."
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=2000)
    parser.add_argument("--noise", type=float, nargs="+", default=[0.0, 0.01])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    torch.set_num_threads(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        robot = URDFRobot(str(KUKA), friction="sigmoid", offset=True)
    for noise in args.noise:
        table(robot, args.samples, noise, args.repeats)


if __name__ == "__main__":
    main()
