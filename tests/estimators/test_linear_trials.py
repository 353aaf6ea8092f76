"""The least-squares family fitted over stacked trials (``fit_trials``): each trial gets its own
``fit``'s estimate, whatever the chunk and the other trials, and a bad trial is named.

References: each trial's own ``fit`` (a stack of one), and independently numpy's ``lstsq`` and
``svd`` per trial, and the cvxpy SOCP for RLS.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.costs.paper import f13
from idkit.data.scenarios import simulate, simulate_batch
from idkit.estimators.linear.least_squares import LeastSquares, TotalLeastSquares
from idkit.estimators.linear.observation import IdentificationError, IdentificationWarning
from idkit.estimators.linear.robust_ls import RobustLeastSquares
from idkit.estimators.trials import fit_trials
from idkit.problem import Problem, Samples
from idkit.relative import RelativeFloorWarning
from idkit.robots.cylindrical import CylindricalRobot

ESTIMATORS = {
    "LS": lambda: LeastSquares(),
    "LS-rel": lambda: LeastSquares(relative=True),
    "TLS": lambda: TotalLeastSquares(),
    "TLS-rel": lambda: TotalLeastSquares(relative=True),
    "RLS": lambda: RobustLeastSquares(),
    "RLS-rel": lambda: RobustLeastSquares(relative=True),
}
#: What differs between a trial fitted alone and in a stack: the stack's size and wall time.
BATCH_KEYS = {"batched_trials", "batch_wall_time_s"}
ROBOT = CylindricalRobot()


def trials_of(scenarios: tuple[str, ...], per_scenario: int, seed: int = 0) -> list[Problem]:
    """``per_scenario`` noise draws of each scenario (different noise kinds and sample counts)."""
    problems = []
    for k, scenario in enumerate(scenarios):
        batch = simulate_batch(ROBOT, scenario, trials=per_scenario, seed=seed + k)
        problems += [Problem(ROBOT, batch[t], seed=100 * k + t) for t in range(per_scenario)]
    return problems


@pytest.fixture(scope="module")
def problems() -> list[Problem]:
    return trials_of(("state_noise", "torque_noise", "all_noise", "outliers"), 3)


def assert_same_estimate(got, expected, rtol: float = 1e-12) -> None:
    """Equal label, record and warnings; every number equal to ``rtol`` (bitwise on one CPU)."""
    assert got.estimator == expected.estimator
    np.testing.assert_allclose(got.vector(), expected.vector(), rtol=rtol, atol=0)
    mine = {k: v for k, v in got.details.items() if k not in BATCH_KEYS}
    theirs = {k: v for k, v in expected.details.items() if k not in BATCH_KEYS}
    assert_close(
        (got.params, got.base_params, got.cost, mine),
        (expected.params, expected.base_params, expected.cost, theirs),
        rtol,
    )


def assert_close(got, expected, rtol: float, where: str = "") -> None:
    """Nested dicts and lists of the same shape whose floats agree to ``rtol``."""
    if isinstance(expected, dict):
        assert isinstance(got, dict) and got.keys() == expected.keys(), where
        for key in expected:
            assert_close(got[key], expected[key], rtol, f"{where}.{key}")
    elif isinstance(expected, (list, tuple)):
        assert isinstance(got, (list, tuple)) and len(got) == len(expected), where
        for i, (a, b) in enumerate(zip(got, expected, strict=True)):
            assert_close(a, b, rtol, f"{where}[{i}]")
    elif isinstance(expected, float):
        assert got == pytest.approx(expected, rel=rtol), where
    else:
        assert got == expected, where


@pytest.mark.parametrize("name", list(ESTIMATORS))
def test_each_trial_gets_its_own_fit(problems, name):
    estimator = ESTIMATORS[name]()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentificationWarning)  # nearly degenerate TLS draws
        stacked = fit_trials(estimator, problems)
        alone = [estimator.fit(p) for p in problems]
    assert [len(e) for e in stacked] == [1] * len(problems)
    for (got,), expected in zip(stacked, alone, strict=True):
        assert_same_estimate(got, expected)
        assert got.details["batched_trials"] > 1 and expected.details["batched_trials"] == 1
        assert got.wall_time_s == pytest.approx(
            got.details["batch_wall_time_s"] / got.details["batched_trials"]
        )


@pytest.mark.parametrize("name", list(ESTIMATORS))
def test_numbers_do_not_depend_on_the_chunk(problems, name):
    estimator = ESTIMATORS[name]()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentificationWarning)
        by_chunk = {chunk: fit_trials(estimator, problems, chunk=chunk) for chunk in (1, 3, None)}
    for chunk in (3, None):
        for (got,), (expected,) in zip(by_chunk[chunk], by_chunk[1], strict=True):
            assert_same_estimate(got, expected)
    assert max(e[0].details["batched_trials"] for e in by_chunk[3]) == 3


@settings(max_examples=8, deadline=None)
@given(chunk=st.integers(1, 7), seed=st.integers(0, 2**16))
def test_any_chunk_gives_the_same_ls_rel_numbers(chunk, seed):
    problems = trials_of(("torque_noise", "outliers"), 3, seed)
    ls = LeastSquares(relative=True)
    assert [e[0].params for e in fit_trials(ls, problems, chunk=chunk)] == [
        e[0].params for e in fit_trials(ls, problems, chunk=1)
    ]


def numpy_system(problem: Problem, relative: bool) -> tuple[np.ndarray, np.ndarray]:
    """``W``, ``tau`` of one trial sample by sample (eqs. 8–9, 36–37; no torque here is near 0)."""
    s = problem.samples
    Y = ROBOT.regressor(s.q, s.qd, s.qdd).numpy()
    W = np.vstack(list(Y))
    tau = s.tau.numpy().reshape(-1)
    return (W / tau[:, None], np.ones_like(tau)) if relative else (W, tau)


@pytest.mark.parametrize("relative", [False, True])
def test_stacked_ls_and_tls_match_numpy_per_trial(problems, relative):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentificationWarning)
        ls = fit_trials(LeastSquares(relative=relative), problems)
        tls = fit_trials(TotalLeastSquares(relative=relative), problems)
    for problem, (got_ls,), (got_tls,) in zip(problems, ls, tls, strict=True):
        W, tau = numpy_system(problem, relative)
        expected = np.linalg.lstsq(W, tau, rcond=None)[0]
        np.testing.assert_allclose(list(got_ls.base_params.values()), expected, rtol=1e-10)
        _, s, vt = np.linalg.svd(np.column_stack([W, tau]))
        np.testing.assert_allclose(list(got_tls.base_params.values()), -vt[-1, :-1] / vt[-1, -1], rtol=1e-8)
        assert got_tls.details["rho"] == pytest.approx(s[-1], rel=1e-10)


def test_stacked_rls_matches_the_cvxpy_reference(problems):
    """The closed form (batched SVD + secular equation per trial) against eq. (18) by cvxpy."""
    chosen = problems[::3]
    closed = fit_trials(RobustLeastSquares(relative=True), chosen)
    socp = fit_trials(RobustLeastSquares(relative=True, solver="cvxpy"), chosen)
    for (got,), (reference,) in zip(closed, socp, strict=True):
        np.testing.assert_allclose(got.vector(), reference.vector(), rtol=1e-9)
        assert got.details["rho"] == reference.details["rho"]


def test_costs_are_ignored_and_the_problem_cost_is_reported(problems):
    """A fixed criterion: one estimate per trial whatever ``costs``; ``cost`` is the problem's."""
    with_cost = [Problem(p.robot, p.samples, f13(), seed=p.seed) for p in problems[:4]]
    got = fit_trials(LeastSquares(), with_cost, costs=[f13(), f13()])
    assert [len(e) for e in got] == [1] * 4
    for (estimate,), problem in zip(got, with_cost, strict=True):
        params = torch.tensor(estimate.vector(), dtype=torch.float64)
        assert estimate.cost == pytest.approx(float(problem.evaluate(params)), rel=1e-12)
        assert estimate.cost != pytest.approx(estimate.details["criterion_value"])


# --- a bad trial among good ones ------------------------------------------------------------------


def still(problem: Problem) -> Problem:
    """The trial's torques at rest (zero velocities and accelerations): gravity only, so ``W`` has
    zero columns for the inertial base parameters (rank 2 < 4)."""
    s = problem.samples
    zero = torch.zeros_like(s.qd)
    return Problem(problem.robot, Samples(s.q, zero, zero, s.tau), seed=problem.seed)


@pytest.mark.parametrize("name", ["LS", "TLS-rel", "RLS-rel"])
def test_a_rank_deficient_trial_is_named_with_its_own_fit_error(problems, name):
    estimator = ESTIMATORS[name]()
    bad = still(problems[4])
    trials = [*problems[:4], bad, *problems[5:]]
    with pytest.raises(IdentificationError) as alone:
        estimator.fit(bad)
    assert str(alone.value).startswith("robot CylindricalRobot: observation matrix W")
    with pytest.raises(IdentificationError) as stacked:
        fit_trials(estimator, trials, chunk=3)
    assert str(stacked.value) == f"trial 4 (seed {bad.seed}): {alone.value}"


def test_a_trial_without_a_relative_error_is_named(problems):
    """All torques of joint 1 zero: the relative system of that trial alone is undefined."""
    s = problems[1].samples
    dead = Problem(ROBOT, Samples(s.q, s.qd, s.qdd, s.tau * torch.tensor([0.0, 1.0, 1.0])), seed=77)
    with pytest.raises(
        ValueError, match=r"^trial 1 \(seed 77\): relative error undefined: .*joint\(s\) \[0\]"
    ):
        fit_trials(LeastSquares(relative=True), [problems[0], dead, problems[2]])


def test_warnings_belong_to_their_trial_and_reach_the_caller(problems):
    """One trial with a zero torque: only its estimate lists the floor warning."""
    q, qd, qdd = (getattr(problems[0].samples, k).clone() for k in ("q", "qd", "qdd"))
    qd[0, 0] = qdd[0, 0] = 0.0  # sample 0: tau_1 = 0 exactly
    tau = ROBOT.inverse_dynamics(ROBOT.nominal_params(), q, qd, qdd)
    floored = Problem(ROBOT, Samples(q, qd, qdd, tau * 1.01), seed=5)
    trials = [problems[0], floored, problems[3]]
    with pytest.warns(RelativeFloorWarning) as caught:
        got = fit_trials(RobustLeastSquares(relative=True), trials)
    assert len([w for w in caught if w.category is RelativeFloorWarning]) == 1
    assert [any("RelativeFloorWarning" in w for w in e[0].details["warnings"]) for e in got] == [
        False,
        True,
        False,
    ]
    with pytest.warns(RelativeFloorWarning):
        alone = RobustLeastSquares(relative=True).fit(floored)
    assert_same_estimate(got[1][0], alone)


def test_trials_of_another_robot_are_refused(problems):
    class OtherRobot(CylindricalRobot):
        pass

    other = Problem(OtherRobot(), problems[1].samples, seed=1)
    with pytest.raises(ValueError, match="trial 1: robot OtherRobot differs from trial 0's"):
        fit_trials(LeastSquares(), [problems[0], other])


def test_trials_of_two_robot_objects_are_stacked_separately(problems):
    # Same class, other constants: a stack with trial 0's regressor would fit the wrong model.
    lunar = CylindricalRobot(g=1.62)
    other = Problem(lunar, simulate(lunar, "torque_noise", seed=3), seed=3)
    got = fit_trials(LeastSquares(), [problems[0], other, problems[1]])
    for trial, problem in zip(got, [problems[0], other, problems[1]], strict=True):
        assert_same_estimate(trial[0], LeastSquares().fit(problem))


def test_trials_of_different_sample_counts_are_stacked_separately():
    robot = ROBOT
    trials = [
        Problem(robot, simulate(robot, "torque_noise", seed=s, n_samples=n), seed=s)
        for s, n in enumerate((10, 7, 10, 7, 12))
    ]
    got = fit_trials(TotalLeastSquares(relative=True), trials)
    assert [e[0].details["batched_trials"] for e in got] == [2, 2, 2, 2, 1]
    for (estimate,), problem in zip(got, trials, strict=True):
        assert_same_estimate(estimate, TotalLeastSquares(relative=True).fit(problem))


def test_float32_trials(problems):
    trials = [Problem(p.robot, p.samples, seed=p.seed, dtype="float32") for p in problems[:4]]
    got = fit_trials(RobustLeastSquares(), trials)
    reference = fit_trials(RobustLeastSquares(), problems[:4])
    for (single,), (double,) in zip(got, reference, strict=True):
        assert single.details["dtype"] == "float32"
        np.testing.assert_allclose(single.vector(), double.vector(), rtol=1e-3)
        assert all(math.isfinite(v) for v in single.vector())
