"""Joint torques of a motion under the robot's nominal model, against its effort limits.

A motion is runnable only if the drives can produce its torques: ``tau = ID(θ_nominal, q, qd, qdd)``
(inverse dynamics with the robot's a-priori parameters, e.g. a URDF's CAD inertials; friction and
offsets are 0 in it) must stay within ``<limit effort>`` of every joint at every instant.

A URDF declares no acceleration limits. :func:`default_acceleration_limits` derives them from the
effort limits instead of refusing: joint ``j`` may accelerate at ``fraction · effort_j / M_jj``,
with ``M_jj`` the largest diagonal entry of the nominal mass matrix over a set of poses within the
position limits — the acceleration at which joint ``j``'s own inertia alone takes ``fraction`` of
its effort limit wherever the arm is (``fraction = 0.5`` keeps the other half for gravity, velocity
terms and the coupling of the other joints). The effort check on the motion's torques remains
the real test; the acceleration limit only keeps the search from proposing violent motions.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from idkit.interfaces import Robot
from idkit.limits import MotionLimits
from idkit.options import positive_number
from idkit.seeds import torch_generator

#: Share of a joint's effort limit its own inertia may take at the default acceleration limit.
DEFAULT_EFFORT_FRACTION = 0.5

#: Poses (uniform within the position limits, seed 0) the largest inertia is taken over.
INERTIA_POSES = 256


def effort_limits(robot: Robot) -> Tensor | None:
    """The robot's effort limits ``[n]`` (float64) if it declares one for every joint, else ``None``."""
    limits = getattr(robot, "effort_limits", None)
    return None if limits is None else torch.as_tensor(limits, dtype=torch.float64)


def nominal_torques(robot: Robot, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
    """``tau[..., T, n]`` of states ``[..., T, n]`` under ``robot.nominal_params()``.

    Raises:
        ValueError: the robot has no nominal parameters.
    """
    params = robot.nominal_params()
    if params is None:
        raise ValueError(f"robot {type(robot).__name__} has no nominal parameters to compute torques with")
    n = robot.n_joints
    batch = q.shape[:-1]
    flat = (x.reshape(-1, n) for x in (q, qd, qdd))
    tau = robot.inverse_dynamics(torch.as_tensor(params).to(q), *flat)
    return tau.reshape(*batch, n)


def mass_matrix_diagonal(robot: Robot, q: Tensor) -> Tensor:
    """``M_jj(q)`` ``[P, n]`` of the nominal model at poses ``q[P, n]``: ``tau(q, 0, e_j) - tau(q, 0, 0)``."""
    poses, n = q.shape
    eye = torch.eye(n, dtype=q.dtype, device=q.device)
    states = q[:, None, :].expand(poses, n + 1, n)
    qdd = torch.cat((eye, torch.zeros(1, n, dtype=q.dtype, device=q.device)))  # unit accelerations, then 0
    tau = nominal_torques(robot, states, torch.zeros_like(states), qdd.expand(poses, n + 1, n))
    return (tau[:, :n] - tau[:, n:]).diagonal(dim1=-2, dim2=-1)


def default_acceleration_limits(robot: Robot, fraction: float = DEFAULT_EFFORT_FRACTION) -> Tensor:
    """``fraction · effort_j / max_pose M_jj`` ``[n]`` (module docstring), rad/s² or m/s².

    The poses are :data:`INERTIA_POSES` uniform draws within the position limits (``±π`` for a
    joint without them; seed 0), so the number is reproducible.

    Raises:
        ValueError: the robot declares no effort limits (then an acceleration limit must be given).
    """
    effort = effort_limits(robot)
    if effort is None:
        raise ValueError(
            f"robot {type(robot).__name__} has no acceleration limits and no effort limits to derive them "
            "from; give excitation.acceleration_limit=<one number, or a list with one per joint> in rad/s² "
            "(m/s² for a prismatic joint)"
        )
    limits = robot.motion_limits()
    lower = torch.where(limits.lower[0].isinf(), -torch.pi, limits.lower[0])
    upper = torch.where(limits.upper[0].isinf(), torch.pi, limits.upper[0])
    generator = torch_generator(0)
    unit = torch.rand(INERTIA_POSES, robot.n_joints, generator=generator, dtype=torch.float64)
    inertia = mass_matrix_diagonal(robot, lower + (upper - lower) * unit).amax(0)
    return fraction * effort / inertia


def acceleration_bounded_limits(
    robot: Robot, acceleration_limit: float | Sequence[float] | None = None
) -> tuple[MotionLimits, str]:
    """The robot's motion limits with every joint's acceleration bounded, and where that bound is from.

    ``|q̈_j| <= acceleration_limit[_j]`` when given (one number for all joints, or one per joint; it
    replaces the robot's own). Otherwise the robot's own limits where it has them, and
    :func:`default_acceleration_limits` for joints without (a URDF declares none).

    Returns:
        ``(limits, source)``, ``source`` one of ``"given"``, ``"robot"``, ``"effort"``.

    Raises:
        ValueError: a bad ``acceleration_limit`` (not positive and finite, wrong length), or a joint
            without an acceleration limit on a robot without effort limits.
    """
    limits = robot.motion_limits()
    names = limits.joint_names
    if acceleration_limit is not None:
        values = (
            [acceleration_limit] if isinstance(acceleration_limit, (int, float)) else list(acceleration_limit)
        )
        bad = [v for v in values if not positive_number(v)]
        if bad or len(values) not in (1, len(names)):
            raise ValueError(
                f"excitation.acceleration_limit must be one positive number or one per joint "
                f"({len(names)}: {', '.join(names)}), got {acceleration_limit!r}"
            )
        bound = torch.tensor(values * len(names) if len(values) == 1 else values, dtype=torch.float64)
        return limits.replace("acceleration", -bound, bound), "given"
    unbounded = limits.lower[2].isinf() | limits.upper[2].isinf()
    if not unbounded.any():
        return limits, "robot"
    default = default_acceleration_limits(robot)
    lower = torch.where(unbounded, -default, limits.lower[2])
    upper = torch.where(unbounded, default, limits.upper[2])
    return limits.replace("acceleration", lower, upper), "effort"
