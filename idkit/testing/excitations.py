"""Conformance checks for ``Excitation`` plugins (``idkit.excitations``)."""

from __future__ import annotations

from collections.abc import Callable

import torch

from idkit.interfaces import Excitation
from idkit.testing._common import (
    BATCH_SHAPES,
    DTYPES,
    call,
    check_hyperparameters,
    conformance_check,
    expect_close,
    expect_tensor,
    fail,
)

TIMES = torch.linspace(0.25, 9.75, 7, dtype=torch.float64)


def _perturbed(excitation: Excitation, batch: tuple[int, ...]) -> torch.Tensor:
    """Coefficient sets ``[*batch, C]`` near the excitation's own (seeded)."""
    vector = call("to_vector()", excitation.to_vector)
    g = torch.Generator().manual_seed(0)
    return vector + 0.05 * (1 + vector.abs()) * torch.randn(
        *batch, vector.numel(), generator=g, dtype=vector.dtype
    )


@conformance_check
def check_excitation_shapes_and_dtypes(excitation: Excitation) -> None:
    """``evaluate(c[..., C], t[T])`` is finite ``[..., T, n]`` in ``t``'s dtype; ``__call__`` ``[T, n]``."""
    n = excitation.n_joints
    for dtype in DTYPES:
        t = TIMES.to(dtype)
        for batch in BATCH_SHAPES:
            out = call(
                f"evaluate(c{list(batch)}, t[7], {dtype})",
                excitation.evaluate,
                _perturbed(excitation, batch),
                t,
            )
            if not (isinstance(out, tuple) and len(out) == 3):
                fail(f"evaluate must return a tuple (q, qd, qdd), got {type(out).__name__}")
            for name, x in zip(("q", "qd", "qdd"), out, strict=True):
                expect_tensor(x, f"evaluate(c{list(batch)}, t[7], {dtype}) {name}", (*batch, 7, n), dtype)
        for name, x in zip(("q", "qd", "qdd"), call(f"__call__(t[7], {dtype})", excitation, t), strict=True):
            expect_tensor(x, f"__call__(t[7], {dtype}) {name}", (7, n), dtype)


@conformance_check
def check_excitation_batch_invariance(excitation: Excitation) -> None:
    """A batch of coefficient sets gives the stacked results of each set alone."""
    coefficients = _perturbed(excitation, (2, 3))
    batched = excitation.evaluate(coefficients, TIMES)
    for index in ((0, 0), (1, 2)):
        single = excitation.evaluate(coefficients[index], TIMES)
        for name, a, b in zip(("q", "qd", "qdd"), batched, single, strict=True):
            expect_close(a[index], b, f"evaluate batch element {index} {name} vs alone", rtol=1e-12)


@conformance_check
def check_excitation_round_trips(excitation: Excitation) -> None:
    """``from_vector(to_vector())`` and ``type(e)(**e.options())`` rebuild the same excitation."""
    vector = excitation.to_vector()
    again = call("from_vector(to_vector())", excitation.from_vector, vector)
    if not torch.equal(again.to_vector(), vector):
        fail("from_vector(to_vector()).to_vector() differs from to_vector()")
    rebuilt = call(f"{type(excitation).__name__}(**options())", type(excitation), **excitation.options())
    if not torch.equal(rebuilt.to_vector(), vector):
        fail("rebuilding from options() changed the coefficient vector (a YAML file would not restore it)")


@conformance_check
def check_excitation_derivatives(excitation: Excitation) -> None:
    """``qd`` and ``qdd`` are the time derivatives of ``q`` and ``qd`` (central differences, h = 1e-4)."""
    h = 1e-4
    q, qd, qdd = excitation(TIMES)
    q_plus, qd_plus, _ = excitation(TIMES + h)
    q_minus, qd_minus, _ = excitation(TIMES - h)
    expect_close((q_plus - q_minus) / (2 * h), qd, "central difference of q vs qd", rtol=1e-5)
    expect_close((qd_plus - qd_minus) / (2 * h), qdd, "central difference of qd vs qdd", rtol=1e-5)


EXCITATION_CHECKS: tuple[Callable[[Excitation], None], ...] = (
    check_hyperparameters,
    check_excitation_shapes_and_dtypes,
    check_excitation_batch_invariance,
    check_excitation_round_trips,
    check_excitation_derivatives,
)
