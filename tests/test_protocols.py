"""Capability protocols: what an estimator can do is read from the members it has, not its class."""

from __future__ import annotations

import pytest

from idkit import registry
from idkit.estimate import Estimate
from idkit.estimators.trials import fit_trials
from idkit.interfaces import BatchedEstimator, CostSearcher
from idkit.testing import make_problem

BATCHED = {"ls", "tls", "rls", "pso", "adam", "pso_f13_f14", "irls"}
SEARCHERS = {"pso", "adam"}


@pytest.mark.parametrize("name", ["ls", "tls", "rls", "pso", "adam", "pso_f13_f14", "pcls", "irls"])
def test_built_in_estimators_declare_their_capabilities(name):
    estimator = registry.create("estimator", name)
    assert isinstance(estimator, BatchedEstimator) == (name in BATCHED)
    assert isinstance(estimator, CostSearcher) == (name in SEARCHERS)


class _Fixed:
    """A third-party estimator that subclasses nothing: one constant estimate per problem."""

    def fit(self, problem):
        names = problem.robot.param_names
        return Estimate(estimator="fixed", params=dict.fromkeys(names, 1.0), cost=0.0, wall_time_s=0.0)


class _BatchedFixed(_Fixed):
    def __init__(self):
        self.batches = []

    def fit_trials(self, problems, costs=None, chunk=None):
        self.batches.append(len(problems))
        return [[self.fit(p)] for p in problems]


def test_fit_trials_batches_whatever_has_the_member_and_fits_the_rest_one_by_one():
    problems = [make_problem(seed=seed) for seed in range(3)]
    batched = _BatchedFixed()
    assert isinstance(batched, BatchedEstimator) and not isinstance(_Fixed(), BatchedEstimator)
    assert [e.params for (e,) in fit_trials(batched, problems)] == [
        e.params for (e,) in fit_trials(_Fixed(), problems)
    ]
    assert batched.batches == [3]
