"""Robust costs of the torque error matrix ``E[..., n, N]``: Huber and trimmed mean of squares.

Both act on the absolute error ``E = measured - predicted`` or, with ``relative=True``, on the
relative error ``E / T`` of eq. (27), using idkit's near-zero policy for the measured torques
``T`` (``idkit.relative``: entries below ``floor`` x their joint's RMS are floored, with a
warning). Both average over the ``n x N`` entries, so their scale does not grow with ``N``.

Both are idkit's entrywise reductions (``idkit.costs.reductions``): each cost calls the one
function and declares it (``structure()``), so idkit's estimators evaluate it fused with other
costs, on the same tensors, instead of calling the cost once per cost and trial.
"""

from __future__ import annotations

from idkit.costs.reductions import PARAMETRIC, huber_mean, trimmed_mean_square
from idkit.interfaces import Cost, NormStructure
from idkit.relative import DEFAULT_FLOOR, relative_denominator, relative_error
from torch import Tensor


def _errors(name: str, error: Tensor, measured: Tensor, relative: bool, floor: float) -> Tensor:
    """The (relative) error matrix ``[..., n, N]``, after checking ``measured`` is ``[n, N]`` (or
    several trials' ``[T, 1, ..., n, N]`` broadcasting against ``error``: ``Cost.stacked_measured``)."""
    if error.ndim < 2 or measured.shape[-2:] != error.shape[-2:] or measured.ndim > error.ndim:
        raise ValueError(
            f"{name}: error must be [..., n, N] and measured [n, N] with the same n, N; got error "
            f"{tuple(error.shape)} and measured {tuple(measured.shape)}"
        )
    if not relative:
        return error
    if measured.ndim == 2:
        return relative_error(error, measured, floor)
    return error / relative_denominator(measured, floor)


class HuberCost(Cost):
    """Mean Huber loss of the error entries: quadratic within ``±delta``, linear beyond.

    ``rho(e) = e²/2`` for ``|e| <= delta``, ``delta (|e| - delta/2)`` otherwise (Huber 1964). Large
    errors (outliers) then pull on the estimate with a bounded force, unlike squares.

    Args:
        delta: the threshold between quadratic and linear, in the error's units: N m (or N) for
            the absolute error, a fraction for the relative error (0.1 = 10 %).
        relative: use the relative error ``E / T`` (eq. 27) instead of ``E``.
        floor: near-zero policy of the relative error (``idkit.relative``).
    """

    stacked_measured = True

    def __init__(self, delta: float = 1.0, relative: bool = False, floor: float = DEFAULT_FLOOR) -> None:
        PARAMETRIC["huber"].check("huber", delta)
        self.delta = delta
        self.relative = relative  # type: ignore[misc]  # an option here: shadows Cost's class default
        self.floor = floor

    def __call__(self, error: Tensor, measured: Tensor) -> Tensor:
        """``value[...]`` for ``error[..., n, N]`` and ``measured[n, N]``."""
        return huber_mean(_errors("huber", error, measured, self.relative, self.floor), self.delta)

    def structure(self) -> NormStructure | None:
        """The mean Huber loss of the (relative) error; ``None`` for a subclass with its own ``__call__``."""
        if type(self).__call__ is not HuberCost.__call__:
            return None
        return NormStructure(("huber",), bool(self.relative), float(self.floor), (float(self.delta),))

    def __repr__(self) -> str:
        return f"HuberCost(delta={self.delta}, relative={self.relative}, floor={self.floor})"


class TrimmedCost(Cost):
    """Trimmed mean of the squared error entries: the largest ``trim`` fraction is left out.

    The criterion of least trimmed squares (Rousseeuw 1984): of the ``m = n N`` squared entries
    the ``floor(trim m)`` largest are dropped and the rest averaged, so up to that many
    outliers have no influence at all. ``trim=0`` is the mean squared error.

    Args:
        trim: fraction of entries to drop, ``0 <= trim < 1``.
        relative: use the relative error ``E / T`` (eq. 27) instead of ``E``.
        floor: near-zero policy of the relative error (``idkit.relative``).
    """

    stacked_measured = True

    def __init__(self, trim: float = 0.1, relative: bool = False, floor: float = DEFAULT_FLOOR) -> None:
        PARAMETRIC["trimmed"].check("trimmed", trim)
        self.trim = trim
        self.relative = relative  # type: ignore[misc]  # an option here: shadows Cost's class default
        self.floor = floor

    def __call__(self, error: Tensor, measured: Tensor) -> Tensor:
        """``value[...]`` for ``error[..., n, N]`` and ``measured[n, N]``."""
        return trimmed_mean_square(_errors("trimmed", error, measured, self.relative, self.floor), self.trim)

    def structure(self) -> NormStructure | None:
        """The trimmed mean of squares of the (relative) error; ``None`` for a subclass with its own
        ``__call__``."""
        if type(self).__call__ is not TrimmedCost.__call__:
            return None
        return NormStructure(("trimmed",), bool(self.relative), float(self.floor), (float(self.trim),))

    def __repr__(self) -> str:
        return f"TrimmedCost(trim={self.trim}, relative={self.relative}, floor={self.floor})"
