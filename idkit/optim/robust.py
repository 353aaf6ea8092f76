"""Robust losses of residuals, and a scale that sets itself.

:mod:`idkit.optim.levenberg` minimises ``Σ ρ(r)`` of a residual vector ``r``; the losses here bound the
pull of a large residual — a glitched sample — on the fit:

- ``"huber"``: ``ρ(r) = r²/2`` within ``±k``, ``k(|r| − k/2)`` beyond (Huber 1964);
- ``"cauchy"``: ``ρ(r) = (k²/2) log(1 + (r/k)²)``, whose pull vanishes for large ``r``;
- ``"linear"``: least squares.

A Gauss–Newton Hessian weighs each residual by the IRLS weight ``ψ(r)/r`` (:func:`weights`: positive, a
majorizer of the loss — reliable far from the solution, but only linearly convergent) or by ``ρ''(r)``
(:func:`psi_slope`: Huber's exact second derivative, zero for an outlier — fast near the solution).

The residuals given are already divided by a scale ``σ`` (per channel) and ``k = K · σ`` in those units:
:func:`mad_scale` is that scale, 1.4826 × the median absolute residual — the standard deviation of
Gaussian noise, unmoved by up to half the samples being glitches — so that no loss scale is set by
hand. ``K`` is Huber's 1.345 and Cauchy's 2.385 (95 % efficiency under Gaussian noise).
"""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np

Loss = Literal["huber", "cauchy", "linear"]
LOSSES: tuple[str, ...] = get_args(Loss)
#: Thresholds in standard deviations: 95 % asymptotic efficiency under Gaussian noise.
TUNING = {"huber": 1.345, "cauchy": 2.385, "linear": np.inf}
#: 1 / Φ⁻¹(3/4): a median absolute deviation in standard deviations of Gaussian noise.
MAD_TO_SIGMA = 1.4826


def mad_scale(residual: np.ndarray, axis: int = -1) -> np.ndarray:
    """1.4826 × the median of ``|residual|`` along ``axis`` (residuals about zero: no centring, so an
    offset counts as error)."""
    return MAD_TO_SIGMA * np.median(np.abs(residual), axis=axis)


def rho(loss: Loss, r: np.ndarray, k: float) -> np.ndarray:
    """The loss of each residual."""
    if loss == "linear":
        return 0.5 * r * r
    a = np.abs(r)
    if loss == "huber":
        inner = np.minimum(a, k)
        return inner * (a - 0.5 * inner)
    return 0.5 * k * k * np.log1p((r / k) ** 2)


def psi(loss: Loss, r: np.ndarray, k: float) -> np.ndarray:
    """The loss's derivative ``ρ'(r)``."""
    if loss == "linear":
        return r
    if loss == "huber":
        return np.clip(r, -k, k)
    return r / (1.0 + (r / k) ** 2)


def psi_slope(loss: Loss, r: np.ndarray, k: float) -> np.ndarray:
    """``ρ''(r)`` (for the covariance's efficiency factor)."""
    if loss == "linear":
        return np.ones_like(r)
    if loss == "huber":
        return (np.abs(r) <= k).astype(np.float64)
    u = (r / k) ** 2
    return (1.0 - u) / (1.0 + u) ** 2


def weights(loss: Loss, r: np.ndarray, k: float) -> np.ndarray:
    """IRLS weights ``ψ(r)/r`` (1 at ``r = 0``)."""
    if loss == "linear":
        return np.ones_like(r)
    if loss == "huber":
        a = np.abs(r)
        return np.where(a <= k, 1.0, k / np.maximum(a, 1e-300))
    return 1.0 / (1.0 + (r / k) ** 2)


def channel_log_scales(error: np.ndarray, trim: float = 0.1) -> np.ndarray:
    """``[..., C]`` log of each row's root mean square once its largest ``trim`` fraction is left out.

    The default criterion of rollout searches: summed over channels it is the Gaussian log-likelihood
    with one unknown noise level per channel, so channels in any units count alike, and a trimmed mean
    ignores the few samples a glitch spoils. ``error`` is ``[..., C, k]``; a non-finite row is ``inf``.
    """
    squares = np.square(error)
    keep = squares.shape[-1] - int(trim * squares.shape[-1])
    kept = np.partition(squares, keep - 1, axis=-1)[..., :keep] if keep < squares.shape[-1] else squares
    with np.errstate(divide="ignore", invalid="ignore"):
        out = 0.5 * np.log(np.mean(kept, axis=-1) + 1e-300)
    return np.where(np.isfinite(out), out, np.inf)
