"""Conformance suite for idkit plugins — run it in your plugin's tests.

In the spirit of scikit-learn's ``check_estimator`` and BoTorch's test mix-ins: every check is a
plain function that raises ``ConformanceError`` (an ``AssertionError``) naming the check, the
plugin class and exactly what broke. No pytest needed to import or run it.

All checks at once (one error listing every failure)::

    from idkit.testing import check_cost, check_estimator, check_robot

    check_robot(MyRobot())
    check_cost(MyCost())
    check_estimator(MyEstimator(iterations=5))                 # on the core cylindrical robot
    check_estimator(MyEstimator(), functools.partial(make_problem, MyRobot()))

One pytest test per check::

    @pytest.mark.parametrize("check", ROBOT_CHECKS, ids=lambda c: c.__name__)
    def test_my_robot(check):
        check(MyRobot())

By registered name (built with the class's ``conformance_options``, if it declares any)::

    check_plugin("estimator", "irls")

What is checked: hyperparameters are keyword arguments with defaults stored as same-named
attributes, and for estimators ``get_params()`` round-trips the constructor and an option assigned
after construction takes effect (or the assignment raises; ``idkit.hyperparameters``); shapes
over batch shapes ``()``, ``(2,)``, ``(2, 3)``; float32/float64 preserved; batched calls equal
stacked single calls; regressor consistency (``Y @ base_params(p) == inverse_dynamics(p)``,
``base_params(params_from_base(a)) == a``); well-formed bounds; finite
outputs and gradients on valid input; wrong trailing sizes raise instead of broadcasting;
estimators are deterministic under a seed, report ``Estimate.cost`` on ``problem.cost``, give
strict-JSON estimates, work in float32, keep ``details["history"]`` in the documented format
(``idkit.estimate.history_table``), refuse problems with fewer equations than parameters, and fail
clearly on problems they cannot handle.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from idkit.testing._common import (
    BATCH_SHAPES,
    DTYPES,
    ConformanceError,
    check_hyperparameters,
    get_params,
    options_for_checks,
)
from idkit.testing.costs import COST_CHECKS
from idkit.testing.estimators import ESTIMATOR_CHECKS, ProblemFactory, make_problem, problem_factory_for
from idkit.testing.excitations import EXCITATION_CHECKS
from idkit.testing.robots import ROBOT_CHECKS

__all__ = [
    "BATCH_SHAPES",
    "COST_CHECKS",
    "DTYPES",
    "ESTIMATOR_CHECKS",
    "EXCITATION_CHECKS",
    "ROBOT_CHECKS",
    "ConformanceError",
    "build_for_checks",
    "check_cost",
    "check_estimator",
    "check_excitation",
    "check_hyperparameters",
    "check_plugin",
    "check_robot",
    "checks_for",
    "get_params",
    "make_problem",
    "problem_factory_for",
]

_CHECKS: dict[str, Sequence[Callable[..., None]]] = {
    "robot": ROBOT_CHECKS,
    "cost": COST_CHECKS,
    "estimator": ESTIMATOR_CHECKS,
    "excitation": EXCITATION_CHECKS,
}


def checks_for(kind: str) -> Sequence[Callable[..., None]]:
    """The checks of one plugin kind (``"robot"``, ``"cost"``, ``"estimator"``), for parametrize."""
    try:
        return _CHECKS[kind]
    except KeyError:
        raise ValueError(f"unknown plugin kind {kind!r}; the kinds are {', '.join(_CHECKS)}") from None


def _run_all(plugin: Any, checks: Sequence[Callable[..., None]], *args: Any) -> None:
    failures = []
    for check in checks:
        try:
            check(plugin, *args)
        except ConformanceError as err:
            failures.append(str(err))
    if failures:
        raise ConformanceError(
            f"{len(failures)} of {len(checks)} conformance checks failed:\n- " + "\n- ".join(failures)
        )


def check_robot(robot: Any) -> None:
    """Run every robot check; raise one ``ConformanceError`` listing all failures."""
    _run_all(robot, ROBOT_CHECKS)


def check_cost(cost: Any) -> None:
    """Run every cost check; raise one ``ConformanceError`` listing all failures."""
    _run_all(cost, COST_CHECKS)


def check_estimator(estimator: Any, problem_factory: ProblemFactory | None = None) -> None:
    """Run every estimator check on problems from ``problem_factory(dtype=..., seed=...)``
    (default: ``problem_factory_for(estimator)``, the core cylindrical robot unless the class
    declares a ``conformance_robot``).

    Fits take as long as the estimator's options make them: build it with cheap options.
    """
    _run_all(estimator, ESTIMATOR_CHECKS, problem_factory or problem_factory_for(estimator))


def check_excitation(excitation: Any) -> None:
    """Run every excitation check; raise one ``ConformanceError`` listing all failures."""
    _run_all(excitation, EXCITATION_CHECKS)


def build_for_checks(kind: str, name: str, **options: Any) -> Any:
    """Create a registered plugin with ``options``, or else its class's ``conformance_options``."""
    from idkit import registry

    factory = registry.load(kind, name)
    return factory(**(options or options_for_checks(factory)))


def check_plugin(kind: str, name: str, **options: Any) -> None:
    """Load a plugin by its registered name and run every check of its kind."""
    plugin = build_for_checks(kind, name, **options)
    run = {"robot": check_robot, "cost": check_cost, "estimator": check_estimator}
    run["excitation"] = check_excitation
    run[kind](plugin)
