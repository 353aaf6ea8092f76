"""Adam multi-start baseline and the paper's final estimate (pso_f13_f14)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from idkit import registry
from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators.adam import AdamMultiStart
from idkit.estimators.paper import PaperFinalEstimate
from idkit.estimators.pso import ParticleSwarm
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot

CHEAP_PSO = {"runs": 3, "particles": 6, "iterations": 20}


@pytest.fixture(scope="module")
def robot():
    return CylindricalRobot()


def test_noise_free_adam_f1_recovers_the_true_parameters(robot):
    samples = simulate(robot, "clean", seed=0)
    est = AdamMultiStart().fit(Problem(robot, samples, paper.f1(), seed=0))
    assert est.estimator == "Adam-f1"
    np.testing.assert_allclose(est.vector(), robot.true_params, rtol=1e-3)


def test_starts_are_independent_and_reproducible(robot):
    """The loss is a sum, so start i's path depends only on its own start point."""
    problem = Problem(robot, simulate(robot, "torque_noise", seed=0), paper.f9(), seed=7)
    two = AdamMultiStart(starts=2, steps=40).fit(problem)
    three = AdamMultiStart(starts=3, steps=40).fit(problem)
    again = AdamMultiStart(starts=3, steps=40).fit(problem)
    # The first 2·P uniforms are the same draws for both, so the first two starts coincide.
    np.testing.assert_allclose(
        np.array(three.details["run_params"])[:2], two.details["run_params"], rtol=1e-12
    )
    assert three.params == again.params
    history = np.array(three.details["history"])
    assert history.shape == (3, 40)


def test_projection_keeps_starts_in_the_box(robot):
    """With the truth (m2 = 5) outside the box, every start ends inside it, the best on the wall
    (a start that has not reached the wall in 300 steps may still be kept: its cost is within 5 %)."""
    boxed = CylindricalRobot(upper=(4.0, 10.0, 1.0, 10.0))
    samples = simulate(boxed, "clean", seed=0)
    est = AdamMultiStart(starts=4, steps=300).fit(Problem(boxed, samples, paper.f1(), seed=0))
    params = np.array(est.details["run_params"])
    lo, hi = (b.numpy() for b in boxed.bounds())
    assert ((params >= lo) & (params <= hi)).all()
    best = int(np.argmin(est.details["run_costs"]))
    assert params[best, 0] == pytest.approx(4.0, abs=1e-6)


def test_adam_options_and_errors(robot):
    est = registry.create("estimator", "adam", starts=2, steps=5, lr=0.1)
    assert isinstance(est, AdamMultiStart) and est.lr == 0.1 and est.starts == 2
    with pytest.raises(ValueError, match="problem.cost"):
        est.fit(Problem(robot, simulate(robot, "clean", seed=0)))
    with pytest.raises(ValueError, match="lr"):
        AdamMultiStart(lr=0.0)


def test_paper_final_estimate_is_the_mean_of_pso_f13_and_pso_f14(robot):
    samples = simulate(robot, "outliers", seed=0)
    problem = Problem(robot, samples, paper.f13(), seed=3)
    final = registry.create("estimator", "pso_f13_f14", pso=CHEAP_PSO).fit(problem)
    parts = ParticleSwarm(**CHEAP_PSO).fit_costs(problem, [paper.f13(), paper.f14()])
    assert final.estimator == "PSO-f13/f14"
    np.testing.assert_allclose(
        final.vector(), (np.array(parts[0].vector()) + parts[1].vector()) / 2, rtol=1e-12
    )
    assert set(final.details["parts"]) == {"PSO-f13", "PSO-f14"}
    x = torch.tensor(final.vector(), dtype=torch.float64)
    assert final.cost == pytest.approx(float(problem.evaluate(x)), rel=1e-12)
    assert final.details["costs_at_average"]["f14"] == pytest.approx(
        float(paper.f14()(problem.error(x), samples.measured_matrix())), rel=1e-12
    )
    assert PaperFinalEstimate(pso=CHEAP_PSO).fit(Problem(robot, samples)).cost is None
