"""Every factor a cost may declare in its ``NormStructure``, named once: the registry of factors.

A factor is a matrix norm of the error ``E[..., n, N]`` (``idkit.costs.norms``) or an entrywise
reduction with one parameter (``idkit.costs.reductions``). Each entry holds the factor's
**reference**: its definition in torch, the function the paper's costs (and the plugins') call.
The faster forms are checked against it, never the other way round: the fused torch form
(``idkit.optim.fused``) and the compiled kernel's form (``idkit.optim.kernel``, by the codes in
``idkit.optim.codes.FORMS``) — ``tests/optim/test_factor_forms.py`` compares all three for every
entry here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from torch import Tensor

from idkit.costs.norms import NORMS
from idkit.costs.reductions import PARAMETRIC, Reduction


@dataclass(frozen=True)
class Factor:
    """One factor: its name, its reference ``(e[..., n, N], parameter) → [...]`` and, for an
    entrywise reduction, its parameter's name and domain (``None`` for a matrix norm, which takes
    none: ``0.0`` in its place)."""

    name: str
    reference: Callable[[Tensor, float], Tensor]
    parameter: Reduction | None = None


def _norm(function: Callable[[Tensor], Tensor]) -> Callable[[Tensor, float], Tensor]:
    def reference(e: Tensor, parameter: float = 0.0) -> Tensor:
        return function(e)

    reference.__doc__ = function.__doc__
    return reference


#: Factor name -> factor: the matrix norms, then the entrywise reductions.
FACTORS: dict[str, Factor] = {
    **{name: Factor(name, _norm(function)) for name, function in NORMS.items()},
    **{name: Factor(name, reduction.function, reduction) for name, reduction in PARAMETRIC.items()},
}


def factor_parameters(names: Sequence[str], parameters: Sequence[float] = ()) -> tuple[float, ...]:
    """One checked parameter per factor of ``names`` (``NormStructure.norms``/``parameters``).

    A reduction's parameter must lie in its domain (``Reduction.check``); a matrix norm takes none
    (``0.0`` in its place). Raises ``ValueError`` naming the factor and what is wrong.
    """
    unknown = [name for name in names if name not in FACTORS]
    if unknown:
        raise ValueError(
            f"unknown factor(s) {unknown}; known norms: {', '.join(NORMS)}; "
            f"entrywise reductions: {', '.join(PARAMETRIC)}"
        )
    if parameters and len(parameters) != len(names):
        raise ValueError(f"parameters {tuple(parameters)} do not align with the factors {tuple(names)}")
    checked = []
    for i, name in enumerate(names):
        reduction = FACTORS[name].parameter
        if reduction is not None:
            if not parameters:
                raise ValueError(
                    f"factor {name!r} needs its {reduction.parameter} ({reduction.domain}) in the "
                    "structure's parameters; none given"
                )
            checked.append(reduction.check(name, parameters[i]))
        elif parameters and parameters[i] != 0:
            raise ValueError(f"norm {name!r} takes no parameter (0.0 in its place), got {parameters[i]!r}")
        else:
            checked.append(0.0)
    return tuple(checked)
