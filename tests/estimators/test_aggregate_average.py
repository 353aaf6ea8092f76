"""The paper's final average has one home and is taken in the space the parts searched."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators.aggregate import average_estimates, average_params, mean_params
from idkit.estimators.paper import PaperFinalEstimate
from idkit.estimators.pso import ParticleSwarm
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot
from idkit.studies import robustness

CHEAP = {"runs": 3, "particles": 8, "iterations": 30}


class BaseSpaceCylinder(CylindricalRobot):
    """The cylindrical robot searched in base space: its map to physical parameters is nonlinear
    (``s3z = α3 / α2``, ``I = α0 − α3² / α2``), so a mean of physical parameters is not the physical
    parameters of the mean."""

    search_space = "base"

    def base_bounds(self) -> tuple[torch.Tensor, torch.Tensor]:
        lower, upper = self.bounds()
        corners = torch.cartesian_prod(*[torch.stack((lo, hi)) for lo, hi in zip(lower, upper, strict=True)])
        alpha = self.base_params(corners)
        return alpha.amin(0), alpha.amax(0)


@pytest.fixture(scope="module")
def fitted():
    robot = BaseSpaceCylinder()
    problem = Problem(robot, simulate(robot, "outliers", seed=0), None, seed=3)
    costs = [paper.f13(), paper.f14()]
    parts = ParticleSwarm(**CHEAP).fit_costs(problem, costs)
    return robot, problem, costs, parts


def test_the_average_of_a_base_space_search_is_the_mean_of_its_base_parameters(fitted):
    robot, problem, costs, parts = fitted
    assert {part.details["space"] for part in parts} == {"base"}
    final = average_estimates(problem, parts, costs, "PSO-f13/f14")
    expected = mean_params([part.base_params for part in parts])
    assert final.base_params == pytest.approx(expected, rel=1e-12)
    # the physical parameters are those of the mean, which predict the mean of the parts' torques
    alpha = torch.tensor([final.base_params[n] for n in robot.base_param_names], dtype=torch.float64)
    torch.testing.assert_close(robot.base_params(torch.tensor(final.vector(), dtype=torch.float64)), alpha)
    s = problem.tensors()
    predicted = [
        robot.inverse_dynamics(torch.tensor(e.vector(), dtype=torch.float64), s.q, s.qd, s.qdd)
        for e in (*parts, final)
    ]
    torch.testing.assert_close(predicted[-1], (predicted[0] + predicted[1]) / 2, rtol=1e-9, atol=1e-9)
    # …which the plain mean of the physical parameters does not
    plain = np.mean([part.vector() for part in parts], axis=0)
    assert not np.allclose(plain, final.vector(), rtol=1e-6)


def test_the_studies_and_the_estimator_report_the_same_average(fitted):
    robot, problem, costs, parts = fitted
    from_study = average_params(parts, robot)
    estimator = PaperFinalEstimate(pso=CHEAP).fit(problem)
    assert estimator.params == pytest.approx(from_study, rel=1e-12)
    assert robustness.average_params is average_params  # the robustness study's one import of it


def test_parts_of_different_spaces_are_not_averaged(fitted):
    robot, problem, costs, parts = fitted
    other = parts[1].__class__(**{**parts[1].to_dict(), "details": {**parts[1].details, "space": "physical"}})
    with pytest.raises(ValueError, match="different spaces"):
        average_params([parts[0], other], robot)
