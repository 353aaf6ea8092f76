"""The task check is a type check: an estimator runs in the tasks whose study builds the kind of
problem it fits (``Estimator.problem_type``)."""

from __future__ import annotations

import pytest

from idkit import registry
from idkit.cli.tasks import TASKS, arguments, get_task
from idkit.estimators.pso import ParticleSwarm
from idkit.estimators.rollout import RolloutEstimator
from idkit.interfaces import problem_type
from idkit.problem import IdentificationProblem, Problem
from idkit.sim.problem import RolloutProblem


class _LegacyRollout(ParticleSwarm):
    """A plugin written to the older docs: its task by name, no problem_type of its own."""

    task = "rollout"


def _use(monkeypatch, cls):
    real = registry.load
    monkeypatch.setattr(registry, "load", lambda kind, name: cls if name == "demo" else real(kind, name))


def test_both_problem_kinds_declare_the_protocol():
    for kind in (Problem, RolloutProblem):
        assert IdentificationProblem in kind.__mro__
    assert problem_type(RolloutEstimator) is RolloutProblem and problem_type(ParticleSwarm) is Problem
    assert get_task("rollout").problem_type() is RolloutProblem
    assert all(TASKS[name].problem_type() is Problem for name in ("single", "paper", "robustness", "kuka"))


def test_a_torque_estimator_is_refused_by_the_rollout_task_naming_the_single_task():
    study = get_task("rollout").study_function()
    config = {"task": "rollout", "estimator": {"_name_": "pso"}, "model": "arm.xml", "data": "log.csv"}
    with pytest.raises(ValueError, match=r"^estimator=pso runs in the single task, not the rollout task"):
        arguments("rollout", config, study)


def test_a_plugin_declaring_its_task_by_name_still_works_with_a_deprecation_warning(monkeypatch):
    _use(monkeypatch, _LegacyRollout)
    study = get_task("single").study_function()
    config = {"task": "single", "estimator": {"_name_": "demo"}}
    warned = pytest.warns(DeprecationWarning, match="task = 'rollout' is deprecated; declare the kind")
    with warned, pytest.raises(ValueError, match=r"runs in the rollout task, not the single task"):
        arguments("single", config, study)


def test_a_problem_type_that_is_not_a_class_is_named():
    class Broken(ParticleSwarm):
        problem_type = "rollout"  # type: ignore[assignment]

    with pytest.raises(TypeError, match="Broken.problem_type must be a class"):
        problem_type(Broken)
