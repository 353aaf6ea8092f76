"""URDF cases shared by the URDF robot, export and pcls tests: a branched test robot and
pinocchio as the independent reference (its torques and regressor in idkit's joint order)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from idkit.robots.urdf import URDFRobot

pin = pytest.importorskip("pinocchio")

# ruff: noqa: E501  (the test URDF below keeps one element per line)

# A branched robot exercising what the KUKA and the cylindrical robot do not: a continuous joint,
# rpy origins, a prismatic joint off the axis, inertial frames rotated w.r.t. the link, a fixed
# tool welded to a moving link (merged), a fixed link on the root (dropped) and a second branch.
TREE_URDF = """<?xml version="1.0" encoding="ISO-8859-1"?>
<!-- test robot: a tree, numbers arbitrary (non-ASCII on purpose: é) -->
<robot name="tree">
  <link name="world"/>
  <link name="pedestal"><inertial><mass value="3"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <link name="a">
    <inertial><origin xyz="0.1 -0.05 0.2" rpy="0.3 -0.2 0.5"/><mass value="2.0"/>
      <inertia ixx="0.05" ixy="0.001" ixz="-0.002" iyy="0.04" iyz="0.003" izz="0.03"/></inertial>
  </link>
  <link name="b">
    <inertial><origin xyz="0.02 0.3 -0.01" rpy="-0.4 0.1 0.2"/><mass value="1.5"/>
      <inertia ixx="0.02" ixy="-0.001" ixz="0.0" iyy="0.01" iyz="0.002" izz="0.025"/></inertial>
  </link>
  <link name="tool">
    <inertial><origin xyz="0.0 0.05 0.1"/><mass value="0.4"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.0015"/></inertial>
  </link>
  <link name="c">
    <inertial><origin xyz="0.0 0.0 0.15" rpy="0 0.7 0"/><mass value="0.8"/>
      <inertia ixx="0.004" ixy="0" ixz="0.0005" iyy="0.005" iyz="0" izz="0.003"/></inertial>
  </link>
  <link name="d">
    <inertial><origin xyz="0.05 0 0"/><mass value="0.5"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>
  </link>
  <joint name="weld" type="fixed"><parent link="world"/><child link="pedestal"/><origin xyz="0 0 0.5" rpy="0 0 0.3"/></joint>
  <joint name="j1" type="revolute"><parent link="pedestal"/><child link="a"/>
    <origin xyz="0.1 0 0.3" rpy="0.1 0.2 0.3"/><axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j2" type="prismatic"><parent link="a"/><child link="b"/>
    <origin xyz="0.2 0.1 0.4" rpy="-1.5707963267948966 0 0.4"/><axis xyz="0.6 0 0.8"/><limit lower="0" upper="0.5" effort="1" velocity="1"/></joint>
  <joint name="flange" type="fixed"><parent link="b"/><child link="tool"/><origin xyz="0.1 0.2 0" rpy="0.5 0 0"/></joint>
  <joint name="j3" type="continuous"><parent link="tool"/><child link="c"/>
    <origin xyz="0 0.1 0.05" rpy="0 0.3 0"/><axis xyz="1 1 0"/></joint>
  <joint name="j4" type="revolute"><parent link="a"/><child link="d"/>
    <origin xyz="-0.1 0 0.2" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>
"""

# Pinocchio orders a body's inertia as (xx, xy, yy, xz, yz, zz); idkit as (xx, xy, xz, yy, yz, zz).
PIN_ORDER = [0, 1, 2, 3, 4, 5, 7, 6, 8, 9]


def pin_model(urdf: str) -> pin.Model:
    if urdf.lstrip().startswith("<"):
        return pin.buildModelFromXML(urdf)
    return pin.buildModelFromUrdf(urdf)


def pin_maps(robot: URDFRobot, model: pin.Model) -> tuple[list[int], list[int]]:
    """Pinocchio velocity index of each idkit joint, and pinocchio regressor column of each idkit column."""
    ids = [model.getJointId(name) for name in robot.joint_names]
    rows = [model.joints[i].idx_v for i in ids]
    cols = [10 * (i - 1) + PIN_ORDER[k] for i in ids for k in range(10)]
    return rows, cols


def random_states(robot: URDFRobot, n: int, seed: int) -> tuple[torch.Tensor, ...]:
    return robot.random_states(n, torch.Generator().manual_seed(seed))


def pin_torques_and_regressor(
    robot: URDFRobot, model: pin.Model, q: torch.Tensor, qd: torch.Tensor, qdd: torch.Tensor
) -> tuple[np.ndarray, np.ndarray]:
    """Pinocchio's ``rnea`` and ``computeJointTorqueRegressor`` per sample, in pinocchio's order.

    idkit's joint ``i`` goes to pinocchio's ``idx_q`` / ``idx_v`` of the same name; a continuous
    joint's configuration is ``(cos q, sin q)`` in pinocchio.
    """
    data = model.createData()
    joints = [model.joints[model.getJointId(name)] for name in robot.joint_names]
    taus, regs = [], []
    for x, v, a in zip(q.numpy(), qd.numpy(), qdd.numpy(), strict=True):
        q_pin, v_pin, a_pin = np.zeros(model.nq), np.zeros(model.nv), np.zeros(model.nv)
        for i, joint in enumerate(joints):
            if joint.nq == 2:
                q_pin[joint.idx_q : joint.idx_q + 2] = np.cos(x[i]), np.sin(x[i])
            else:
                q_pin[joint.idx_q] = x[i]
            v_pin[joint.idx_v], a_pin[joint.idx_v] = v[i], a[i]
        taus.append(pin.rnea(model, data, q_pin, v_pin, a_pin).copy())
        regs.append(pin.computeJointTorqueRegressor(model, data, q_pin, v_pin, a_pin).copy())
    return np.stack(taus), np.stack(regs)
