"""The conformance suite itself: good toy plugins pass, each deliberately broken one fails the
check meant to catch it, with a message that says what broke."""

from __future__ import annotations

import functools
import subprocess
import sys
import time

import pytest
import torch

from idkit.estimate import Estimate
from idkit.interfaces import Cost, Estimator, Robot
from idkit.testing import (
    COST_CHECKS,
    ESTIMATOR_CHECKS,
    ROBOT_CHECKS,
    ConformanceError,
    check_cost,
    check_estimator,
    check_robot,
    make_problem,
)
from idkit.testing import costs as cost_checks
from idkit.testing import estimators as est_checks
from idkit.testing import robots as robot_checks
from idkit.testing._common import check_hyperparameters

# --- good toy plugins ------------------------------------------------------------------------


class Pendulum(Robot):
    """One revolute joint: ``tau = J qdd + g h cos q + fv qd`` with params ``(h, J, fv)``."""

    joint_names = ("q",)
    param_names = ("h", "J", "fv")
    base_param_names = ("h", "J", "fv")

    def __init__(self, g: float = 9.81) -> None:
        self.g = g

    def bounds(self):
        return torch.tensor([0.1, 0.1, 0.0], dtype=torch.float64), torch.tensor([2.0, 2.0, 1.0])

    def nominal_params(self):
        return torch.tensor([1.0, 0.5, 0.2], dtype=torch.float64)

    def inverse_dynamics(self, params, q, qd, qdd):
        if params.shape[-1] != 3 or q.shape[-1] != 1:
            raise ValueError("pendulum: params must be [..., 3] and states [N, 1]")
        h, inertia, fv = (params[..., i, None, None] for i in range(3))  # each [..., 1, 1]
        return inertia * qdd + self.g * h * torch.cos(q) + fv * qd

    def regressor(self, q, qd, qdd):
        if q.shape[-1] != 1:
            raise ValueError("pendulum: states must be [N, 1]")
        return torch.stack((self.g * torch.cos(q), qdd, qd), dim=-1)

    def base_params(self, params):
        return params.clone()

    def params_from_base(self, alpha):
        return alpha.clone()


class MeanSquare(Cost):
    def __init__(self, relative: bool = False) -> None:
        self.relative = relative

    def __call__(self, error, measured):
        if measured.shape != error.shape[-2:]:
            raise ValueError("measured must be [n, N]")
        e = error / measured if self.relative else error
        return e.square().mean(dim=(-2, -1))


class RandomSearch(Estimator):
    """Best of ``candidates`` uniform draws in the box: seeded by the problem, reports its cost."""

    def __init__(self, candidates: int = 64) -> None:
        self.candidates = candidates

    def draw(self, problem, lower, upper):
        u = torch.rand(self.candidates, len(lower), generator=problem.generator(), dtype=torch.float64)
        return lower + u * (upper - lower)

    def fit(self, problem):
        problem.check_identifiable()
        return self.search(problem)

    def search(self, problem):
        start = time.perf_counter()
        if problem.cost is None:
            raise ValueError("random search needs problem.cost")
        lower, upper = problem.robot.bounds()
        x = self.draw(problem, lower, upper).to(problem.torch_dtype)
        costs = problem.evaluate(x)
        best = x[costs.argmin()]
        return Estimate(
            estimator="RS",
            params=dict(zip(problem.robot.param_names, best.tolist(), strict=True)),
            cost=float(problem.evaluate(best)),
            wall_time_s=time.perf_counter() - start,
            details={"candidates": self.candidates},
        )


pendulum_problem = functools.partial(make_problem, Pendulum())


def test_good_plugins_pass_everything():
    check_robot(Pendulum())
    check_cost(MeanSquare())
    check_cost(MeanSquare(relative=True))
    check_estimator(RandomSearch(), pendulum_problem)
    check_estimator(RandomSearch(candidates=8))  # default problem: the cylindrical robot


# --- broken robots -----------------------------------------------------------------------------


class Transposed(Pendulum):
    def inverse_dynamics(self, params, q, qd, qdd):
        return super().inverse_dynamics(params, q, qd, qdd).transpose(-1, -2)


class AlwaysDouble(Pendulum):
    def inverse_dynamics(self, params, q, qd, qdd):
        return super().inverse_dynamics(params.double(), q.double(), qd.double(), qdd.double())


class MixesBatch(Pendulum):
    def inverse_dynamics(self, params, q, qd, qdd):
        return (
            super().inverse_dynamics(params - params.mean() + params.mean().detach(), q, qd, qdd)
            * (1 + 0 * params.sum())
            + 1e-3 * params.mean()
        )


class Truncates(Pendulum):
    def inverse_dynamics(self, params, q, qd, qdd):
        return super().inverse_dynamics(params[..., :3], q[:, :1], qd[:, :1], qdd[:, :1])


class WrongRegressor(Pendulum):
    def regressor(self, q, qd, qdd):
        return super().regressor(q, qd, qdd) * 1.01


class LossyInverse(Pendulum):
    def params_from_base(self, alpha):
        return alpha * torch.tensor([1.0, 1.0, 0.0], dtype=alpha.dtype)


class EmptyBox(Pendulum):
    def bounds(self):
        lower, upper = super().bounds()
        return lower, upper.clone().index_fill_(0, torch.tensor([1]), 0.05)


class NominalOutside(Pendulum):
    def nominal_params(self):
        return torch.tensor([1.0, 5.0, 0.2], dtype=torch.float64)


class Detached(Pendulum):
    def inverse_dynamics(self, params, q, qd, qdd):
        return super().inverse_dynamics(params.detach(), q, qd, qdd)


class MutatesInput(Pendulum):
    def inverse_dynamics(self, params, q, qd, qdd):
        q.add_(0.0).mul_(1.0 + 1e-12)
        return super().inverse_dynamics(params, q, qd, qdd)


class DuplicateNames(Pendulum):
    param_names = ("h", "J", "h")


class BadExcitation(Pendulum):
    def excitation(self, t):
        q, qd, qdd = super().excitation(t)
        return q.T, qd, qdd


class ForgetsOption(Pendulum):
    def __init__(self, g: float = 9.81, scale: float = 1.0) -> None:
        self.g = g


class NoDefault(Pendulum):
    def __init__(self, g: float) -> None:
        self.g = g


class StoresModified(Pendulum):
    def __init__(self, g: float = 9.81) -> None:
        self.g = -g


class MisAnnotated(Pendulum):
    def __init__(self, g: float = 9.81, steps: int = 0.5) -> None:  # type: ignore[assignment]
        self.g = g
        self.steps = steps


class Kwargs(Pendulum):
    def __init__(self, **options) -> None:
        self.g = options.get("g", 9.81)


ROBOT_CASES = [
    (Transposed(), robot_checks.check_robot_shapes_and_dtypes, "returned shape"),
    (AlwaysDouble(), robot_checks.check_robot_shapes_and_dtypes, "dtype must be preserved"),
    (MixesBatch(), robot_checks.check_robot_batch_invariance, "six calls"),
    (Truncates(), robot_checks.check_robot_rejects_bad_sizes, "instead of raising"),
    (WrongRegressor(), robot_checks.check_robot_regressor, "Y @ base_params"),
    (LossyInverse(), robot_checks.check_robot_regressor, "base_params(params_from_base(alpha))"),
    (EmptyBox(), robot_checks.check_robot_bounds, "lower >= upper for 'J'"),
    (NominalOutside(), robot_checks.check_robot_nominal_params, "nominal J = 5.0 is outside"),
    (Detached(), robot_checks.check_robot_differentiable, "autograd"),
    (MutatesInput(), robot_checks.check_robot_shapes_and_dtypes, "modified its input 'q'"),
    (DuplicateNames(), robot_checks.check_robot_names, "duplicates ['h']"),
    (BadExcitation(), robot_checks.check_robot_excitation, "excitation"),
    (ForgetsOption(), check_hyperparameters, "not stored as attribute self.scale"),
    (StoresModified(), check_hyperparameters, "stores self.g = -9.81"),
    (Kwargs(), check_hyperparameters, "takes **options"),
    (MisAnnotated(), check_hyperparameters, "option 'steps' must be an int, got 0.5"),
]


@pytest.mark.parametrize(("robot", "check", "message"), ROBOT_CASES, ids=lambda x: type(x).__name__)
def test_broken_robot_is_caught(robot, check, message):
    assert check in ROBOT_CHECKS
    check(Pendulum())  # the good twin passes the same check
    with pytest.raises(
        ConformanceError, match=f"^{check.__name__} failed for .*{type(robot).__name__}"
    ) as err:
        check(robot)
    assert message in str(err.value)


def test_no_default_option_is_caught():
    with pytest.raises(ConformanceError, match="option 'g' has no default"):
        check_hyperparameters(NoDefault(9.81))


# --- broken costs ------------------------------------------------------------------------------


class NoBatch(MeanSquare):
    def __call__(self, error, measured):
        return super().__call__(error, measured).sum()


class Upcasts(MeanSquare):
    def __call__(self, error, measured):
        return super().__call__(error.double(), measured.double())


class MixesCostBatch(MeanSquare):
    def __call__(self, error, measured):
        value = super().__call__(error, measured)
        return value + 1e-3 * value.mean()


class RewardsError(MeanSquare):
    def __call__(self, error, measured):
        return -super().__call__(error, measured)


class NotScaleFree(MeanSquare):
    def __call__(self, error, measured):
        return super().__call__(error, measured) + error.abs().mean(dim=(-2, -1))


class Broadcasts(MeanSquare):
    def __call__(self, error, measured):
        e = error / measured if self.relative else error
        return e.square().mean(dim=(-2, -1))


class Rounds(MeanSquare):
    def __call__(self, error, measured):
        return super().__call__(error.detach(), measured)


COST_CASES = [
    (NoBatch(), cost_checks.check_cost_shapes_and_dtypes, "returned shape"),
    (Upcasts(), cost_checks.check_cost_shapes_and_dtypes, "dtype must be preserved"),
    (MixesCostBatch(), cost_checks.check_cost_batch_invariance, "six calls"),
    (RewardsError(), cost_checks.check_cost_zero_error_is_best, "perfect fit must be a minimum"),
    (NotScaleFree(relative=True), cost_checks.check_cost_relative_scale_invariance, "3.7"),
    (Broadcasts(relative=True), cost_checks.check_cost_rejects_bad_shapes, "measured[1, 7]"),
    (Rounds(), cost_checks.check_cost_differentiable, "autograd"),
]


@pytest.mark.parametrize(("cost", "check", "message"), COST_CASES, ids=lambda x: type(x).__name__)
def test_broken_cost_is_caught(cost, check, message):
    assert check in COST_CHECKS
    check(type(cost).__mro__[1](relative=cost.relative))  # the good twin passes
    with pytest.raises(
        ConformanceError, match=f"^{check.__name__} failed for .*{type(cost).__name__}"
    ) as err:
        check(cost)
    assert message in str(err.value)


# --- broken estimators -------------------------------------------------------------------------


class GlobalRandom(RandomSearch):
    def draw(self, problem, lower, upper):
        return lower + torch.rand(self.candidates, len(lower), dtype=torch.float64) * (upper - lower)


class RemembersFits(RandomSearch):
    fits = 0

    def draw(self, problem, lower, upper):
        self.fits += 1  # a warm start of sorts: the second fit draws other candidates
        gen = torch.Generator().manual_seed(problem.seed + self.fits)
        return lower + torch.rand(self.candidates, len(lower), generator=gen, dtype=torch.float64) * (
            upper - lower
        )


class NotJson(RandomSearch):
    def fit(self, problem):
        estimate = super().fit(problem)
        estimate.details["robot"] = problem.robot
        return estimate


class OwnCriterion(RandomSearch):
    def fit(self, problem):
        estimate = super().fit(problem)
        estimate.cost = estimate.cost * 2
        return estimate


class TensorParams(RandomSearch):
    def fit(self, problem):
        estimate = super().fit(problem)
        estimate.params = {k: torch.tensor(v) for k, v in estimate.params.items()}
        return estimate


class MutatesSamples(RandomSearch):
    def fit(self, problem):
        problem.samples.tau.mul_(1.0 + 1e-9)
        return super().fit(problem)


class CrashesWithoutCost(RandomSearch):
    def fit(self, problem):
        problem.cost.relative  # noqa: B018 - AttributeError when cost is None
        return super().fit(problem)


class Float64Only(RandomSearch):
    def fit(self, problem):
        if problem.torch_dtype != torch.float64:
            return super().fit(problem).__class__("RS", {"h": float("nan")}, None, 0.0)
        return super().fit(problem)


class UnequalHistory(RandomSearch):
    def fit(self, problem):
        estimate = super().fit(problem)
        estimate.details["history"] = [[3.0, 2.0, 1.0], [3.0, 2.0]]  # a run that stopped early
        return estimate


class IgnoresFewEquations(RandomSearch):
    def fit(self, problem):
        return self.search(problem)  # no problem.check_identifiable()


ESTIMATOR_CASES = [
    (GlobalRandom(), est_checks.check_estimator_deterministic, "problem.generator()"),
    (RemembersFits(), est_checks.check_estimator_deterministic, "two fits with seed 7 differ"),
    (NotJson(), est_checks.check_estimator_json, "to_json()"),
    (OwnCriterion(), est_checks.check_estimator_cost_convention, "problem.evaluate"),
    (TensorParams(), est_checks.check_estimator_estimate, "finite Python float"),
    (MutatesSamples(), est_checks.check_estimator_leaves_problem_unchanged, "problem.samples.tau"),
    (CrashesWithoutCost(), est_checks.check_estimator_unsupported_problem, "problem.cost = None"),
    (Float64Only(), est_checks.check_estimator_float32, "Estimate.params (float32 problem)"),
    (UnequalHistory(), est_checks.check_estimator_history, "run 1 has 2 iterations but run 0 has 3"),
    (IgnoresFewEquations(), est_checks.check_estimator_too_few_equations, "2 equations for 3 parameters"),
]


@pytest.mark.parametrize(("estimator", "check", "message"), ESTIMATOR_CASES, ids=lambda x: type(x).__name__)
def test_broken_estimator_is_caught(estimator, check, message):
    assert check in ESTIMATOR_CHECKS
    check(RandomSearch(), pendulum_problem)  # the good twin passes
    with pytest.raises(
        ConformanceError, match=f"^{check.__name__} failed for .*{type(estimator).__name__}"
    ) as e:
        check(estimator, pendulum_problem)
    assert message in str(e.value)


def test_check_functions_report_every_failure_at_once():
    with pytest.raises(ConformanceError) as err:
        check_robot(Transposed())
    text = str(err.value)
    assert text.startswith("3 of 10 conformance checks failed")
    for name in ("check_robot_shapes_and_dtypes", "check_robot_regressor", "check_robot_excitation"):
        assert name in text


def test_importable_and_usable_without_pytest():
    code = (
        "import sys; sys.modules['pytest'] = None\n"
        "import idkit.testing as t\n"
        "t.check_cost(t.build_for_checks('cost', 'f1'))\n"
        "print('pytest' in sys.modules and sys.modules['pytest'] is not None)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


class Expensive(RandomSearch):
    conformance_options = {"candidates": 4}


def test_conformance_options_are_used_by_build_for_checks_only(monkeypatch):
    from idkit import registry
    from idkit.testing import build_for_checks

    monkeypatch.setattr(registry, "load", lambda kind, name: Expensive)
    assert build_for_checks("estimator", "expensive").candidates == 4
    assert build_for_checks("estimator", "expensive", candidates=9).candidates == 9  # explicit wins
    assert Expensive().candidates == 64  # the plugin's real default is untouched
