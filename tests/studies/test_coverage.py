"""The printed standard deviations cover the truth: 95 % intervals on many noise draws of the README
tour's recording, raw CSV through the default preprocessing, fitted as the tour fits it."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from idkit.data.options import DataOptions
from idkit.data.pipeline import read_training
from idkit.data.recording import save_recording
from idkit.estimators.linear.least_squares import LeastSquares
from idkit.estimators.physical import PhysicallyConsistentLS
from idkit.estimators.varpro import VariableProjection
from idkit.problem import Problem
from tests.tour_cases import (
    DRIVE_SCALE,
    DRIVE_TRUTH,
    drive_robot,
    noisy_recording,
    tour_motion,
    tour_robot,
    tour_urdf,
    true_params,
)

DRAWS = 100
Z95 = 1.959964


@pytest.fixture(scope="module")
def tour(tmp_path_factory) -> tuple[Path, tuple[np.ndarray, ...]]:
    """The tour's URDF and its optimised motion (one excitation search for the module)."""
    urdf = tour_urdf(tmp_path_factory.mktemp("tour"))
    return urdf, tour_motion(urdf)


def coverage(z: list[np.ndarray]) -> tuple[float, np.ndarray]:
    """The share of all parameter-draws, and of each parameter's draws, with ``|z| < 1.96``."""
    covered = np.abs(np.array(z)) < Z95  # [draws, parameters]
    return float(covered.mean()), covered.mean(0)


@pytest.mark.slow
@pytest.mark.statistical
def test_95_percent_intervals_cover_the_truth_on_the_tours_recording(tour, tmp_path):
    """100 noise draws of ``train.csv`` (the tour's motion, 1 % torque noise, 1e-4 rad encoder noise),
    each written as a raw CSV, read with the default ``preprocess`` (cut-off chosen by
    cross-validation, torques unfiltered) and fitted by ``pcls`` (``prior_weight=auto``) and ``ls``;
    every base parameter of each fit is scored: 100 × 14 = 1,400 parameter-draws per estimator.

    Measured on other draws (``bench/uncertainty_coverage.py``, ``docs/uncertainty.md``): 95.0 % (pcls)
    and 94.8 % (ls). Asserted: ≥ 90 % overall and
    ≥ 80 % for every parameter. If the intervals covered 95 % as they claim, the overall share of
    1,400 draws (binomial, sd 0.58 %) falls below 90 % with probability < 1e-15, and one parameter's
    share of 100 (sd 2.2 %) below 80 % with probability < 1e-9 — each draw's 14 parameters are
    correlated, so the overall bound is looser than independence makes it, yet still far. The
    issue's biased fit (Coulomb and viscous friction 10–40 % off with 1–2 % printed) scored 0 % on
    those parameters."""
    urdf, motion = tour
    robot = tour_robot(urdf)
    params = true_params(robot)
    truth = robot.base_params(params).numpy()
    rng = np.random.default_rng(20240523)
    z = {"pcls": [], "ls": []}
    path = tmp_path / "train.csv"
    for _ in range(DRAWS):
        save_recording(noisy_recording(robot, params, motion, rng), path)
        with warnings.catch_warnings():  # the chosen cut-off and prior weight are notes
            warnings.simplefilter("ignore", UserWarning)
            problem = Problem(robot, read_training(robot, str(path), DataOptions.of()).files[0].samples)
            fits = {"pcls": PhysicallyConsistentLS().fit(problem), "ls": LeastSquares().fit(problem)}
        for name, fit in fits.items():
            estimate = np.array([fit.base_params[n] for n in robot.base_param_names])
            std = np.array([fit.details["uncertainty"]["std"][n] for n in robot.base_param_names])
            z[name].append((estimate - truth) / std)
    for name, scores in z.items():
        overall, each = coverage(scores)
        per_parameter = dict(zip(robot.base_param_names, each.round(2).tolist(), strict=True))
        assert overall >= 0.90 and each.min() >= 0.80, (name, overall, per_parameter)


@pytest.mark.slow
@pytest.mark.statistical
def test_95_percent_intervals_of_the_drive_cover_the_truth_shapes_included(tour, tmp_path):
    """100 noise draws of the tour's ``current.csv`` (the drive: rotor inertia, sigmoid friction,
    efforts in amps), fitted by ``varpro``: every base parameter and every shape it gives a std for
    (those the box did not stop), 100 × 17–18 parameter-draws.

    Measured on other draws (``docs/uncertainty.md``): 94.4 %. Asserted: ≥ 90 % overall (as for the
    arm), ≥ 70 % per parameter — the linearised std of the steepness ``d2.phi2``, the most nonlinear
    parameter, covers about 80 %, so an 80 % floor would fail one run in two. With the shapes held at
    the found values the std of ``d3.phi1`` covered 30 %."""
    urdf, motion = tour
    robot = drive_robot(urdf)
    params = true_params(robot, DRIVE_TRUTH)
    truth = dict(zip(robot.param_names, params.tolist(), strict=True))
    truth |= dict(zip(robot.base_param_names, robot.base_params(params).tolist(), strict=True))
    rng = np.random.default_rng(20240524)
    path = tmp_path / "current.csv"
    z: dict[str, list[float]] = {}
    for _ in range(DRAWS):
        save_recording(noisy_recording(robot, params, motion, rng, 1 / np.array(DRIVE_SCALE)), path)
        with warnings.catch_warnings():  # the cut-off note; theta1's shape at its bound (phi1 = 0)
            warnings.simplefilter("ignore", UserWarning)
            fit = VariableProjection().fit(
                Problem(robot, read_training(robot, str(path), DataOptions.of()).files[0].samples)
            )
        values = {**fit.params, **fit.base_params}
        for name, std in fit.details["uncertainty"]["std"].items():
            if np.isfinite(std):  # an infinite std (a shape without a step) claims nothing to cover
                z.setdefault(name, []).append((values[name] - truth[name]) / std)
    covered = {name: float(np.mean(np.abs(scores) < Z95)) for name, scores in z.items()}
    overall = sum(covered[n] * len(z[n]) for n in z) / sum(len(v) for v in z.values())
    # the steepness d2.phi2 is the most nonlinear parameter: its linearised std covers ~80 % (docs)
    assert overall >= 0.90 and min(covered.values()) >= 0.70, (overall, covered)
    assert {"d2.phi2", "d3.phi2"} <= set(z), "the shapes' std is what this test is about"
