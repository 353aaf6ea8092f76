"""Nominal torques and the effort-derived acceleration limits, against pinocchio."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from idkit.excitation.effort import (
    DEFAULT_EFFORT_FRACTION,
    INERTIA_POSES,
    acceleration_bounded_limits,
    default_acceleration_limits,
    effort_limits,
    mass_matrix_diagonal,
    nominal_torques,
)
from idkit.robots.urdf import URDFRobot
from idkit.seeds import torch_generator
from tests.urdf_cases import TREE_URDF, pin, pin_maps, pin_model, pin_torques_and_regressor

#: The test tree with an effort limit on its continuous joint too (every joint declares one).
TREE = TREE_URDF.replace(
    '<axis xyz="1 1 0"/></joint>', '<axis xyz="1 1 0"/><limit effort="2" velocity="1"/></joint>'
)


def test_nominal_torques_equal_pinocchio_for_batches_of_trajectories():
    robot = URDFRobot(TREE_URDF, friction=True, offset=True)  # friction and offset are 0 in the nominal model
    g = torch.Generator().manual_seed(0)
    q, qd, qdd = (torch.randn(2, 5, 4, generator=g, dtype=torch.float64) for _ in range(3))
    tau = nominal_torques(robot, q, qd, qdd)
    assert tau.shape == (2, 5, 4)
    model = pin_model(TREE_URDF)
    rows, _ = pin_maps(robot, model)
    expected, _ = pin_torques_and_regressor(robot, model, *(x.reshape(-1, 4) for x in (q, qd, qdd)))
    np.testing.assert_allclose(tau.reshape(-1, 4).numpy(), expected[:, rows], rtol=1e-10, atol=1e-10)


def test_mass_matrix_diagonal_equals_pinocchio_crba():
    robot = URDFRobot(TREE_URDF)
    poses = torch.tensor([[0.3, 0.1, -1.0, 0.5], [-1.2, 0.4, 2.0, -0.7]], dtype=torch.float64)
    found = mass_matrix_diagonal(robot, poses).numpy()
    model = pin.buildModelFromXML(TREE_URDF)
    data = model.createData()
    for pose, row in zip(poses.numpy(), found, strict=True):
        config = pin_configuration(model, robot, pose)
        mass = pin.crba(model, data, config)
        mass = np.triu(mass) + np.triu(mass, 1).T
        expected = [
            mass[model.idx_vs[model.getJointId(j)], model.idx_vs[model.getJointId(j)]]
            for j in robot.joint_names
        ]
        np.testing.assert_allclose(row, expected, rtol=1e-10, atol=1e-12)


def pin_configuration(model, robot, pose: np.ndarray) -> np.ndarray:
    config = pin.neutral(model)
    for value, name in zip(pose, robot.joint_names, strict=True):
        joint = model.getJointId(name)
        index, nq = model.idx_qs[joint], model.nqs[joint]
        config[index : index + nq] = (np.cos(value), np.sin(value)) if nq == 2 else value
    return config


def test_default_acceleration_limits_are_the_documented_rule():
    """``fraction · effort / max M_jj`` over the seeded poses, recomputed with pinocchio's CRBA."""
    robot = URDFRobot(TREE)
    assert robot.effort_limits.tolist() == [1.0, 1.0, 2.0, 1.0]
    found = default_acceleration_limits(robot).numpy()
    limits = robot.motion_limits()
    lower = torch.where(limits.lower[0].isinf(), -torch.pi, limits.lower[0])
    upper = torch.where(limits.upper[0].isinf(), torch.pi, limits.upper[0])
    unit = torch.rand(INERTIA_POSES, 4, generator=torch_generator(0), dtype=torch.float64)
    model = pin.buildModelFromXML(TREE)
    data = model.createData()
    largest = np.zeros(4)
    for pose in (lower + (upper - lower) * unit).numpy():
        mass = pin.crba(model, data, pin_configuration(model, robot, pose))
        index = [model.idx_vs[model.getJointId(j)] for j in robot.joint_names]
        largest = np.maximum(largest, np.diag(mass)[index])
    np.testing.assert_allclose(found, DEFAULT_EFFORT_FRACTION * robot.effort_limits / largest, rtol=1e-10)
    # The default bounds each joint's own inertial torque: M_jj · a_j <= fraction · effort_j everywhere.
    assert (largest * found <= DEFAULT_EFFORT_FRACTION * robot.effort_limits * (1 + 1e-12)).all()


def test_acceleration_limits_given_robot_or_from_effort(cylindrical):
    urdf = URDFRobot("cylindrical")
    given, source = acceleration_bounded_limits(urdf, [1.0, 2.0, 3.0])
    assert (
        source == "given"
        and given.upper[2].tolist() == [1.0, 2.0, 3.0]
        and given.lower[2].tolist() == [-1, -2, -3]
    )
    one, _ = acceleration_bounded_limits(urdf, 2.5)
    assert one.upper[2].tolist() == [2.5] * 3
    derived, source = acceleration_bounded_limits(urdf)
    assert source == "effort"
    torch.testing.assert_close(derived.upper[2], default_acceleration_limits(urdf), rtol=0, atol=0)
    torch.testing.assert_close(derived.lower[:2], urdf.motion_limits().lower[:2], rtol=0, atol=0)
    own, source = acceleration_bounded_limits(cylindrical)
    assert source == "robot" and torch.equal(own.upper, cylindrical.motion_limits().upper)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("inf"), [1.0, 2.0], [1.0, True, 2.0], "3"])
def test_bad_acceleration_limits_are_refused_naming_the_joints(bad):
    with pytest.raises(ValueError, match=r"one positive number or one per joint \(3: theta1, d2, d3\)"):
        acceleration_bounded_limits(URDFRobot("cylindrical"), bad)


def test_a_robot_without_effort_or_acceleration_limits_must_be_given_them():
    robot = URDFRobot(TREE_URDF)  # its continuous joint declares no effort limit
    assert effort_limits(robot) is None
    with pytest.raises(ValueError, match="no acceleration limits and no effort limits to derive them from"):
        acceleration_bounded_limits(robot)
    assert acceleration_bounded_limits(robot, 1.0)[1] == "given"
