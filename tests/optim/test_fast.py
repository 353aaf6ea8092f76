"""The fast engine against the eager torch engine (itself checked against a textbook loop)."""

from __future__ import annotations

import _thread
import signal
from dataclasses import replace

import numpy as np
import pytest
import torch

from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators import pso as pso_module
from idkit.estimators.objective import Objective
from idkit.estimators.pso import ParticleSwarm, SlowEngineWarning
from idkit.interfaces import Cost, NormStructure
from idkit.optim import codes, fast, swarm
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot

ALL_COSTS = [getattr(paper, f"f{i}")() for i in range(1, 17)]
RULES = {
    "paper (clamp)": swarm.SwarmRules(),
    "constriction (reflect)": swarm.SwarmRules(1.49618, 1.49618, (0.7298, 0.5, 10), "reflect"),
    "random walls, per particle": swarm.SwarmRules(1.3, 1.7, (0.9, 0.4, 5), "random", per_particle=True),
    "clamp, v_max": swarm.SwarmRules(1.3, 1.7, (0.9, 0.4, 5), velocity_limit=0.2),
}
# Trajectories agree to rounding only while no comparison is decided by rounding. A velocity limit
# moves m2 and m3 by exactly ±v_max, which keeps m2 + m3 — all that joint 2's torque sees — equal,
# so max-type costs (f3–f8, f11–f16) can tie exactly and either engine may keep either particle.
# With v_max, only the sum-type costs are compared step by step.
COSTS = {name: ALL_COSTS for name in RULES} | {
    "clamp, v_max": [paper.f1(), paper.f2(), paper.f9(), paper.f10()]
}


@pytest.fixture(scope="module")
def problem():
    robot = CylindricalRobot()
    return Problem(robot, simulate(robot, "outliers", seed=1), paper.f13(), seed=5)


def _draws(seed: int, like: torch.Tensor, trials: int = 1) -> swarm.Draws:
    return swarm.Draws([swarm.Uniform(torch.Generator().manual_seed(seed + t), like) for t in range(trials)])


def test_the_kernel_builds_here():
    """No compiler is involved: numba (LLVM) builds it, so it must be available wherever idkit is."""
    assert isinstance(fast.kernel(), fast.Build), fast.kernel()


@pytest.mark.parametrize("name", RULES)
def test_fast_run_equals_the_eager_run_for_every_paper_cost(problem, name):
    rules = RULES[name]
    objective = Objective(problem, COSTS[name])
    eager_draws, fast_draws = _draws(7, objective.lower), _draws(7, objective.lower)
    shape = (objective.slots, 3)
    eager_state, eager_history = swarm.run(
        objective, objective.lower, objective.upper, shape, 5, 12, rules, eager_draws
    )
    state, history = fast.run(objective.spec(), objective.lower, objective.upper, 3, 5, 12, rules, fast_draws)
    # the kernel drew the same numbers from the same streams and left them where the eager engine did
    assert np.array_equal(fast_draws.draw((1, 3)).numpy(), eager_draws.draw((1, 3)).numpy())
    np.testing.assert_allclose(history.numpy(), eager_history.numpy(), rtol=1e-9, atol=0)
    for got, expected in zip(state, eager_state, strict=True):
        np.testing.assert_allclose(got.numpy(), expected.numpy(), rtol=1e-9, atol=1e-12)


def test_estimate_matches_eager_and_is_reproducible(problem):
    options = {"preset": "paper", "runs": 4, "particles": 8, "iterations": 40}
    eager = ParticleSwarm(engine="eager", **options).fit(problem)
    quick = ParticleSwarm(engine="native", **options).fit(problem)
    again = ParticleSwarm(engine="auto", **options).fit(problem)
    assert quick.details["engine"] == "native" and eager.details["engine"] == "eager"
    assert quick.params == again.params  # same seed, same engine: identical numbers
    np.testing.assert_allclose(quick.vector(), eager.vector(), rtol=1e-6)
    assert quick.cost == pytest.approx(eager.cost, rel=1e-6)
    assert quick.details["engine_build_s"] >= 0 and quick.wall_time_s > 0


class _Unstructured(Cost):
    """A third-party cost without a declared structure."""

    def __call__(self, error: torch.Tensor, measured: torch.Tensor) -> torch.Tensor:
        return error.abs().sum(dim=(-2, -1))


class _Overridden(paper.f1):
    """A subclass that changes what f1 computes must lose f1's declared structure."""

    def __call__(self, error: torch.Tensor, measured: torch.Tensor) -> torch.Tensor:
        return 2 * super().__call__(error, measured)


def test_costs_without_structure_take_the_eager_path(problem):
    assert paper.f13().structure().norms == ("1", "inf") and paper.f13().structure().relative
    assert _Overridden().structure() is None and _Unstructured().structure() is None
    options = {"runs": 2, "particles": 5, "iterations": 5}
    with pytest.warns(SlowEngineWarning, match="no norm structure"):
        other, f1 = ParticleSwarm(**options).fit_costs(problem, [_Unstructured(), paper.f1()])
    assert other.details["engine"] == "eager" and "no norm structure" in other.details["engine_build"]
    assert f1.details["engine"] == "native"  # the structured cost still takes the kernel
    with pytest.raises(ValueError, match="engine='native' is impossible"):
        ParticleSwarm(engine="native", **options).fit_costs(problem, [_Overridden()])


def test_without_the_kernel_the_eager_engine_runs_and_says_why_once(problem, monkeypatch):
    monkeypatch.setattr(fast, "kernel", lambda: "numba is not installed")
    monkeypatch.setattr(pso_module, "_WARNED", set())
    pso = ParticleSwarm(runs=2, particles=5, iterations=5)
    with pytest.warns(SlowEngineWarning, match="numba is not installed") as caught:
        estimate = pso.fit(problem)
        pso.fit(problem)
    assert len([w for w in caught if issubclass(w.category, SlowEngineWarning)]) == 1
    assert (
        estimate.details["engine"] == "eager" and "numba is not installed" in estimate.details["engine_build"]
    )


def test_threads_split_trials_without_changing_numbers(problem, monkeypatch):
    monkeypatch.setattr(fast, "EVALUATIONS_PER_THREAD", 1)  # split even this small batch
    monkeypatch.setattr(fast, "EVALUATIONS_PER_CALL", 50)  # and cut each trial's run into blocks
    trials = [problem, *(replace(problem, seed=seed) for seed in (6, 7))]
    objective = Objective(trials, [paper.f13(), paper.f6()])
    spec, rules = objective.spec(), RULES["constriction (reflect)"]

    def fit(threads: int) -> tuple[swarm.SwarmState, torch.Tensor, np.ndarray]:
        draws = swarm.Draws([swarm.Uniform(p.generator(), objective.lower) for p in trials])
        state, history = fast.run(spec, objective.lower, objective.upper, 5, 4, 8, rules, draws, threads)
        return state, history, draws.draw((3, 2)).numpy()

    one, two, three = fit(1), fit(2), fit(3)
    for other in (two, three):
        assert torch.equal(one[1], other[1]) and torch.equal(one[0].position, other[0].position)
        assert np.array_equal(one[2], other[2])


def test_history_keeps_every_stride_th_iteration_and_the_last(problem):
    objective = Objective(problem, [paper.f1()])
    rules = RULES["paper (clamp)"]
    full_state, full = fast.run(
        objective.spec(), objective.lower, objective.upper, 2, 4, 11, rules, _draws(1, objective.lower)
    )
    state, thinned = fast.run(
        objective.spec(),
        objective.lower,
        objective.upper,
        2,
        4,
        11,
        rules,
        _draws(1, objective.lower),
        stride=4,
    )
    assert swarm.history_rows(11, 4) == [0, 4, 8, 10]
    assert torch.equal(thinned, full[[0, 4, 8, 10]]) and torch.equal(state.position, full_state.position)
    eager_state, eager = swarm.run(
        objective,
        objective.lower,
        objective.upper,
        (1, 2),
        4,
        11,
        rules,
        _draws(1, objective.lower),
        stride=4,
    )
    np.testing.assert_allclose(eager.numpy(), thinned.numpy(), rtol=1e-9)


def test_ctrl_c_stops_between_kernel_calls(problem, monkeypatch):
    """The kernel returns to Python after each block of moves: an interrupt then ends the run
    (KeyboardInterrupt), after at most the block in progress."""
    monkeypatch.setattr(fast, "EVALUATIONS_PER_CALL", 20 * 10)  # 10 moves of 20 particles per call
    built = fast.kernel()
    calls = []

    def interrupted(*args):
        calls.append(1)
        if len(calls) == 2:
            _thread.interrupt_main()
        return built.run_trial(*args)

    monkeypatch.setattr(fast, "kernel", lambda: replace(built, run_trial=interrupted))
    # Python's own Ctrl-C handler, whatever this process inherited: a shell starts a background job
    # (`cmd &`) with SIGINT ignored, and an ignored signal makes interrupt_main() do nothing
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    pso = ParticleSwarm(runs=1, particles=20, iterations=10_000, history=False, engine="native")
    try:
        with pytest.raises(KeyboardInterrupt):
            pso.fit(problem)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert len(calls) == 2  # of the 1000 calls this fit would make


def test_a_map_that_is_not_translated_gives_the_same_run(problem):
    """A base map the tape cannot express stays in torch, handed to the kernel every move."""
    objective = Objective(problem, [paper.f13(), paper.f2()])
    spec, rules = objective.spec(), RULES["constriction (reflect)"]
    assert spec.tape is not None
    by_tape = fast.run(spec, objective.lower, objective.upper, 3, 6, 15, rules, _draws(2, objective.lower))
    given = fast.run(
        replace(spec, tape=None),
        objective.lower,
        objective.upper,
        3,
        6,
        15,
        rules,
        _draws(2, objective.lower),
    )
    for got, expected in zip((*given[0], given[1]), (*by_tape[0], by_tape[1]), strict=True):
        np.testing.assert_allclose(got.numpy(), expected.numpy(), rtol=1e-12, atol=1e-14)


def test_factor_codes_and_their_checks():
    found, values = fast.factor_codes(
        [NormStructure(("1", "inf")), NormStructure(("huber",), parameters=(0.5,)),
         NormStructure(("trimmed",), parameters=(0.1,))],
        30,
    )  # fmt: skip
    assert found[:, :2].tolist() == [[codes.COLUMN_SUM, codes.ROW_SUM], [codes.HUBER, 0], [codes.TRIMMED, 0]]
    assert values[1, 0] == 0.5 and values[2, 0] == 27 and not values[0].any()  # trimmed: 27 of 30 kept
    for bad, message in (
        (NormStructure(("huber",), parameters=(0.0,)), "delta must be > 0"),
        (NormStructure(("trimmed",), parameters=(1.0,)), "trim must be"),
        (NormStructure(("nuclear",)), "no form for nuclear"),
        (NormStructure(("1",) * 5), "at most 4 factors"),
        (NormStructure(()), "at least one"),
        (NormStructure(("1", "inf"), parameters=(0.1, 0.0)), "takes no parameter"),
    ):
        with pytest.raises(ValueError, match=message):
            fast.factor_codes([bad], 30)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
def test_cuda_runs_the_same_code(problem):
    cuda = replace(problem, device="cuda")
    estimate = ParticleSwarm(runs=3, particles=6, iterations=15).fit(cuda)
    assert estimate.details["device"].startswith("cuda") and estimate.details["engine"] == "eager"
    cpu = ParticleSwarm(runs=3, particles=6, iterations=15, engine="eager").fit(problem)
    assert np.isfinite(estimate.vector()).all() and estimate.cost == pytest.approx(cpu.cost, rel=0.5)


def test_one_trial_cut_into_blocks_of_moves_equals_one_call(problem, monkeypatch):
    """With one trial and every iteration kept, the kernel writes the history in place, block by block."""
    objective = Objective(problem, [paper.f13(), paper.f6()])
    rules = RULES["random walls, per particle"]

    def fit() -> tuple[swarm.SwarmState, torch.Tensor]:
        return fast.run(
            objective.spec(), objective.lower, objective.upper, 3, 4, 9, rules, _draws(2, objective.lower)
        )

    whole = fit()
    monkeypatch.setattr(fast, "EVALUATIONS_PER_CALL", 40)  # blocks of 40 / (2 costs × 3 runs × 4) = 1 move
    cut = fit()
    assert torch.equal(whole[1], cut[1]) and torch.equal(whole[0].position, cut[0].position)
