"""The payload's σ on an arm model that is wrong: coverage of its 95 % intervals over noise and motion
draws (issue 31: σ that admit model error).

The arm is the branched test robot with Coulomb and viscous friction on every joint; the payload is
fitted on the arm model *without* friction, so the unmodelled friction is a model error correlated
over the motion. Each draw is a new smooth motion (three harmonics of 0.1 Hz per joint, one 10 s
period at 40 Hz, random amplitudes and phases) with 1 % torque noise, torques from pinocchio (an
independent simulator). Measured on these 60 draws (the mass and the three centre-of-mass
coordinates, 240 quantity-draws): the textbook ``s² (AᵀA)⁻¹`` the payload used before covered 57 %
(per quantity 48–63 %, draws up to 20 σ away); the HAC sandwich covers 97 % (95–100 %, at most 4.4 σ).

Not covered (the σ are model-conditional, :mod:`idkit.std_source`): the same excitation repeated
(two periods of it: the sandwich covered 91 %, the textbook 45 %, with draws up to 19 σ away — a
periodic motion repeats the bias, which no residual shows), and an arm-model error the payload's
columns absorb.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from urdf_cases import TREE_URDF, pin_model, pin_torques_and_regressor

from idkit.estimators.payload import PayloadIdentification
from idkit.problem import Problem, Samples
from idkit.robots.urdf import URDFRobot

pin = pytest.importorskip("pinocchio")

DRAWS = 60
MASS, COM = 0.7, np.array([0.03, -0.02, 0.1])
INERTIA = np.array([[0.002, 0.0003, -0.0001], [0.0003, 0.0025, 0.0002], [-0.0001, 0.0002, 0.0015]])
COULOMB, VISCOUS = np.array([0.3, 0.2, 0.1, 0.25]), np.array([0.5, 0.4, 0.2, 0.3])


def drawn_motion(robot: URDFRobot, model: pin.Model, seed: int, seconds: float = 10.0) -> Samples:
    """A smooth random motion at 40 Hz; pinocchio's torques with the payload, friction, 1 % noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, seconds, 1 / 40)[:, None, None]
    w = 2 * np.pi * 0.1 * np.arange(1, 4)[None, None, :]
    a = rng.normal(0, 0.6, (1, robot.n_joints, 3)) / np.arange(1, 4)
    phase = rng.uniform(0, 2 * np.pi, (1, robot.n_joints, 3))
    q = (a * np.sin(w * t + phase)).sum(-1)
    qd = (a * w * np.cos(w * t + phase)).sum(-1)
    qdd = (-a * w**2 * np.sin(w * t + phase)).sum(-1)
    states = tuple(torch.as_tensor(x) for x in (q, qd, qdd))
    torques, _ = pin_torques_and_regressor(robot, model, *states)
    rows = [model.joints[model.getJointId(name)].idx_v for name in robot.joint_names]
    tau = torques[:, rows] + COULOMB * np.sign(qd) + VISCOUS * qd
    tau = tau + 0.01 * np.sqrt((tau**2).mean(0)) * rng.normal(size=tau.shape)
    return Samples(*states, torch.as_tensor(tau))


@pytest.mark.slow
@pytest.mark.statistical
def test_the_payload_sigma_covers_an_arm_model_without_its_friction():
    """≥ 90 % of 240 quantity-draws within 1.96 σ (claimed 95 %: binomial σ 1.4 %, 90 % is 3.6 of them
    away; the textbook σ's 57 % fails by far), and every quantity ≥ 80 % of its 60 draws."""
    robot = URDFRobot(TREE_URDF)  # no friction: the arm model is wrong
    model = pin_model(TREE_URDF)
    model.appendBodyToJoint(model.getJointId("j3"), pin.Inertia(MASS, COM, INERTIA), pin.SE3.Identity())
    z = []
    for seed in range(DRAWS):
        found = PayloadIdentification(link="c").fit(Problem(robot, drawn_motion(robot, model, seed)))
        block = found.details["payload"]
        assert block["std_method"] == "weighted-hac" and "model-conditional" in block["std_source"]
        error = np.r_[block["mass"] - MASS, np.subtract(block["com"], COM)]
        z.append(error / np.r_[block["mass_std"], block["com_std"]])
    covered = np.abs(np.array(z)) < 1.96
    assert covered.mean() >= 0.9, f"coverage {covered.mean():.1%}"
    assert (covered.mean(0) >= 0.8).all(), f"per quantity {covered.mean(0)}"
