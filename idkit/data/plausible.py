"""A recording checked against the robot it is for: positions, velocities and torques within its limits.

Numbers in another unit than the model's are a silent wrong answer: positions logged in degrees
(±114 where the URDF says ±π) fit without a word, with masses off by factors of 1.6 and 1/3000. A
robot stops at its limits, so a recording far beyond them is in another unit, or of another robot.
Every file is compared with the robot's limits (``Robot.motion_limits``: a URDF's ``<limit>``;
``Robot.effort_limits``), per joint, where the robot declares one:

* **positions**: beyond a limit by more than 5 % of the joint's range where the values divided by
  a unit factor — 180/π (degrees for radians), 1000 (millimetres for metres) — lie within it is
  refused in one line naming the file, the joint, the value, the limit and that likely cause. Any
  other excursion is said in one line (a :class:`LimitWarning`): far beyond, another unit (motor-side
  positions?), joint order or robot; a little beyond, another zero, a calibration offset, or a URDF
  whose limits are not the robot's (the dynamics do not need the limits, so the fit goes on);
* **velocities**, where the fit uses the file's own (a samples file, or
  ``preprocess.velocities=measured``): beyond a limit is said, with the unit mistake that would
  explain it. Only said: URDF velocity limits are often nominal, and velocities in another unit than
  their positions are rare (the positions' check catches a file in degrees);
* **torques** (joint torques: after ``effort_scale``) more than :data:`EFFORT_FACTOR` times a joint's
  effort limit are said in one line: a wrong ``effort_scale`` or another unit. Only said, since
  effort limits are often nominal and drives may exceed them briefly.

A robot without limits (``motion_limits`` not implemented) and a joint without one (a continuous
joint, a URDF without ``velocity``) are not checked.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np

from idkit.data.load import Source
from idkit.interfaces import Robot

#: Unit mistakes a limit check recognises: the factor the values are too large by, and what it means.
UNIT_FACTORS = {180.0 / math.pi: "degrees where radians are due", 1000.0: "millimetres where metres are due"}
#: Torques beyond this many times a joint's effort limit are said (module doc).
EFFORT_FACTOR = 1.5


class LimitWarning(UserWarning):
    """A recording goes beyond one of the robot's limits (by too little to be another unit)."""


def check_motion(robot: Robot, source: Source, role: str, measured_velocities: bool) -> None:
    """Check ``source``'s positions (and its own velocities, if the fit uses them: ``measured_velocities``
    for a raw recording; always for samples) and its torques (joint torques: after ``effort_scale``)
    against ``robot``'s limits (module doc).

    Raises:
        ValueError: a value far beyond a limit, naming the file, joint, value, limit and likely cause.
    """
    try:
        limits = robot.motion_limits()
    except NotImplementedError:
        limits = None
    where = f"{role} file {source.path}"
    if source.recording is not None:
        recording = source.recording
        q, qd, tau = recording.q, recording.qd if measured_velocities else None, recording.tau
    else:
        assert source.samples is not None
        q, qd, tau = (source.samples.q, source.samples.qd, source.samples.tau)
        q, qd, tau = (x.detach().cpu().double().numpy() for x in (q, qd, tau))
    joints = robot.joint_names
    if limits is not None:
        lower, upper = limits.lower.double().numpy(), limits.upper.double().numpy()
        _check_box(where, "position", q, lower[0], upper[0], joints, refuse=True)
        if qd is not None:
            _check_box(where, "velocity", qd, lower[1], upper[1], joints, refuse=False)
    effort = getattr(robot, "effort_limits", None)
    if effort is not None:
        _check_effort(where, tau, np.asarray(effort, dtype=np.float64), joints)


def _check_box(
    where: str,
    quantity: str,
    values: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    joints: Sequence[str],
    refuse: bool,
) -> None:
    """Say values ``[N, n]`` beyond ``[lower, upper]`` in one line each, with a unit mistake that
    explains them; ``refuse``: raise instead where they are far beyond (module doc)."""
    low, high = values.min(0), values.max(0)
    for j, joint in enumerate(joints):
        lo, hi = float(lower[j]), float(upper[j])
        beyond = max(lo - float(low[j]), float(high[j]) - hi)
        if not (math.isfinite(lo) and math.isfinite(hi)) or beyond <= 0:
            continue
        worst = float(low[j]) if lo - float(low[j]) >= float(high[j]) - hi else float(high[j])
        said = (
            f"{where}: joint {joint}'s {quantity} reaches {worst:.4g}, beyond the robot's limits "
            f"[{lo:.4g}, {hi:.4g}]"
        )
        units = [
            why for factor, why in UNIT_FACTORS.items() if lo <= low[j] / factor and high[j] / factor <= hi
        ]
        if units and refuse and beyond > 0.05 * (hi - lo):
            raise ValueError(
                f"{said}: logged in {units[0]}? (divided by the factor it lies within them); convert the "
                "file, or correct the robot's limits if they are wrong"
            )
        if units:
            cause = f"{units[0]}?"
        elif beyond > hi - lo:
            cause = "far beyond: another unit (motor-side positions?), joint order or robot?"
        else:
            cause = "another zero, a calibration offset, or limits not the robot's?"
        warnings.warn(f"{said} by {beyond:.3g}: {cause}", LimitWarning, stacklevel=4)


def _check_effort(where: str, tau: np.ndarray, effort: np.ndarray, joints: Sequence[str]) -> None:
    """Say joint torques ``[N, n]`` beyond :data:`EFFORT_FACTOR` × the effort limits ``[n]``."""
    peak = np.abs(tau).max(0)
    known = np.isfinite(effort) & (effort > 0)
    for j in np.flatnonzero(known & (peak > EFFORT_FACTOR * np.where(known, effort, 0.0))):
        warnings.warn(
            f"{where}: joint {joints[j]}'s torque reaches {peak[j]:.4g}, {peak[j] / effort[j]:.3g} times its "
            f"effort limit {effort[j]:.4g}: is robot.effort_scale right, or are the efforts in another unit?",
            LimitWarning,
            stacklevel=4,
        )
