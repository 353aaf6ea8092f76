"""Parameters a bounded search left at the edge of its box: there the box, not the data, set them.

``pso``, ``adam`` and ``varpro`` search inside boxes (the robot's ``bounds()`` or ``base_bounds()``, the
sigmoid shapes' ``steepness_range`` and ``max_shift``). A value that ends at a bound is the best the box
allowed, not the data's minimum: the data may want it further out (the box is too small, or the model
lacks a term the parameter stands in for), and its uncertainty says nothing. Each estimate lists them
in ``details["at_bound"]`` (``{name: "lower" | "upper"}``) and a single fit says so in one
``warning:`` line.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

from torch import Tensor

#: A value within this fraction of its box's width from a bound ended at it.
AT_BOUND = 1e-3
#: How many parameters the warning names before "and k more".
SHOWN = 6


class BoundWarning(UserWarning):
    """A bounded search ended with parameters at the edge of their box."""


def at_bounds(
    names: Sequence[str], values: Tensor, lower: Tensor, upper: Tensor, tolerance: float = AT_BOUND
) -> dict[str, str]:
    """``{name: "lower" | "upper"}`` of the ``values[D]`` within ``tolerance`` × the box width of
    ``lower[D]`` or ``upper[D]``, in the order of ``names``."""
    low, high = near_bounds(values, lower, upper, tolerance)
    return sides(names, low.tolist(), high.tolist())


def near_bounds(
    values: Tensor, lower: Tensor, upper: Tensor, tolerance: float = AT_BOUND
) -> tuple[Tensor, Tensor]:
    """Masks ``[..., D]`` of the ``values[..., D]`` at the lower and at the upper bound (``at_bounds``)."""
    margin = tolerance * (upper - lower)
    return values <= lower + margin, values >= upper - margin


def sides(names: Sequence[str], low: Sequence[bool], high: Sequence[bool]) -> dict[str, str]:
    """``{name: "lower" | "upper"}`` of the parameters flagged in ``low`` or ``high``."""
    flagged = zip(names, low, high, strict=True)
    return {name: "lower" if lo else "upper" for name, lo, hi in flagged if lo or hi}


def warn_at_bounds(
    label: str, ended: dict[str, str], names: Sequence[str], lower: Tensor, upper: Tensor, widen: str
) -> None:
    """One :class:`BoundWarning` line naming the parameters of ``ended`` (``at_bounds``) and the bound
    each sits at; ``widen`` says what sets the box. Nothing when ``ended`` is empty."""
    if not ended:
        return
    index = {name: k for k, name in enumerate(names)}
    shown = [
        f"{name} at its {side} bound {float((lower if side == 'lower' else upper)[index[name]]):.4g}"
        for name, side in list(ended.items())[:SHOWN]
    ]
    more = f" and {len(ended) - SHOWN} more" if len(ended) > SHOWN else ""
    warnings.warn(
        f"{label}: {len(ended)} parameter(s) ended at a bound of the search box, where the box, not the "
        f"data, set them: {', '.join(shown)}{more} (widen {widen}, or check the model and the data)",
        BoundWarning,
        stacklevel=3,
    )
