"""A torque or current log as rollout commands: efforts become the ``ctrl`` of motor-driven joints.

A robot that logs what its joints did and the efforts its drives applied (joint torques, or motor
currents that ``effort_scale`` turns into joint torques) has logged the commands of a torque-driven
simulator: the torque a joint's motor applies is ``effort × scale − offset``, with the drive scale and
the constant sensor offsets of the torque fit that the rollout starts from
(:mod:`idkit.sim.from_run`). The file is read as the torque path reads a raw recording
(:func:`idkit.data.load.read_source`: CSV with ``t``, ``<joint>.q``, ``<joint>.qd``, ``<joint>.tau``
columns; an ``.npz`` with ``t, q, qd, tau`` or FloBaRoID's ``times, positions, velocities, torques``;
a ROS log's ``JointState`` positions, velocities and efforts), and becomes a
:class:`~idkit.data.commands.RobotLog` whose commands are ``<joint>.ctrl``, one per joint, on the
states' own clock (the simulator holds each until the next sample).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from idkit.data.commands import RobotLog
from idkit.data.options import RecordingOptions


def read_effort_log(
    path: str | Path,
    joints: Sequence[str],
    scale: np.ndarray,
    offset: np.ndarray,
    options: RecordingOptions | None = None,
) -> RobotLog:
    """The log at ``path`` with ``<joint>.ctrl = effort × scale − offset`` as its commands.

    Args:
        path: a CSV, ``.npz`` or ROS log of positions, velocities and efforts.
        joints: the joints, in the order of ``scale`` and ``offset`` (a file that names its joints is
            read by these names; one that does not holds them in this order).
        scale: ``[n]`` joint torque per recorded effort unit (1 for logged joint torques).
        offset: ``[n]`` the torque sensors' constant offsets (N·m) the torque fit found.
        options: a ROS log's topics.

    Raises:
        ValueError: no velocities in the file, or what the reader refuses — naming the file.
    """
    from idkit.data.load import read_source

    joints = tuple(joints)
    scale, offset = np.asarray(scale, dtype=np.float64), np.asarray(offset, dtype=np.float64)
    if scale.shape != (len(joints),) or offset.shape != (len(joints),):
        raise ValueError(
            f"{path}: {len(joints)} joints but {scale.size} effort scale(s) and {offset.size} offset(s)"
        )
    source = read_source(path, apply="on", joints=joints, log=options)
    recording = source.recording
    assert recording is not None  # apply="on" reads every file as a recording
    if recording.qd is None:
        raise ValueError(
            f"{path}: no joint velocities (qd / velocities): a rollout starts each segment from the "
            "logged positions and velocities"
        )
    if recording.q.shape[1] != len(joints):
        raise ValueError(
            f"{path}: {recording.q.shape[1]} joints in the file, the torque fit has {len(joints)}"
        )
    torque = recording.tau * scale - offset
    return RobotLog(
        recording.t, recording.q, recording.qd, recording.t, torque, joints,
        tuple(f"{j}.ctrl" for j in joints), str(path),
    )  # fmt: skip
