"""One definition per factor: the fused torch form and the kernel's form agree with the reference
(``idkit.costs.factors.FACTORS``) for every registered factor, alone and in products."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit import registry
from idkit.costs.factors import FACTORS
from idkit.data.scenarios import simulate
from idkit.estimators.objective import Objective, fast_structure
from idkit.interfaces import NormStructure
from idkit.optim import codes, fast
from idkit.optim.base_map import identity
from idkit.optim.fused import NormProducts
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot

#: A few parameters per factor: 0 for a norm; for the reductions, values that exercise each branch.
PARAMETERS = {
    "huber": (0.05, 0.7, 50.0),  # all linear, mixed, all quadratic
    "trimmed": (0.0, 0.1, 0.29, 0.5, 0.97),
}
CASES = [(name, value) for name in FACTORS for value in PARAMETERS.get(name, (0.0,))]


def test_every_registered_factor_has_a_kernel_form():
    assert set(FACTORS) == set(codes.FORMS)


def _kernel_costs(structures: list[NormStructure], e: torch.Tensor) -> torch.Tensor:
    """The kernel's costs ``[L, K]`` of the error matrices ``e[L, K, n, N]``: positions ``x = I``
    (one-hot per particle), so ``E = offset + x · linear`` is exactly ``e[l, k]`` with
    ``linear[l, k] = e[l, k]`` and no offset."""
    slots, particles, n, samples = e.shape
    linear = e.reshape(slots, particles, n * samples).contiguous()
    offset = torch.zeros(slots, n * samples, dtype=torch.float64)
    spec = fast.ProductSpec(linear, offset, n, tuple(structures), lambda x: x, identity(particles))
    x = torch.eye(particles, dtype=torch.float64).expand(slots, particles, particles)
    return fast.evaluate(spec, x)


def _error(seed: int, slots: int, particles: int, samples: int) -> torch.Tensor:
    """Dyadic entries of few bits: sums are exact in any order, so only each form's own rounding
    remains (an entry near 0 would otherwise carry the construction's rounding)."""
    generator = torch.Generator().manual_seed(seed)
    return torch.randint(-(2**10), 2**10, (slots, particles, 3, samples), generator=generator).double() / 2**8


def _check(seed: int, samples: int, particles: int = 5) -> None:
    structures = [NormStructure((name,), parameters=(value,)) for name, value in CASES]
    structures.append(NormStructure(("huber", "2", "trimmed"), parameters=(0.7, 0.0, 0.1)))  # a product
    structures.append(NormStructure(("1", "inf", "fro", "max_abs")))
    e = _error(seed, len(structures), particles, samples)
    kernel = _kernel_costs(structures, e)
    for slot, structure in enumerate(structures):
        reference = torch.ones(e.shape[1], dtype=torch.float64)
        for name, value in zip(structure.norms, structure.parameters or (0.0,) * 4, strict=False):
            reference = reference * FACTORS[name].reference(e[slot], value)
        fused = NormProducts([structure], 3, samples, e)(e[slot : slot + 1])[0]
        np.testing.assert_allclose(fused, reference, rtol=1e-12, err_msg=f"fused {structure}")
        np.testing.assert_allclose(kernel[slot], reference, rtol=1e-12, err_msg=f"kernel {structure}")


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_fused_and_kernel_forms_agree_with_the_reference(seed):
    _check(seed, samples=10)


def test_forms_agree_on_a_long_recording():
    _check(0, samples=400)


def test_forms_agree_for_many_particles_side_by_side():
    """150 particles in one tile: the kernel's trimmed mean selects for ``LANES`` of them at a time
    (two full groups and a remainder), the spectral norm sums their Gram matrices side by side."""
    from idkit.optim.kernel import LANES, TILE

    assert 2 * LANES < 150 <= TILE
    _check(1, samples=10, particles=150)


@pytest.mark.parametrize("name", FACTORS)
def test_a_nan_entry_never_makes_a_best(name):
    """A NaN error (e.g. a base map's sqrt of a negative) must never look like a good cost: the
    kernel's cost is NaN, so the particle's personal best stays at its start, infinity."""
    e = _error(1, 1, 1, 10)
    e[0, 0, 1, 3] = math.nan
    value = 0.5 if name == "trimmed" else PARAMETERS.get(name, (0.0,))[-1]
    assert _kernel_costs([NormStructure((name,), parameters=(value,))], e)[0, 0] == math.inf


@pytest.mark.parametrize("name", registry.available("cost"))
def test_every_registered_cost_gives_the_same_value_on_the_kernel_as_its_own_call(name):
    """The whole chain for each registered cost that declares a structure: the objective's spec
    (relative denominators, regressor, base map) on the kernel = the cost's ``__call__``."""
    cost = registry.create("cost", name)
    if fast_structure(cost) is None:
        pytest.skip(f"{name} declares no structure: it is called as it is")
    robot = CylindricalRobot()
    problem = Problem(robot, simulate(robot, "outliers", seed=2), cost, seed=0)
    objective = Objective(problem, [cost])
    lower, upper = objective.lower, objective.upper
    x = lower + (upper - lower) * torch.rand(
        1, 9, 4, generator=torch.Generator().manual_seed(1), dtype=torch.float64
    )
    kernel = fast.evaluate(objective.spec(), x)[0]
    own = torch.stack([cost(problem.error(point), problem.samples.measured_matrix()) for point in x[0]])
    rtol = 1e-8 if "2" in fast_structure(cost).norms else 1e-12  # the spectral norm's closed form
    np.testing.assert_allclose(kernel, own, rtol=rtol)
