"""Motion limits: construction errors, excursions against numpy, the robots' limits from their sources."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import torch

from idkit.limits import MotionLimits
from idkit.robots.urdf import URDFRobot


def box() -> MotionLimits:
    return MotionLimits.from_ranges(
        ("a", "b"), [(-1.0, 1.0), (0.0, 2.0)], [(-3.0, 3.0), (-math.inf, math.inf)], [(-5.0, 4.0)] * 2
    )


def test_excess_equals_numpy():
    limits = box()
    g = torch.Generator().manual_seed(0)
    motion = 3 * torch.randn(4, 3, 50, 2, generator=g, dtype=torch.float64)  # [batch, 3, T, n]
    got = limits.excess(*motion.unbind(1))
    m, lo, hi = motion.numpy(), limits.lower.numpy(), limits.upper.numpy()
    expected = np.maximum(
        np.maximum(lo[None, :, None] - m, m - hi[None, :, None]).max(axis=2), 0.0
    )  # [batch, 3, n]
    np.testing.assert_array_equal(got.numpy(), expected)
    assert got.shape == (4, 3, 2) and torch.all(got[:, 1, 1] == 0)  # b's velocity is free


def test_replace_sets_one_variable():
    limits = box().replace("acceleration", -1.0, [1.0, 2.0])
    assert limits.lower[2].tolist() == [-1.0, -1.0] and limits.upper[2].tolist() == [1.0, 2.0]
    assert torch.equal(limits.lower[:2], box().lower[:2])
    assert limits.as_dict()["b"]["acceleration"] == [-1.0, 2.0]


@pytest.mark.parametrize(
    ("build", "match"),
    [
        (lambda: box().replace("jerk", -1, 1), "unknown variable 'jerk'; use one of position, velocity"),
        (lambda: box().replace("position", 1.0, 0.0), "lower >= upper for a position, b position"),
        (
            lambda: MotionLimits(("a",), torch.zeros(3, 2), torch.ones(3, 2)),
            r"lower must be a \[3, 1\] tensor",
        ),
        (lambda: MotionLimits.from_ranges(("a",), [(0, 1)], [], [(0, 1)]), "velocity needs one"),
    ],
)
def test_bad_limits_are_named(build, match):
    with pytest.raises(ValueError, match=match):
        build()


def test_cylindrical_limits_are_eq38(cylindrical):
    limits = cylindrical.motion_limits()
    assert limits.joint_names == ("theta1", "d2", "d3")
    assert limits.as_dict() == {
        "theta1": {"position": [-math.pi, math.pi], "velocity": [-4.0, 4.0], "acceleration": [-3.0, 3.0]},
        "d2": {"position": [0.0, 1.0], "velocity": [-2.0, 2.0], "acceleration": [-2.0, 2.0]},
        "d3": {"position": [0.0, 1.0], "velocity": [-1.5, 1.5], "acceleration": [-1.0, 1.0]},
    }


def test_urdf_limits_are_its_limit_tags(kuka_dir):
    path = kuka_dir / "kuka_lwr4.urdf"
    limits = URDFRobot(str(path)).motion_limits()
    tags = {
        j.get("name"): j.find("limit")
        for j in ET.parse(path).getroot().findall("joint")
        if j.get("type") != "fixed"
    }
    for j, name in enumerate(limits.joint_names):
        tag = tags[name]
        assert limits.lower[0, j] == float(tag.get("lower")) and limits.upper[0, j] == float(tag.get("upper"))
        assert limits.upper[1, j] == float(tag.get("velocity")) == -limits.lower[1, j]
    assert torch.isinf(limits.upper[2]).all() and torch.isinf(limits.lower[2]).all()


def test_urdf_continuous_joint_without_velocity_is_unlimited():
    urdf = """<robot name="r"><link name="base"/><link name="arm">
      <inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
      <joint name="spin" type="continuous"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/></joint>
    </robot>"""
    limits = URDFRobot(urdf, n_states=20).motion_limits()
    assert torch.isinf(limits.upper).all() and torch.isinf(limits.lower).all()
