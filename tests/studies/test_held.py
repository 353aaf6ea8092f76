"""Sigmoid friction shapes that an estimator held at the robot's reference are said, not shown as fitted."""

from __future__ import annotations

import warnings

import pytest

from idkit.estimators.physical import PhysicallyConsistentLS
from idkit.reports import single as report
from idkit.robots.urdf import URDFRobot
from idkit.studies import single
from idkit.studies.held import HeldWarning

SHAPES = [f"{j}.{k}" for k in ("phi2", "phi3") for j in ("theta1", "d2", "d3")]


def robot() -> URDFRobot:
    return URDFRobot("cylindrical", friction="sigmoid", sigmoid_steepness=[5.0, 20.0, 10.0])


@pytest.mark.parametrize("estimator", ["ls", PhysicallyConsistentLS(prior_weight=0.0)])
def test_a_linear_fit_says_it_held_the_shape_and_the_table_marks_it(estimator):
    with pytest.warns(HeldWarning, match=r"^(LS|PCLS): the sigmoid friction shape is held at the robot's"):
        result = single.run(robot(), estimator, None, "clean", n_samples=200)
    assert result.estimate.details["held"] == SHAPES
    rows = {line.split()[0]: line for line in report.text(result).splitlines() if line.strip()}
    assert all(rows[name].endswith("held") for name in SHAPES)
    assert not rows["d2.phi1"].endswith("held")


def test_varpro_fits_the_shape_and_says_nothing():
    with warnings.catch_warnings():
        warnings.simplefilter("error", HeldWarning)
        result = single.run(robot(), "varpro", None, "clean", n_samples=200)
    assert "held" not in result.estimate.details
