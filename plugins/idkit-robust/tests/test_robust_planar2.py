"""planar2 against two independent references: pinocchio's RNEA on a URDF of the same arm, and
the Euler-Lagrange equations differentiated by autograd from the arm's kinetic and potential energy."""

from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit_robust.planar2 import NOMINAL_PARAMS, Planar2Robot

URDF = """<?xml version="1.0"?>
<robot name="planar2">
  <link name="base"/>
  <link name="link1">
    <inertial><origin xyz="{c1!r} 0 0"/><mass value="{m1!r}"/>
      <inertia ixx="1e-4" ixy="0" ixz="0" iyy="{i1!r}" iyz="0" izz="{i1!r}"/></inertial>
  </link>
  <link name="link2">
    <inertial><origin xyz="{c2!r} 0 0"/><mass value="{m2!r}"/>
      <inertia ixx="1e-4" ixy="0" ixz="0" iyy="{i2!r}" iyz="0" izz="{i2!r}"/></inertial>
  </link>
  <!-- The arm moves in the x-z plane, z up (pinocchio's gravity is -9.81 z). A rotation about
       -y by q turns x towards +z, so q1 is measured from the horizontal, positive up. -->
  <joint name="q1" type="revolute"><parent link="base"/><child link="link1"/>
    <origin xyz="0 0 0"/><axis xyz="0 -1 0"/><limit lower="-10" upper="10" effort="1e3" velocity="1e3"/>
  </joint>
  <joint name="q2" type="revolute"><parent link="link1"/><child link="link2"/>
    <origin xyz="{l1!r} 0 0"/><axis xyz="0 -1 0"/><limit lower="-10" upper="10" effort="1e3" velocity="1e3"/>
  </joint>
</robot>
"""


def states(n: int = 9, seed: int = 3) -> tuple[torch.Tensor, ...]:
    gen = torch.Generator().manual_seed(seed)
    return tuple(4 * torch.rand(n, 2, generator=gen, dtype=torch.float64) - 2 for _ in range(3))


def random_params(batch: int, seed: int = 5) -> torch.Tensor:
    robot = Planar2Robot()
    lower, upper = robot.bounds()
    gen = torch.Generator().manual_seed(seed)
    return lower + torch.rand(batch, 8, generator=gen, dtype=torch.float64) * (upper - lower)


def test_matches_pinocchio_rnea_plus_viscous_friction():
    pin = pytest.importorskip("pinocchio")
    robot = Planar2Robot(l1=0.45)
    q, qd, qdd = states()
    params = random_params(4)
    ours = robot.inverse_dynamics(params, q, qd, qdd)
    for k, p in enumerate(params.tolist()):
        m1, c1, i1, m2, c2, i2, fv1, fv2 = p
        model = pin.buildModelFromXML(URDF.format(m1=m1, c1=c1, i1=i1, m2=m2, c2=c2, i2=i2, l1=0.45))
        data = model.createData()
        assert tuple(model.names)[1:] == robot.joint_names
        for s in range(q.shape[0]):
            tau = pin.rnea(model, data, q[s].numpy(), qd[s].numpy(), qdd[s].numpy())
            tau = tau + [fv1 * qd[s, 0].item(), fv2 * qd[s, 1].item()]
            torch.testing.assert_close(ours[k, s], torch.as_tensor(tau), rtol=1e-12, atol=1e-12)


def lagrangian_torques(p: torch.Tensor, q: torch.Tensor, qd: torch.Tensor, qdd: torch.Tensor, l1, g):
    """``tau = d/dt dL/dqd - dL/dq + fv qd`` for one sample, from energies, by autograd."""
    m1, c1, i1, m2, c2, i2, fv1, fv2 = p

    def centres(q):  # centre-of-mass positions (x, y) of both links
        q1, q12 = q[0], q[0] + q[1]
        p1 = c1 * torch.stack((torch.cos(q1), torch.sin(q1)))
        p2 = l1 * torch.stack((torch.cos(q1), torch.sin(q1))) + c2 * torch.stack(
            (torch.cos(q12), torch.sin(q12))
        )
        return p1, p2

    def lagrangian(q, qd):
        (j1, j2) = torch.func.jacrev(centres)(q)
        v1, v2 = j1 @ qd, j2 @ qd
        kinetic = 0.5 * (m1 * v1 @ v1 + i1 * qd[0] ** 2 + m2 * v2 @ v2 + i2 * (qd[0] + qd[1]) ** 2)
        p1, p2 = centres(q)
        return kinetic - g * (m1 * p1[1] + m2 * p2[1])

    d_qd = torch.func.grad(lagrangian, argnums=1)
    mass = torch.func.jacrev(d_qd, argnums=1)(q, qd)  # d²L/dqd²
    mixed = torch.func.jacrev(d_qd, argnums=0)(q, qd)  # d²L/dqd dq
    d_q = torch.func.grad(lagrangian, argnums=0)(q, qd)
    return mass @ qdd + mixed @ qd - d_q + torch.stack((fv1, fv2)) * qd


@settings(max_examples=15, deadline=None)
@given(
    st.lists(st.floats(-3, 3), min_size=6, max_size=6),
    st.lists(st.floats(0.05, 3), min_size=8, max_size=8),
    st.floats(0.1, 1.0),
)
def test_matches_autograd_euler_lagrange(state, params, l1):
    robot = Planar2Robot(l1=l1)
    q, qd, qdd = torch.tensor(state, dtype=torch.float64).reshape(3, 1, 2)
    p = torch.tensor(params, dtype=torch.float64)
    expected = lagrangian_torques(p, q[0], qd[0], qdd[0], l1, robot.g)
    torch.testing.assert_close(robot.inverse_dynamics(p, q, qd, qdd)[0], expected, rtol=1e-10, atol=1e-10)


def test_base_parameters_of_the_nominal_arm_by_hand():
    alpha = Planar2Robot().base_params(torch.tensor(NOMINAL_PARAMS, dtype=torch.float64))
    # I1 + m1 c1² + m2 l1² = 0.05 + 2·0.0625 + 1.5·0.25; m1 c1 + m2 l1 = 0.5 + 0.75; ...
    expected = torch.tensor([0.55, 1.25, 0.03 + 1.5 * 0.04, 0.3, 0.4, 0.25], dtype=torch.float64)
    torch.testing.assert_close(alpha, expected, rtol=1e-15, atol=1e-15)


def test_params_from_base_recovers_nominal_and_keeps_the_reference_masses():
    robot = Planar2Robot()
    nominal = robot.nominal_params()
    torch.testing.assert_close(robot.params_from_base(robot.base_params(nominal)), nominal)
    other = robot.params_from_base(robot.base_params(random_params(3)))
    assert torch.equal(other[:, 0], torch.full((3,), NOMINAL_PARAMS[0], dtype=torch.float64))
    assert torch.equal(other[:, 3], torch.full((3,), NOMINAL_PARAMS[3], dtype=torch.float64))


def test_excitation_derivatives_are_exact_and_ten_samples_identify_all_base_params():
    robot = Planar2Robot()
    t = torch.linspace(0.3, 9.7, 13, dtype=torch.float64)
    q, qd, qdd = robot.excitation(t)
    for j in range(2):
        vel = torch.func.vmap(torch.func.grad(lambda s, j=j: robot.excitation(s[None])[0][0, j]))(t)
        acc = torch.func.vmap(torch.func.grad(lambda s, j=j: robot.excitation(s[None])[1][0, j]))(t)
        torch.testing.assert_close(vel, qd[:, j], rtol=1e-12, atol=1e-12)
        torch.testing.assert_close(acc, qdd[:, j], rtol=1e-12, atol=1e-12)
    assert (q[:, 0] + math.pi / 2).abs().max() < 1.45 and q[:, 1].abs().max() < 1.45
    ten = robot.regressor(*robot.excitation(torch.arange(1, 11, dtype=torch.float64))).reshape(20, 6)
    assert torch.linalg.matrix_rank(ten) == 6
    assert torch.linalg.cond(ten) < 100


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"l1": 0.0}, "l1 must be > 0"),
        ({"lower": (0.0,) * 7}, "lower needs 8 values"),
        ({"upper": (0.0,) * 8}, "empty search box"),
        ({"true_params": (0.0,) * 8}, "masses m1, m2"),
    ],
)
def test_bad_options_are_rejected(options, message):
    with pytest.raises(ValueError, match=message):
        Planar2Robot(**options)


def test_bad_shapes_name_the_array():
    robot = Planar2Robot()
    q, qd, qdd = states()
    with pytest.raises(ValueError, match=r"params must be \[\.\.\., 8\]"):
        robot.inverse_dynamics(torch.zeros(6, dtype=torch.float64), q, qd, qdd)
    with pytest.raises(ValueError, match=r"qd must be \[N, 2\]"):
        robot.inverse_dynamics(random_params(1), q, qd[:-1], qdd)
