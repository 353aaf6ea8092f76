"""idkit-robust's plugins pass idkit's public conformance suite, in the configurations people use."""

from __future__ import annotations

import functools

import pytest
from idkit.testing import COST_CHECKS, ESTIMATOR_CHECKS, ROBOT_CHECKS, make_problem

from idkit_robust.costs import HuberCost, TrimmedCost
from idkit_robust.irls import IRLS
from idkit_robust.planar2 import Planar2Robot

COSTS = [
    HuberCost(),
    HuberCost(delta=0.1, relative=True),
    TrimmedCost(),
    TrimmedCost(trim=0.3, relative=True),
]
ESTIMATORS = [IRLS(), IRLS(weight="tukey"), IRLS(relative=True), IRLS(weight="tukey", relative=True)]
PROBLEMS = {
    "cylindrical": make_problem,  # the core robot: IRLS is not tied to this package's robot
    "planar2": functools.partial(make_problem, Planar2Robot(), cost=HuberCost()),
}


@pytest.mark.parametrize("check", ROBOT_CHECKS, ids=lambda c: c.__name__)
@pytest.mark.parametrize("robot", [Planar2Robot(), Planar2Robot(l1=0.8, g=1.62)], ids=repr)
def test_planar2(robot, check):
    check(robot)


@pytest.mark.parametrize("check", COST_CHECKS, ids=lambda c: c.__name__)
@pytest.mark.parametrize("cost", COSTS, ids=repr)
def test_costs(cost, check):
    check(cost)


@pytest.mark.parametrize("check", ESTIMATOR_CHECKS, ids=lambda c: c.__name__)
@pytest.mark.parametrize("problem", sorted(PROBLEMS))
@pytest.mark.parametrize("estimator", ESTIMATORS, ids=lambda e: e.label)
def test_irls(estimator, problem, check):
    check(estimator, PROBLEMS[problem])
