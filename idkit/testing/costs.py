"""Conformance checks for ``Cost`` plugins.

Shape (``idkit.interfaces``): ``cost(error[..., n, N], measured[n, N]) -> value[...]``, where
``error = measured - predicted`` in the paper's joints x samples layout. A cost that declares what
it computes (``Cost.structure()``) is held to it: estimators evaluate the declaration, not the cost.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from idkit.costs.factors import FACTORS
from idkit.estimators.objective import fast_structure
from idkit.interfaces import Cost
from idkit.optim.fused import NormProducts
from idkit.relative import relative_denominator
from idkit.testing._common import (
    BATCH_SHAPES,
    DTYPES,
    RTOL,
    call,
    check_hyperparameters,
    conformance_check,
    expect_close,
    expect_raises,
    expect_tensor,
    fail,
    shape_str,
)

#: Joints and samples of the checks' error matrices (distinct, so a transposed use shows).
N_JOINTS, N_SAMPLES = 3, 7


def measured_torques(dtype: torch.dtype = torch.float64) -> Tensor:
    """Reproducible measured torques ``[n, N]`` with ``0.5 <= |T| <= 2`` (no near-zero entries)."""
    gen = torch.Generator().manual_seed(20260201)
    size = torch.rand(N_JOINTS, N_SAMPLES, generator=gen, dtype=torch.float64) * 1.5 + 0.5
    sign = torch.where(torch.rand(N_JOINTS, N_SAMPLES, generator=gen, dtype=torch.float64) < 0.5, -1.0, 1.0)
    return (sign * size).to(dtype)


def errors(batch: tuple[int, ...] = (), dtype: torch.dtype = torch.float64) -> Tensor:
    """Reproducible error matrices ``[*batch, n, N]``, normal with standard deviation 0.3."""
    gen = torch.Generator().manual_seed(20260202)
    return (0.3 * torch.randn(*batch, N_JOINTS, N_SAMPLES, generator=gen, dtype=torch.float64)).to(dtype)


def _cost_call(cost: Cost, error: Tensor, measured: Tensor) -> Tensor:
    what = f"cost({shape_str('error', error.shape)}, {shape_str('measured', measured.shape)})"
    return call(what, cost, error, measured)


@conformance_check
def check_cost_relative_flag(cost: Cost) -> None:
    """``relative`` is a bool: whether the cost divides by the measured torques."""
    if not isinstance(cost.relative, bool):
        fail(f"relative must be a bool, got {cost.relative!r}")


@conformance_check
def check_cost_shapes_and_dtypes(cost: Cost) -> None:
    """``error[*b, n, N]`` gives finite ``value[*b]`` of the input dtype for ``b`` in ``()``, ``(2,)``,
    ``(2, 3)`` and float32/float64, without changing its inputs."""
    for dtype in DTYPES:
        measured = measured_torques(dtype)
        for batch in BATCH_SHAPES:
            error = errors(batch, dtype)
            before = error.clone(), measured.clone()
            value = _cost_call(cost, error, measured)
            expect_tensor(value, f"cost({shape_str('error', error.shape)}, {dtype})", batch, dtype)
            if not (torch.equal(before[0], error) and torch.equal(before[1], measured)):
                fail(f"cost({shape_str('error', error.shape)}) modified its inputs in place")


@conformance_check
def check_cost_batch_invariance(cost: Cost) -> None:
    """A batched call equals the stack of unbatched calls (no mixing across the batch)."""
    measured, error = measured_torques(), errors((2, 3))
    batched = _cost_call(cost, error, measured)
    single = torch.stack(
        [torch.stack([_cost_call(cost, error[i, j], measured) for j in range(3)]) for i in range(2)]
    )
    expect_close(batched, single, "cost(error[2, 3, n, N]) vs. six calls with error[n, N]", 1e-10)


@conformance_check
def check_cost_zero_error_is_best(cost: Cost) -> None:
    """A perfect fit (zero error) costs no more than any of several random errors."""
    measured = measured_torques()
    zero = _cost_call(cost, torch.zeros(N_JOINTS, N_SAMPLES, dtype=torch.float64), measured)
    expect_tensor(zero, "cost(zero error)", (), torch.float64)
    values = _cost_call(cost, errors((8,)), measured)
    worse = (values < zero).nonzero().flatten().tolist()
    if worse:
        fail(
            f"a random error costs {values[worse[0]].item()!r} < {zero.item()!r} = cost of zero error; "
            "identification minimises the cost, so a perfect fit must be a minimum"
        )


@conformance_check
def check_cost_relative_scale_invariance(cost: Cost) -> None:
    """A relative cost depends on ``error / measured`` only: scaling both by 3.7 changes nothing."""
    if not cost.relative:
        return
    measured, error = measured_torques(), errors((2,))
    base = _cost_call(cost, error, measured)
    scaled = _cost_call(cost, 3.7 * error, 3.7 * measured)
    expect_close(
        scaled, base, "relative cost of (3.7 error, 3.7 measured) vs (error, measured)", RTOL[torch.float64]
    )


@conformance_check
def check_cost_rejects_bad_shapes(cost: Cost) -> None:
    """A relative cost given ``measured`` that does not match ``error``'s ``[n, N]`` raises instead of
    broadcasting. (An absolute cost may ignore ``measured``.)"""
    if not cost.relative:
        return
    error, good = errors((2,)), measured_torques()
    fix = "Check that measured.shape == error.shape[-2:] and raise ValueError."
    wrong = (
        torch.cat([good, good[:, :1]], dim=1),  # [n, N + 1]
        torch.cat([good, good[:1]], dim=0),  # [n + 1, N]
        good[:1],  # [1, N]: would broadcast silently over the joints
    )
    for measured in wrong:
        expect_raises(
            f"cost(error[2, {N_JOINTS}, {N_SAMPLES}], {shape_str('measured', measured.shape)})",
            cost,
            error,
            measured,
            fix=fix,
        )


@conformance_check
def check_cost_differentiable(cost: Cost) -> None:
    """Autograd gives finite gradients w.r.t. the error (gradient estimators such as Adam need them)."""
    error = errors((2,)).requires_grad_(True)
    value = _cost_call(cost, error, measured_torques())
    if not value.requires_grad:
        fail("cost output does not depend on error through autograd (detached?)")
    (grad,) = torch.autograd.grad(value.sum(), error, allow_unused=True)
    if grad is None:
        fail("cost output has no gradient w.r.t. error")
    expect_tensor(grad, "d cost / d error", tuple(error.shape), error.dtype)


#: Scales of the error matrices ``check_cost_structure_matches_call`` uses, so entries fall on both
#: sides of a reduction's threshold (Huber's ``delta``, a trimmed mean's cut).
STRUCTURE_SCALES = (0.01, 0.3, 3.0, 30.0)


@conformance_check
def check_cost_structure_matches_call(cost: Cost) -> None:
    """A declared structure (``Cost.structure()``) computes what ``__call__`` does, to 1e-12 relative.

    Search estimators evaluate the declaration (fused with other costs, or in a compiled kernel)
    instead of calling the cost, so a declaration that differs from ``__call__`` would silently
    optimise another criterion. Checked: every factor is one idkit knows, parameters are valid,
    ``relative`` matches the cost's, and the fused value (``NormProducts`` on the error divided by
    ``relative_denominator(measured, floor)`` when relative) equals ``cost(error, measured)`` over
    error matrices of several scales. A cost without a structure passes.
    """
    structure = call("cost.structure()", cost.structure)
    if structure is None:
        return
    unknown = sorted(set(structure.norms) - FACTORS.keys())
    if unknown or not structure.norms:
        fail(
            f"structure() declares {structure}: factor(s) {unknown} unknown to idkit (known: "
            f"{', '.join(sorted(FACTORS))}); declare only known factors, or return None"
        )
    try:
        fast_structure(cost)
    except ValueError as err:
        fail(str(err))
    if structure.relative != cost.relative:
        fail(f"structure().relative is {structure.relative} but the cost's relative is {cost.relative}")
    measured = measured_torques()
    error = torch.cat([scale * errors((4,)) for scale in STRUCTURE_SCALES])
    value = _cost_call(cost, error, measured)
    e = error / relative_denominator(measured, structure.floor) if structure.relative else error
    fused = NormProducts([structure], N_JOINTS, N_SAMPLES, e)(e[None])[0]
    expect_close(fused, value, f"declared {structure} vs cost(error[{len(error)}, n, N], measured)", 1e-12)


COST_CHECKS: tuple[Callable[[Cost], None], ...] = (
    check_hyperparameters,
    check_cost_relative_flag,
    check_cost_shapes_and_dtypes,
    check_cost_batch_invariance,
    check_cost_zero_error_is_best,
    check_cost_relative_scale_invariance,
    check_cost_rejects_bad_shapes,
    check_cost_differentiable,
    check_cost_structure_matches_call,
)
