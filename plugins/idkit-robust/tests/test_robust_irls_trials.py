"""irls over stacked trials (``fit_trials``): each trial stops where its own ``fit`` stops, so the
estimates equal the per-trial fits whatever the chunk, and a bad trial is named.

The per-trial ``fit`` is itself checked against a numpy IRLS and scipy in test_robust_irls.py.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch
from idkit import registry
from idkit.data.scenarios import simulate_batch
from idkit.estimators.trials import fit_trials
from idkit.problem import Problem, Samples
from robust_data import outlier_problem

from idkit_robust.irls import IRLS
from idkit_robust.planar2 import Planar2Robot

BATCH_KEYS = {"batched_trials", "batch_wall_time_s"}
OPTIONS = [{}, {"relative": True}, {"weight": "tukey"}, {"weight": "tukey", "relative": True}]


@pytest.fixture(scope="module")
def cylindrical_trials() -> list[Problem]:
    """Noise draws of two scenarios (10 and 20 samples), the outlier one as in the study."""
    robot = registry.create("robot", "cylindrical")
    problems = []
    for k, scenario in enumerate(("outliers", "all_noise")):
        batch = simulate_batch(robot, scenario, trials=6, seed=k)
        problems += [Problem(robot, batch[t], seed=10 * k + t) for t in range(6)]
    return problems


@pytest.fixture(scope="module")
def planar_trials() -> list[Problem]:
    robot = Planar2Robot()
    return [
        Problem(robot, outlier_problem(robot, seed=s, fraction=0.05 * s).samples, seed=s) for s in range(5)
    ]


def assert_same(got, expected) -> None:
    """Same estimate up to the batch's size and wall time (floats to 1e-12; bitwise on one CPU)."""
    assert got.estimator == expected.estimator
    np.testing.assert_allclose(got.vector(), expected.vector(), rtol=1e-12, atol=0)
    np.testing.assert_allclose(
        list(got.base_params.values()), list(expected.base_params.values()), rtol=1e-12, atol=0
    )
    mine = {k: v for k, v in got.details.items() if k not in BATCH_KEYS}
    theirs = {k: v for k, v in expected.details.items() if k not in BATCH_KEYS}
    assert mine.keys() == theirs.keys()
    np.testing.assert_allclose(mine.pop("weights"), theirs.pop("weights"), rtol=1e-12, atol=1e-15)
    for key in ("criterion_value", "scale"):
        np.testing.assert_allclose(mine.pop(key), theirs.pop(key), rtol=1e-12)
    assert mine == theirs  # stages (iterations, converged), counts, labels


def fitted(estimator: IRLS, problems: list[Problem], chunk: int | None = None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # slow Huber trials hit max_iter
        stacked = fit_trials(estimator, problems, chunk=chunk)
        alone = [estimator.fit(p) for p in problems]
    return stacked, alone


@pytest.mark.parametrize("options", OPTIONS, ids=str)
@pytest.mark.parametrize("robot", ["cylindrical", "planar2"])
def test_each_trial_gets_its_own_fit(cylindrical_trials, planar_trials, robot, options):
    problems = cylindrical_trials if robot == "cylindrical" else planar_trials
    stacked, alone = fitted(IRLS(**options), problems)
    assert [len(e) for e in stacked] == [1] * len(problems)
    for (got,), expected in zip(stacked, alone, strict=True):
        assert_same(got, expected)
    iterations = {e[0].details["stages"][-1]["iterations"] for e in stacked}
    assert len(iterations) > 1  # the trials stopped at different iterations of the batch


@pytest.mark.parametrize("chunk", [1, 4])
def test_numbers_do_not_depend_on_the_chunk(cylindrical_trials, chunk):
    estimator = IRLS(weight="tukey")
    everything, _ = fitted(estimator, cylindrical_trials)
    chunked, _ = fitted(estimator, cylindrical_trials, chunk=chunk)
    for (got,), (expected,) in zip(chunked, everything, strict=True):
        assert_same(got, expected)
    assert max(e[0].details["batched_trials"] for e in chunked) == chunk


def test_each_unconverged_trial_warns_and_says_so(cylindrical_trials):
    estimator = IRLS(max_iter=25)
    with pytest.warns(RuntimeWarning, match="huber stage did not converge in 25 iterations") as caught:
        stacked = fit_trials(estimator, cylindrical_trials)
    unconverged = [not e[0].details["stages"][0]["converged"] for e in stacked]
    assert 0 < sum(unconverged) < len(stacked)
    assert len([w for w in caught if w.category is RuntimeWarning]) == sum(unconverged)
    assert {
        e[0].details["stages"][0]["iterations"] for e, u in zip(stacked, unconverged, strict=True) if u
    } == {25}


def test_an_exact_trial_among_noisy_ones(planar_trials):
    s, robot = planar_trials[0].samples, planar_trials[0].robot
    tau = robot.inverse_dynamics(robot.nominal_params(), s.q, s.qd, s.qdd)
    exact = Problem(robot, Samples(s.q, s.qd, s.qdd, tau), seed=9)
    trials = [planar_trials[1], exact, planar_trials[2]]
    stacked, alone = fitted(IRLS(weight="tukey"), trials)
    assert [e[0].details["stages"][0]["exact_fit"] for e in stacked] == [False, True, False]
    for (got,), expected in zip(stacked, alone, strict=True):
        assert_same(got, expected)


def test_a_rank_deficient_trial_is_named(planar_trials):
    s = planar_trials[2].samples
    still = Problem(
        Planar2Robot(), Samples(s.q, torch.zeros_like(s.qd), torch.zeros_like(s.qdd), s.tau), seed=4
    )
    with pytest.raises(ValueError, match="rank") as alone:
        IRLS().fit(still)
    with pytest.raises(ValueError) as stacked:
        fit_trials(IRLS(), [*planar_trials[:2], still, planar_trials[3]])
    assert str(stacked.value) == f"trial 2 (seed 4): {alone.value}"


def test_too_few_weights_is_named_by_trial(planar_trials):
    with pytest.raises(ValueError, match=r"^trial 0 \(seed 0\): irls: only \d+ residuals keep a non-zero"):
        fit_trials(IRLS(weight="tukey", tuning=1e-6), planar_trials)
