"""``check_cost_structure_matches_call``: every cost that declares a structure is held to it."""

from __future__ import annotations

import pytest
import torch

from idkit.costs import paper
from idkit.costs.reductions import huber_mean
from idkit.interfaces import Cost, NormStructure
from idkit.relative import relative_error
from idkit.testing import COST_CHECKS, ConformanceError
from idkit.testing.costs import check_cost_structure_matches_call


class Huber(Cost):
    """Declares the mean Huber loss of its ``delta``; the twins below get something wrong."""

    def __init__(self, delta: float = 1.0, relative: bool = False) -> None:
        self.delta = delta
        self.relative = relative

    def __call__(self, error: torch.Tensor, measured: torch.Tensor) -> torch.Tensor:
        e = relative_error(error, measured, 1e-3) if self.relative else error
        return huber_mean(e, self.delta)

    def structure(self) -> NormStructure | None:
        return NormStructure(("huber",), self.relative, 1e-3, (self.delta,))


class OtherDelta(Huber):
    def structure(self) -> NormStructure | None:
        return NormStructure(("huber",), self.relative, 1e-3, (2 * self.delta,))


class AbsoluteClaim(Huber):
    def structure(self) -> NormStructure | None:
        return NormStructure(("huber",), False, 1e-3, (self.delta,))


class UnknownFactor(Huber):
    def structure(self) -> NormStructure | None:
        return NormStructure(("pseudo_huber",), self.relative, 1e-3, (self.delta,))


class NoParameter(Huber):
    def structure(self) -> NormStructure | None:
        return NormStructure(("huber",), self.relative, 1e-3)


class WrongNorm(Huber):
    """Computes Huber, declares the Frobenius norm."""

    def structure(self) -> NormStructure | None:
        return NormStructure(("fro",), self.relative, 1e-3)


@pytest.mark.parametrize(
    ("cost", "message"),
    [
        (OtherDelta(), "declared NormStructure(norms=('huber',)"),
        (OtherDelta(relative=True), "worst mismatch"),
        (AbsoluteClaim(relative=True), "structure().relative is False but the cost's relative is True"),
        (UnknownFactor(), "factor(s) ['pseudo_huber'] unknown to idkit"),
        (NoParameter(), "factor 'huber' needs its delta"),
        (WrongNorm(), "declared NormStructure(norms=('fro',)"),
    ],
    ids=lambda x: type(x).__name__ if isinstance(x, Cost) else "",
)
def test_a_declaration_that_differs_from_call_is_caught(cost, message):
    assert check_cost_structure_matches_call in COST_CHECKS
    check_cost_structure_matches_call(Huber(relative=cost.relative))  # the honest twin passes
    prefix = f"^check_cost_structure_matches_call failed for .*{type(cost).__name__}"
    with pytest.raises(ConformanceError, match=prefix) as err:
        check_cost_structure_matches_call(cost)
    assert message in str(err.value)


def test_costs_without_a_structure_and_the_paper_costs_pass():
    class Plain(Cost):
        def __call__(self, error, measured):
            return error.abs().mean(dim=(-2, -1))

    check_cost_structure_matches_call(Plain())
    for index in range(1, 17):
        check_cost_structure_matches_call(getattr(paper, f"f{index}")())
