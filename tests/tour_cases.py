"""The README tour's simulated arm, made as its scripts make it: the URDF, the optimised motion, the
truth its log-writing script sets, and noisy raw recordings of it (the coverage test and
``bench/uncertainty_coverage.py`` draw many)."""

from __future__ import annotations

import warnings
from importlib.resources import files
from pathlib import Path

import numpy as np
import torch

from idkit.data.recording import Recording
from idkit.robots.urdf import URDFRobot

#: What the tour's script changes in the URDF's arm (``truth = {...}`` in the README).
TRUTH = {
    "link2.m": 5.5,
    "theta1.fc": 0.5,
    "d2.fc": 2.0,
    "d3.fc": 1.0,
    "theta1.fv": 0.2,
    "d2.fv": 1.0,
    "d3.fv": 0.5,
    "theta1.offset": 0.1,
    "d2.offset": -0.5,
    "d3.offset": 0.3,
}

#: What the tour's script sets for its drive (``current.csv``): rotor inertia and sigmoid friction.
DRIVE_TRUTH = {"d2.armature": 2.0, "d2.phi1": 3.0, "d2.phi2": 30.0, "d3.phi1": 2.0}
#: The drive's effort per joint torque, N·m/A (``effort_scale``): current = torque / scale.
DRIVE_SCALE = (5.0, 40.0, 40.0)


def tour_urdf(folder: Path) -> Path:
    """The paper's robot with a small axial inertia on its rods, written to ``folder/arm.urdf``."""
    urdf = (files("idkit") / "robots/assets/cylindrical.urdf").read_text()
    path = folder / "arm.urdf"
    path.write_text(urdf.replace('izz="0"', 'izz="0.05"').replace('izz="1.0"', 'izz="0.9"'))
    return path


def tour_robot(urdf: Path) -> URDFRobot:
    """The arm the tour fits: Coulomb and viscous friction, torque offsets."""
    return URDFRobot(str(urdf), friction=True, offset=True)


def drive_robot(urdf: Path) -> URDFRobot:
    """The drive the tour fits with ``varpro``: rotor inertia, sigmoid friction, efforts in amps."""
    with warnings.catch_warnings():  # theta1's armature merges with link1: said by the robot
        warnings.simplefilter("ignore", UserWarning)
        return URDFRobot(str(urdf), friction="sigmoid", armature=True, effort_scale=list(DRIVE_SCALE))


def tour_motion(urdf: Path) -> tuple[np.ndarray, ...]:
    """``t, q, qd, qdd`` of the tour's optimised excitation (20 s, 100 criterion samples), taken at
    200 Hz from its 1 kHz export as the tour's script does."""
    from idkit.studies import excitation

    study = excitation.run({"_name_": "urdf", "urdf": str(urdf), "friction": True, "offset": True},
                           t_end=20.0, n_samples=100)  # fmt: skip
    trajectory = study.trajectory
    return tuple(np.array(x[::5]) for x in (trajectory.t, trajectory.q, trajectory.qd, trajectory.qdd))


def true_params(robot: URDFRobot, truth: dict[str, float] = TRUTH) -> torch.Tensor:
    """The robot's nominal parameters with ``truth``'s values."""
    params = robot.nominal_params().clone()
    for name, value in truth.items():
        params[robot.param_names.index(name)] = value
    return params


def noisy_recording(
    robot: URDFRobot,
    params: torch.Tensor,
    motion: tuple[np.ndarray, ...],
    rng: np.random.Generator,
    effort_per_torque: np.ndarray | float = 1.0,
) -> Recording:
    """A raw recording of ``motion`` as the tour's ``log()`` writes one: the exact torques plus 1 % of
    each joint's torque spread as white noise, the positions plus 1e-4 rad of encoder noise, the
    efforts in the drive's unit (``effort_per_torque``)."""
    t, q, qd, qdd = motion
    tau = robot.inverse_dynamics(params, *(torch.from_numpy(x) for x in (q, qd, qdd))).numpy()
    tau = tau + 0.01 * tau.std(0) * rng.standard_normal(tau.shape)
    noisy_q = q + 1e-4 * rng.standard_normal(q.shape)
    return Recording(t, noisy_q, tau * effort_per_torque, joint_names=robot.joint_names)
