"""irls against an independent numpy IRLS, against scipy's Huber least squares at the same scale,
and on data with gross outliers against plain least squares."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from idkit import registry
from idkit.problem import Problem
from robust_data import outlier_problem
from scipy.optimize import least_squares
from scipy.stats import norm

from idkit_robust.irls import IRLS
from idkit_robust.planar2 import Planar2Robot

TUNING = {"huber": 1.345, "tukey": 4.685}


def stacked(problem: Problem, relative: bool) -> tuple[np.ndarray, np.ndarray]:
    """``W[N n, B]``, ``t[N n]`` in numpy; relative rows divided by the measured torque (no
    torque here is near zero, so idkit's floor never applies)."""
    s = problem.samples
    w = problem.robot.regressor(s.q, s.qd, s.qdd).numpy().reshape(-1, len(problem.robot.base_param_names))
    tau = s.tau.numpy()
    t = tau.reshape(-1)
    if not relative:
        return w, t
    assert (np.abs(tau) >= 1e-3 * np.sqrt((tau**2).mean(axis=0))).all()  # idkit's floor is inactive
    return w / t[:, None], np.ones_like(t)


def numpy_irls(w: np.ndarray, t: np.ndarray, weight: str, tol: float = 1e-13) -> tuple[np.ndarray, float]:
    """Textbook IRLS with MAD scale; Tukey starts from the Huber solution."""
    a = np.linalg.lstsq(w, t, rcond=None)[0]
    for name in ["huber"] if weight == "huber" else ["huber", "tukey"]:
        c = TUNING[name]
        for _ in range(1000):
            r = t - w @ a
            scale = np.median(np.abs(r)) / norm.ppf(0.75)
            u = np.abs(r / scale)
            wt = np.minimum(1.0, c / u) if name == "huber" else np.where(u < c, (1 - (u / c) ** 2) ** 2, 0.0)
            new = np.linalg.lstsq(w * np.sqrt(wt)[:, None], t * np.sqrt(wt), rcond=None)[0]
            done = np.linalg.norm(new - a) <= tol * np.linalg.norm(new)
            a = new
            if done:
                break
    return a, float(np.median(np.abs(t - w @ a)) / norm.ppf(0.75))


ROBOTS = {"planar2": Planar2Robot, "cylindrical": lambda: registry.create("robot", "cylindrical")}


@pytest.mark.parametrize("robot", sorted(ROBOTS))
@pytest.mark.parametrize("weight", ["huber", "tukey"])
@pytest.mark.parametrize("relative", [False, True])
def test_matches_numpy_reference(robot, weight, relative):
    problem = outlier_problem(ROBOTS[robot](), seed=2)
    est = IRLS(weight=weight, relative=relative, tol=1e-13, max_iter=1000).fit(problem)
    expected, scale = numpy_irls(*stacked(problem, relative), weight)
    np.testing.assert_allclose(list(est.base_params.values()), expected, rtol=1e-9, atol=1e-12)
    assert est.details["scale"] == pytest.approx(scale, rel=1e-9)
    assert all(stage["converged"] for stage in est.details["stages"])


@pytest.mark.parametrize("relative", [False, True])
def test_huber_agrees_with_scipy_least_squares_at_the_final_scale(relative):
    """For a fixed scale s, IRLS-Huber's fixed point minimises sum huber_{c s}(r_i) — what
    scipy's trust-region least_squares(loss="huber", f_scale=c s) minimises by another route."""
    problem = outlier_problem(Planar2Robot(), seed=3)
    est = IRLS(relative=relative, tol=1e-13, max_iter=1000).fit(problem)
    w, t = stacked(problem, relative)
    ref = least_squares(
        lambda a: w @ a - t,
        np.linalg.lstsq(w, t, rcond=None)[0],
        loss="huber",
        f_scale=1.345 * est.details["scale"],
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
    )
    np.testing.assert_allclose(list(est.base_params.values()), ref.x, rtol=1e-7)


@pytest.mark.parametrize("robot", sorted(ROBOTS))
@pytest.mark.parametrize("seed", range(4))
def test_outliers_hurt_irls_far_less_than_least_squares(robot, seed):
    problem = outlier_problem(ROBOTS[robot](), seed=seed)
    truth = problem.robot.base_params(problem.robot.nominal_params()).numpy()
    ls = np.linalg.lstsq(*stacked(problem, False), rcond=None)[0]
    ls_error = np.abs((ls - truth) / truth).max()
    for options in ({}, {"weight": "tukey"}, {"relative": True}, {"weight": "tukey", "relative": True}):
        est = IRLS(**options).fit(problem)
        error = np.abs((np.array(list(est.base_params.values())) - truth) / truth).max()
        assert error < 0.35 * ls_error, (options, error, ls_error)


@pytest.mark.parametrize("robot", sorted(ROBOTS))
def test_noise_free_data_are_fitted_exactly(robot):
    noisy = outlier_problem(ROBOTS[robot](), fraction=0.0)
    s, robot = noisy.samples, noisy.robot
    tau = robot.inverse_dynamics(robot.nominal_params(), s.q, s.qd, s.qdd)
    problem = Problem(robot, type(s)(s.q, s.qd, s.qdd, tau))
    est = IRLS(weight="tukey").fit(problem)
    np.testing.assert_allclose(list(est.params.values()), problem.robot.nominal_params().numpy(), rtol=1e-9)
    assert est.details["stages"][0]["exact_fit"]


def test_estimate_record():
    problem = outlier_problem(Planar2Robot(), seed=1, cost=registry.create("cost", "huber", delta=0.5))
    est = IRLS(weight="tukey", relative=True).fit(problem)
    assert est.estimator == "IRLS-Tukey-rel"
    assert list(est.params) == list(Planar2Robot.param_names)
    params = torch.tensor(list(est.params.values()), dtype=torch.float64)
    assert est.cost == pytest.approx(float(problem.evaluate(params)), rel=1e-12)
    weights = np.array(est.details["weights"])
    assert weights.shape == (30, 2) and est.details["rejected"] == int((weights == 0).sum()) > 0
    assert est.details["threads"] == 1


def test_restores_torch_threads():
    before = torch.get_num_threads()
    IRLS(threads=1).fit(outlier_problem(Planar2Robot()))
    assert torch.get_num_threads() == before


def test_clear_errors():
    with pytest.raises(ValueError, match="weight must be one of"):
        IRLS(weight="cauchy")
    with pytest.raises(ValueError, match="tuning must be > 0"):
        IRLS(tuning=0.0)
    with pytest.raises(ValueError, match=r"rank 2 < 6 base parameters"):
        IRLS().fit(outlier_problem(Planar2Robot(), n_samples=1))
    with pytest.raises(ValueError, match="fewer than the 6 base parameters"):
        IRLS(weight="tukey", tuning=1e-6).fit(outlier_problem(Planar2Robot(), seed=1))
