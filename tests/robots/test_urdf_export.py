"""identified.urdf: pinocchio loads it and its rigid-body torques equal idkit's with the same parameters."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from urdf_cases import TREE_URDF, pin_model, pin_torques_and_regressor, random_states

from idkit.robots.urdf import URDFRobot
from idkit.robots.urdf_export import identified_urdf, write_identified_urdf
from idkit.robots.urdf_model import ASSETS, parse_urdf

pin = pytest.importorskip("pinocchio")


def perturbed(robot: URDFRobot, seed: int) -> torch.Tensor:
    """Physical parameters other than the CAD ones: each link's mass, centre of mass and inertia moved
    (the CAD inertial scaled and shifted by a point mass keeps it physical); friction filled in."""
    rng = np.random.default_rng(seed)
    params = robot.nominal_params().clone()
    for i in range(len(robot.link_names)):
        block = params[10 * i : 10 * i + 10] * rng.uniform(0.7, 1.3)
        mass, point = rng.uniform(0.1, 0.5), rng.normal(scale=0.1, size=3)
        inertia = mass * (point @ point * np.eye(3) - np.outer(point, point))
        block += torch.as_tensor([mass, *(mass * point), *inertia[np.triu_indices(3)]])
        params[10 * i : 10 * i + 10] = block
    extra = params.numel() - 10 * len(robot.link_names)
    params[params.numel() - extra :] = torch.as_tensor(rng.uniform(0.05, 1.0, extra))
    return params


@pytest.fixture(params=["cylindrical", "tree", "kuka"])
def source(request) -> str:
    if request.param == "kuka":
        return str(request.getfixturevalue("kuka_dir") / "kuka_lwr4.urdf")
    return {"cylindrical": str(ASSETS / "cylindrical.urdf"), "tree": TREE_URDF}[request.param]


def test_pinocchio_torques_of_the_identified_urdf_equal_idkit(source, tmp_path):
    robot = URDFRobot(source, friction=True)
    params = perturbed(robot, seed=0)
    path = write_identified_urdf(robot, params, tmp_path / "identified.urdf")
    model = pin_model(str(path))
    rigid = URDFRobot(str(path))  # the written file read back by idkit as well
    q, qd, qdd = random_states(rigid, 50, seed=1)
    expected = robot.inverse_dynamics(params, q, qd, qdd) - robot.drives.torque(
        params[10 * len(robot.link_names) :], qd, qdd
    )
    torques, _ = pin_torques_and_regressor(rigid, model, q, qd, qdd)
    rows = [model.joints[model.getJointId(name)].idx_v for name in robot.joint_names]
    np.testing.assert_allclose(torques[:, rows], expected.numpy(), rtol=0, atol=1e-9)
    # The written inertials are the identified ones, and friction is in <dynamics>.
    np.testing.assert_allclose(rigid.nominal_params().numpy(), params[: rigid.n_params].numpy(), atol=1e-12)
    ids = [model.getJointId(name) for name in robot.joint_names]
    n = robot.n_joints
    fc, fv = params[-2 * n : -n].numpy(), params[-n:].numpy()
    np.testing.assert_allclose([model.friction[model.joints[i].idx_v] for i in ids], fc, atol=1e-15)
    np.testing.assert_allclose([model.damping[model.joints[i].idx_v] for i in ids], fv, atol=1e-15)


def test_everything_else_is_kept_and_welded_links_are_merged():
    robot = URDFRobot(TREE_URDF, offset=True)
    text = identified_urdf(robot, perturbed(robot, seed=2))
    assert "test robot: a tree" in text  # comments survive
    tree = parse_urdf(text)
    assert [b.joint for b in tree.bodies] == [b.joint for b in robot.tree.bodies]
    for old, new in zip(robot.tree.bodies, tree.bodies, strict=True):
        np.testing.assert_array_equal(new.rotation, old.rotation)
        assert new.limits == old.limits and new.welded == old.welded
    assert "tool" in robot.tree.bodies[1].welded
    assert text.count("<inertial>") == len(robot.link_names) + 1  # + the pedestal welded to the root
    assert "idkit: offset=" in text


def test_names_and_non_physical_inputs(tmp_path):
    robot = URDFRobot(TREE_URDF)
    params = robot.nominal_params().clone()
    params[10] = -1.0
    with pytest.raises(ValueError, match="link 'b' has mass -1 <= 0"):
        identified_urdf(robot, params)
    params = robot.nominal_params().clone()
    params[4:10] *= -1  # negative inertia on link a
    with pytest.warns(UserWarning, match="not positive semidefinite for a"):
        identified_urdf(robot, params)
    named = dict(zip(robot.param_names, robot.nominal_params().tolist(), strict=True))
    assert identified_urdf(robot, named) == identified_urdf(robot, robot.nominal_params())
    del named["a.m"]
    with pytest.raises(ValueError, match="parameters missing: a.m"):
        identified_urdf(robot, named)
