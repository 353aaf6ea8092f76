"""The judged payload case: 2.3 kg on the KUKA LWR4+'s last link, torques by pinocchio (the URDF with
the payload appended as a body of the last joint) on the real measurements_1 motion, 1 % noise."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from idkit.estimators.payload import PayloadIdentification
from idkit.problem import Problem, Samples
from idkit.robots.urdf import URDFRobot
from idkit.robots.urdf_export import identified_urdf

pin = pytest.importorskip("pinocchio")
pytestmark = pytest.mark.kuka

MASS, COM = 2.3, np.array([0.02, -0.015, 0.08])
INERTIA = np.array([[0.012, 0.001, -0.0005], [0.001, 0.015, 0.0008], [-0.0005, 0.0008, 0.008]])


def recorded_motion(kuka_dir, k: int) -> tuple[np.ndarray, ...]:
    with np.load(kuka_dir / f"measurements_{k}.npz") as data:
        return data["positions"], data["velocities"], data["accelerations"]


def pinocchio_samples(urdf: str, robot: URDFRobot, motion, payload: bool, seed: int) -> Samples:
    """pinocchio's torques of ``urdf`` (with the payload appended to the last joint) plus Gaussian noise
    of 1 % of each joint's RMS torque."""
    model = pin.buildModelFromUrdf(urdf)
    if payload:
        model.appendBodyToJoint(
            model.getJointId("lwr_6_joint"), pin.Inertia(MASS, COM, INERTIA), pin.SE3.Identity()
        )
    data = model.createData()
    q, qd, qdd = motion
    rows = [model.joints[model.getJointId(name)].idx_v for name in robot.joint_names]
    tau = np.array([pin.rnea(model, data, *state) for state in zip(q, qd, qdd, strict=True)])[:, rows]
    tau = tau + 0.01 * np.sqrt((tau**2).mean(0)) * np.random.default_rng(seed).standard_normal(tau.shape)
    return Samples(*(torch.as_tensor(x) for x in (q, qd, qdd, tau)))


def test_two_point_three_kilograms_on_the_last_link(kuka_dir):
    urdf = str(kuka_dir / "kuka_lwr4.urdf")
    robot = URDFRobot(urdf)
    samples = pinocchio_samples(urdf, robot, recorded_motion(kuka_dir, 1), payload=True, seed=0)
    found = PayloadIdentification().fit(Problem(robot, samples)).details["payload"]
    assert found["link"] == "lwr_7_link"
    assert abs(found["mass"] - MASS) < 0.01 * MASS  # judged: within 1 %
    assert np.linalg.norm(np.subtract(found["com"], COM)) < 0.003  # judged: within 3 mm
    assert abs(found["mass"] - MASS) < 4 * found["mass_std"]
    assert (np.abs(np.subtract(found["com"], COM)) < 4 * np.array(found["com_std"])).all()


def test_the_reference_recording_on_the_kuka_with_a_ten_percent_wrong_arm(kuka_dir, tmp_path):
    urdf = str(kuka_dir / "kuka_lwr4.urdf")
    truth = URDFRobot(urdf)
    wrong = truth.nominal_params().clone()
    scales = np.random.default_rng(1).choice([0.9, 1.1], len(truth.link_names))
    for i, scale in enumerate(scales):
        wrong[10 * i : 10 * i + 10] *= scale
    (tmp_path / "arm.urdf").write_text(identified_urdf(truth, wrong))
    model = URDFRobot(str(tmp_path / "arm.urdf"))
    with_tool = pinocchio_samples(urdf, truth, recorded_motion(kuka_dir, 1), payload=True, seed=2)
    # the reference runs another motion (measurements_3's, faster): correction=model needs no replay
    bare = pinocchio_samples(urdf, truth, recorded_motion(kuka_dir, 3), False, 3)
    alone = PayloadIdentification().fit(Problem(model, with_tool)).details["payload"]
    both = PayloadIdentification(reference=bare).fit(Problem(model, with_tool))
    found = both.details["payload"]
    assert abs(alone["mass"] - MASS) > 0.02 * MASS
    assert abs(found["mass"] - MASS) < 0.01 * MASS
    assert np.linalg.norm(np.subtract(found["com"], COM)) < 0.003
    assert both.details["reference"]["rel_error_corrected"] < 0.5 * both.details["reference"]["rel_error_arm"]
