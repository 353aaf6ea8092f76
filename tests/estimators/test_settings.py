"""Typed settings of the least-squares family and pcls: checked once, in the constructor."""

from __future__ import annotations

import dataclasses

import pytest

from idkit import registry
from idkit.conic.program import AUTO_SOLVERS, ConsistentSettings
from idkit.estimators.linear.least_squares import LinearSettings
from idkit.estimators.linear.robust_ls import RLSSettings
from idkit.options import OptionError


@pytest.mark.parametrize(
    ("name", "options", "message"),
    [
        ("ls", {"floor": -1.0}, "ls: floor must be a finite number >= 0, got -1.0"),
        ("tls", {"floor": float("inf")}, "tls: floor must be a finite number >= 0, got inf"),
        ("ls", {"max_cond": 0.0}, "ls: max_cond must be None or a number > 0, got 0.0"),
        ("rls", {"threads": 0}, "rls: threads must be None or an integer >= 1, got 0"),
        ("rls", {"rho": -1.0}, "rls: rho must be None or a finite number >= 0, got -1.0"),
        (
            "pcls",
            {"prior_weight": -1.0},
            "pcls: prior_weight must be a finite number >= 0 or 'auto', got -1.0",
        ),
        ("pcls", {"min_mass": -0.5}, r"pcls: min_mass must be None or a finite number >= 0 \(kg\), got -0.5"),
    ],
)
def test_a_value_the_fit_cannot_use_is_refused_by_the_constructor(name, options, message):
    with pytest.raises(ValueError, match=f"^{message}$"):
        registry.create("estimator", name, **options)


@pytest.mark.parametrize(
    ("name", "choices"), [("pcls", "'auto' or 'clarabel' or 'scs'"), ("rls", "'closed_form' or 'cvxpy'")]
)
def test_a_string_choice_outside_its_literal_is_one_line_listing_the_choices(name, choices):
    with pytest.raises(OptionError) as caught:
        registry.create("estimator", name, solver="CLARABEL")
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith(f"estimator {name!r} option 'solver' must be {choices}, got 'CLARABEL' (str)")


def test_a_prior_weight_that_is_neither_a_number_nor_auto_is_one_line():
    with pytest.raises(
        OptionError, match=r"^estimator 'pcls' option 'prior_weight' must be a float or 'auto'"
    ):
        registry.create("estimator", "pcls", prior_weight="soon")
    assert registry.create("estimator", "pcls", prior_weight="300").resolve().prior_weight == 300.0
    from idkit.estimators.physical import PhysicallyConsistentLS

    with pytest.raises(
        ValueError, match=r"^pcls: prior_weight must be a finite number >= 0 or 'auto', got 'soon'$"
    ):
        PhysicallyConsistentLS(prior_weight="soon")  # type: ignore[arg-type]


def test_pcls_refuses_an_unknown_solver_from_python_too():
    from idkit.estimators.physical import PhysicallyConsistentLS

    with pytest.raises(
        ValueError, match="^pcls: solver must be one of 'auto', 'clarabel', 'scs', got 'CLARABEL'$"
    ):
        PhysicallyConsistentLS(solver="CLARABEL")


def test_settings_are_resolved_and_frozen_while_the_options_stay_as_given():
    from idkit.estimators.linear.robust_ls import RobustLeastSquares

    rls = RobustLeastSquares(relative=True, solver="cvxpy", floor=0)
    assert rls.floor == 0 and isinstance(rls.floor, int)  # stored unchanged (scikit-learn's contract)
    assert rls.resolve() == RLSSettings(
        relative=True,
        floor=0.0,
        max_cond=None,
        threads=None,
        rho=None,
        solver="cvxpy",
        cvxpy_solver=None,
        polish=True,
    )
    assert isinstance(rls.resolve(), LinearSettings)
    with pytest.raises(dataclasses.FrozenInstanceError):
        rls.resolve().solver = "closed_form"
    pcls = registry.create("estimator", "pcls")
    assert pcls.resolve() == ConsistentSettings("auto", None, "auto", AUTO_SOLVERS)
    pcls.solver = "scs"  # resolved when asked (at every fit): a changed option takes effect
    assert pcls.resolve().conic_solvers == ("SCS",)
    assert registry.create("estimator", "pcls", solver="scs").resolve().conic_solvers == ("SCS",)
    with pytest.raises(dataclasses.FrozenInstanceError):
        pcls.resolve().solver = "scs"
