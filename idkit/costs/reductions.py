"""Entrywise reductions of error matrices ``E[..., n, N]``, each with one parameter: robust losses.

Not norms: they average a loss of the ``m = n · N`` entries, whatever their place in the matrix, so
an outlier pulls with a bounded force (Huber) or not at all (trimmed) and the scale does not grow
with ``N``. A cost computing one of them declares it in its ``NormStructure`` beside the matrix
norms of ``idkit.costs.norms`` (``parameters`` gives the value), and estimators evaluate it fused.

- ``"huber"``, parameter ``delta > 0``: mean of ``rho(e) = e²/2`` for ``|e| <= delta``,
  ``delta (|e| - delta/2)`` beyond (Huber 1964);
- ``"trimmed"``, parameter ``trim`` in ``[0, 1)``: mean of the ``m - floor(trim · m)`` smallest
  squared entries (least trimmed squares, Rousseeuw 1984); ``trim = 0`` is the mean square.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor

#: Slack of ``floor(trim · m)``, so that ``0.29 · 100`` drops 29 entries, not 28.
TRIM_SLACK = 1e-9


def huber_mean(e: Tensor, delta: float) -> Tensor:
    """Mean Huber loss ``[...]`` of the entries of ``e[..., n, N]``.

    ``min(|e|, delta) · (|e| − min(|e|, delta)/2)`` is ``e²/2`` within ``±delta`` and
    ``delta (|e| − delta/2)`` beyond, without a branch: halving is exact, so it rounds as the
    two-branch formula does (short of subnormal results).
    """
    a = e.abs()
    inner = a.clamp(max=delta)
    return (inner * (a - 0.5 * inner)).mean(dim=(-2, -1))


def kept_entries(entries: int, trim: float) -> int:
    """Entries a trimmed mean of ``entries`` squares keeps: ``entries − floor(trim · entries)``."""
    return entries - math.floor(trim * entries + TRIM_SLACK)


def trimmed_mean_square(e: Tensor, trim: float) -> Tensor:
    """Mean ``[...]`` of the ``kept_entries(n · N, trim)`` smallest squared entries of ``e[..., n, N]``."""
    squares = e.square().flatten(-2)
    keep = kept_entries(squares.shape[-1], trim)
    if keep < 1:
        raise ValueError(f"trimmed: trim={trim} leaves none of the {squares.shape[-1]} entries")
    return torch.topk(squares, keep, dim=-1, largest=False, sorted=False).values.mean(dim=-1)


@dataclass(frozen=True)
class Reduction:
    """An entrywise reduction and the domain of its parameter (for clear errors on bad values)."""

    function: Callable[[Tensor, float], Tensor]
    parameter: str  #: the parameter's name, as the costs' option (``delta``, ``trim``)
    domain: str  #: the valid values, in words (``"> 0"``)
    valid: Callable[[float], bool]

    def check(self, name: str, value: float) -> float:
        """``value`` as a float, or ``ValueError`` naming the reduction, the parameter and its domain."""
        if not (isinstance(value, numbers.Real) and math.isfinite(value) and self.valid(value)):
            raise ValueError(f"{name}: {self.parameter} must be {self.domain}, got {value!r}")
        return float(value)


#: Reduction name -> reduction; these names may stand beside ``NORMS``' in ``NormStructure.norms``.
PARAMETRIC: dict[str, Reduction] = {
    "huber": Reduction(huber_mean, "delta", "> 0", lambda delta: delta > 0),
    "trimmed": Reduction(trimmed_mean_square, "trim", "in [0, 1)", lambda trim: 0 <= trim < 1),
}
