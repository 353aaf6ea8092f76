"""The paper's 3-DOF cylindrical robot (Table I): eqs. (19)–(24), batched in torch.

Joints: ``theta1`` (revolute about the vertical), ``d2`` (prismatic, vertical), ``d3`` (prismatic,
radial). Physical parameters ``(m2, m3, s3z, I)`` with ``I = I1zz + I2yy + I3yy`` (eq. 22); the
paper's tables print ``-s3z``. Eqs. (19)–(21) assume link 1 is a point and links 2 and 3 are thin
rods with no sideways centre-of-mass offset; friction is omitted, as in the paper.

A matching URDF ships as ``idkit/robots/assets/cylindrical.urdf`` (Table I read as standard DH;
``idkit.verify.cylindrical_urdf`` renders it for any parameters), and the tests check eqs. (19)–(21)
against a pytorch-kinematics Lagrangian oracle and pinocchio on it to 1e-9. They are the *exact*
rigid-body dynamics of that robot only under these assumptions:

* gravity along ``-z`` and joint ``d2`` vertical (``tau2`` sees no other mass than ``m2 + m3``);
* link 1's and link 2's centres of mass on the vertical axis (their height is free): a horizontal
  offset ``r`` would add ``m r²`` to the ``theta1`` inertia;
* link 3's centre of mass on joint 3's axis, at ``s3z`` along it (a vertical offset is harmless): a
  horizontal offset ``x`` across that axis adds ``m3 x²`` to the ``theta1`` inertia and couples
  ``tau1`` and ``tau3`` through ``-m3 x d̈3`` and ``-m3 x θ̈1``;
* only the moments about the vertical enter — ``I1zz`` of frame 1, ``I2yy`` and ``I3yy`` of DH
  frames 2 and 3, whose ``y`` axis is vertical — and only their sum ``I`` (eq. 22) is identifiable;
  "thin rod" just fixes which entry that is (products of inertia are taken by the prismatic joints);
* rigid links, no friction, no motor/gear inertia.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from idkit.interfaces import Excitation, Robot
from idkit.limits import MotionLimits
from idkit.registry import create

TRUE_PARAMS = (5.0, 3.0, -0.5, 3.0)

#: Eq. (38), per joint (theta1, d2, d3): ``(lower, upper)`` of position, velocity, acceleration.
PAPER_LIMITS = (
    ((-math.pi, math.pi), (-4.0, 4.0), (-3.0, 3.0)),
    ((0.0, 1.0), (-2.0, 2.0), (-2.0, 2.0)),
    ((0.0, 1.0), (-1.5, 1.5), (-1.0, 1.0)),
)


class CylindricalRobot(Robot):
    """Closed-form inverse dynamics, regressor (eq. 23) and base parameters (eq. 24).

    Args:
        g: gravitational acceleration (m/s²) acting along −z on the vertical joint ``d2``.
        true_params: simulation truth ``(m2, m3, s3z, I)``; the paper's values by default.
        lower, upper: the search box for estimators that need one. Masses and ``I`` start at
            0 (physical), ``s3z`` spans the 1 m radial stroke on either side.
    """

    joint_names = ("theta1", "d2", "d3")
    #: whether each joint's effort is a torque (N·m) or a force (N), for the reports
    joint_kinds = ("revolute", "prismatic", "prismatic")
    param_names = ("m2", "m3", "s3z", "I")
    base_param_names = ("I+m3*s3z^2", "m2", "m3", "m3*s3z")

    def __init__(
        self,
        g: float = 9.81,
        true_params: Sequence[float] = TRUE_PARAMS,
        lower: Sequence[float] = (0.0, 0.0, -1.0, 0.0),
        upper: Sequence[float] = (10.0, 10.0, 1.0, 10.0),
    ) -> None:
        self.g = g
        self.true_params = tuple(true_params)
        self.lower = tuple(lower)
        self.upper = tuple(upper)
        for name, value in (("true_params", self.true_params), ("lower", self.lower), ("upper", self.upper)):
            if len(value) != 4:
                raise ValueError(f"cylindrical: {name} needs 4 values (m2, m3, s3z, I), got {len(value)}")
        if any(lo >= hi for lo, hi in zip(self.lower, self.upper, strict=True)):
            raise ValueError(f"cylindrical: empty search box lower={self.lower} upper={self.upper}")

    def bounds(self) -> tuple[Tensor, Tensor]:
        return torch.tensor(self.lower, dtype=torch.float64), torch.tensor(self.upper, dtype=torch.float64)

    def nominal_params(self) -> Tensor:
        return torch.tensor(self.true_params, dtype=torch.float64)

    def inverse_dynamics(self, params: Tensor, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
        """Eqs. (19)–(21): ``tau[..., N, 3]`` for ``params[..., 4]`` and states ``[N, 3]``."""
        self.check_inputs(params, q, qd, qdd)
        m2, m3, s3z, inertia = (params[..., i, None] for i in range(4))  # each [..., 1]
        d3 = q[:, 2]
        th_d, d3_d = qd[:, 0], qd[:, 2]
        th_dd, d2_dd, d3_dd = qdd[:, 0], qdd[:, 1], qdd[:, 2]
        r = s3z + d3  # [..., N]: radial position of link 3's centre of mass
        tau1 = (inertia + m3 * r.square()) * th_dd + 2.0 * m3 * r * d3_d * th_d
        tau2 = (m2 + m3) * (d2_dd + self.g)
        tau3 = m3 * d3_dd - m3 * r * th_d.square()
        return torch.stack((tau1, tau2.expand_as(tau1), tau3), dim=-1)

    def default_excitation(self) -> Excitation:
        """The paper's PSO-planned trajectory, eq. (39) (the ``paper`` excitation)."""
        return create("excitation", "paper")

    def motion_limits(self) -> MotionLimits:
        """Eq. (38): the box the paper's planned trajectory should observe."""
        return MotionLimits.from_ranges(self.joint_names, *zip(*PAPER_LIMITS, strict=True))

    def regressor(self, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
        """Eq. (23): ``Y[N, 3, 4]`` with ``tau = Y @ alpha``."""
        self.check_inputs(None, q, qd, qdd)
        d3 = q[:, 2]
        th_d, d3_d = qd[:, 0], qd[:, 2]
        th_dd, d2_dd, d3_dd = qdd[:, 0], qdd[:, 1], qdd[:, 2]
        zero = torch.zeros_like(d3)
        lift = d2_dd + self.g
        rows = (
            (th_dd, zero, 2 * d3 * d3_d * th_d + d3.square() * th_dd, 2 * d3_d * th_d + 2 * d3 * th_dd),
            (zero, lift, lift, zero),
            (zero, zero, d3_dd - d3 * th_d.square(), -th_d.square()),
        )
        return torch.stack([torch.stack(row, dim=-1) for row in rows], dim=-2)

    def base_params(self, params: Tensor) -> Tensor:
        """Eq. (24): ``alpha = (I + m3 s3z², m2, m3, m3 s3z)``."""
        m2, m3, s3z, inertia = params.unbind(-1)
        return torch.stack((inertia + m3 * s3z.square(), m2, m3, m3 * s3z), dim=-1)

    def params_from_base(self, alpha: Tensor) -> Tensor:
        """Inverse of eq. (24). Divides by ``m3``: ``alpha[..., 2] == 0`` gives non-finite ``s3z``, ``I``."""
        a1, m2, m3, m3_s3z = alpha.unbind(-1)
        s3z = m3_s3z / m3
        return torch.stack((m2, m3, s3z, a1 - m3_s3z * s3z), dim=-1)
