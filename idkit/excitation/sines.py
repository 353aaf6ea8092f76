"""What the sine-based excitation families share: coefficient layout checks and search boxes.

A single sinusoid ``A sin(w t + phi)`` stays within a joint's limits on its own when
``A <= (upper - lower) / 2`` (position), ``A w <= max |velocity|`` and ``A w² <= max |acceleration|``;
those caps size the optimiser's search box (the optimiser then scales every candidate into the
limits, so the box only has to be of the right order).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from idkit.limits import MotionLimits

#: Offset range of a joint without position limits (a continuous joint turns freely).
FREE_OFFSET = (-math.pi, math.pi)


def as_matrix(
    value: Sequence[float] | Sequence[Sequence[float]], shape: tuple[int | None, ...], where: str
) -> Tensor:
    """``value`` as a finite float64 tensor of ``shape`` (``None``: any size); errors name ``where``."""
    try:
        tensor = torch.as_tensor(value, dtype=torch.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: expected numbers of shape {list(shape)}: {exc}") from None
    expected = [size if size is not None else "any" for size in shape]
    if tensor.ndim != len(shape) or any(
        s is not None and s != got for s, got in zip(shape, tensor.shape, strict=True)
    ):
        raise ValueError(f"{where}: expected shape {expected}, got {list(tensor.shape)}")
    if not torch.isfinite(tensor).all():
        raise ValueError(f"{where}: every value must be finite")
    return tensor


def offset_box(limits: MotionLimits) -> tuple[Tensor, Tensor]:
    """``(lower[n], upper[n])`` of the joints' offsets: their position limits (``FREE_OFFSET`` if none)."""
    lower, upper = limits.lower[0], limits.upper[0]
    return torch.where(lower.isinf(), FREE_OFFSET[0], lower), torch.where(
        upper.isinf(), FREE_OFFSET[1], upper
    )


def amplitude_caps(limits: MotionLimits, omega: Tensor) -> Tensor:
    """Largest amplitude ``[n, K]`` of one sinusoid of angular frequency ``omega[n, K]`` within ``limits``.

    Raises:
        ValueError: a joint has no finite limit at all (its amplitude would be unbounded).
    """
    half_range = (limits.upper - limits.lower) / 2  # [3, n]
    reach = torch.minimum(limits.upper.abs(), limits.lower.abs())  # symmetric part of a rate limit
    caps = torch.stack(
        (
            half_range[0, :, None].expand_as(omega),
            reach[1, :, None] / omega,
            reach[2, :, None] / omega.square(),
        )
    ).amin(0)
    unbounded = caps.isinf().any(-1).nonzero().flatten().tolist()
    if unbounded:
        names = ", ".join(limits.joint_names[j] for j in unbounded)
        raise ValueError(
            f"motion limits: joint(s) {names} have no finite position, velocity or acceleration limit; "
            "give one (e.g. MotionLimits.replace('acceleration', ...))"
        )
    return caps
