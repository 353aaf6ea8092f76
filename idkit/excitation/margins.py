"""Safety margins: how far inside each limit a motion must stay, as a share of the limit's half-range.

A motion that touches a limit on paper leaves it on the robot: the controller tracks the reference
with an error of a few per cent of its velocity in transients, the nominal model's torques (CAD
inertials, no friction) differ from the real ones by more than that, and a position limit in a
URDF is often the hard stop itself. So the optimiser keeps, and the check
(:mod:`idkit.excitation.check`) enforces, a margin ``m`` on every limit:

* a box ``[lower, upper]`` (position, velocity, acceleration) becomes
  ``[lower + m h, upper - m h]`` with ``h = (upper - lower) / 2`` its half-range, so a symmetric
  velocity limit ``±v`` becomes ``±(1 - m) v``;
* an effort limit ``±e`` becomes ``±(1 - m) e``.

A sample keeps the margin when its distance to the nearest limit is at least ``m h`` — the
``share`` the check prints is that distance over ``h``, so "margin met" means ``share >= m``. A
limit with an infinite side has no half-range and gets no margin (none is needed for an unlimited
continuous joint; a one-sided limit is left as it is and said so by a ``nan`` share).

``DEFAULT_MARGIN`` (5 %) is the tracking error of a well-tuned joint controller in transients with
room to spare, and costs the excitation little (docs/excitation.md measures it on the tour's arm).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

from idkit.limits import MOTION_VARIABLES, MotionLimits

#: The margin of every limit unless one is given (``excitation.margin``): a share of its half-range.
DEFAULT_MARGIN = 0.05

#: The quantities a margin applies to.
QUANTITIES = (*MOTION_VARIABLES, "effort")

#: Round-off allowance of the check: a sample whose share falls short of the margin by less than this
#: (relative to the half-range) still keeps it. The optimiser aims this far inside the margin.
SHARE_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Margins:
    """One margin per quantity, each a share in ``[0, 1)`` of the limit's half-range (module doc)."""

    position: float = DEFAULT_MARGIN
    velocity: float = DEFAULT_MARGIN
    acceleration: float = DEFAULT_MARGIN
    effort: float = DEFAULT_MARGIN

    @classmethod
    def of(cls, spec: float | Mapping[str, float] | Margins | None, setting: str = "margin") -> Margins:
        """Margins from one share for every limit, or a mapping ``{quantity: share}`` (the others keep
        the default); ``None`` is the default.

        Raises:
            ValueError: a share that is not a number in ``[0, 1)``, or an unknown quantity; the
                message names ``setting``.
        """
        if spec is None:
            return cls()
        if isinstance(spec, Margins):
            return spec
        if isinstance(spec, Mapping):
            unknown = sorted(set(spec) - set(QUANTITIES))
            if unknown:
                raise ValueError(
                    f"{setting}.{unknown[0]} is not a limit with a margin; they are {', '.join(QUANTITIES)}"
                )
            values = {key: _share(f"{setting}.{key}", value) for key, value in spec.items()}
            return cls(**values)
        share = _share(setting, spec)
        return cls(share, share, share, share)

    def share(self, quantity: str) -> float:
        """The margin of ``quantity`` (``position``, ``velocity``, ``acceleration`` or ``effort``)."""
        return float(getattr(self, quantity))

    def as_dict(self) -> dict[str, float]:
        return {quantity: self.share(quantity) for quantity in QUANTITIES}

    def describe(self) -> str:
        """``5 % of each limit's half-range`` or ``position 5 %, velocity 10 %, …``."""
        shares = self.as_dict()
        if len(set(shares.values())) == 1:
            return f"{100 * self.position:.3g} % of each limit's half-range"
        return ", ".join(f"{q} {100 * v:.3g} %" for q, v in shares.items()) + " of each half-range"

    def narrowed(self, limits: MotionLimits, extra: float = SHARE_TOLERANCE) -> MotionLimits:
        """``limits`` with each finite box narrowed by its margin (plus ``extra``) at both ends."""
        lower, upper = limits.lower.clone(), limits.upper.clone()
        for row, quantity in enumerate(MOTION_VARIABLES):
            half = (upper[row] - lower[row]) / 2
            finite = torch.isfinite(half)
            inset = torch.where(finite, (self.share(quantity) + extra) * half, torch.zeros_like(half))
            lower[row], upper[row] = lower[row] + inset, upper[row] - inset
        return MotionLimits(limits.joint_names, lower, upper)

    def narrowed_effort(self, effort: Tensor | None, extra: float = SHARE_TOLERANCE) -> Tensor | None:
        """Effort limits ``[n]`` less their margin (``None`` stays ``None``)."""
        return None if effort is None else effort * (1.0 - self.effort - extra)


def _share(setting: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < 1:
        raise ValueError(
            f"{setting} must be a share of each limit's half-range in [0, 1) (0.05 keeps 5 % away from "
            f"every limit), got {value!r}"
        )
    return float(value)
