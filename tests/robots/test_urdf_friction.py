"""The urdf robot's friction model: Stribeck term, per-joint scales, and its regressor."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from idkit.robots.urdf import URDFRobot


@pytest.mark.parametrize("scales", [0.1, [0.05, 0.2, 0.5]])
def test_stribeck_term_in_torques_and_regressor(scales):
    robot = URDFRobot("cylindrical", friction=True, offset=True, stribeck_velocity=scales)
    rigid = URDFRobot("cylindrical")
    n = robot.n_joints
    assert robot.param_names[-2 * n : -n] == tuple(f"{j}.fs" for j in robot.joint_names)
    q, qd, qdd = robot.random_states(40, torch.Generator().manual_seed(0))
    params = torch.cat([rigid.nominal_params(), torch.linspace(0.1, 1.5, 4 * n, dtype=torch.float64)])
    fc, fv, fs, offset = params[rigid.n_params :].reshape(4, n)
    vs = torch.as_tensor(np.broadcast_to(scales, (n,)).copy())
    by_hand = (
        rigid.inverse_dynamics(rigid.nominal_params(), q, qd, qdd)
        + fc * torch.sign(qd)
        + fv * qd
        + fs * torch.exp(-((qd / vs) ** 2)) * torch.sign(qd)
        + offset
    )
    torch.testing.assert_close(robot.inverse_dynamics(params, q, qd, qdd), by_hand, rtol=0, atol=1e-12)
    torch.testing.assert_close(robot.standard_regressor(q, qd, qdd) @ params, by_hand, rtol=0, atol=1e-12)
    lower, upper = robot.bounds()
    assert (lower[rigid.n_params : rigid.n_params + 2 * n] == 0).all()
    assert (lower[rigid.n_params + 2 * n : rigid.n_params + 3 * n] < 0).all()
    assert (upper > lower).all()


@pytest.mark.parametrize(
    "options",
    [
        {"stribeck_velocity": 0.1},
        {"friction": True, "stribeck_velocity": -1.0},
        {"friction": True, "stribeck_velocity": [0.1, 0.2]},
    ],
)
def test_bad_stribeck_velocity_is_named(options):
    with pytest.raises(ValueError, match="stribeck_velocity=.* needs friction=true and one value > 0"):
        URDFRobot("cylindrical", **options)


def test_effort_limits_come_from_the_urdf():
    np.testing.assert_array_equal(URDFRobot("cylindrical").effort_limits, [1000.0, 1000.0, 1000.0])
