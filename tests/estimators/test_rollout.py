"""The ``rollout`` estimator: recovery, robustness, uncertainty, refusals.

Fast tests use the 5-DOF arm of ``mujoco.sysid``'s integration test (case ``a``) and small pendulums;
the hidden-case kinds (case ``b``: 36 unknowns under servos, ``c``: its corrupted log) are slow tests.
"""

from __future__ import annotations

import numpy as np
import pytest

from idkit import registry
from idkit.data.commands import RobotLog
from idkit.estimators.rollout import (
    FITTED_POLISH_ITERATIONS,
    POLISH_ITERATIONS,
    RolloutEstimator,
    _polish_iterations,
)
from idkit.problem import Problem
from idkit.sim.model import load_model
from idkit.sim.problem import RolloutProblem, SimRobot
from idkit.sim.quantities import select_unknowns
from idkit.testing import make_problem
from idkit.testing import rollout_cases as cases
from idkit.testing.rollout_cases import Case, corrupt, simulate

PENDULUM = cases.ARM5.split('<body name="link3"')[0] + (
    "</body></body></worldbody><actuator>"
    '<motor name="act1" joint="joint1"/><motor name="act2" joint="joint2"/></actuator></mujoco>'
)


def _errors(estimate, truth: dict[str, float]) -> np.ndarray:
    return np.array([abs(estimate.params[k] / v - 1) for k, v in truth.items()])


def test_recovers_case_a_from_far_starts():
    case = cases.case_a()
    for start in [case.start, *case.starts(2, seed=3)]:
        estimate = RolloutEstimator().fit(cases.problem_of(case, start, threads=1))
        assert _errors(estimate, case.truth).max() < 1e-6
        assert estimate.details.exact_fit


def test_a_fitted_start_gets_the_short_polish_unless_told():
    case = cases.case_a()
    fitted = cases.problem_of(case, case.start, threads=1, start_fitted=True)
    guessed = cases.problem_of(case, case.start, threads=1)
    assert _polish_iterations(guessed, RolloutEstimator()) == POLISH_ITERATIONS
    assert _polish_iterations(fitted, RolloutEstimator()) == FITTED_POLISH_ITERATIONS < POLISH_ITERATIONS
    assert _polish_iterations(fitted, RolloutEstimator(polish_iterations=7)) == 7
    estimate = RolloutEstimator().fit(fitted)
    assert estimate.details.polish
    assert max(solve.iterations for solve in estimate.details.polish) <= FITTED_POLISH_ITERATIONS
    searched = RolloutEstimator().fit(guessed).details.search
    assert estimate.details.search.evaluations < searched.evaluations  # half the swarm's iterations


def test_is_robust_to_glitches_without_a_tuned_scale():
    """Noise and 3 % glitched samples on a 2-joint pendulum: Huber at the median's scale stays near the
    truth; least squares (loss=linear) is pulled away by the glitches."""
    t = np.arange(600) * 0.002
    ctrl = np.column_stack([3 * np.sin(2 * np.pi * 1.3 * t), 2 * np.cos(2 * np.pi * 1.9 * t)])
    q, qd = simulate(PENDULUM, ctrl)
    q, qd = corrupt(q, qd, (1e-4, 1e-2), 0.03, np.random.default_rng(5))
    log = RobotLog(t, q, qd, t, ctrl, ("joint1", "joint2"), ("act1.ctrl", "act2.ctrl"), "glitched pendulum")
    truth = {"joint1.armature": 0.5, "joint2.armature": 0.4, "joint1.damping": 1.0, "joint2.damping": 0.8}
    case = Case(
        "p", PENDULUM, ("armature", "damping"), truth, log, log, {}, {k: 2 * v for k, v in truth.items()}
    )
    robust = RolloutEstimator().fit(cases.problem_of(case, threads=1))
    plain = RolloutEstimator(loss="linear").fit(cases.problem_of(case, threads=1))
    assert _errors(robust, truth).max() < 0.02
    assert _errors(plain, truth).max() > 3 * _errors(robust, truth).max()


def test_reports_uncertainty_and_names_a_flat_direction():
    """A position servo's damping term and the joint's damping are one force: the pair is flat."""
    text = PENDULUM.replace(
        '<motor name="act1" joint="joint1"/>', '<position name="act1" joint="joint1" kp="30" kv="2"/>'
    )
    t = np.arange(400) * 0.002
    ctrl = np.column_stack([0.5 * np.sin(2 * np.pi * 1.1 * t), 2 * np.cos(2 * np.pi * 1.7 * t)])
    q, qd = simulate(text, ctrl)
    log = RobotLog(t, q, qd, t, ctrl, ("joint1", "joint2"), ("joint1.q_ref", "act2.ctrl"), "servo pendulum")
    sim = load_model(text)
    unknowns = select_unknowns(
        sim,
        log.joint_names,
        ["joint1.damping", "act1.kv", "joint2.armature"],
        start={"joint1.damping": 0.8, "act1.kv": 2.5},
    )
    problem = RolloutProblem(SimRobot(sim, unknowns, log.joint_names), log, threads=1)
    estimate = RolloutEstimator().fit(problem)
    flat = estimate.details.uncertainty.flat
    assert len(flat) == 1 and set(flat[0]["direction"]) == {"joint1.damping", "act1.kv"}
    assert estimate.params["joint1.damping"] + estimate.params["act1.kv"] == pytest.approx(3.0, rel=1e-6)
    assert estimate.params["joint2.armature"] == pytest.approx(0.4, rel=1e-6)
    assert np.isinf(estimate.details.uncertainty.std["act1.kv"])
    assert np.isfinite(estimate.details.uncertainty.std["joint2.armature"])


def test_refuses_a_torque_problem_naming_the_task():
    with pytest.raises(ValueError, match=r"\+experiment=rollout"):
        RolloutEstimator().fit(make_problem())
    problem = cases.conformance_problem()
    with pytest.raises(ValueError, match="RolloutProblem"):
        RolloutEstimator().fit(Problem(problem.robot, problem.samples, cost=None))


def test_options_are_checked():
    with pytest.raises(ValueError, match="search_share"):
        registry.create("estimator", "rollout", search_share=0)
    with pytest.raises(ValueError, match="loss"):
        registry.create("estimator", "rollout", loss="l1")


def test_a_registered_cost_is_what_the_search_minimises_and_reports():
    problem = cases.conformance_problem()
    estimate = RolloutEstimator().fit(problem)
    values = [estimate.params[name] for name in problem.robot.param_names]
    import torch

    assert estimate.cost == pytest.approx(
        float(problem.evaluate(torch.tensor(values, dtype=torch.float64))), rel=1e-9
    )
    assert estimate.details.criterion == "problem cost"


@pytest.mark.slow
@pytest.mark.parametrize("corrupted", [False, True], ids=["b", "c"])
def test_36_unknowns_under_servos_from_random_starts(corrupted):
    """The hidden cases' kinds: every unknown within 5 % (the delay within 0.1 ms) from three starts in
    [0.2, 5] × the truth, with the defaults (no loss scale given)."""
    case = cases.case_b(corrupted=corrupted)
    for start in [case.start, *case.starts(2, seed=7)]:
        estimate = RolloutEstimator().fit(cases.problem_of(case, start))
        errors = {k: abs(estimate.params[k] / v - 1) for k, v in case.truth.items() if k != "command_delay"}
        assert max(errors.values()) < 0.05, max(errors, key=errors.get)
        assert abs(estimate.params["command_delay"] - case.truth["command_delay"]) < 1e-4


def test_a_links_inertia_is_recovered_through_its_physical_coordinates():
    """The last link's 10 inertial parameters from case a's log, started at a quarter of its mass: the
    mass, centre of mass and inertia come back (the arm's 5 moving joints excite all 10)."""
    case = cases.case_a()
    sim = load_model(case.model)
    start = {"link5.inertia.alpha": -1.5}
    unknowns = select_unknowns(sim, case.fit.joint_names, ["link5.inertia"], start=start)
    problem = RolloutProblem(SimRobot(sim, unknowns, case.fit.joint_names), case.fit, threads=1)
    estimate = RolloutEstimator(iterations=0).fit(problem)  # the polish alone: the parametrisation
    body = estimate.details.bodies["link5"]
    assert body["mass"] == pytest.approx(0.2, rel=1e-6)
    np.testing.assert_allclose(body["com"], [0, 0, 0.03], atol=1e-8)
    np.testing.assert_allclose(body["inertia"], np.diag([0.002, 0.002, 0.001]), atol=1e-9)
    assert not estimate.details.uncertainty.flat


@pytest.mark.statistical
def test_sigma_from_the_jacobian_is_the_spread_over_noise_draws():
    """60 noise draws on the 2-joint pendulum (Gaussian, 1e-3 rad and 0.1 rad/s; no glitches), the
    defaults: ``(estimate − truth) / sigma`` over the 240 values has a root mean square near 1 and the
    95 % intervals hold the truth about 95 % of the time. Bands: ~3 standard errors for 240 values,
    widened for the four unknowns of one draw being correlated."""
    t = np.arange(600) * 0.002
    ctrl = np.column_stack([3 * np.sin(2 * np.pi * 1.3 * t), 2 * np.cos(2 * np.pi * 1.9 * t)])
    clean = simulate(PENDULUM, ctrl)
    truth = {"joint1.armature": 0.5, "joint2.armature": 0.4, "joint1.damping": 1.0, "joint2.damping": 0.8}
    z, inside = [], []
    for draw in range(60):
        q, qd = corrupt(*clean, (1e-3, 1e-1), 0.0, np.random.default_rng(100 + draw))
        log = RobotLog(t, q, qd, t, ctrl, ("joint1", "joint2"), ("act1.ctrl", "act2.ctrl"), "noisy pendulum")
        start = {k: 1.5 * v for k, v in truth.items()}
        case = Case("p", PENDULUM, ("armature", "damping"), truth, log, log, {}, start)
        estimate = RolloutEstimator().fit(cases.problem_of(case, threads=1))
        for name, value in truth.items():
            z.append((estimate.params[name] - value) / estimate.details.uncertainty.std[name])
            low, high = estimate.details.uncertainty.interval95[name]
            inside.append(low <= value <= high)
    assert 0.8 < float(np.sqrt(np.mean(np.square(z)))) < 1.25
    assert 0.88 <= float(np.mean(inside)) <= 1.0
