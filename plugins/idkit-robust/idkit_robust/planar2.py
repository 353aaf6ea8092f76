"""A 2-link revolute-revolute arm moving in the vertical plane, with gravity and viscous friction.

Geometry: joint 1 at the origin, ``q1`` measured from the horizontal ``x`` axis (positive towards
``+y``, up; gravity ``g`` along ``-y``), ``q2`` relative to link 1. Link 1 has length ``l1``;
each link's centre of mass lies on its own axis (symmetric links, as in Spong et al., *Robot
Modeling and Control*, sec. 7.4), at distance ``c_i`` from its joint.

Physical parameters ``(m1, c1, I1, m2, c2, I2, fv1, fv2)``: masses (kg), centre-of-mass
distances (m), inertias about the centre of mass (kg m²), viscous friction (N m s/rad).

Base parameters (the standard minimal set for this arm, Gautier & Khalil 1990; 6 of the 8
physical parameters are identifiable)::

    ZZ1R = I1 + m1 c1² + m2 l1²     (link 1 about joint 1, with link 2's mass at the elbow)
    MX1R = m1 c1 + m2 l1            (first moment of link 1 + link 2's mass at the elbow)
    ZZ2  = I2 + m2 c2²              (link 2 about joint 2)
    MX2  = m2 c2                    (first moment of link 2)
    fv1, fv2

Dynamics, with ``C2 = cos q2``, ``S2 = sin q2``, ``C1 = cos q1``, ``C12 = cos(q1 + q2)``::

    tau1 = ZZ1R qdd1 + ZZ2 (qdd1 + qdd2) + MX2 l1 (C2 (2 qdd1 + qdd2) - S2 (2 qd1 qd2 + qd2²))
           + g (MX1R C1 + MX2 C12) + fv1 qd1
    tau2 = ZZ2 (qdd1 + qdd2) + MX2 l1 (C2 qdd1 + S2 qd1²) + g MX2 C12 + fv2 qd2

which is linear in the base parameters: ``tau = Y(q, qd, qdd) @ alpha`` — this module computes
the torques that way, and its tests check them against pinocchio and an autograd Lagrangian.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from idkit.interfaces import Robot
from torch import Tensor

#: Simulation truth ``(m1, c1, I1, m2, c2, I2, fv1, fv2)``: a light arm, 0.5 m upper link.
NOMINAL_PARAMS = (2.0, 0.25, 0.05, 1.5, 0.2, 0.03, 0.4, 0.25)
LOWER = (0.1, 0.0, 0.001, 0.1, 0.0, 0.001, 0.0, 0.0)
UPPER = (5.0, 0.5, 0.2, 5.0, 0.5, 0.2, 1.0, 1.0)

#: Excitation terms per joint: offset and ``(amplitude rad, harmonic k, phase rad)`` of
#: ``amplitude sin(k w t + phase)``, ``w = 2 pi / 10 s``. Joint 1 swings about hanging down.
EXCITATION = (
    (-math.pi / 2, ((0.9, 1, 0.0), (0.35, 3, 0.5), (0.15, 5, 2.0))),
    (0.0, ((0.8, 2, 1.0), (0.4, 3, 2.5), (0.2, 7, 0.3))),
)


class Planar2Robot(Robot):
    """Closed-form dynamics, regressor and base parameters of a vertical 2R arm.

    Args:
        l1: length of link 1 (m): where joint 2 sits. A kinematic constant, not identified.
        g: gravitational acceleration (m/s²) along ``-y``.
        true_params: simulation truth ``(m1, c1, I1, m2, c2, I2, fv1, fv2)``; also the masses
            ``m1``, ``m2`` that ``params_from_base`` assumes (they are not identifiable).
        lower, upper: the search box of the physical parameters.
    """

    joint_names = ("q1", "q2")
    param_names = ("m1", "c1", "I1", "m2", "c2", "I2", "fv1", "fv2")
    base_param_names = ("I1+m1*c1^2+m2*l1^2", "m1*c1+m2*l1", "I2+m2*c2^2", "m2*c2", "fv1", "fv2")

    def __init__(
        self,
        l1: float = 0.5,
        g: float = 9.81,
        true_params: Sequence[float] = NOMINAL_PARAMS,
        lower: Sequence[float] = LOWER,
        upper: Sequence[float] = UPPER,
    ) -> None:
        self.l1 = l1
        self.g = g
        self.true_params = tuple(true_params)
        self.lower = tuple(lower)
        self.upper = tuple(upper)
        for name, value in (("true_params", self.true_params), ("lower", self.lower), ("upper", self.upper)):
            if len(value) != 8:
                raise ValueError(f"planar2: {name} needs 8 values {self.param_names}, got {len(value)}")
        if not l1 > 0:
            raise ValueError(f"planar2: l1 must be > 0, got {l1}")
        if any(lo >= hi for lo, hi in zip(self.lower, self.upper, strict=True)):
            raise ValueError(f"planar2: empty search box lower={self.lower} upper={self.upper}")
        if self.true_params[0] <= 0 or self.true_params[3] <= 0:
            raise ValueError(f"planar2: masses m1, m2 in true_params must be > 0, got {self.true_params}")

    def bounds(self) -> tuple[Tensor, Tensor]:
        return torch.tensor(self.lower, dtype=torch.float64), torch.tensor(self.upper, dtype=torch.float64)

    def nominal_params(self) -> Tensor:
        return torch.tensor(self.true_params, dtype=torch.float64)

    def inverse_dynamics(self, params: Tensor, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
        """Joint torques ``tau[..., N, 2]`` for ``params[..., 8]`` and states ``[N, 2]``."""
        self.check_inputs(params, q, qd, qdd)
        return torch.einsum("snb,...b->...sn", self.regressor(q, qd, qdd), self.base_params(params))

    def regressor(self, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
        """``Y[N, 2, 6]`` with ``tau = Y @ alpha``; columns in ``base_param_names`` order."""
        self.check_inputs(None, q, qd, qdd)
        q1, q2 = q.unbind(-1)
        qd1, qd2 = qd.unbind(-1)
        qdd1, qdd2 = qdd.unbind(-1)
        c1, c2, s2, c12 = torch.cos(q1), torch.cos(q2), torch.sin(q2), torch.cos(q1 + q2)
        zero = torch.zeros_like(q1)
        l1, g = self.l1, self.g
        rows = (
            (
                qdd1,
                g * c1,
                qdd1 + qdd2,
                l1 * (c2 * (2 * qdd1 + qdd2) - s2 * (2 * qd1 * qd2 + qd2.square())) + g * c12,
                qd1,
                zero,
            ),
            (zero, zero, qdd1 + qdd2, l1 * (c2 * qdd1 + s2 * qd1.square()) + g * c12, zero, qd2),
        )
        return torch.stack([torch.stack(row, dim=-1) for row in rows], dim=-2)

    def base_params(self, params: Tensor) -> Tensor:
        """``alpha[..., 6] = (ZZ1R, MX1R, ZZ2, MX2, fv1, fv2)`` of ``params[..., 8]``."""
        if params.shape[-1:] != (8,):
            raise ValueError(f"planar2: params must be [..., 8], got shape {tuple(params.shape)}")
        m1, c1, i1, m2, c2, i2, fv1, fv2 = params.unbind(-1)
        l1 = self.l1
        return torch.stack(
            (i1 + m1 * c1.square() + m2 * l1**2, m1 * c1 + m2 * l1, i2 + m2 * c2.square(), m2 * c2, fv1, fv2),
            dim=-1,
        )

    def params_from_base(self, alpha: Tensor) -> Tensor:
        """Physical ``params[..., 8]`` with the given base parameters and the masses of ``true_params``.

        ``m1`` and ``m2`` cannot be identified (only the six combinations above can), so they are
        taken from ``true_params``; ``c1, I1, c2, I2`` then follow. With noisy ``alpha`` the
        inertias may come out negative — the base parameters are what the data determine.
        """
        if alpha.shape[-1:] != (6,):
            raise ValueError(f"planar2: alpha must be [..., 6], got shape {tuple(alpha.shape)}")
        zz1r, mx1r, zz2, mx2, fv1, fv2 = alpha.unbind(-1)
        m1 = torch.full_like(zz1r, self.true_params[0])
        m2 = torch.full_like(zz1r, self.true_params[3])
        l1 = self.l1
        c2 = mx2 / m2
        c1 = (mx1r - m2 * l1) / m1
        i2 = zz2 - m2 * c2.square()
        i1 = zz1r - m1 * c1.square() - m2 * l1**2
        return torch.stack((m1, c1, i1, m2, c2, i2, fv1, fv2), dim=-1)

    def excitation(self, t: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """A periodic (10 s) sum of sines per joint, ``(q, qd, qdd)`` each ``[N, 2]``, exact derivatives.

        Joint 1 swings ±1.4 rad about hanging straight down, joint 2 ±1.4 rad about straight; the
        harmonics excite inertia, gravity and friction columns alike, so 10 samples over 10 s
        already give a full-rank regressor.
        """
        w = 2 * math.pi / 10.0
        out = []
        for offset, terms in EXCITATION:
            q, qd, qdd = torch.full_like(t, offset), torch.zeros_like(t), torch.zeros_like(t)
            for amplitude, k, phase in terms:
                angle = k * w * t + phase
                q = q + amplitude * torch.sin(angle)
                qd = qd + amplitude * k * w * torch.cos(angle)
                qdd = qdd - amplitude * (k * w) ** 2 * torch.sin(angle)
            out.append((q, qd, qdd))
        q, qd, qdd = (torch.stack(x, dim=-1) for x in zip(*out, strict=True))
        return q, qd, qdd
