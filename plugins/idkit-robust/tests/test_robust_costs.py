"""huber and trimmed against plain numpy formulations, the robustness they are for, and the
structure they declare to idkit's estimators."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from idkit import registry
from idkit.data.scenarios import simulate_batch
from idkit.estimators.objective import fast_structure
from idkit.estimators.pso import ParticleSwarm
from idkit.interfaces import NormStructure
from idkit.problem import Problem
from idkit.relative import DEFAULT_FLOOR
from idkit.robots.cylindrical import CylindricalRobot

from idkit_robust.costs import HuberCost, TrimmedCost

RNG = np.random.default_rng(11)
ERROR = RNG.standard_normal((2, 3, 3, 12)) * 2.0  # [2, 3, n=3, N=12]
MEASURED = RNG.choice([-1, 1], (3, 12)) * RNG.uniform(1.0, 5.0, (3, 12))


def numpy_huber(e: np.ndarray, delta: float) -> np.ndarray:
    a = np.abs(e)
    return np.where(a <= delta, 0.5 * a**2, delta * (a - 0.5 * delta)).mean(axis=(-2, -1))


def numpy_trimmed(e: np.ndarray, trim: float) -> np.ndarray:
    flat = np.sort((e**2).reshape(*e.shape[:-2], -1), axis=-1)
    drop = int(np.floor(trim * flat.shape[-1] + 1e-9))
    return flat[..., : flat.shape[-1] - drop].mean(axis=-1)


@pytest.mark.parametrize("relative", [False, True])
@pytest.mark.parametrize("delta", [0.3, 1.0, 50.0])
def test_huber_matches_numpy(relative, delta):
    cost = HuberCost(delta=delta, relative=relative)
    e = ERROR / MEASURED if relative else ERROR
    value = cost(torch.from_numpy(ERROR), torch.from_numpy(MEASURED))
    np.testing.assert_allclose(value.numpy(), numpy_huber(e, delta), rtol=1e-13)


@pytest.mark.parametrize("relative", [False, True])
@pytest.mark.parametrize("trim", [0.0, 0.1, 0.25, 0.5])
def test_trimmed_matches_numpy(relative, trim):
    cost = TrimmedCost(trim=trim, relative=relative)
    e = ERROR / MEASURED if relative else ERROR
    value = cost(torch.from_numpy(ERROR), torch.from_numpy(MEASURED))
    np.testing.assert_allclose(value.numpy(), numpy_trimmed(e, trim), rtol=1e-13)


def test_limits_are_the_mean_square():
    e, t = torch.from_numpy(ERROR), torch.from_numpy(MEASURED)
    mse = e.square().mean(dim=(-2, -1))
    torch.testing.assert_close(TrimmedCost(trim=0.0)(e, t), mse)
    torch.testing.assert_close(HuberCost(delta=1e6)(e, t), 0.5 * mse)


def test_outlier_influence_is_bounded_for_huber_and_nil_for_trimmed():
    e, t = torch.from_numpy(ERROR[0, 0]).clone(), torch.from_numpy(MEASURED)
    m = e.numel()
    big, bigger = e.clone(), e.clone()
    big[1, 4], bigger[1, 4] = 100.0, 1000.0
    huber = HuberCost(delta=1.0)
    # beyond delta the loss grows linearly: 900 more error costs delta * 900 / m on the mean
    torch.testing.assert_close(huber(bigger, t) - huber(big, t), torch.tensor(900.0 / m, dtype=torch.float64))
    trimmed = TrimmedCost(trim=0.1)  # drops floor(0.1 * 36) = 3 entries, the outlier among them
    torch.testing.assert_close(trimmed(bigger, t), trimmed(big, t))


def test_registered_names_build_with_options():
    cost = registry.create("cost", "huber", delta=0.1, relative=True)
    assert isinstance(cost, HuberCost) and cost.relative and cost.delta == 0.1
    assert registry.create("cost", "trimmed", trim=0.2).trim == 0.2
    assert type(registry.create("cost", "f1")).relative is False  # the class default is untouched


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: HuberCost(delta=0.0), "delta must be > 0"),
        (lambda: TrimmedCost(trim=1.0), r"trim must be in \[0, 1\)"),
        (lambda: TrimmedCost(trim=-0.1), r"trim must be in \[0, 1\)"),
    ],
)
def test_bad_options(make, message):
    with pytest.raises(ValueError, match=message):
        make()


@pytest.mark.parametrize("cost", [HuberCost(), TrimmedCost()])
def test_shape_mismatch_is_an_error(cost):
    with pytest.raises(ValueError, match=r"measured \[n, N\]"):
        cost(torch.zeros(2, 3, 12, dtype=torch.float64), torch.ones(3, 11, dtype=torch.float64))


@pytest.mark.parametrize("relative", [False, True])
@pytest.mark.parametrize(
    "make", [lambda r: HuberCost(delta=0.3, relative=r), lambda r: TrimmedCost(relative=r)]
)
def test_stacked_measured_equals_one_call_per_trial(make, relative):
    """``Cost.stacked_measured``: trials' torques [T, 1, n, N] in one call = one call per trial."""
    gen = torch.Generator().manual_seed(5)
    measured = torch.rand(4, 2, 7, generator=gen, dtype=torch.float64) + 0.5
    error = torch.randn(4, 6, 2, 7, generator=gen, dtype=torch.float64)
    cost = make(relative)
    assert cost.stacked_measured
    stacked = cost(error, measured.view(4, 1, 2, 7))
    one_by_one = torch.stack([cost(error[t], measured[t]) for t in range(4)])
    torch.testing.assert_close(stacked, one_by_one, rtol=1e-15, atol=0)


# --- the declared structure: idkit's estimators evaluate it instead of calling the cost ----------


@pytest.mark.parametrize(
    ("cost", "declared"),
    [
        (HuberCost(delta=0.3), NormStructure(("huber",), False, DEFAULT_FLOOR, (0.3,))),
        (HuberCost(delta=0.1, relative=True, floor=1e-2), NormStructure(("huber",), True, 1e-2, (0.1,))),
        (TrimmedCost(trim=0.25), NormStructure(("trimmed",), False, DEFAULT_FLOOR, (0.25,))),
        (TrimmedCost(trim=0.0, relative=True), NormStructure(("trimmed",), True, DEFAULT_FLOOR, (0.0,))),
    ],
    ids=repr,
)
def test_costs_declare_their_reduction(cost, declared):
    assert cost.structure() == declared


def test_a_subclass_with_its_own_call_loses_the_structure():
    class Scaled(HuberCost):
        def __call__(self, error, measured):
            return 3 * super().__call__(error, measured)

    class Kept(TrimmedCost):  # changes nothing that is computed: keeps the structure
        pass

    assert Scaled().structure() is None and Kept().structure() is not None


class _Undeclared(HuberCost):
    """The same loss, called as it is (the general path of costs without a structure)."""

    def __call__(self, error, measured):
        return super().__call__(error, measured)


class _UndeclaredTrimmed(TrimmedCost):
    def __call__(self, error, measured):
        return super().__call__(error, measured)


@pytest.mark.parametrize("relative", [False, True])
def test_pso_runs_them_fused_and_finds_what_calling_them_finds(relative):
    """On the eager engine, the fused path (declared structure) and the per-cost path (the same loss
    undeclared) give the same estimates: the same error matrices up to rounding, the same
    reductions."""
    assert fast_structure(HuberCost()) is not None and fast_structure(_Undeclared()) is None
    robot = CylindricalRobot()
    batch = simulate_batch(robot, "outliers", trials=3, seed=2)
    problems = [Problem(robot, batch[t], None, seed=10 + t) for t in range(3)]
    pso = ParticleSwarm(runs=3, particles=8, iterations=30, engine="eager")
    options = {"relative": relative}
    declared = pso.fit_trials(problems, [HuberCost(delta=0.2, **options), TrimmedCost(**options)])
    called = pso.fit_trials(problems, [_Undeclared(delta=0.2, **options), _UndeclaredTrimmed(**options)])
    for fused, plain in zip(declared, called, strict=True):
        for a, b in zip(fused, plain, strict=True):
            np.testing.assert_allclose(a.vector(), b.vector(), rtol=1e-9)
            assert a.cost == pytest.approx(b.cost, rel=1e-9)
