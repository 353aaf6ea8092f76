"""The excitation conformance checks pass on the built-ins and catch what they claim to catch."""

from __future__ import annotations

import pytest

from idkit.excitation.fourier import FourierExcitation
from idkit.testing import ConformanceError, check_excitation, check_plugin
from idkit.testing import excitations as checks


class WrongVelocity(FourierExcitation):
    def evaluate(self, coefficients, t):
        q, qd, qdd = super().evaluate(coefficients, t)
        return q, 2 * qd, qdd


class FirstOfBatchOnly(FourierExcitation):
    def evaluate(self, coefficients, t):
        return super().evaluate(coefficients.reshape(-1, coefficients.shape[-1])[0], t)


class ForgetsCoefficients(FourierExcitation):
    def options(self):
        return {"n_joints": self.n_joints, "harmonics": self.harmonics, "period": self.period}


@pytest.mark.parametrize("name", ["paper", "fourier"])
def test_built_ins_conform(name):
    check_plugin("excitation", name)


@pytest.mark.parametrize(
    ("plugin", "check", "match"),
    [
        (WrongVelocity(2, a=[[1.0] * 5] * 2, b=[[0.5] * 5] * 2), checks.check_excitation_derivatives, "qd"),
        (FirstOfBatchOnly(2), checks.check_excitation_shapes_and_dtypes, r"expected \(2, 7, 2\)"),
        (
            ForgetsCoefficients(2, a=[[1.0] * 5] * 2, b=[[0.5] * 5] * 2),
            checks.check_excitation_round_trips,
            "options",
        ),
    ],
)
def test_checks_catch_broken_excitations(plugin, check, match):
    with pytest.raises(ConformanceError, match=match):
        check(plugin)
    with pytest.raises(ConformanceError, match="conformance checks failed"):
        check_excitation(plugin)
