"""Trial batching: every number depends on (seed, trial) and the options, never on the chunk size."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit import registry
from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators.adam import AdamMultiStart
from idkit.estimators.linear.least_squares import LeastSquares
from idkit.estimators.paper import PaperFinalEstimate
from idkit.estimators.pso import ParticleSwarm
from idkit.estimators.trials import fit_trials
from idkit.interfaces import Cost
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot


class _SumAbs(Cost):
    """A third-party cost without a norm structure (runs eager beside the native ones)."""

    def __call__(self, error: torch.Tensor, measured: torch.Tensor) -> torch.Tensor:
        return error.abs().sum(dim=(-2, -1))


COSTS = [paper.f1(), _SumAbs(), paper.f13(), paper.f16()]
TRIALS = 5


@pytest.fixture(scope="module")
def problems():
    robot = CylindricalRobot()
    scenarios = ("torque_noise", "outliers", "all_noise")
    return [
        Problem(robot, simulate(robot, scenarios[t % 3], seed=100 + t), seed=1000 + t) for t in range(TRIALS)
    ]


def _vectors(estimates):
    return [[e.vector() + [e.cost] for e in per_trial] for per_trial in estimates]


@pytest.mark.parametrize("engine", ["auto", "eager"])
def test_pso_trials_do_not_depend_on_the_chunk_size(problems, engine):
    pso = ParticleSwarm(runs=3, particles=6, iterations=12, engine=engine, history=False)
    by_chunk = {chunk: _vectors(pso.fit_trials(problems, COSTS, chunk=chunk)) for chunk in (1, 3, None)}
    assert by_chunk[1] == by_chunk[3] == by_chunk[None]
    alone = [pso.fit_costs(p, COSTS) for p in problems]  # each trial on its own, same seed
    assert _vectors(alone) == by_chunk[1]
    batched = pso.fit_trials(problems, COSTS, chunk=3)
    expected = {"auto": ["native", "eager", "native", "native"], "eager": ["eager"] * 4}[engine]
    assert [e.details["engine"] for e in batched[0]] == expected
    shared = [e[0].details["batched_trials"] for e in batched]
    assert max(shared) == 3  # trials of equal sample counts stacked, at most `chunk` of them


def test_adam_trials_do_not_depend_on_the_chunk_size(problems):
    adam = AdamMultiStart(starts=3, steps=15, history=False)
    by_chunk = {
        chunk: _vectors(adam.fit_trials(problems, COSTS[:2], chunk=chunk)) for chunk in (1, 3, TRIALS)
    }
    np.testing.assert_allclose(by_chunk[3], by_chunk[1], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(by_chunk[TRIALS], by_chunk[1], rtol=1e-12, atol=1e-12)
    alone = [adam.fit_costs(p, COSTS[:2]) for p in problems]
    np.testing.assert_allclose(_vectors(alone), by_chunk[1], rtol=1e-12, atol=1e-12)


def test_trials_of_different_sample_counts_are_batched_separately(problems):
    robot = problems[0].robot
    short = Problem(robot, simulate(robot, "torque_noise", seed=9, n_samples=7), seed=9)
    mixed = [problems[0], short, problems[1]]
    pso = ParticleSwarm(runs=2, particles=5, iterations=6, history=False)
    got = pso.fit_trials(mixed, [paper.f13()])
    assert [g[0].params for g in got] == [pso.fit_costs(p, [paper.f13()])[0].params for p in mixed]


def test_fit_trials_function_covers_every_estimator(problems):
    f13 = paper.f13()
    shared = [Problem(p.robot, p.samples, f13, seed=p.seed) for p in problems[:2]]
    pso = ParticleSwarm(runs=2, particles=5, iterations=6, history=False)
    assert _vectors(fit_trials(pso, shared)) == _vectors(pso.fit_trials(shared, [f13]))
    ls = fit_trials(LeastSquares(relative=True), problems[:2])
    assert [e[0].params for e in ls] == [LeastSquares(relative=True).fit(p).params for p in problems[:2]]
    final = fit_trials(PaperFinalEstimate(pso={"runs": 2, "particles": 5, "iterations": 6}), problems[:2])
    assert final[1][0].estimator == "PSO-f13/f14"
    assert (
        final[1][0].params
        == PaperFinalEstimate(pso={"runs": 2, "particles": 5, "iterations": 6}).fit(problems[1]).params
    )
    with pytest.raises(ValueError, match="share one cost"):
        fit_trials(pso, problems[:2])
    with pytest.raises(ValueError, match="chunk"):
        pso.fit_trials(shared, [f13], chunk=0)


@pytest.mark.parametrize(
    ("name", "option", "value"),
    [
        ("pso", "particles", 0),
        ("pso", "runs", 0),
        ("pso", "iterations", -1),
        ("adam", "starts", 0),
        ("adam", "steps", 0),
    ],
)
def test_non_positive_counts_name_the_option(name, option, value):
    with pytest.raises(ValueError, match=f"option {option} must be an integer >= 1"):
        registry.create("estimator", name, **{option: value})


def test_a_fractional_count_is_refused_by_the_option_check_before_the_constructor():
    with pytest.raises(ValueError, match="option 'particles' must be an int .* fractional part"):
        registry.create("estimator", "pso", particles=2.5)


def test_pso_f13_f14_options_are_a_pso_config():
    with pytest.raises(ValueError, match="option particles must be"):
        PaperFinalEstimate(pso={"particles": 0})
    estimator = PaperFinalEstimate(pso={"runs": 2})
    assert estimator.resolve().runs == 2 and estimator.resolve() is not estimator.resolve()


@settings(max_examples=5, deadline=None)
@given(st.integers(1, TRIALS), st.integers(0, 2**31 - 1))
def test_any_chunk_gives_the_same_numbers(problems, chunk, seed):
    trials = [Problem(p.robot, p.samples, seed=seed + t) for t, p in enumerate(problems)]
    pso = ParticleSwarm(runs=2, particles=4, iterations=5, history=False)
    assert _vectors(pso.fit_trials(trials, [paper.f13()], chunk=chunk)) == _vectors(
        pso.fit_trials(trials, [paper.f13()], chunk=1)
    )
