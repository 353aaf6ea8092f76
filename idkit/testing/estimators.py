"""Conformance checks for ``Estimator`` plugins, and the small problems they are run on.

``fit(problem) -> Estimate``. Each check takes the estimator and a ``problem_factory(dtype=...,
seed=...) -> Problem``; the default, ``make_problem``, simulates the cylindrical robot on its
excitation trajectory with 2 % torque noise and the cost ``f1``. Pass
``functools.partial(make_problem, MyRobot())`` to check an estimator on another robot.

Estimators are checked with the options they were built with: build them cheaply (few
iterations), or declare ``conformance_options`` on the class and use ``check_plugin``.
"""

from __future__ import annotations

import functools
import inspect
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any, Protocol

import numpy as np
import torch
from torch import Tensor

from idkit.estimate import Estimate, HistoryError, history_table
from idkit.hyperparameters import get_params
from idkit.interfaces import Cost, Estimator, Robot, problem_type
from idkit.model import IdentifiedModel
from idkit.problem import IdentificationProblem, Problem, Samples
from idkit.testing._common import (
    call,
    check_hyperparameters,
    conformance_check,
    expect_close,
    fail,
    options_for_checks,
    same,
)


class ProblemFactory(Protocol):
    def __call__(self, *, dtype: str = "float64", seed: int = 0) -> Any: ...


def make_problem(
    robot: Robot | None = None,
    *,
    n_samples: int = 20,
    noise: float = 0.02,
    cost: Cost | str | None = "f1",
    dtype: str = "float64",
    seed: int = 0,
) -> Problem:
    """A small simulated identification problem.

    States come from ``robot.excitation`` at ``n_samples`` instants in ``(0, 10]`` s; torques from
    the robot's nominal parameters (the middle of ``bounds()`` if it has none), times
    ``1 + noise * u`` with ``u ~ U(-1, 1)``. The data are the same for every ``seed`` (the seed
    is the problem's, for the estimator's own randomness), so fits with equal seeds must agree.

    Args:
        robot: defaults to the core ``cylindrical`` robot.
        n_samples: number of samples ``N``.
        noise: multiplicative uniform torque noise level (0.02 = up to 2 %).
        cost: a ``Cost``, a registered cost name, or ``None``.
        dtype: the problem's dtype, ``"float64"`` or ``"float32"``.
        seed: the problem's seed.
    """
    from idkit import registry

    if robot is None:
        robot = registry.create("robot", "cylindrical")
    criterion = registry.create("cost", cost) if isinstance(cost, str) else cost
    truth = robot.nominal_params()
    if truth is None:
        lower, upper = robot.bounds()
        truth = (lower + upper) / 2
    t = 10.0 * torch.arange(1, n_samples + 1, dtype=torch.float64) / n_samples
    q, qd, qdd = robot.excitation(t)
    with torch.no_grad():
        tau = IdentifiedModel.from_params(robot, truth, "truth").predict(q, qd, qdd)
    gen = torch.Generator().manual_seed(20260301)
    tau = tau * (1 + noise * (2 * torch.rand(tau.shape, generator=gen, dtype=torch.float64) - 1))
    return Problem(robot, Samples(q, qd, qdd, tau), cost=criterion, seed=seed, dtype=dtype)


def problem_factory_for(estimator: Estimator) -> ProblemFactory:
    """The problems an estimator is checked on, of the kind it fits (``problem_type``): those of the
    factory its class declares as ``conformance_problem`` (``"module:function"``, called with ``dtype``
    and ``seed``; required when the kind is not the torque ``Problem``, e.g. ``rollout``'s), else
    ``make_problem`` on the robot it declares as ``conformance_robot`` (``(registered name, options)``:
    e.g. ``pcls`` needs a ``urdf`` robot), else on the default."""
    factory = getattr(type(estimator), "conformance_problem", None)
    if factory is not None:
        import importlib

        module, _, name = factory.partition(":")
        return getattr(importlib.import_module(module), name)
    kind = problem_type(estimator)
    if not issubclass(kind, Problem):
        fail(
            f"{type(estimator).__name__} fits {kind.__name__} problems, which idkit cannot make: name a "
            'factory of small ones as the class attribute conformance_problem = "package.module:function"'
        )
    spec = getattr(type(estimator), "conformance_robot", None)
    if spec is None:
        return make_problem
    from idkit import registry

    name, options = spec
    return functools.partial(make_problem, registry.create("robot", name, **options))


def _fit(estimator: Estimator, problem: Problem) -> Estimate:
    what = (
        f"fit(problem with robot {type(problem.robot).__name__}, dtype {problem.dtype}, seed {problem.seed})"
    )
    estimate = call(what, estimator.fit, problem)
    if not isinstance(estimate, Estimate):
        fail(f"{what} must return an idkit.estimate.Estimate, got {type(estimate).__name__}")
    return estimate


def _finite_floats(values: Any, what: str, names: tuple[str, ...]) -> None:
    if not isinstance(values, dict) or list(values) != list(names):
        keys = list(values) if isinstance(values, dict) else type(values).__name__
        fail(f"{what} must be a dict keyed by {list(names)} in that order, got keys {keys}")
    for name, value in values.items():
        if not isinstance(value, float) or not math.isfinite(value):
            fail(f"{what}[{name!r}] must be a finite Python float, got {value!r} ({type(value).__name__})")


@conformance_check
def check_estimator_estimate(estimator: Estimator, problem_factory: ProblemFactory = make_problem) -> None:
    """``fit`` returns an ``Estimate``: a label, finite ``params`` keyed by ``param_names``,
    ``base_params`` keyed by ``base_param_names`` (or ``None``), a wall time and a ``details`` dict."""
    problem = problem_factory(dtype="float64", seed=0)
    robot = problem.robot
    est = _fit(estimator, problem)
    if not isinstance(est.estimator, str) or not est.estimator:
        fail(f"Estimate.estimator must be a non-empty label such as 'LS-rel', got {est.estimator!r}")
    _finite_floats(est.params, "Estimate.params", robot.param_names)
    if est.base_params is not None:
        _finite_floats(est.base_params, "Estimate.base_params", robot.base_param_names)
    if not (isinstance(est.wall_time_s, float) and math.isfinite(est.wall_time_s) and est.wall_time_s >= 0):
        fail(f"Estimate.wall_time_s must be a finite float >= 0, got {est.wall_time_s!r}")
    if not isinstance(est.details, Mapping):
        fail(
            "Estimate.details must be a dict (or a record that reads as a mapping), got "
            f"{type(est.details).__name__}"
        )


@conformance_check
def check_estimator_cost_convention(
    estimator: Estimator, problem_factory: ProblemFactory = make_problem
) -> None:
    """With ``problem.cost`` set, ``Estimate.cost`` is that cost at the reported parameters (so
    estimates of different estimators compare on one criterion); their own criterion goes in details."""
    problem = problem_factory(dtype="float64", seed=0)
    if problem.cost is None:
        return
    est = _fit(estimator, problem)
    if not isinstance(est.cost, float):
        fail(f"Estimate.cost must be a float when problem.cost is set, got {est.cost!r}")
    params = torch.tensor(list(est.params.values()), dtype=torch.float64)
    with torch.no_grad():
        expected = problem.evaluate(params)
    expect_close(torch.tensor(est.cost), expected, "Estimate.cost vs problem.evaluate(Estimate.params)", 1e-6)


@conformance_check
def check_estimator_json(estimator: Estimator, problem_factory: ProblemFactory = make_problem) -> None:
    """The estimate is strict JSON (no NaN tokens) and survives ``Estimate.from_json(e.to_json())``."""
    est = _fit(estimator, problem_factory(dtype="float64", seed=0))
    text = call("Estimate.to_json()", est.to_json)
    try:
        json.loads(text)
    except ValueError as exc:
        fail(f"Estimate.to_json() is not valid JSON: {exc}")
    if Estimate.from_json(text).to_dict() != est.to_dict():
        fail("Estimate.from_json(e.to_json()) differs from e; keep details to str keys and JSON values")
    for key in est.details:
        if not isinstance(key, str):
            fail(f"Estimate.details key {key!r} is not a str; JSON would turn it into {str(key)!r}")


@conformance_check
def check_estimator_deterministic(
    estimator: Estimator, problem_factory: ProblemFactory = make_problem
) -> None:
    """Two fits with the same seed give identical params, base params and cost: all randomness
    comes from ``problem.generator()``, and no state carries over from one fit to the next."""
    fits = []
    for global_seed in (1, 2):  # a different global RNG state each time: it must not matter
        with torch.random.fork_rng():
            torch.manual_seed(global_seed)
            fits.append(_fit(estimator, problem_factory(dtype="float64", seed=7)))
    first, second = fits
    for what in ("params", "base_params", "cost"):
        a, b = getattr(first, what), getattr(second, what)
        if a != b:
            fail(
                f"two fits with seed 7 differ in Estimate.{what}: {a!r} vs {b!r}; draw random numbers "
                "only from problem.generator() and keep no state between fits"
            )


@conformance_check
def check_estimator_float32(estimator: Estimator, problem_factory: ProblemFactory = make_problem) -> None:
    """A float32 problem fits without code changes and gives finite parameters."""
    problem = problem_factory(dtype="float32", seed=0)
    est = _fit(estimator, problem)
    _finite_floats(est.params, "Estimate.params (float32 problem)", problem.robot.param_names)


@conformance_check
def check_estimator_leaves_problem_unchanged(
    estimator: Estimator, problem_factory: ProblemFactory = make_problem
) -> None:
    """``fit`` does not modify the samples it is given (every array of ``problem.samples``)."""
    problem = problem_factory(dtype="float64", seed=0)
    arrays = {k: v for k, v in vars(problem.samples).items() if isinstance(v, (Tensor, np.ndarray))}
    before = {k: torch.as_tensor(v).clone() for k, v in arrays.items()}
    _fit(estimator, problem)
    for name, old in before.items():
        if not torch.equal(old, torch.as_tensor(getattr(problem.samples, name))):
            fail(f"fit modified problem.samples.{name} in place")


@conformance_check
def check_estimator_history(estimator: Estimator, problem_factory: ProblemFactory = make_problem) -> None:
    """``details["history"]``, if kept, has the documented format (``idkit.estimate.history_table``):
    a list of numbers, a list of equal-length lists ``[runs][iterations]``, or a mapping of
    equal-length named lists — so it can be written as a table after the fit."""
    est = _fit(estimator, problem_factory(dtype="float64", seed=0))
    try:
        history_table(est.details.get("history"))
    except HistoryError as exc:
        fail(str(exc))


@conformance_check
def check_estimator_too_few_equations(
    estimator: Estimator, problem_factory: ProblemFactory = make_problem
) -> None:
    """With fewer equations (samples × joints) than parameters to identify, ``fit`` raises
    ValueError instead of returning an arbitrary estimate of near-zero cost; calling
    ``problem.check_identifiable()`` at the top of ``fit`` does it."""
    problem = problem_factory(dtype="float64", seed=0)
    n_samples = math.ceil(problem.n_identifiable / problem.robot.n_joints) - 1
    if n_samples < 1:  # one sample already gives enough equations: nothing to check
        return
    equations = n_samples * problem.robot.n_joints
    what = f"fit on {n_samples} sample(s) ({equations} equations for {problem.n_identifiable} parameters)"
    try:  # a problem that cannot even be built on so few samples is refused too
        estimate = estimator.fit(_first_samples(problem, n_samples))
    except ValueError:
        return
    except Exception as exc:
        fail(
            f"{what} raised {type(exc).__name__}: {exc}; raise ValueError (problem.check_identifiable() does)"
        )
    fail(
        f"{what} returned an estimate (cost {estimate.cost!r}) instead of raising ValueError; "
        "call problem.check_identifiable() at the top of fit"
    )


def _first_samples(problem: IdentificationProblem, n: int) -> IdentificationProblem:
    """The problem on its first ``n`` samples (every kind says how: ``head(n)``)."""
    return problem.head(n)


class _WithoutRegressor(Robot):
    """A robot that hides its regressor: what an estimator meets with, e.g., a URDF-less plugin."""

    def __init__(self, robot: Robot) -> None:
        self._robot = robot
        self.joint_names, self.param_names = robot.joint_names, robot.param_names

    def bounds(self) -> tuple[Tensor, Tensor]:
        return self._robot.bounds()

    def nominal_params(self) -> Tensor | None:
        return self._robot.nominal_params()

    def excitation(self, t: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        return self._robot.excitation(t)

    def inverse_dynamics(self, params: Tensor, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
        return self._robot.inverse_dynamics(params, q, qd, qdd)


@conformance_check
def check_estimator_unsupported_problem(
    estimator: Estimator, problem_factory: ProblemFactory = make_problem
) -> None:
    """On a problem it cannot handle — no cost, or a robot without a regressor — ``fit`` either
    works or raises ValueError/NotImplementedError saying what is missing, never a stray
    AttributeError/TypeError from deep inside."""
    problem = problem_factory(dtype="float64", seed=0)
    variants: dict[str, IdentificationProblem] = {"problem.cost = None": replace(problem, cost=None)}
    if isinstance(problem, Problem):  # the torque kind: its robot may lack the linear part
        variants["a robot without regressor()"] = Problem(
            _WithoutRegressor(problem.robot), problem.samples, cost=problem.cost
        )
    for what, variant in variants.items():
        try:
            estimator.fit(variant)
        except (ValueError, NotImplementedError):
            continue
        except Exception as exc:
            fail(
                f"fit on {what} raised {type(exc).__name__}: {exc}; raise ValueError (or "
                "NotImplementedError) that says what the estimator needs"
            )


def _comparable(a: Any, b: Any) -> bool | None:
    """Whether two attribute values are equal, or ``None`` where their type cannot tell (no ``__eq__``
    of its own: a lock, a generator)."""
    if isinstance(a, Tensor) and isinstance(b, Tensor):
        return a.shape == b.shape and a.dtype == b.dtype and bool(torch.equal(a.cpu(), b.cpu()))
    equality: object = type(a).__eq__  # only compared by identity: any callable will do
    if type(a) is type(b) and equality is object.__eq__:
        return None
    return same(a, b)


def _assigned(cls: type, start: dict[str, Any], target: dict[str, Any]) -> tuple[Any, list[str]]:
    """``cls(**start)`` given ``target``'s values by assignment, and the options whose assignment was
    refused (those are given to the constructor instead: a frozen object's way)."""
    refused: list[str] = []
    while True:
        built = call(f"{cls.__name__}(**options)", cls, **{**start, **{k: target[k] for k in refused}})
        failed = []
        for name, value in target.items():
            if name in refused or same(start.get(name), value):
                continue
            try:
                setattr(built, name, value)
            except (AttributeError, TypeError):
                failed.append(name)
        if not failed:
            return built, refused
        refused += failed


@conformance_check
def check_estimator_params(estimator: Estimator, problem_factory: ProblemFactory = make_problem) -> None:
    """scikit-learn's contract beyond storing the options (``idkit.hyperparameters``):

    - ``get_params()`` gives the constructor's keywords as stored, and ``cls(**get_params())``
      rebuilds the estimator; ``set_params(**options)`` returns it and refuses an unknown option;
    - an option assigned after construction takes effect (or the assignment raises: a frozen object):
      the estimator built with other options (the defaults, or the class's ``conformance_options``),
      then given this one's by assignment, holds the state ``cls(**options)`` holds and fits exactly
      as this estimator does. Nothing is compared where the two option sets agree: build the
      estimator with options other than its defaults for this part to bite.
    """
    cls = type(estimator)
    stored = get_params(estimator)
    if hasattr(estimator, "get_params"):
        _check_get_params(estimator, stored)
    if hasattr(estimator, "set_params"):
        _check_set_params(cls, stored)
    parameters = inspect.signature(cls).parameters
    if any(parameters[name].default is inspect.Parameter.empty for name in stored):
        return  # check_hyperparameters says which option has no default
    defaults = {name: parameters[name].default for name in stored}
    start = defaults
    if all(same(defaults[k], stored[k]) for k in stored):
        start = {**defaults, **options_for_checks(cls)}
    changed = [k for k in stored if not same(start.get(k), stored[k])]
    if not changed:
        return
    assigned, refused = _assigned(cls, start, stored)
    built = call(f"{cls.__name__}(**options)", cls, **stored)
    shown = ", ".join(f"{k}={stored[k]!r}" for k in changed if k not in refused)
    for key in sorted(set(vars(assigned)) | set(vars(built))):
        a, b = vars(assigned).get(key), vars(built).get(key)
        if _comparable(a, b) is False:
            fail(
                f"{cls.__name__}({', '.join(f'{k}={start[k]!r}' for k in changed)}) then assigning {shown} "
                f"holds self.{key} = {a!r}, but {cls.__name__} built with those options holds {b!r}: a "
                "value derived in __init__ ignores a later change; derive it in fit (a resolve() method "
                "both call, idkit.hyperparameters) or refuse the assignment"
            )
    problem = problem_factory(dtype="float64", seed=0)
    after, direct = _fit(assigned, problem), _fit(estimator, problem)
    for what in ("params", "base_params", "cost"):
        if getattr(after, what) != getattr(direct, what):
            fail(
                f"assigning {shown} after construction and fitting gives another Estimate.{what} than "
                f"building with them: {getattr(after, what)!r} vs {getattr(direct, what)!r}; read the "
                "options in fit (idkit.hyperparameters), not values derived from them in __init__"
            )


def _check_get_params(estimator: Any, stored: dict[str, Any]) -> None:
    """``get_params()`` gives the stored constructor keywords, and ``cls(**get_params())`` rebuilds."""
    cls = type(estimator)
    reported = call(f"{cls.__name__}.get_params()", estimator.get_params)
    if not isinstance(reported, dict) or list(reported) != list(stored):
        keys = list(reported) if isinstance(reported, dict) else type(reported).__name__
        fail(f"get_params() returned keys {keys}; expected the constructor's keywords {list(stored)}")
    for name, value in stored.items():
        if not same(reported[name], value):
            fail(f"get_params()[{name!r}] is {reported[name]!r} but self.{name} is {value!r}")
    rebuilt = call(f"{cls.__name__}(**get_params())", cls, **reported)
    for name, value in rebuilt.get_params().items():
        if not same(value, stored[name]):
            fail(f"{cls.__name__}(**get_params()) has {name}={value!r}, expected {stored[name]!r}")


def _check_set_params(cls: type, stored: dict[str, Any]) -> None:
    """``set_params(**options)`` returns the estimator (or refuses every assignment: a frozen object)
    and refuses an unknown option."""
    twin = call(f"{cls.__name__}(**options)", cls, **stored)
    try:
        returned = twin.set_params(**stored)
    except (AttributeError, TypeError):  # a frozen object refuses every assignment
        returned = twin
    except Exception as exc:
        fail(f"set_params(**get_params()) raised {type(exc).__name__} on valid input: {exc}")
    if returned is not twin:
        fail("set_params must return the estimator itself (scikit-learn's convention)")
    try:
        twin.set_params(no_such_option=1)
    except (ValueError, TypeError):
        pass
    else:
        fail("set_params(no_such_option=1) was accepted; an unknown option must raise a ValueError")


ESTIMATOR_CHECKS: tuple[Callable[..., None], ...] = (
    check_hyperparameters,
    check_estimator_params,
    check_estimator_estimate,
    check_estimator_cost_convention,
    check_estimator_json,
    check_estimator_deterministic,
    check_estimator_float32,
    check_estimator_leaves_problem_unchanged,
    check_estimator_unsupported_problem,
    check_estimator_history,
    check_estimator_too_few_equations,
)
