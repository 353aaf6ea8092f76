"""The paper's 16 cost functions (eqs. 27–35) as registered variants of two small classes.

``f1``–``f8`` act on the error matrix E, ``f9``–``f16`` the same on the relative error E_rel.
Each is a product of the norms in ``idkit.costs.norms``.

Deviation from the paper: eq. (35) prints ``f8 = max_ij E_ij``, a signed maximum that a model
over-predicting every torque drives to −∞; idkit's ``f8``/``f16`` use ``max_ij |E_ij|``.
"""

from __future__ import annotations

import functools
import operator
from typing import ClassVar, TypeVar

from torch import Tensor

from idkit.costs.norms import NORMS
from idkit.interfaces import Cost, NormStructure
from idkit.relative import DEFAULT_FLOOR, relative_error


class NormProductCost(Cost):
    """Product of named norms (keys of ``idkit.costs.norms.NORMS``) of the error matrix."""

    norms: ClassVar[tuple[str, ...]] = ()

    def error_matrix(self, error: Tensor, measured: Tensor) -> Tensor:
        return error

    def __call__(self, error: Tensor, measured: Tensor) -> Tensor:
        e = self.error_matrix(error, measured)
        return functools.reduce(operator.mul, (NORMS[name](e) for name in self.norms))

    def structure(self) -> NormStructure | None:
        """The declared norm product; ``None`` for a subclass that changes what is computed."""
        own = type(self).__call__ is NormProductCost.__call__ and type(self).error_matrix in (
            NormProductCost.error_matrix,
            RelativeNormProductCost.error_matrix,
        )
        if not own or not self.norms:
            return None
        return NormStructure(tuple(self.norms), bool(self.relative), float(getattr(self, "floor", 0.0)))

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class RelativeNormProductCost(NormProductCost):
    """The same product on the relative error (eq. 27); see ``idkit.relative`` for ``floor``."""

    relative = True

    def __init__(self, floor: float = DEFAULT_FLOOR) -> None:
        self.floor = floor

    def error_matrix(self, error: Tensor, measured: Tensor) -> Tensor:
        return relative_error(error, measured, self.floor)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(floor={self.floor})"


_PAPER = {  # eq.: norms, in the order of eqs. (28)-(35)
    "28": ("fro",),
    "29": ("2",),
    "30": ("1",),
    "31": ("inf",),
    "32": ("1", "inf"),
    "33": ("1", "2", "inf"),
    "34": ("max_row_sq",),
    "35": ("max_abs",),
}


_Base = TypeVar("_Base", bound=NormProductCost)


def _variant(index: int, eq: str, base: type[_Base]) -> type[_Base]:
    norms = _PAPER[eq]
    matrix = "E_rel" if base.relative else "E"
    doc = f"f{index}: product of norms {' · '.join(norms)} of {matrix} (eq. {eq})."
    return type(f"f{index}", (base,), {"norms": norms, "__doc__": doc, "__module__": __name__})


f1, f2, f3, f4, f5, f6, f7, f8 = (_variant(i + 1, eq, NormProductCost) for i, eq in enumerate(_PAPER))
f9, f10, f11, f12, f13, f14, f15, f16 = (
    _variant(i + 9, eq, RelativeNormProductCost) for i, eq in enumerate(_PAPER)
)
