"""Plausible, not only consistent: the bound pcls enforces on request, the flag every fit carries, and
the held-out cost the study prints when a fit leaves a link implausible."""

from __future__ import annotations

import torch
from urdf_cases import TREE_URDF

from idkit.estimators.physical import PhysicallyConsistentLS
from idkit.problem import Problem, Samples
from idkit.reports.single import text
from idkit.robots.urdf import URDFRobot
from idkit.studies import single


def recording(robot: URDFRobot, params: torch.Tensor, seed: int, n: int = 400) -> Samples:
    generator = torch.Generator().manual_seed(seed)
    q, qd, qdd = robot.random_states(n, generator)
    tau = robot.inverse_dynamics(params, q, qd, qdd)
    noise = 0.01 * tau.square().mean(0).sqrt() * torch.randn(tau.shape, generator=generator, dtype=tau.dtype)
    return Samples(q, qd, qdd, tau + noise)


def heavy_link_b() -> tuple[URDFRobot, torch.Tensor]:
    """The tree robot whose link 'b' really weighs three times its CAD mass (a consistent body)."""
    robot = URDFRobot(TREE_URDF, friction=True, offset=True)
    params = robot.nominal_params().clone()
    b = robot.link_names.index("b")
    params[10 * b : 10 * b + 10] *= 3.0
    return robot, params


def test_the_flag_and_the_bound():
    robot, truth = heavy_link_b()
    problem = Problem(robot, recording(robot, truth, seed=1))
    free = PhysicallyConsistentLS(prior_weight=1.0).fit(problem)
    found = free.details["plausibility"]
    assert found["enforced"] == "none" and found["implausible"] == ["b"]
    assert found["mass"]["b"] / found["cad_mass"]["b"] > 2.5  # the data say 3x: the fit follows them
    bounded = PhysicallyConsistentLS(prior_weight=1.0, plausible=True, mass_ratio=(0.5, 2.0)).fit(problem)
    kept = bounded.details["plausibility"]
    assert kept["implausible"] == [] and "b" in kept["at_bound"]  # (c may go to its bound too)
    for link, mass in kept["mass"].items():
        assert 0.5 - 1e-6 <= mass / kept["cad_mass"][link] <= 2.0 + 1e-6
    # the price: the bounded model explains the training data worse
    assert bounded.details["rel_error_train"] > 1.5 * free.details["rel_error_train"]


def test_the_study_prints_what_plausibility_costs_on_the_held_out_file():
    robot, truth = heavy_link_b()
    result = single.run(
        robot=robot,
        estimator={"_name_": "pcls", "prior_weight": 1.0},
        cost=None,
        data=recording(robot, truth, seed=2),
        validate=[recording(robot, truth, seed=3)],
    )
    assert result.plausible is not None and result.plausible.implausible == ("b",)
    (reported,), (bounded,) = [h.scores for h in result.validation], result.plausible.scores
    assert bounded.rel_all > reported.rel_all  # the truth is implausible: bounding it costs accuracy
    shown = text(result)
    said = "with estimator.plausible=true (masses within [0.5, 2] x CAD, inside each link's geometry)"
    assert said in shown
    assert f"{100 * bounded.rel_all:.2f} %" in shown
    payload = result.payload()["plausible_alternative"]
    assert payload["option"] == "estimator.plausible=true" and "b" in payload["at_bound"]
