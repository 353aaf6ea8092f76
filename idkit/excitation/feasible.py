"""Make any candidate motion respect the joint limits, by scaling its amplitude per joint.

For a family that is an offset plus a motion linear in the other coefficients of each joint
(``Excitation.coefficient_joints``), multiplying joint ``j``'s motion coefficients by ``s_j``
turns ``q_j`` into ``offset_j + s_j (q_j - offset_j)`` and ``qd_j``, ``qdd_j`` into ``s_j qd_j``,
``s_j qdd_j``. ``fit_into_limits`` chooses the largest ``s_j <= 1`` that keeps every sample of a
time grid inside the box: candidates already inside are left unchanged, the others are shrunk
until they touch the tightest limit. Every candidate an optimiser proposes is thereby feasible by
construction (on that grid), the map is continuous and almost everywhere differentiable, and the
optimiser needs no penalty weight.

Between grid points a smooth signal ``x`` can exceed its largest sample by at most
``h² / 8 · max |x''|`` (``h`` the grid step), so a fine grid makes the constraint hold in
continuous time up to that bound.

Constraints that are not a box on ``q, qd, qdd`` (torques within effort limits, no self-collision)
are not linear in the scale; :func:`largest_feasible_scale` finds, by bisection, the largest common
factor of all joints' motions that satisfies any such test (``s = 0`` is the rest pose at the
offsets). Shrinking a motion that is inside the box keeps it inside, so the two compose.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from idkit.interfaces import Excitation
from idkit.limits import MotionLimits

#: ``s`` is multiplied by this so that rounding cannot put a touching sample beyond the limit.
ROUNDING_SAFETY = 1.0 - 1e-12


def _ratio_where(binds: Tensor, limit: Tensor, extreme: Tensor) -> Tensor:
    """``limit / extreme`` where ``binds``, else ``inf``; no infinity ever enters the division
    (``inf / x`` would give NaN gradients through ``torch.where``)."""
    ratio = torch.where(binds, limit, 1.0) / torch.where(binds, extreme, 1.0)
    return torch.where(binds, ratio, torch.full_like(ratio, float("inf")))


def _largest_scale(motion: Tensor, lower: Tensor, upper: Tensor) -> Tensor:
    """Largest ``s >= 0`` with ``lower <= s · motion <= upper`` at every sample: ``[..., n]``.

    Args:
        motion: ``[..., T, n]`` deviations from the offset (or rates).
        lower, upper: ``[..., n]`` with ``lower <= 0 <= upper``; infinite ones never bind.
    """
    high, low = motion.amax(-2), motion.amin(-2)
    by_upper = _ratio_where((high > 0) & upper.isfinite(), upper, high)
    by_lower = _ratio_where((low < 0) & lower.isfinite(), lower, low)
    return torch.minimum(by_upper, by_lower)


def offset_indices(excitation: Excitation) -> Tensor:
    """``[n]``: the index of joint ``j``'s offset among the coefficients (the pose at zero motion)."""
    joints, is_offset = excitation.coefficient_joints()
    n = excitation.n_joints
    return joints.masked_fill(~is_offset, n).argsort(stable=True)[:n]


def fit_into_limits(
    excitation: Excitation, coefficients: Tensor, limits: MotionLimits, grid: Tensor
) -> Tensor:
    """Coefficients ``[..., C]`` scaled per joint so the motion stays within ``limits`` on ``grid[G]``.

    Offsets are never changed: one outside the joint's position range cannot be fixed by scaling
    (``coefficient_box`` keeps an optimiser's offsets inside).
    """
    offset = coefficients[..., offset_indices(excitation).to(coefficients.device)]  # [..., n]
    q, qd, qdd = excitation.evaluate(coefficients, grid.to(coefficients))
    lower, upper = limits.lower.to(coefficients), limits.upper.to(coefficients)
    scale = torch.stack(
        (
            _largest_scale(q - offset[..., None, :], lower[0] - offset, upper[0] - offset),
            _largest_scale(qd, lower[1].expand_as(offset), upper[1].expand_as(offset)),
            _largest_scale(qdd, lower[2].expand_as(offset), upper[2].expand_as(offset)),
        )
    ).amin(0)
    return scale_motion(excitation, coefficients, (scale * ROUNDING_SAFETY).clamp(0.0, 1.0))


def scale_motion(excitation: Excitation, coefficients: Tensor, scale: Tensor) -> Tensor:
    """Coefficients ``[..., C]`` with joint ``j``'s motion about its offset scaled by ``scale[..., n]``."""
    joints, is_offset = (x.to(coefficients.device) for x in excitation.coefficient_joints())
    per_coefficient = torch.where(is_offset, torch.ones_like(scale[..., joints]), scale[..., joints])
    return coefficients * per_coefficient


def largest_feasible_scale(
    excitation: Excitation, coefficients: Tensor, feasible: Callable[[Tensor], bool], steps: int = 20
) -> float:
    """Largest common scale ``s`` in ``[0, 1]`` of all joints' motions with ``feasible(scaled)`` true.

    Bisection over ``s`` for ``steps`` halvings (``s`` to ``2^-steps``), keeping the invariant that
    the lower end passed the test, so the returned scale was tested feasible; the test need not be
    monotone in ``s``. ``coefficients[C]``; ``feasible`` takes scaled coefficients ``[C]``.

    Raises:
        ValueError: even ``s = 0`` (the rest pose at the offsets) fails the test.
    """
    ones = torch.ones(excitation.n_joints, dtype=coefficients.dtype, device=coefficients.device)
    if feasible(coefficients):
        return 1.0
    if not feasible(scale_motion(excitation, coefficients, 0.0 * ones)):
        raise ValueError("no amplitude of this motion is feasible: its rest pose (the offsets) already fails")
    low, high = 0.0, 1.0
    for _ in range(steps):
        middle = (low + high) / 2
        if feasible(scale_motion(excitation, coefficients, middle * ones)):
            low = middle
        else:
            high = middle
    return low
