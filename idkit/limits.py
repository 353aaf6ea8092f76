"""Joint motion limits: the box an excitation trajectory must stay in.

A robot declares them (``Robot.motion_limits``: the cylindrical robot's eq. (38), a URDF's
``<limit>`` tags) and the excitation optimiser treats them as hard constraints. Rows are the
three motion variables ``MOTION_VARIABLES`` = position, velocity, acceleration; ``±inf`` marks a
variable without a limit (a continuous joint's position, a URDF's accelerations).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

MOTION_VARIABLES = ("position", "velocity", "acceleration")


@dataclass(frozen=True)
class MotionLimits:
    """Box ``lower[3, n] <= (q, qd, qdd) <= upper[3, n]`` (rows in ``MOTION_VARIABLES`` order).

    Attributes:
        joint_names: the ``n`` joints, in the robot's order.
        lower, upper: float64 CPU tensors ``[3, n]``; ``-inf`` / ``inf`` where unlimited.
    """

    joint_names: tuple[str, ...]
    lower: Tensor
    upper: Tensor

    def __post_init__(self) -> None:
        shape = (len(MOTION_VARIABLES), len(self.joint_names))
        for name in ("lower", "upper"):
            value = getattr(self, name)
            if not isinstance(value, Tensor) or value.shape != shape or value.isnan().any():
                got = tuple(value.shape) if isinstance(value, Tensor) else type(value).__name__
                raise ValueError(
                    f"motion limits: {name} must be a [3, {shape[1]}] tensor without NaN, got {got}"
                )
        empty = (self.lower >= self.upper).nonzero().tolist()
        if empty:
            where = ", ".join(f"{self.joint_names[j]} {MOTION_VARIABLES[v]}" for v, j in empty)
            raise ValueError(f"motion limits: lower >= upper for {where}")

    @classmethod
    def from_ranges(
        cls,
        joint_names: Sequence[str],
        position: Sequence[tuple[float, float]],
        velocity: Sequence[tuple[float, float]],
        acceleration: Sequence[tuple[float, float]],
    ) -> MotionLimits:
        """Build from one ``(lower, upper)`` pair per joint for each variable."""
        rows = []
        for name, ranges in zip(MOTION_VARIABLES, (position, velocity, acceleration), strict=True):
            if len(ranges) != len(joint_names):
                raise ValueError(
                    f"motion limits: {name} needs one (lower, upper) per joint ({len(joint_names)}), "
                    f"got {len(ranges)}"
                )
            rows.append(torch.tensor([list(r) for r in ranges], dtype=torch.float64))  # [n, 2]
        stacked = torch.stack(rows)  # [3, n, 2]
        return cls(tuple(joint_names), stacked[..., 0], stacked[..., 1])

    def replace(
        self, variable: str, lower: float | Sequence[float] | Tensor, upper: float | Sequence[float] | Tensor
    ) -> MotionLimits:
        """A copy with one variable's limits set (a number applies to every joint)."""
        row = self._row(variable)
        new_lower, new_upper = self.lower.clone(), self.upper.clone()
        new_lower[row] = torch.as_tensor(lower, dtype=torch.float64)
        new_upper[row] = torch.as_tensor(upper, dtype=torch.float64)
        return MotionLimits(self.joint_names, new_lower, new_upper)

    def _row(self, variable: str) -> int:
        if variable not in MOTION_VARIABLES:
            raise ValueError(
                f"motion limits: unknown variable {variable!r}; use one of {', '.join(MOTION_VARIABLES)}"
            )
        return MOTION_VARIABLES.index(variable)

    def excess(self, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
        """How far each variable of each joint leaves the box at worst: ``[..., 3, n]``, 0 when inside.

        Args:
            q, qd, qdd: ``[..., T, n]`` on a (dense) time grid.
        """
        motion = torch.stack((q, qd, qdd), dim=-3)  # [..., 3, T, n]
        lower, upper = self.lower.to(motion), self.upper.to(motion)
        below = (lower[:, None] - motion).amax(-2)
        above = (motion - upper[:, None]).amax(-2)
        return torch.maximum(below, above).clamp_min(0.0)

    def as_dict(self) -> dict[str, dict[str, list[float]]]:
        """``{joint: {"position": [lo, hi], ...}}`` (``±inf`` where unlimited)."""
        return {
            joint: {
                variable: [float(self.lower[v, j]), float(self.upper[v, j])]
                for v, variable in enumerate(MOTION_VARIABLES)
            }
            for j, joint in enumerate(self.joint_names)
        }
