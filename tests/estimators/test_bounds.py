"""Bounded searches name the parameters that ended at a bound of their box."""

from __future__ import annotations

import warnings

import pytest
import torch

from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators.adam import AdamMultiStart
from idkit.estimators.bounds import BoundWarning, at_bounds, warn_at_bounds
from idkit.estimators.pso import ParticleSwarm
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot


def test_at_bounds_uses_a_fraction_of_each_box_width():
    lower, upper = torch.tensor([0.0, -1.0, 0.0, 5.0]), torch.tensor([10.0, 1.0, 1e-3, 6.0])
    values = torch.tensor([0.009, 0.998, 5e-4, 5.5])  # within 1e-3 of the width: a, b; c and d inside
    assert at_bounds(list("abcd"), values, lower, upper) == {"a": "lower", "b": "upper"}
    assert at_bounds(list("abcd"), values, lower, upper, tolerance=0.0) == {}


def test_the_warning_is_one_line_naming_each_parameter_and_its_bound():
    lower, upper = torch.zeros(8), torch.ones(8)
    ended = {f"p{k}": "upper" if k % 2 else "lower" for k in range(8)}
    with pytest.warns(BoundWarning) as caught:
        warn_at_bounds("PSO-f1", ended, [f"p{k}" for k in range(8)], lower, upper, "the robot's bounds")
    (message,) = [str(w.message) for w in caught]
    assert "\n" not in message
    assert message.startswith("PSO-f1: 8 parameter(s) ended at a bound of the search box, where the box")
    assert "p0 at its lower bound 0, p1 at its upper bound 1" in message and "and 2 more" in message
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_at_bounds("PSO-f1", {}, [], lower, upper, "the robot's bounds")  # nothing to say


def outside_the_box() -> Problem:
    """The cylindrical robot's torques from I = 14 kg·m², above its bound of 10: the fit must stop there."""
    robot = CylindricalRobot()
    truth = robot.nominal_params().clone()
    truth[robot.param_names.index("I")] = 14.0
    return Problem(robot, simulate(robot, "clean", seed=0, n_samples=60, params=truth), paper.f1(), seed=0)


@pytest.mark.parametrize(
    "estimator",
    [
        ParticleSwarm(runs=2, particles=20, iterations=200, history=False),
        AdamMultiStart(starts=2, steps=150, lr=0.05),
    ],
    ids=["pso", "adam"],
)
def test_a_search_stopped_by_its_box_says_so(estimator):
    """Its runs end at the bound (the reported mean of the runs may lie just inside)."""
    said = r"-f1: \d parameter\(s\) ended at a bound .*I at its upper bound 10 "
    with pytest.warns(BoundWarning, match=said):
        estimate = estimator.fit(outside_the_box())
    assert estimate.details["at_bound"]["I"] == "upper"
    assert estimate.params["I"] > 9.5


def test_a_search_inside_its_box_says_nothing():
    robot = CylindricalRobot()
    problem = Problem(robot, simulate(robot, "clean", seed=0, n_samples=60), paper.f1(), seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", BoundWarning)
        estimate = ParticleSwarm(runs=2, particles=10, iterations=40, history=False).fit(problem)
    assert estimate.details["at_bound"] == {}
