"""Estimators as scikit-learn users expect (idkit.hyperparameters): a changed option counts, a bad one
is refused at construction and at fit, get_params / set_params; and the conformance check that holds
every estimator to it can fail."""

from __future__ import annotations

import functools
from typing import Any

import pytest

from idkit import registry
from idkit.estimate import Estimate
from idkit.estimators.pso import ParticleSwarm
from idkit.interfaces import Estimator
from idkit.options import OptionError
from idkit.studies import single
from idkit.testing import ConformanceError, make_problem, problem_factory_for
from idkit.testing.estimators import check_estimator_params

#: Every estimator idkit registers, with options other than its defaults (and cheap).
OTHER_OPTIONS: dict[str, dict[str, Any]] = {
    "ls": {"relative": True, "floor": 0.01},
    "tls": {"relative": True, "max_cond": 1e12},
    "rls": {"relative": True, "rho": 0.05},
    "pso": {"runs": 2, "particles": 5, "iterations": 12, "keep": "all"},
    "adam": {"starts": 2, "steps": 15, "lr": 0.1},
    "pso_f13_f14": {"pso": {"runs": 2, "particles": 5, "iterations": 10}, "floor": 0.01},
    "varpro": {"particles": 6, "iterations": 4, "polish": 1, "search_samples": 10},
    "irls": {"weight": "tukey", "tuning": 4.0},
    "pcls": {"prior_weight": 1.0},
    "payload": {"min_mass": 0.1},
    "rollout": {"particles": 3, "iterations": 2, "search_share": 0.5, "loss": "cauchy", "threads": 1},
}


def test_every_registered_estimator_is_listed_here():
    assert set(registry.available("estimator")) == set(OTHER_OPTIONS)


@pytest.mark.parametrize("name", list(OTHER_OPTIONS))
def test_an_option_assigned_after_construction_counts(name):
    """The conformance check with options other than the defaults: the estimator built with its
    defaults and given these by assignment holds the same state and fits the same numbers."""
    estimator = registry.create("estimator", name, **OTHER_OPTIONS[name])
    check_estimator_params(estimator, problem_factory_for(estimator))


def test_the_issues_example_runs_the_assigned_particles():
    swarm = ParticleSwarm(runs=1, particles=8, iterations=5)
    swarm.particles = 40
    estimate = swarm.fit(make_problem())
    assert estimate.details["settings"]["particles"] == 40


def test_a_bad_value_is_refused_at_construction_and_when_assigned_at_the_fit():
    with pytest.raises(ValueError, match="pso option particles must be an integer >= 1, got 0"):
        ParticleSwarm(particles=0)
    swarm = ParticleSwarm(runs=1, iterations=5)
    swarm.particles = 0
    with pytest.raises(ValueError, match="pso option particles must be an integer >= 1, got 0"):
        swarm.fit(make_problem())
    with pytest.raises(ValueError, match="varpro option particles must be an integer >= 1, got 0"):
        registry.create("estimator", "varpro", particles=0)
    least_squares = registry.create("estimator", "ls")
    least_squares.floor = -1.0
    with pytest.raises(ValueError, match="ls: floor must be a finite number >= 0, got -1.0"):
        least_squares.fit(make_problem())


def test_a_bad_option_is_refused_before_the_data_are_loaded(tmp_path):
    """The command builds the estimator before reading data= (an error after a long load is worse)."""
    missing = tmp_path / "not-there.csv"
    with pytest.raises(ValueError, match="pso option particles must be an integer >= 1"):
        single.run(estimator={"_name_": "pso", "particles": 0}, data=missing)


def test_set_params_checks_converts_and_leaves_the_estimator_as_it_was_when_it_refuses():
    swarm = registry.create("estimator", "pso", particles=8)
    assert swarm.set_params(particles="12", runs=3) is swarm
    assert (swarm.particles, swarm.runs) == (12, 3)
    with pytest.raises(OptionError, match="estimator 'ParticleSwarm' has no option 'particls'.*particles"):
        swarm.set_params(particls=3)
    with pytest.raises(ValueError, match="particles must be an integer >= 1, got 0"):
        swarm.set_params(runs=5, particles=0)
    assert (swarm.particles, swarm.runs) == (12, 3)


def test_get_params_rebuilds_every_estimator():
    for name, options in OTHER_OPTIONS.items():
        estimator = registry.create("estimator", name, **options)
        params = estimator.get_params()
        assert {k: params[k] for k in options} == options, name
        assert type(estimator)(**params).get_params() == params, name


# --- the conformance check fails what it should ---------------------------------------------------


class Derived(Estimator):
    """Derives its budget in __init__: a later assignment is silently ignored (the bug)."""

    def __init__(self, steps: int = 3) -> None:
        self.steps = steps
        self.budget = 2 * steps

    def fit(self, problem):
        problem.check_identifiable()
        value = float(self.budget)
        return Estimate("Derived", dict.fromkeys(problem.robot.param_names, value), None, 0.0)


class Resolved(Derived):
    """The same estimator done right: derived at the fit."""

    def __init__(self, steps: int = 3) -> None:
        self.steps = steps

    def fit(self, problem):
        self.budget = 2 * self.steps
        return super().fit(problem)


class Frozen(Derived):
    """Derives in __init__ but refuses assignment: also within the contract."""

    def __setattr__(self, name, value):
        if hasattr(self, "budget"):
            raise AttributeError(f"{type(self).__name__} is frozen: build a new one")
        super().__setattr__(name, value)


def test_the_check_names_a_value_derived_in_init():
    factory = functools.partial(make_problem, cost=None)
    with pytest.raises(
        ConformanceError, match=r"Derived\(steps=3\) then assigning steps=5 holds self\.budget = 6"
    ):
        check_estimator_params(Derived(steps=5), factory)
    check_estimator_params(Resolved(steps=5), factory)
    check_estimator_params(Frozen(steps=5), factory)
