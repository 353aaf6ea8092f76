"""A small arm over a table, with collision primitives whose contacts have a closed form.

The table's top is the plane ``z = 0`` (a box 2 × 2 × 2 m on the root; ``arm_urdf(top)`` raises it). Joint ``j1`` turns about
``z`` at height 0.5 m; ``j2`` tilts the ``arm`` about ``y``; the arm ends in a sphere of radius 0.1 m
0.6 m from ``j2``, whose lowest point is at ``0.4 - 0.6 sin(q2)``: it touches the table exactly when
``sin(q2) > 2/3`` (whatever ``q1``, ``q3``, ``q4``). ``wrist`` carries no collision geometry, so
``arm`` and ``hand`` count as adjacent — their spheres always overlap and must not be reported.
``shoulder``'s sphere touches the table never, and the arm never (adjacent anyway).
"""

from __future__ import annotations

import math

# ruff: noqa: E501  (one element per line)

ARM_TEMPLATE = """<?xml version="1.0"?>
<robot name="table_arm">
  <link name="table">
    <collision><origin xyz="0 0 {centre}"/><geometry><box size="2 2 2"/></geometry></collision>
  </link>
  <link name="shoulder">
    <inertial><mass value="2.0"/><inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.01"/></inertial>
    <collision><geometry><sphere radius="0.1"/></geometry></collision>
  </link>
  <link name="arm">
    <inertial><origin xyz="0.3 0 0"/><mass value="1.5"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.05"/></inertial>
    <collision><origin xyz="0.6 0 0"/><geometry><sphere radius="0.1"/></geometry></collision>
  </link>
  <link name="wrist">
    <inertial><mass value="0.3"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>
  </link>
  <link name="hand">
    <inertial><origin xyz="0 0 0.05"/><mass value="0.4"/><inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.001"/></inertial>
    <collision><geometry><sphere radius="0.08"/></geometry></collision>
  </link>
  <joint name="j1" type="revolute"><parent link="table"/><child link="shoulder"/><origin xyz="0 0 0.5"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="40" velocity="2"/></joint>
  <joint name="j2" type="revolute"><parent link="shoulder"/><child link="arm"/><axis xyz="0 1 0"/>
    <limit lower="-1.5" upper="1.5" effort="40" velocity="2"/></joint>
  <joint name="j3" type="revolute"><parent link="arm"/><child link="wrist"/><origin xyz="0.6 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-2" upper="2" effort="10" velocity="3"/></joint>
  <joint name="j4" type="revolute"><parent link="wrist"/><child link="hand"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="10" velocity="3"/></joint>
</robot>
"""


def arm_urdf(top: float = 0.0) -> str:
    """The arm with the table's top at height ``top`` (m)."""
    return ARM_TEMPLATE.replace("{centre}", repr(top - 1.0))


ARM_URDF = arm_urdf()

#: ``q2`` above which the arm's sphere touches the table.
TOUCH = math.asin(2.0 / 3.0)


def touches_table(q2: float) -> bool:
    """Closed form of the arm-table contact (module docstring)."""
    return math.sin(q2) > 2.0 / 3.0
