"""Does an excitation trajectory observe a box such as the paper's eq. (38)? A report, never a clip.

``check_bounds`` lists every excursion of a trajectory outside a box (variable, side, worst value,
time intervals, share of the time); ``paper_bounds_report`` runs it on eq. (39) over a dense grid:
eq. (39) does leave eq. (38) — ``d2`` starts at −0.014 m, for example. Command line::

    python -m idkit.verify bounds [--points 10001]
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import torch
from torch import Tensor

from idkit.excitation.paper import PaperExcitation
from idkit.robots.cylindrical import PAPER_LIMITS, CylindricalRobot

PAPER_JOINTS = CylindricalRobot.joint_names

#: Eq. (38) as ``name -> (lower, upper)`` (``theta1``, ``theta1_d``, ``theta1_dd``, ...), from the
#: robot's own table so the two never disagree.
PAPER_BOUNDS: dict[str, tuple[float, float]] = {
    f"{joint}{suffix}": box
    for joint, boxes in zip(PAPER_JOINTS, PAPER_LIMITS, strict=True)
    for suffix, box in zip(("", "_d", "_dd"), boxes, strict=True)
}


@dataclass(frozen=True)
class BoundViolation:
    """One variable leaving one side of its box.

    Attributes:
        variable: e.g. ``"d2"`` or ``"theta1_dd"``.
        side: ``"lower"`` or ``"upper"``.
        limit: the bound that is crossed.
        worst: the most extreme value beyond it, reached at ``t_worst``.
        excess: ``|worst - limit|``, how far it goes beyond the bound.
        intervals: ``(t_first, t_last)`` of each run of consecutive grid times outside the bound.
        fraction: share of the grid times outside the bound.
    """

    variable: str
    side: str
    limit: float
    worst: float
    excess: float
    t_worst: float
    intervals: tuple[tuple[float, float], ...]
    fraction: float

    def __str__(self) -> str:
        spans = ", ".join(f"[{a:.3f}, {b:.3f}]" for a, b in self.intervals)
        sign = "<" if self.side == "lower" else ">"
        return (
            f"{self.variable} {sign} {self.limit:g} (worst {self.worst:.4g} at t={self.t_worst:.3f} s, "
            f"beyond by {self.excess:.3g}; {100 * self.fraction:.1f} % of the time, t in {spans} s)"
        )


def _runs(t: Tensor, outside: Tensor) -> tuple[tuple[float, float], ...]:
    """``(t_first, t_last)`` of each run of ``True`` in ``outside[N]``."""
    flags = torch.cat((outside.new_zeros(1), outside, outside.new_zeros(1))).to(torch.int8)
    edges = flags.diff()  # +1 where a run starts, -1 one past where it ends
    starts = (edges == 1).nonzero().flatten().tolist()
    ends = ((edges == -1).nonzero().flatten() - 1).tolist()
    return tuple((float(t[a]), float(t[b])) for a, b in zip(starts, ends, strict=True))


def check_bounds(
    t: Tensor,
    q: Tensor,
    qd: Tensor,
    qdd: Tensor,
    bounds: Mapping[str, tuple[float, float]] = PAPER_BOUNDS,
    joint_names: tuple[str, ...] = PAPER_JOINTS,
) -> list[BoundViolation]:
    """Every excursion of a trajectory outside a box such as eq. (38), none hidden or clipped.

    Args:
        t: times ``[N]``, ascending (use a dense grid, e.g. ``torch.linspace(0, 10, 10001)``:
            the report resolves crossing times to the grid spacing).
        q, qd, qdd: ``[N, n]``.
        bounds: ``"<joint>"``, ``"<joint>_d"``, ``"<joint>_dd"`` -> ``(lower, upper)``; variables
            without an entry are not checked.
        joint_names: the ``n`` joint names used to build those keys.

    Returns:
        One ``BoundViolation`` per (variable, side) that is crossed, in the order of ``bounds``;
        an empty list when the trajectory stays inside.
    """
    series = {}
    for j, joint in enumerate(joint_names):
        for suffix, x in (("", q), ("_d", qd), ("_dd", qdd)):
            series[joint + suffix] = x[:, j]
    unknown = set(bounds) - set(series)
    if unknown:
        raise ValueError(f"check_bounds: no variable named {sorted(unknown)}; known: {sorted(series)}")
    t = t.detach().cpu().double()
    found = []
    for name, (lower, upper) in bounds.items():
        x = series[name].detach().cpu().double()
        for side, limit, outside in (("lower", lower, x < lower), ("upper", upper, x > upper)):
            if not outside.any():
                continue
            i = int(x.argmin() if side == "lower" else x.argmax())
            found.append(
                BoundViolation(
                    variable=name,
                    side=side,
                    limit=float(limit),
                    worst=float(x[i]),
                    excess=abs(float(x[i]) - limit),
                    t_worst=float(t[i]),
                    intervals=_runs(t, outside),
                    fraction=float(outside.double().mean()),
                )
            )
    return found


def format_violations(violations: list[BoundViolation]) -> str:
    """Readable report, one line per violation (``"within bounds"`` when there is none)."""
    if not violations:
        return "within bounds"
    return "\n".join(str(v) for v in violations)


def paper_bounds_report(n_points: int = 10001, t_end: float = 10.0) -> list[BoundViolation]:
    """Where eq. (39) leaves eq. (38) on a dense grid of ``n_points`` over ``0 <= t <= t_end``."""
    t = torch.linspace(0.0, t_end, n_points, dtype=torch.float64)
    return check_bounds(t, *PaperExcitation()(t))
