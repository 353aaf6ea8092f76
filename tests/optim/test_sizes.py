"""Sizes of the search estimators: capped, checked against memory before allocation, bounded history."""

from __future__ import annotations

import numpy as np
import pytest

from idkit import memory, registry
from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators.adam import AdamMultiStart
from idkit.estimators.pso import ParticleSwarm
from idkit.optim import sizes, swarm
from idkit.options import OptionError
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot


@pytest.fixture(scope="module")
def problem():
    robot = CylindricalRobot()
    return Problem(robot, simulate(robot, "torque_noise", seed=0), paper.f13(), seed=0)


@pytest.mark.parametrize(
    "options",
    [{"iterations": 1e9}, {"runs": 1e9}, {"iterations": 1e8}, {"particles": 1e9}],
    ids=["iterations=1e9", "runs=1e9", "iterations=1e8", "particles=1e9"],
)
def test_huge_search_budgets_are_refused_in_one_line_where_config_is_checked(options):
    with pytest.raises(
        ValueError, match=r"pso: runs × particles × iterations = .* above idkit's cap"
    ) as error:
        registry.create("estimator", "pso", **options)
    assert "\n" not in str(error.value)


def test_adam_budget_is_capped_too():
    with pytest.raises(ValueError, match=r"adam: starts × steps = 10 × 1000000000 .* above idkit's cap"):
        registry.create("estimator", "adam", steps=1e9)


def test_a_batch_that_does_not_fit_in_memory_is_refused_before_allocation(problem, monkeypatch):
    monkeypatch.setattr(memory, "available_memory", lambda: 10**6)  # a machine with 1 MB free
    with pytest.raises(
        memory.SizeError, match=r"pso: .*runs=1000 .* needs about .* this machine has 1 MB"
    ) as error:
        ParticleSwarm(runs=1000).fit(problem)
    assert "\n" not in str(error.value)
    with pytest.raises(
        memory.SizeError, match=r"adam: .*starts=1000 .* needs about .* this machine has 1 MB"
    ):
        AdamMultiStart(starts=1000, steps=2).fit(problem)


def test_the_history_is_thinned_to_a_bounded_number_of_rows(problem):
    estimate = ParticleSwarm(runs=2, particles=3, iterations=4321).fit(problem)
    history = np.array(estimate.details["history"])
    stride = estimate.details["history_stride"]
    assert stride == 5 and history.shape == (2, len(swarm.history_rows(4321, 5))) == (
        2,
        865,
    )  # 0, 5, …, 4320: the last is on the stride
    assert (np.diff(history, axis=1) <= 0).all()  # still the best so far
    np.testing.assert_allclose(history[:, -1], estimate.details["run_costs"])  # the last iteration kept
    assert sizes.history_stride(3_000_000) == 3000 and len(swarm.history_rows(3_000_000, 3000)) == 1001
    assert sizes.history_stride(300) == 1


@pytest.mark.parametrize("name, value", [("engine", "natve"), ("boundary", "wrap"), ("preset", "fast")])
def test_string_options_are_literals_refused_with_the_choices(name, value):
    with pytest.raises(OptionError, match=rf"option '{name}' must be .*'.*' or '.*got '{value}'") as error:
        registry.create("estimator", "pso", **{name: value})
    assert "\n" not in str(error.value)


def test_the_cap_counts_what_a_step_costs_besides_its_evaluations():
    """iterations=1e8 of one run of 4 particles is 4e8 evaluations, under the cap, but each swarm
    iteration also takes as long as ~20 evaluations (bench/step_cost.py): it ran for minutes unasked."""
    with pytest.raises(
        ValueError,
        match=r"^pso: runs × particles × iterations = 1 × 4 × 100000000 = 4\.0e\+08 cost evaluations per "
        r"cost, and iterations=100000000 steps that each take as long as about 20 evaluations: 2\.4e\+09 "
        r"in all, above idkit's cap of 1e\+09",
    ):
        registry.create("estimator", "pso", runs=1, particles=4, iterations=10**8)
    registry.create("estimator", "pso", runs=1, particles=4, iterations=4 * 10**7)  # 9.6e8: under the cap
    budget = {"runs": 1, "particles": 4, "iterations": 4 * 10**7}
    assert sizes.check_evaluations("pso", budget, "iterations", 20) == 4 * 10**7 * (4 + 20)
    with pytest.raises(ValueError, match=r"^adam: starts × steps = 1 × 1000000 .* about 1000 evaluations"):
        registry.create("estimator", "adam", starts=1, steps=10**6)
    registry.create("estimator", "adam", starts=1, steps=9 * 10**5)  # 9.0e8: under the cap


def test_a_long_search_says_so_before_it_starts(problem, monkeypatch):
    """Evaluations × residuals (samples × joints) × ns per residual above LONG_SEARCH_SECONDS: one
    warning line before the fit. The threshold is lowered here, so that a small fit is a 'long' one."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", sizes.LongSearchWarning)
        ParticleSwarm(runs=2, particles=3, iterations=10).fit(problem)  # 60 evaluations: not long
    assert problem.samples.tau.numel() == 30
    monkeypatch.setattr(sizes, "LONG_SEARCH_SECONDS", 1e-6)  # 1 µs
    with pytest.warns(
        sizes.LongSearchWarning,
        match=r"^pso: a long search: 1 cost\(s\) × 6\.0e\+01 cost evaluations on 30 residuals \(samples × "
        r"joints\) each, 1\.8e\+03 residual evaluations: about 6e-08 minutes of one core or more \(at 2 ns",
    ):  # 1800 × 2 ns = 3.6 µs
        ParticleSwarm(runs=2, particles=3, iterations=10).fit(problem)
    with pytest.warns(
        sizes.LongSearchWarning, match=r"^adam: a long search: 1 cost\(s\) × 2\.0e\+01 .*at 50 ns"
    ):
        AdamMultiStart(starts=2, steps=10).fit(problem)
    trials = [Problem(problem.robot, problem.samples, problem.cost, seed=s) for s in (1, 2)]
    with pytest.warns(
        sizes.LongSearchWarning, match=r"^pso: a long search: 2 trials × 1 cost\(s\) × 6\.0e\+01"
    ):
        ParticleSwarm(runs=2, particles=3, iterations=10).fit_trials(trials)
