"""The printed standard deviations cover the truth: 95 % intervals on many noise draws of the README
tour's recording, raw CSV through the default preprocessing, fitted as the tour fits it."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from idkit.data.recording import save_recording
from idkit.estimators.linear.least_squares import LeastSquares
from idkit.estimators.physical import PhysicallyConsistentLS
from idkit.problem import Problem
from idkit.studies.recordings import load_training
from tests.tour_cases import noisy_recording, tour_motion, tour_robot, tour_urdf, true_params

DRAWS = 100
Z95 = 1.959964


@pytest.mark.slow
@pytest.mark.statistical
def test_95_percent_intervals_cover_the_truth_on_the_tours_recording(tmp_path):
    """100 noise draws of ``train.csv`` (the tour's motion, 1 % torque noise, 1e-4 rad encoder noise),
    each written as a raw CSV, read with the default ``preprocess`` (cut-off chosen by
    cross-validation, torques unfiltered) and fitted by ``pcls`` (``prior_weight=auto``) and ``ls``;
    every base parameter of each fit is scored: 100 × 14 = 1,400 parameter-draws per estimator.

    Measured (``docs/estimators.md``): 94.4 % (pcls) and 94.7 % (ls). Asserted: ≥ 90 % overall and
    ≥ 80 % for every parameter. If the intervals covered 95 % as they claim, the overall share of
    1,400 draws (binomial, sd 0.58 %) falls below 90 % with probability < 1e-15, and one parameter's
    share of 100 (sd 2.2 %) below 80 % with probability < 1e-9 — each draw's 14 parameters are
    correlated, so the overall bound is looser than independence makes it, yet still far. The
    issue's biased fit (Coulomb and viscous friction 10–40 % off with 1–2 % printed) scored 0 % on
    those parameters."""
    urdf = tour_urdf(tmp_path)
    robot = tour_robot(urdf)
    params = true_params(robot)
    truth = robot.base_params(params).numpy()
    motion = tour_motion(urdf)
    rng = np.random.default_rng(20240523)
    z = {"pcls": [], "ls": []}
    path = tmp_path / "train.csv"
    for _ in range(DRAWS):
        save_recording(noisy_recording(robot, params, motion, rng), path)
        with warnings.catch_warnings():  # the chosen cut-off and prior weight are notes
            warnings.simplefilter("ignore", UserWarning)
            problem = Problem(robot, load_training(robot, str(path)).files[0].samples)
            fits = {"pcls": PhysicallyConsistentLS().fit(problem), "ls": LeastSquares().fit(problem)}
        for name, fit in fits.items():
            estimate = np.array([fit.base_params[n] for n in robot.base_param_names])
            std = np.array([fit.details["uncertainty"]["std"][n] for n in robot.base_param_names])
            z[name].append((estimate - truth) / std)
    for name, scores in z.items():
        covered = np.abs(np.array(scores)) < Z95  # [DRAWS, B]
        per_parameter = dict(zip(robot.base_param_names, covered.mean(0).round(2).tolist(), strict=True))
        assert covered.mean() >= 0.90 and covered.mean(0).min() >= 0.80, (name, covered.mean(), per_parameter)
