"""The pytorch-kinematics dynamics oracle against the closed-form cylindrical robot and pinocchio."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from idkit.robots.cylindrical import CylindricalRobot
from idkit.verify.cylindrical_urdf import cylindrical_urdf, shipped_cylindrical_urdf
from idkit.verify.oracle import PKDynamics

# The box of eq. (38): rows q, qd, qdd; columns theta1, d2, d3.
LOWER = torch.tensor([[-math.pi, 0.0, 0.0], [-4.0, -2.0, -1.5], [-3.0, -2.0, -1.0]], dtype=torch.float64)
UPPER = torch.tensor([[math.pi, 1.0, 1.0], [4.0, 2.0, 1.5], [3.0, 2.0, 1.0]], dtype=torch.float64)


def states_in_box(n: int, gen: torch.Generator) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``n`` uniform random states ``(q, qd, qdd)``, each ``[n, 3]``, within the bounds (38)."""
    x = LOWER + (UPPER - LOWER) * torch.rand(n, 3, 3, generator=gen, dtype=torch.float64)
    return x.unbind(1)


def test_shipped_urdf_is_the_rendered_true_robot():
    path = shipped_cylindrical_urdf()
    assert path.is_file()
    assert path.read_text() == cylindrical_urdf()


def test_closed_form_equals_oracle_on_shipped_urdf(cylindrical, rng):
    oracle = PKDynamics(shipped_cylindrical_urdf())
    assert oracle.joint_names == cylindrical.joint_names
    q, qd, qdd = states_in_box(1000, rng)
    expected = cylindrical.inverse_dynamics(cylindrical.nominal_params(), q, qd, qdd)
    torch.testing.assert_close(oracle.inverse_dynamics(q, qd, qdd), expected, rtol=0, atol=1e-9)


def test_closed_form_equals_oracle_at_random_parameters(rng):
    """Random (m2, m3, s3z, I) and a random split of I over I1zz, I2yy, I3yy: only the sum matters."""
    robot = CylindricalRobot()
    lower, upper = robot.bounds()
    q, qd, qdd = states_in_box(1000, rng)
    for _ in range(4):
        params = lower + (upper - lower) * torch.rand(4, generator=rng, dtype=torch.float64)
        split = torch.rand(3, generator=rng, dtype=torch.float64)
        text = cylindrical_urdf(params.tolist(), (split / split.sum()).tolist())  # str with an encoding line
        expected = robot.inverse_dynamics(params, q, qd, qdd)
        torch.testing.assert_close(PKDynamics(text).inverse_dynamics(q, qd, qdd), expected, rtol=0, atol=1e-9)


def test_joint_order_is_by_name(cylindrical, rng):
    order = ("d3", "theta1", "d2")
    perm = [cylindrical.joint_names.index(n) for n in order]
    oracle = PKDynamics(shipped_cylindrical_urdf(), joint_names=order)
    q, qd, qdd = states_in_box(50, rng)
    expected = cylindrical.inverse_dynamics(cylindrical.nominal_params(), q, qd, qdd)[:, perm]
    torch.testing.assert_close(
        oracle.inverse_dynamics(q[:, perm], qd[:, perm], qdd[:, perm]), expected, rtol=0, atol=1e-9
    )


def test_bad_input_is_explained():
    with pytest.raises(ValueError, match="permutation"):
        PKDynamics(shipped_cylindrical_urdf(), joint_names=("theta1", "d2"))
    with pytest.raises(ValueError, match=r"\[N, 3\]"):
        PKDynamics(shipped_cylindrical_urdf()).inverse_dynamics(
            *(torch.zeros(4, 2, dtype=torch.float64),) * 3
        )
    with pytest.raises(FileNotFoundError):
        PKDynamics("no/such/robot.urdf")
    with pytest.raises(ValueError, match="split"):
        cylindrical_urdf(split=(0.5, 0.5, 0.5))


def _pinocchio(urdf_path: str):
    pin = pytest.importorskip("pinocchio")
    model = pin.buildModelFromUrdf(urdf_path)
    return pin, model, model.createData(), tuple(model.names)[1:]


def test_oracle_equals_pinocchio_on_kuka(kuka_dir, rng):
    """A real 7-DOF arm: fails at ~1e-6 if pk's float32 URDF geometry were used as is."""
    pin, model, data, pin_names = _pinocchio(str(kuka_dir / "kuka_lwr4.urdf"))
    order = tuple(reversed(pin_names))  # deliberately not pinocchio's order: columns map by name
    oracle = PKDynamics(kuka_dir / "kuka_lwr4.urdf", joint_names=order)
    q, qd, qdd = (4.0 * torch.rand(200, 7, generator=rng, dtype=torch.float64) - 2.0 for _ in range(3))
    perm = [order.index(n) for n in pin_names]  # oracle column of each pinocchio joint
    expected = np.stack(
        [
            pin.rnea(model, data, a, b, c)
            for a, b, c in zip(q[:, perm].numpy(), qd[:, perm].numpy(), qdd[:, perm].numpy(), strict=True)
        ]
    )
    tau = oracle.inverse_dynamics(q, qd, qdd)[:, perm].numpy()
    np.testing.assert_allclose(tau, expected, rtol=0, atol=1e-9)
    mass = oracle.mass_matrix(q[:3])[:, perm][:, :, perm].numpy()
    for m, a in zip(mass, q[:3, perm].numpy(), strict=True):
        full = pin.crba(model, data, a)  # pinocchio fills the upper triangle only
        np.testing.assert_allclose(m, np.triu(full) + np.triu(full, 1).T, rtol=0, atol=1e-12)


def test_oracle_equals_pinocchio_on_cylindrical(rng):
    pin, model, data, pin_names = _pinocchio(str(shipped_cylindrical_urdf()))
    oracle = PKDynamics(shipped_cylindrical_urdf(), joint_names=pin_names)
    q, qd, qdd = states_in_box(100, rng)
    expected = np.stack(
        [pin.rnea(model, data, a, b, c) for a, b, c in zip(q.numpy(), qd.numpy(), qdd.numpy(), strict=True)]
    )
    np.testing.assert_allclose(oracle.inverse_dynamics(q, qd, qdd).numpy(), expected, rtol=0, atol=1e-9)


TWO_LINKS_NO_AXIS = """<robot name="two">
  <link name="base"/>
  <link name="a"><inertial><origin xyz="0.1 0.2 0.3" rpy="0.3 -0.2 0.1"/><mass value="2.0"/>
    <inertia ixx="0.3" ixy="0.01" ixz="-0.02" iyy="0.2" iyz="0.03" izz="0.1"/></inertial></link>
  <link name="b"><inertial><origin xyz="0.4 0 -0.1"/><mass value="1.5"/>
    <inertia ixx="0.05" ixy="0" ixz="0" iyy="0.06" iyz="0" izz="0.07"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="a"/>
    <origin xyz="0 0 0.5" rpy="0.1 0.2 0.3"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="a"/><child link="b"/>
    <origin xyz="0.3 0.1 0" rpy="0 0.5 0"/><axis xyz="0 1 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
</robot>"""


def test_missing_axis_means_x_as_in_the_urdf_spec(rng):
    """pk defaults an absent <axis> to z; the URDF spec (and pinocchio) to x. The oracle follows the spec."""
    pin = pytest.importorskip("pinocchio")
    model = pin.buildModelFromXML(TWO_LINKS_NO_AXIS)
    data = model.createData()
    oracle = PKDynamics(TWO_LINKS_NO_AXIS)
    q, qd, qdd = (torch.randn(20, 2, generator=rng, dtype=torch.float64) for _ in range(3))
    expected = np.stack(
        [pin.rnea(model, data, a, b, c) for a, b, c in zip(q.numpy(), qd.numpy(), qdd.numpy(), strict=True)]
    )
    np.testing.assert_allclose(oracle.inverse_dynamics(q, qd, qdd).numpy(), expected, rtol=0, atol=1e-9)


def test_oracle_command_checks_the_urdf_robot(capsys):
    """``python -m idkit.verify oracle cylindrical``: the generic URDF robot agrees with the oracle."""
    from idkit.verify.__main__ import main

    assert main(["oracle", "cylindrical", "--samples", "20"]) == 0
    assert "max |tau_urdf - tau_oracle|" in capsys.readouterr().out
    assert main(["oracle", "cylindrical", "--samples", "20", "--tolerance", "-1"]) == 1


def test_cylindrical_urdf_command_renders_given_parameters(capsys):
    from idkit.verify.__main__ import main

    assert main(["cylindrical-urdf", "4", "2", "0.1", "1"]) == 0
    assert capsys.readouterr().out == cylindrical_urdf([4.0, 2.0, 0.1, 1.0])
