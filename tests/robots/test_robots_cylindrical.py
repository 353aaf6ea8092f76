"""Cylindrical robot: eqs. (19)-(24) against an autograd Lagrangian and their own regressor."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from torch.func import grad, hessian, jacfwd, vmap

from idkit.robots.cylindrical import CylindricalRobot

G = 9.81


def lagrangian(params, q, qd):
    """Kinetic minus potential energy of the cylindrical arm, written from its geometry."""
    m2, m3, s3z, inertia = params
    r = s3z + q[2]
    kinetic = 0.5 * inertia * qd[0] ** 2 + 0.5 * m2 * qd[1] ** 2
    kinetic = kinetic + 0.5 * m3 * (qd[1] ** 2 + qd[2] ** 2 + (r * qd[0]) ** 2)
    return kinetic - (m2 + m3) * G * q[1]


def euler_lagrange(params, q, qd, qdd):
    """tau = d/dt dL/dqd - dL/dq = (d²L/dqd²) qdd + (d²L/dqd dq) qd - dL/dq, by autograd."""
    mass = hessian(lagrangian, argnums=2)(params, q, qd)
    mixed = jacfwd(grad(lagrangian, argnums=2), argnums=1)(params, q, qd)
    return mass @ qdd + mixed @ qd - grad(lagrangian, argnums=1)(params, q, qd)


def random_states(n: int, generator: torch.Generator) -> tuple[torch.Tensor, ...]:
    """States inside the bounds of eq. (38)."""
    lo = torch.tensor([[-torch.pi, 0, 0], [-4, -2, -1.5], [-3, -2, -1]], dtype=torch.float64)
    hi = torch.tensor([[torch.pi, 1, 1], [4, 2, 1.5], [3, 2, 1]], dtype=torch.float64)
    u = torch.rand(3, n, 3, generator=generator, dtype=torch.float64)
    q, qd, qdd = (lo[i] + (hi[i] - lo[i]) * u[i] for i in range(3))
    return q, qd, qdd


def test_matches_autograd_lagrangian(cylindrical, rng):
    q, qd, qdd = random_states(50, rng)
    params = torch.tensor([[5.0, 3.0, -0.5, 3.0], [1.3, 0.7, 0.4, 2.2]], dtype=torch.float64)
    tau = cylindrical.inverse_dynamics(params, q, qd, qdd)
    for p, t in zip(params, tau, strict=True):
        reference = vmap(euler_lagrange, in_dims=(None, 0, 0, 0))(p, q, qd, qdd)
        torch.testing.assert_close(t, reference, rtol=1e-12, atol=1e-12)


@settings(max_examples=20, deadline=None)
@given(batch=st.sampled_from([(), (1,), (2,), (2, 3)]), n=st.integers(1, 20), seed=st.integers(0, 2**16))
def test_regressor_times_base_params_equals_dynamics(batch, n, seed):
    robot = CylindricalRobot()
    generator = torch.Generator().manual_seed(seed)
    q, qd, qdd = random_states(n, generator)
    params = torch.rand(*batch, 4, generator=generator, dtype=torch.float64) * 10 - 2
    tau = robot.inverse_dynamics(params, q, qd, qdd)
    assert tau.shape == (*batch, n, 3)
    linear = torch.einsum("nij,...j->...ni", robot.regressor(q, qd, qdd), robot.base_params(params))
    torch.testing.assert_close(linear, tau, rtol=1e-12, atol=1e-11)


@settings(max_examples=30, deadline=None)
@given(m2=st.floats(0.1, 20), m3=st.floats(0.1, 20), s3z=st.floats(-2, 2), inertia=st.floats(0, 20))
def test_base_params_round_trip(m2, m3, s3z, inertia):
    robot = CylindricalRobot()
    params = torch.tensor([m2, m3, s3z, inertia], dtype=torch.float64)
    back = robot.params_from_base(robot.base_params(params))
    torch.testing.assert_close(back, params, rtol=1e-10, atol=1e-12)


def test_base_params_eq_24(cylindrical):
    alpha = cylindrical.base_params(cylindrical.nominal_params())
    torch.testing.assert_close(alpha, torch.tensor([3.75, 5.0, 3.0, -1.5], dtype=torch.float64))


def test_float32_and_shapes(cylindrical, rng):
    q, qd, qdd = (x.float() for x in random_states(4, rng))
    params = cylindrical.nominal_params().float().expand(2, 3, 4)
    assert cylindrical.inverse_dynamics(params, q, qd, qdd).dtype == torch.float32
    assert cylindrical.regressor(q, qd, qdd).shape == (4, 3, 4)


def test_constructor_validates():
    with pytest.raises(ValueError, match="lower needs 4 values"):
        CylindricalRobot(lower=(0, 0, 0))
    with pytest.raises(ValueError, match="empty search box"):
        CylindricalRobot(lower=(1, 0, 0, 0), upper=(0, 1, 1, 1))
