"""How often do 95 % intervals cover the truth? The printed std against its alternatives, on the tour.

Run: ``python bench/uncertainty_coverage.py [--draws 100]``.

Draws noisy ``train.csv`` and ``current.csv`` recordings of the README tour's arm and drive
(``tests/tour_cases.py``: its motion, 1 % torque noise, 1e-4 rad encoder noise), reads each as a raw
CSV through the default preprocessing, and fits it as the tour does. For every base parameter (and
``varpro``'s shapes) it counts the draws whose interval ``estimate ± 1.96 std`` holds the truth, for:

- ``ls``, std from the textbook ``σ² (WᵀW)⁻¹``, from idkit's sandwich (:mod:`idkit.estimators.linear.
  uncertainty`), and from a moving-block bootstrap (1 s blocks, 200 resamples of the samples);
- ``pcls`` (``prior_weight=auto``): the sandwich alone and with the pull from least squares (idkit's);
- ``varpro``: the sandwich at the found shape held fixed, and over the shapes too (idkit's).

Prints one Markdown table: coverage over all parameter-draws, the worst parameter's, and the time
the std took per fit (the fit itself excluded).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/tour_cases.py

from idkit.data.options import DataOptions
from idkit.data.pipeline import read_training  # noqa: E402
from idkit.data.recording import save_recording  # noqa: E402
from idkit.estimators.linear.least_squares import LeastSquares  # noqa: E402
from idkit.estimators.linear.uncertainty import base_uncertainty  # noqa: E402
from idkit.estimators.physical import PhysicallyConsistentLS  # noqa: E402
from idkit.estimators.varpro import VariableProjection  # noqa: E402
from idkit.problem import Problem  # noqa: E402
from tests import tour_cases  # noqa: E402

Z95 = 1.959964


def textbook(W: np.ndarray, tau: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    residual = tau - W @ alpha
    s2 = residual @ residual / (W.shape[0] - W.shape[1])
    return np.sqrt(s2 * np.diag(np.linalg.inv(W.T @ W)))


def block_bootstrap(Y: np.ndarray, tau: np.ndarray, block: int, rng: np.random.Generator) -> np.ndarray:
    """std of LS over 200 resamples of ``N // block`` blocks of ``block`` consecutive samples."""
    N, _, B = Y.shape
    scale = np.linalg.norm(Y.reshape(-1, B), axis=0)
    starts = np.arange(N - block + 1)
    replicates = []
    for _ in range(200):
        rows = (rng.choice(starts, size=N // block)[:, None] + np.arange(block)).reshape(-1)
        W = (Y[rows] / scale).reshape(-1, B)
        replicates.append(np.linalg.solve(W.T @ W, W.T @ tau[rows].reshape(-1)) / scale)
    return np.std(replicates, axis=0, ddof=1)


def timed(f, *args):
    start = time.perf_counter()
    out = f(*args)
    return out, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=100)
    args = parser.parse_args()
    torch.set_num_threads(1)
    warnings.simplefilter("ignore", UserWarning)  # the chosen cut-off, prior weight; bound notes
    folder = Path(tempfile.mkdtemp())
    urdf = tour_cases.tour_urdf(folder)
    arm, drive = tour_cases.tour_robot(urdf), tour_cases.drive_robot(urdf)
    arm_params = tour_cases.true_params(arm)
    drive_params = tour_cases.true_params(drive, tour_cases.DRIVE_TRUTH)
    arm_truth = dict(zip(arm.base_param_names, arm.base_params(arm_params).tolist(), strict=True))
    drive_truth = dict(zip(drive.param_names, drive_params.tolist(), strict=True))
    drive_truth |= dict(zip(drive.base_param_names, drive.base_params(drive_params).tolist(), strict=True))
    motion = tour_cases.tour_motion(urdf)
    rng = np.random.default_rng(1)
    names = list(arm.base_param_names)
    rows: dict[str, list] = {}  # method -> [(z per parameter dict), seconds]

    def record(method: str, values: dict, std: dict, truth: dict, seconds: float = 0.0) -> None:
        z = {n: (values[n] - truth[n]) / std[n] for n in std if np.isfinite(std[n])}
        rows.setdefault(method, []).append((z, seconds))

    def named(std) -> dict:
        return dict(zip(names, np.asarray(std).tolist(), strict=True))

    for _ in range(args.draws):
        path = folder / "train.csv"
        save_recording(tour_cases.noisy_recording(arm, arm_params, motion, rng), path)
        training = read_training(arm, str(path), DataOptions.of()).files[0]
        samples = training.samples
        problem = Problem(arm, samples)
        Y = arm.regressor(samples.q, samples.qd, samples.qdd).numpy()
        W, tau = Y.reshape(-1, len(names)), samples.tau.numpy()
        system = (torch.as_tensor(W), torch.as_tensor(tau.reshape(-1)))
        fit = LeastSquares().fit(problem)
        alpha = np.array([fit.base_params[n] for n in names])
        std, seconds = timed(textbook, W, tau.reshape(-1), alpha)
        record("ls, textbook σ²(WᵀW)⁻¹", fit.base_params, named(std), arm_truth, seconds)
        hac, seconds = timed(base_uncertainty, *system, torch.as_tensor(alpha), names, (), arm.n_joints)
        record("ls, sandwich (idkit)", fit.base_params, named(hac.std), arm_truth, seconds)
        block = int(round(1.0 / np.median(np.diff(training.times))))
        std, seconds = timed(block_bootstrap, Y, tau, block, rng)
        record("ls, block bootstrap (1 s)", fit.base_params, named(std), arm_truth, seconds)
        fit = PhysicallyConsistentLS().fit(problem)
        alpha = torch.tensor([fit.base_params[n] for n in names], dtype=torch.float64)
        for method, pulled in (("pcls, sandwich", False), ("pcls, sandwich + pull (idkit)", True)):
            start = time.perf_counter()
            std = base_uncertainty(*system, alpha, names, (), arm.n_joints, pulled=pulled).std
            record(method, fit.base_params, named(std), arm_truth, time.perf_counter() - start)
        amps = 1 / np.array(tour_cases.DRIVE_SCALE)
        save_recording(tour_cases.noisy_recording(drive, drive_params, motion, rng, amps), path)
        samples = read_training(drive, str(path), DataOptions.of()).files[0].samples
        fit = VariableProjection().fit(Problem(drive, samples))
        values = {**fit.params, **fit.base_params}
        record(
            "varpro, sandwich over the shapes (idkit)", values, fit.details["uncertainty"]["std"], drive_truth
        )
        shape = {
            "sigmoid_steepness": [fit.params[f"{j}.phi2"] for j in drive.joint_names],
            "sigmoid_shift": [fit.params[f"{j}.phi3"] for j in drive.joint_names],
        }
        held = LeastSquares().fit(Problem(drive.with_options(**shape), samples))
        record("varpro, sandwich at the found shape", values, held.details["uncertainty"]["std"], drive_truth)
    print(f"{args.draws} draws of the tour's recordings; 95 % intervals estimate ± {Z95:.2f} std\n")
    print("| std | parameter-draws | coverage | worst parameter | its coverage | std time per fit |")
    print("|---|---:|---:|---|---:|---:|")
    for method, entries in rows.items():
        covered: dict[str, list[bool]] = {}
        for z, _ in entries:
            for name, value in z.items():
                covered.setdefault(name, []).append(abs(value) < Z95)
        total = sum(len(v) for v in covered.values())
        share = sum(sum(v) for v in covered.values()) / total
        worst = min(covered, key=lambda n: np.mean(covered[n]))
        seconds = np.mean([s for _, s in entries])
        cost = "—" if seconds == 0 else f"{1e3 * seconds:.2g} ms"
        worst_share = 100 * np.mean(covered[worst])
        print(f"| {method} | {total} | {100 * share:.1f} % | {worst} | {worst_share:.0f} % | {cost} |")


if __name__ == "__main__":
    main()
