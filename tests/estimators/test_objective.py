"""Declared structures with entrywise reductions: the contract's checks, the fused evaluation
against the costs' own ``__call__``, and the engine PSO gives such costs."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from idkit.costs import paper
from idkit.costs.factors import factor_parameters
from idkit.costs.norms import NORMS
from idkit.costs.reductions import huber_mean, trimmed_mean_square
from idkit.data.scenarios import simulate
from idkit.estimators.objective import Objective, fast_structure
from idkit.estimators.pso import ParticleSwarm
from idkit.interfaces import Cost, NormStructure
from idkit.optim import codes
from idkit.optim.fused import NormProducts
from idkit.problem import Problem
from idkit.relative import relative_error
from idkit.robots.cylindrical import CylindricalRobot


class Huber(Cost):
    """A third-party cost computing a reduction and declaring it (as idkit-robust's do)."""

    def __init__(self, delta: float = 1.0, relative: bool = False, floor: float = 1e-3) -> None:
        self.delta, self.relative, self.floor = delta, relative, floor

    def __call__(self, error: torch.Tensor, measured: torch.Tensor) -> torch.Tensor:
        e = relative_error(error, measured, self.floor) if self.relative else error
        return huber_mean(e, self.delta)

    def structure(self) -> NormStructure | None:
        if type(self).__call__ is not Huber.__call__:
            return None
        return NormStructure(("huber",), self.relative, self.floor, (self.delta,))


class Trimmed(Cost):
    def __init__(self, trim: float = 0.1, relative: bool = False, floor: float = 1e-3) -> None:
        self.trim, self.relative, self.floor = trim, relative, floor

    def __call__(self, error: torch.Tensor, measured: torch.Tensor) -> torch.Tensor:
        e = relative_error(error, measured, self.floor) if self.relative else error
        return trimmed_mean_square(e, self.trim)

    def structure(self) -> NormStructure | None:
        return NormStructure(("trimmed",), self.relative, self.floor, (self.trim,))


class Declares(Cost):
    """A cost that declares whatever structure it is given (for the checks on declarations)."""

    def __init__(self, structure: NormStructure) -> None:
        self.declared = structure

    def __call__(self, error: torch.Tensor, measured: torch.Tensor) -> torch.Tensor:
        return error.abs().sum(dim=(-2, -1))

    def structure(self) -> NormStructure | None:
        return self.declared


# --- the contract's checks --------------------------------------------------------------------


def test_structure_parameters_are_aligned_finite_numbers():
    structure = NormStructure(["fro", "huber"], parameters=[0, 2])  # lists become hashable tuples
    assert structure.norms == ("fro", "huber") and structure.parameters == (0.0, 2.0)
    assert hash(structure) == hash(NormStructure(("fro", "huber"), parameters=(0.0, 2.0)))
    assert NormStructure(("1", "inf")).parameters == ()
    with pytest.raises(ValueError, match=r"norms must be a tuple of names, e.g. \('fro',\), not a string"):
        NormStructure("fro")
    with pytest.raises(ValueError, match=r"parameters \(1.0,\) must give one value per factor of norms"):
        NormStructure(("fro", "huber"), parameters=(1.0,))
    for bad in (math.nan, math.inf, "wide", None):
        with pytest.raises(ValueError, match="parameter of factor 'huber' must be a finite number"):
            NormStructure(("huber",), parameters=(bad,))


@pytest.mark.parametrize(
    ("norms", "parameters", "message"),
    [
        (("huber",), (), r"factor 'huber' needs its delta \(> 0\) in the structure's parameters"),
        (("trimmed",), (), r"factor 'trimmed' needs its trim \(in \[0, 1\)\)"),
        (("huber",), (0.0,), r"huber: delta must be > 0, got 0.0"),
        (("trimmed",), (1.0,), r"trimmed: trim must be in \[0, 1\), got 1.0"),
        (("fro", "huber"), (0.5, 1.0), r"norm 'fro' takes no parameter \(0.0 in its place\), got 0.5"),
        (("fro", "median"), (), r"unknown factor\(s\) \['median'\]; known norms: fro, 2, 1, inf"),
    ],
)
def test_invalid_factors_are_named(norms, parameters, message):
    with pytest.raises(ValueError, match=message):
        factor_parameters(norms, parameters)


def test_fast_structure_rejects_a_bad_declaration_and_skips_unknown_factors():
    with pytest.raises(ValueError, match=r"cost Declares declares an invalid structure .*delta must be > 0"):
        fast_structure(Declares(NormStructure(("huber",), parameters=(-1.0,))))
    assert fast_structure(Declares(NormStructure(("median",), parameters=(0.5,)))) is None  # general path
    assert fast_structure(Huber(0.5)) == NormStructure(("huber",), False, 1e-3, (0.5,))


def test_a_subclass_that_changes_call_loses_the_structure():
    class Doubled(Huber):
        def __call__(self, error, measured):
            return 2 * super().__call__(error, measured)

    assert Huber().structure() is not None and Doubled().structure() is None


# --- the fused value against the cost's own __call__ ---------------------------------------------

ON_GRID = st.sampled_from([-2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0])  # ±threshold exactly, and ties
ENTRIES = st.one_of(ON_GRID, st.floats(0.01, 4.0), st.floats(-4.0, -0.01))  # no subnormals
POWERS_OF_TWO = st.sampled_from([-4.0, -2.0, -1.0, -0.5, 0.5, 1.0, 2.0, 4.0])


@settings(max_examples=60, deadline=None)
@given(
    data=st.data(),
    shape=st.tuples(st.integers(1, 4), st.integers(1, 10)),
    batch=st.sampled_from([(), (3,), (2, 3)]),
    delta=st.floats(1e-2, 1e2),
    trim=st.one_of(st.sampled_from([0.0, 0.1, 0.5]), st.floats(0.0, 0.9)),
    relative=st.booleans(),
)
def test_fused_reductions_equal_the_costs(data, shape, batch, delta, trim, relative):
    """``NormProducts`` on the error divided as ``Objective`` divides it = ``cost(error, measured)``.

    Entries of the (relative) error sit exactly on ±delta and repeat (ties in the trimmed set):
    measured torques are powers of two, so ``(k · delta · T) / T`` is exactly ``k · delta``.
    """
    multiples = data.draw(arrays(np.float64, (2, *batch, *shape), elements=ENTRIES))
    measured = torch.from_numpy(data.draw(arrays(np.float64, shape, elements=POWERS_OF_TWO)))
    costs = [Huber(delta, relative), Trimmed(trim, relative)]
    target = torch.from_numpy(multiples) * torch.tensor([delta, 1.0]).view(2, *[1] * (len(batch) + 2))
    error = target * measured if relative else target  # [C=2, *batch, n, N]
    divided = relative_error(error, measured, 1e-3) if relative else error
    if relative:
        torch.testing.assert_close(divided, target, rtol=0, atol=0)
    fused = NormProducts([c.structure() for c in costs], *shape, error)(divided)
    own = torch.stack([cost(error[c], measured) for c, cost in enumerate(costs)])
    torch.testing.assert_close(fused, own, rtol=1e-12, atol=0)


def test_groups_follow_factors_and_parameters(rng):
    structures = [
        NormStructure(("huber",), parameters=(0.3,)),
        NormStructure(("trimmed",), parameters=(0.2,)),
        NormStructure(("huber",), parameters=(3.0,)),  # another delta: another group
        NormStructure(("huber",), True, 1e-3, (0.3,)),  # same factors as the first: one group
        NormStructure(("fro", "huber"), parameters=(0.0, 0.3)),  # a norm times a reduction
        NormStructure(("1", "inf")),
        NormStructure(("1", "inf")),  # members 5, 6: evenly spaced, a view
        NormStructure(("huber",), parameters=(0.3,)),  # members 0, 3, 7: not evenly spaced, an index
    ]
    e = 2 * torch.randn(len(structures), 5, 3, 8, generator=rng, dtype=torch.float64)
    products = NormProducts(structures, 3, 8, e)
    assert len(products.groups) == 5
    expected = torch.stack(
        [
            huber_mean(e[0], 0.3),
            trimmed_mean_square(e[1], 0.2),
            huber_mean(e[2], 3.0),
            huber_mean(e[3], 0.3),
            NORMS["fro"](e[4]) * huber_mean(e[4], 0.3),
            NORMS["1"](e[5]) * NORMS["inf"](e[5]),
            NORMS["1"](e[6]) * NORMS["inf"](e[6]),
            huber_mean(e[7], 0.3),
        ]
    )
    torch.testing.assert_close(products(e), expected, rtol=1e-12, atol=0)


@pytest.fixture(scope="module")
def problem():
    robot = CylindricalRobot()
    return Problem(robot, simulate(robot, "outliers", seed=3), paper.f13(), seed=4)


@pytest.mark.parametrize("use_regressor", [True, False])
def test_objective_fuses_reductions_with_the_paper_costs(problem, use_regressor):
    """On the robot: regressor or inverse dynamics, absolute and relative, beside f13."""
    costs = [Huber(0.5), Huber(0.05, relative=True), Trimmed(0.1), Trimmed(0.3, relative=True), paper.f13()]
    lower, upper = problem.robot.bounds()
    x = lower + (upper - lower) * torch.rand(
        len(costs), 4, 6, 4, generator=torch.Generator().manual_seed(2), dtype=torch.float64
    )
    objective = Objective(problem, costs, use_regressor=use_regressor)
    assert objective.fast_costs == list(range(len(costs)))
    measured = problem.samples.measured_matrix()
    own = torch.stack([cost(problem.error(x[c]), measured) for c, cost in enumerate(costs)])
    torch.testing.assert_close(objective(x), own, rtol=1e-12, atol=0)


# --- the engine ---------------------------------------------------------------------------------


def test_pso_runs_reductions_the_kernel_lacks_fused_not_by_calling_them(problem, monkeypatch):
    """Where the fast kernel has no form for a declared factor, ``auto`` runs the cost on the
    eager engine, fused: the cost itself is called only to report the final value, once per trial
    and cost. ``engine="native"`` then refuses it and names the factor."""
    monkeypatch.setattr(codes, "FORMS", {k: v for k, v in codes.FORMS.items() if k != "huber"})
    calls = []
    original = Huber.__call__

    def counted(self, error, measured):
        calls.append(tuple(error.shape))
        return original(self, error, measured)

    monkeypatch.setattr(Huber, "__call__", counted)
    options = {"runs": 2, "particles": 5, "iterations": 6}
    huber, f1 = ParticleSwarm(**options).fit_costs(problem, [Huber(0.5), paper.f1()])
    assert huber.details["engine"] == "eager" and "no form for huber" in huber.details["engine_build"]
    assert f1.details["engine"] == "native"
    assert calls == [(3, 10)]  # the final report only; the search never called it
    params = torch.tensor(list(huber.params.values()), dtype=torch.float64)
    reported = original(Huber(0.5), problem.error(params), problem.samples.measured_matrix())
    assert huber.cost == pytest.approx(float(reported), rel=1e-12)
    with pytest.raises(
        ValueError, match="engine='native' is impossible here: Huber: the fast kernel has no form for huber"
    ):
        ParticleSwarm(engine="native", **options).fit_costs(problem, [Huber(0.5)])
