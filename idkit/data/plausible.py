"""A file checked against the robot it is for, before anything is fitted to it.

Numbers in another unit than the model's are a silent wrong answer: positions logged in degrees
(±114 where the URDF says ±π) fit without a word, with masses off by factors of 1.6 and 1/3000. A
robot stops at its limits, and moves smoothly, so a recording that does neither is in another unit,
of another robot, or damaged. Each check says the file, the joint, the value and the likely cause:

* **timestamps** (a raw recording, or a samples file's ``t``): a median step over 1 s (below
  :data:`MIN_RATE_HZ`) is refused: no identification recording is that slow, so ``t`` is in
  milliseconds, microseconds or nanoseconds (named when the step fits one);
* **positions** against the robot's limits (``Robot.motion_limits``: a URDF's ``<limit>``): beyond a
  limit by more than 5 % of the joint's range where the values divided by a unit factor — 180/π
  (degrees for radians), 1000 (millimetres for metres) — lie within it, spanning 5 % of it as a
  motion does, is refused. Any other
  excursion is said in one line (a :class:`LimitWarning`) and the fit goes on (the dynamics do not
  need the limits): far beyond, another unit (motor-side positions?), joint order or robot; a little
  beyond, another zero, a calibration offset, or a URDF whose limits are not the robot's;
* **position jumps** in a raw recording: a step over π between two samples (not across a gap, where
  preprocessing splits) is refused — no joint
  moves that far in one sample; an angle wrapped at ±π (unwrap it) or a glitch, which the
  differentiation would turn into spikes of velocity and acceleration;
* **velocities** against the velocity limits: the file's own where the fit uses them (a samples file,
  or ``preprocess.velocities=measured``), else the positions' rate of change over
  :data:`RATE_WINDOW` (long enough that encoder noise does not reach a limit) — so that positions in
  degrees on a joint without position limits (a continuous joint) are said too: said, with the unit
  mistake that would explain them (URDF velocity limits are often nominal);
* **torques** (joint torques: after ``effort_scale``): more than :data:`EFFORT_FACTOR` times a joint's
  effort limit (``Robot.effort_limits``) is said — a wrong ``effort_scale`` or another unit — and so
  is a joint whose torques are all exactly zero: an empty effort column or topic, unless the joint is
  passive.

A robot without limits (``motion_limits`` not implemented) and a joint without one (a continuous
joint, a URDF without ``velocity``) are not checked against them.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np
from torch import Tensor

from idkit.data.load import Source
from idkit.interfaces import Robot

#: Seconds over which a raw recording's positions are differenced to check their speed (module doc).
RATE_WINDOW = 0.05
#: Unit mistakes a limit check recognises: the factor the values are too large by, and what it means.
UNIT_FACTORS = {180.0 / math.pi: "degrees where radians are due", 1000.0: "millimetres where metres are due"}
#: Torques beyond this many times a joint's effort limit are said (module doc).
EFFORT_FACTOR = 1.5
#: The slowest sampling (Hz) a recording may have; slower, its timestamps are in another unit.
MIN_RATE_HZ = 1.0
#: Units timestamps are found in instead of seconds: the factor to seconds, and the name.
TIME_UNITS = {1e-3: "milliseconds", 1e-6: "microseconds", 1e-9: "nanoseconds"}


class LimitWarning(UserWarning):
    """A recording goes beyond one of the robot's limits (by too little to be another unit)."""


def check_recording(
    robot: Robot, source: Source, role: str, measured_velocities: bool, max_gap: float
) -> None:
    """Check a read file (module doc): its timestamps, its positions (and its own velocities, if the fit
    uses them: ``measured_velocities`` for a raw recording; always for samples) against ``robot``'s
    limits, a raw recording's position jumps (not across a gap of ``max_gap`` median steps), and its
    torques (joint torques: after ``effort_scale``).

    Raises:
        ValueError: timestamps in another unit, positions in another unit or wrapped, naming the
            file, the joint, the value and the likely cause.
    """
    try:
        limits = robot.motion_limits()
    except NotImplementedError:
        limits = None
    where = f"{role} file {source.path}"
    qd: np.ndarray | None
    if source.recording is not None:
        recording = source.recording
        q, qd, tau = recording.q, recording.qd if measured_velocities else None, recording.tau
    else:
        assert source.samples is not None
        q, qd, tau = (_numpy(x) for x in (source.samples.q, source.samples.qd, source.samples.tau))
    joints = robot.joint_names
    times = source.recording.t if source.recording is not None else source.times
    if times is not None:
        _check_times(where, times)
    if limits is not None:
        lower, upper = limits.lower.double().numpy(), limits.upper.double().numpy()
        _check_box(where, "position", q, lower[0], upper[0], joints, refuse=True)
    if source.recording is not None:  # before the speed: a wrapped angle is a jump, not a fast joint
        _check_jumps(where, source.recording.t, q, joints, max_gap)
    if limits is not None:
        lower, upper = limits.lower.double().numpy(), limits.upper.double().numpy()
        quantity = "velocity"
        if qd is None and source.recording is not None:
            qd, quantity = _rates(source.recording.t, q), "velocity (the positions' rate of change)"
        if qd is not None:
            _check_box(where, quantity, qd, lower[1], upper[1], joints, refuse=False)
    effort = getattr(robot, "effort_limits", None)
    if effort is not None:
        _check_effort(where, tau, np.asarray(effort, dtype=np.float64), joints)
    for j in np.flatnonzero(~np.any(tau, axis=0)):
        warnings.warn(
            f"{where}: joint {joints[j]}'s torques are all exactly zero: an effort column or topic left "
            "empty? (a passive joint's are)",
            LimitWarning,
            stacklevel=3,
        )


def _numpy(values: Tensor) -> np.ndarray:
    return values.detach().cpu().double().numpy()


def _check_times(where: str, times: np.ndarray) -> None:
    """Refuse timestamps whose median step is over ``1 / MIN_RATE_HZ``: in another unit than seconds."""
    if len(times) < 2:
        return
    step = float(np.median(np.diff(times)))
    if step <= 1.0 / MIN_RATE_HZ:
        return
    units = [name for factor, name in TIME_UNITS.items() if 1e-4 <= step * factor <= 0.1]
    guess = f"{units[0]} where seconds are due?" if units else "another unit than seconds?"
    raise ValueError(
        f"{where}: the timestamps step by a median {step:.4g} ({1 / step:.3g} Hz in seconds): {guess} "
        "idkit reads t in seconds; convert the time column"
    )


def _rates(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The positions' ``[N, n]`` change over :data:`RATE_WINDOW` (at least one step) per second: a speed
    to check against the limits, not a velocity to fit (steps that do not move forwards are skipped)."""
    dt = np.diff(t)
    span = max(1, int(round(RATE_WINDOW / float(np.median(dt))))) if dt.size else 1
    if len(t) <= span:
        return np.zeros((0, q.shape[1]))
    elapsed = t[span:] - t[:-span]
    forward = elapsed > 0
    return (q[span:] - q[:-span])[forward] / elapsed[forward, None]


def _check_jumps(where: str, t: np.ndarray, q: np.ndarray, joints: Sequence[str], max_gap: float) -> None:
    """Refuse a position step over π between two samples of a raw recording (module doc); a step across
    a gap in the timestamps (``max_gap`` median steps: preprocessing splits there) may be anything."""
    dt = np.diff(t)
    steps = np.abs(np.diff(q, axis=0)) * (dt <= max_gap * np.median(dt))[:, None]
    if not steps.size or steps.max() <= math.pi:
        return
    k, j = (int(i) for i in np.unravel_index(int(steps.argmax()), steps.shape))
    raise ValueError(
        f"{where}: joint {joints[j]}'s position jumps by {float(q[k + 1, j] - q[k, j]):.4g} between "
        f"samples {k} and {k + 1} (t = {float(t[k]):.6g} s): an angle wrapped at ±π (unwrap it, e.g. "
        "numpy.unwrap) or a glitch? No joint moves that far in one sample; differentiated it is a spike"
    )


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
    if not values.size:
        return
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
            why for factor, why in UNIT_FACTORS.items() if _fits(low[j] / factor, high[j] / factor, lo, hi)
        ]
        if units and refuse and beyond > 0.05 * (hi - lo):
            raise ValueError(
                f"{said}: logged in {units[0]}? (divided by the factor it lies within them); convert the "
                "file, or correct the robot's limits if they are wrong"
            )
        if units:
            cause = f"{units[0]}?"
        elif beyond > hi - lo:
            side = "positions" if quantity == "position" else "speeds"
            cause = f"far beyond: another unit (motor-side {side}?), joint order or robot?"
        elif quantity != "position":
            cause = "a URDF's velocity limit below the robot's (they are often nominal)?"
        else:
            cause = "another zero, a calibration offset, or limits not the robot's?"
        warnings.warn(f"{said} by {beyond:.3g}: {cause}", LimitWarning, stacklevel=4)


def _fits(low: float, high: float, lo: float, hi: float) -> bool:
    """Whether values spanning ``[low, high]`` lie within ``[lo, hi]`` and span 5 % of it, as a motion
    does (values near 0 fit any range: dividing a small overshoot by 57 proves nothing)."""
    return lo <= low and high <= hi and high - low >= 0.05 * (hi - lo)


def _check_effort(where: str, tau: np.ndarray, effort: np.ndarray, joints: Sequence[str]) -> None:
    """Say joint torques ``[N, n]`` beyond :data:`EFFORT_FACTOR` × the effort limits ``[n]``."""
    peak = np.abs(tau).max(0)
    known = np.isfinite(effort) & (effort > 0)
    for j in np.flatnonzero(known & (peak > EFFORT_FACTOR * np.where(known, effort, 0.0))).tolist():
        warnings.warn(
            f"{where}: joint {joints[j]}'s torque reaches {peak[j]:.4g}, {peak[j] / effort[j]:.3g} times its "
            f"effort limit {effort[j]:.4g}: is robot.effort_scale right, or are the efforts in another unit?",
            LimitWarning,
            stacklevel=4,
        )
