"""The native PSO engine against the eager torch engine (itself checked against a textbook loop)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators import native, swarm
from idkit.estimators.base_map import identity_source
from idkit.estimators.objective import Objective
from idkit.estimators.pso import ParticleSwarm
from idkit.interfaces import Cost, NormStructure
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

needs_kernel = pytest.mark.skipif(native.kernel()[0] is None, reason="no C compiler for the native kernel")


@pytest.fixture(scope="module")
def problem():
    robot = CylindricalRobot()
    return Problem(robot, simulate(robot, "outliers", seed=1), paper.f13(), seed=5)


def _draws(seed: int, like: torch.Tensor) -> swarm.Draws:
    return swarm.Draws([swarm.Uniform(torch.Generator().manual_seed(seed), like)])


@needs_kernel
@pytest.mark.parametrize("name", RULES)
def test_native_step_equals_the_eager_step_for_every_paper_cost(problem, name):
    rules = RULES[name]
    objective = Objective(problem, COSTS[name])
    shape = (objective.slots, 3)
    eager_draws, native_draws = _draws(7, objective.lower), _draws(7, objective.lower)
    eager_state, eager_history = swarm.run(
        objective, objective.lower, objective.upper, shape, 5, 12, rules, eager_draws
    )
    state, history = native.run(objective, shape, 5, 12, rules, native_draws)
    # the kernel drew the same numbers in C and left the stream where the eager engine leaves it
    assert np.array_equal(native_draws.bit_states(), eager_draws.bit_states())
    np.testing.assert_allclose(history.numpy(), eager_history.numpy(), rtol=1e-9, atol=0)
    np.testing.assert_allclose(
        state.global_position.numpy(), eager_state.global_position.numpy(), rtol=1e-9, atol=1e-12
    )
    np.testing.assert_allclose(state.position.numpy(), eager_state.position.numpy(), rtol=1e-9, atol=1e-12)


@needs_kernel
@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**63 - 1), lengths=st.lists(st.integers(0, 41), min_size=1, max_size=6))
def test_c_stream_continues_numpy_sfc64_bit_for_bit(seed, lengths):
    """Odd lengths leave half of a 64-bit draw in numpy's buffer for the next call: C must too."""
    library = native.kernel()[0]
    like = torch.zeros(1, dtype=torch.float64)
    by_numpy, by_c = (swarm.Uniform(torch.Generator().manual_seed(seed), like) for _ in range(2))
    for length in lengths:
        bits = by_c.bit_state()
        numbers = np.empty(length, dtype=np.float32)
        library.idkit_uniform(bits.ctypes.data, length, numbers.ctypes.data)
        by_c.set_bit_state(bits)
        np.testing.assert_array_equal(numbers, by_numpy.numpy.random(length, dtype=np.float32))
        assert by_c.bit_state()[4] == by_numpy.bit_state()[4]  # the same half-used draw, or none
    assert np.array_equal(by_c.bit_state(), by_numpy.bit_state())
    assert torch.equal(by_c((3, 5)), by_numpy((3, 5)))  # and numpy goes on from the same place


@needs_kernel
def test_native_engine_estimate_matches_eager_and_is_reproducible(problem):
    options = {"preset": "paper", "runs": 4, "particles": 8, "iterations": 40}
    eager = ParticleSwarm(engine="eager", **options).fit(problem)
    fast = ParticleSwarm(engine="native", **options).fit(problem)
    again = ParticleSwarm(engine="auto", **options).fit(problem)
    assert fast.details["engine"] == "native" and eager.details["engine"] == "eager"
    assert fast.params == again.params  # same seed, same engine: identical numbers
    np.testing.assert_allclose(fast.vector(), eager.vector(), rtol=1e-6)
    assert fast.cost == pytest.approx(eager.cost, rel=1e-6)


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
    other, f1 = ParticleSwarm(**options).fit_costs(problem, [_Unstructured(), paper.f1()])
    assert other.details["engine"] == "eager" and "no norm structure" in other.details["engine_build"]
    assert f1.details["engine"] == "native"  # the structured cost still takes the kernel
    alone = ParticleSwarm(**options).fit_costs(problem, [_Unstructured()])[0]
    assert alone.details["engine"] == "eager" and "no cost declares" in alone.details["engine_build"]
    with pytest.raises(ValueError, match="engine='native' is impossible"):
        ParticleSwarm(engine="native", **options).fit_costs(problem, [_Overridden()])


def test_no_compiler_falls_back_to_eager(problem, monkeypatch):
    monkeypatch.setattr(native, "kernel", lambda *_: (None, "no C compiler found (set CC)", 0.0))
    estimate = ParticleSwarm(runs=2, particles=5, iterations=5).fit(problem)
    assert estimate.details["engine"] == "eager" and "no C compiler" in estimate.details["engine_build"]


def test_kernel_is_built_once_and_cached_on_disk(tmp_path, monkeypatch):
    monkeypatch.setenv("IDKIT_CACHE_DIR", str(tmp_path))
    native.kernel.cache_clear()
    try:
        library, how, _ = native.kernel()
        if library is None:
            pytest.skip(how)
        assert how.startswith("compiled") and list((tmp_path / "native").glob("pso_step-*.so"))
        native.kernel.cache_clear()
        assert native.kernel()[1] == "cached"
    finally:
        monkeypatch.undo()
        native.kernel.cache_clear()


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
def test_cuda_runs_the_same_code(problem):
    cuda = replace(problem, device="cuda")
    estimate = ParticleSwarm(runs=3, particles=6, iterations=15).fit(cuda)
    assert estimate.details["device"].startswith("cuda") and estimate.details["engine"] == "eager"
    cpu = ParticleSwarm(runs=3, particles=6, iterations=15, engine="eager").fit(problem)
    assert np.isfinite(estimate.vector()).all() and estimate.cost == pytest.approx(cpu.cost, rel=0.5)


@needs_kernel
def test_threads_split_trials_without_changing_numbers(problem, monkeypatch):
    monkeypatch.setattr(native, "EVALUATIONS_PER_THREAD", 1)  # split even this small batch
    trials = [problem, *(replace(problem, seed=seed) for seed in (6, 7))]
    objective = Objective(trials, [paper.f13(), paper.f6()])
    rules = RULES["constriction (reflect)"]

    def fit(threads: int) -> tuple[swarm.SwarmState, torch.Tensor, np.ndarray]:
        draws = swarm.Draws([swarm.Uniform(p.generator(), objective.lower) for p in trials])
        state, history = native.run(objective, (objective.slots, 5), 4, 8, rules, draws, threads=threads)
        return state, history, draws.bit_states()

    one, two, three = fit(1), fit(2), fit(3)
    for other in (two, three):
        assert torch.equal(one[1], other[1]) and torch.equal(one[0].position, other[0].position)
        assert np.array_equal(one[2], other[2])


def _kernel_costs(
    structures: list, offset: torch.Tensor, linear: torch.Tensor, x: torch.Tensor
) -> torch.Tensor:
    """The kernel's costs ``[L, K]`` of ``x[K, 4]``, slot ``l`` on ``E = offset[l] + x · linear[l]``.

    One evaluation, no move, base map the identity: the kernel's norms and nothing else.
    """
    slots, particles = len(structures), x.shape[0]
    state = (
        x.expand(slots, particles, 4).contiguous(),
        torch.zeros(slots, particles, 4, dtype=torch.float64),
        torch.zeros(slots, particles, 4, dtype=torch.float64),
        torch.full((slots, particles), torch.inf, dtype=torch.float64),
        torch.empty(slots, 4, dtype=torch.float64),
    )
    box = torch.full((4,), 10.0, dtype=torch.float64)
    step = native.NativeStep(
        linear,
        offset.unsqueeze(1),
        torch.arange(slots),
        structures,
        native.Sizes(3, offset.shape[1] // 3, 4, 4),
        -box,
        box,
        swarm.SwarmRules(),
        state,
        np.zeros((1, 6), dtype=np.uint64),
        base_map=identity_source(4),
    )
    step(torch.empty(1, slots, dtype=torch.float64), torch.empty(0), last=True)
    return state[3]


def _reference(name: str, parameter: float, e: torch.Tensor) -> torch.Tensor:
    """Each norm of ``e[..., 3, 10]`` by its definition, in torch (SVD for the spectral norm)."""
    a = e.abs()
    if name == "huber":
        return torch.where(a <= parameter, 0.5 * e.square(), parameter * (a - 0.5 * parameter)).mean(
            dim=(-2, -1)
        )
    if name == "trimmed":
        squares = e.square().flatten(-2).sort(dim=-1).values
        keep = squares.shape[-1] - math.floor(parameter * squares.shape[-1] + 1e-9)
        return squares[..., :keep].mean(dim=-1)
    ords = {"fro": "fro", "2": 2, "1": 1, "inf": math.inf}
    if name in ords:
        return torch.linalg.matrix_norm(e, ord=ords[name])
    return {"max_row_sq": e.square().sum(-1).amax(-1), "max_abs": a.amax(dim=(-2, -1))}[name]


NORM_CASES = [
    ("fro", 0.0),
    ("2", 0.0),
    ("1", 0.0),
    ("inf", 0.0),
    ("max_row_sq", 0.0),
    ("max_abs", 0.0),
    *(("huber", delta) for delta in (0.05, 0.7, 50.0)),  # all linear, mixed, all quadratic
    *(("trimmed", trim) for trim in (0.0, 0.1, 0.29, 0.5, 0.6, 0.97)),  # drops 0, 3, 8, 15, 18, 29
]


def _check_norms(seed: int, samples: int) -> None:
    """Every norm code, with its parameter, against a direct torch formula of the same definition."""
    generator = torch.Generator().manual_seed(seed)
    slots, particles, entries = len(NORM_CASES) + 1, 7, 3 * samples  # 7: the last group of lanes is partial

    # Dyadic numbers of few bits: E = offset + x · linear is exact in any order of summation, so
    # only the norms' own rounding remains (an entry near 0 would otherwise carry E's rounding).
    def dyadic(*shape: int, bits: int) -> torch.Tensor:
        return torch.randint(-(2**bits), 2**bits, shape, generator=generator).double() / 2 ** (bits - 2)

    offset, linear, x = (
        dyadic(slots, entries, bits=10),
        dyadic(slots, 4, entries, bits=6) / 4,
        dyadic(particles, 4, bits=4),
    )
    structures = [NormStructure((name,), parameters=(value,)) for name, value in NORM_CASES]
    structures.append(NormStructure(("huber", "2", "trimmed"), parameters=(0.7, 0.0, 0.1)))  # a product
    costs = _kernel_costs(structures, offset, linear, x)
    e = (offset.unsqueeze(1) + x @ linear).view(slots, particles, 3, samples)
    for slot, structure in enumerate(structures):
        expected = torch.ones(particles, dtype=torch.float64)
        for name, value in zip(structure.norms, structure.parameters, strict=True):
            expected = expected * _reference(name, value, e[slot])
        np.testing.assert_allclose(costs[slot], expected, rtol=1e-12, err_msg=str(structure))


@needs_kernel
@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_kernel_norms_match_their_definitions(seed):
    _check_norms(seed, samples=10)


@needs_kernel
def test_kernel_norms_of_a_long_recording():
    """3 × 400 entries: the error matrix is too large for the stack and lives on the heap."""
    _check_norms(0, samples=400)


@needs_kernel
def test_kernel_spectral_norm_at_the_ends_of_its_closed_form():
    """Rank one (r = 1: acos(1) = 0) and two equal top singular values (r = -1, where the closed form
    is ill-conditioned: ~1e-8, as idkit.estimators.objective.spectral_norm_3)."""
    generator = torch.Generator().manual_seed(0)
    u, v = torch.randn(3, generator=generator, dtype=torch.float64), torch.randn(10, generator=generator)
    rank_one = torch.outer(u, v.double())
    q, _ = torch.linalg.qr(torch.randn(10, 3, generator=generator, dtype=torch.float64))
    pair = (q * torch.tensor([2.0, 2.0, 0.5], dtype=torch.float64)).T  # singular values 2, 2, 0.5
    offset = torch.stack([rank_one.flatten(), pair.flatten()])
    no_linear = torch.zeros(2, 4, 30, dtype=torch.float64)
    costs = _kernel_costs(
        [NormStructure(("2",))] * 2, offset, no_linear, torch.zeros(1, 4, dtype=torch.float64)
    )
    np.testing.assert_allclose(costs[0, 0], torch.linalg.matrix_norm(rank_one, ord=2), rtol=1e-13)
    np.testing.assert_allclose(costs[1, 0], 2.0, rtol=1e-8)


def test_norm_codes_and_their_checks():
    codes, params = native.norm_codes(
        [NormStructure(("1", "inf")), NormStructure(("huber",), parameters=(0.5,))]
    )
    assert codes[:, :2].tolist() == [[3, 4], [7, 0]] and params[1, 0] == 0.5 and not params[0].any()
    for bad, message in (
        (NormStructure(("huber",), parameters=(0.0,)), "delta must be > 0"),
        (NormStructure(("trimmed",), parameters=(1.0,)), "trim must be"),
        (NormStructure(("nuclear",)), "no code for nuclear"),
        (NormStructure(("1",) * 5), "at most 4 factors"),
        (NormStructure(()), "at least one"),
        (NormStructure(("1", "inf"), parameters=(0.1, 0.0)), "takes no parameter"),
    ):
        with pytest.raises(ValueError, match=message):
            native.norm_codes([bad])
