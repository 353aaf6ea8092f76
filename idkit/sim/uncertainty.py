"""What a rollout fit knows and does not: standard deviations, 95 % intervals and flat directions.

From the polish's Jacobian ``J`` at the solution (residuals standardised by the robust scale, so each
is noise of unit variance where the model fits): the covariance of the variables is
``κ (JᵀJ)⁻¹``, with Huber's factor ``κ = mean ψ(u)² / (mean ψ'(u))²`` for an M-estimator's loss
(``mean u²`` for least squares) and ``M / (M − p)`` for the ``p`` variables fitted. The unknowns'
block of it accounts for the fitted initial states (their information is profiled out first).

A *flat direction* is an eigenvector of the unknowns' information along which the data cannot tell a
change from noise: a standard deviation over ``FLAT`` in coordinates (a factor ``e^0.5 ≈ 1.65`` of a
log-scaled value), or an eigenvalue below ``1e-12`` of the largest. It is named by its largest
components (``j1.armature + 0.9·j1.damping``): those unknowns are not separately identifiable from this
log; a longer or richer motion, or fixing one of them, is what helps.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from idkit.optim.levenberg import BlockJacobian
from idkit.optim.robust import Loss, psi, psi_slope
from idkit.sim.quantities import Unknowns

FLAT = 0.5
#: Components of a flat direction at least this fraction of its largest are named.
NAMED = 0.2


@dataclass(frozen=True)
class Uncertainty:
    """What the fit knows of each unknown (the record every reader of a rollout fit reads).

    Attributes:
        std: per unknown, the standard deviation of its value (``inf``: not determined by the log).
        interval95: per unknown, a 95 % interval (from the coordinate's interval; ``(-inf, inf)``
            when ``std`` is infinite).
        flat: the flat directions, each ``{"direction": {name: weight}, "sigma": coordinate standard
            deviation along it}``.
        at_bound: the unknowns whose estimate ended on a bound.
        model_limited: the residual, not the noise, limits the fit (the intervals are widened).
        misfit: robust residual RMS / noise level (1 ≈ noise-limited; ``nan``: not measured).
        method: how the intervals were computed.
        reason: why that method (or why the fit is called model-limited).
    """

    std: dict[str, float]
    interval95: dict[str, tuple[float, float]]
    flat: list[dict[str, Any]] = field(default_factory=list)
    at_bound: list[str] = field(default_factory=list)
    model_limited: bool = False
    misfit: float = float("nan")
    method: str = "jacobian"
    reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "std": self.std,
            "interval95": {name: list(bounds) for name, bounds in self.interval95.items()},
            "flat_directions": self.flat,
            "at_bound": list(self.at_bound),
            "model_limited": self.model_limited,
            "misfit": self.misfit,
            "method": self.method,
            "reason": self.reason,
        }


def uncertainty(
    jac: BlockJacobian, residual: np.ndarray, threshold: float, loss: Loss, unknowns: Unknowns, z: np.ndarray
) -> Uncertainty:
    """The uncertainty of the unknowns at coordinates ``z[P]`` (module docstring).

    Args:
        jac: the Jacobian of the residual vector, the unknowns' columns first (dense).
        residual: ``[M]`` the residual vector at the solution (standardised, divided by ``√M``).
        threshold: the loss's threshold in the residual's units.
        loss: the loss the polish minimised.
        unknowns: what the first ``P`` variables are.
        z: ``[P]`` their coordinates.
    """
    m, p = jac.shape
    n = len(unknowns)
    scale = np.sqrt(m)
    u, k = residual * scale, threshold * scale
    slope = float(np.mean(psi_slope(loss, u, k)))
    kappa = float(np.mean(psi(loss, u, k) ** 2)) / max(slope, 1e-12) ** 2 * m / max(m - p, 1)
    info = jac.gram(np.ones(m)) * m  # information per unit-variance residual: J_uᵀ J_u with J_u = √M J
    a, b, c = info[:n, :n], info[:n, n:], info[n:, n:]
    profiled = a - b @ np.linalg.pinv(c, hermitian=True) @ b.T if p > n else a
    eigenvalues, vectors = np.linalg.eigh(0.5 * (profiled + profiled.T))
    top = max(float(eigenvalues[-1]), 1e-300)
    flat_mask = eigenvalues <= 1e-12 * top
    safe = np.where(flat_mask, np.inf, eigenvalues)
    covariance = (vectors / safe) @ vectors.T * kappa
    sigma_z = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    sigma_z = np.where((np.abs(vectors[:, flat_mask]) > 1e-6).any(axis=1), np.inf, sigma_z)
    values = unknowns.from_coordinates(z)
    log = np.array([u.logarithmic for u in unknowns.items])
    width = unknowns.vector("upper") - unknowns.vector("lower")
    sigma = np.where(log, values * sigma_z, width * sigma_z)
    low = unknowns.from_coordinates(z - 1.96 * np.where(np.isfinite(sigma_z), sigma_z, 0.0))
    high = unknowns.from_coordinates(z + 1.96 * np.where(np.isfinite(sigma_z), sigma_z, 0.0))
    names = unknowns.names
    flat = []
    for i in range(n):
        along = np.inf if flat_mask[i] else float(np.sqrt(kappa / eigenvalues[i]))
        if along > FLAT:
            v = vectors[:, i] / np.abs(vectors[:, i]).max()
            order = np.argsort(-np.abs(v))
            named = {names[j]: round(float(v[j]), 3) for j in order if abs(v[j]) >= NAMED}
            flat.append({"direction": named, "sigma": along})
    return Uncertainty(
        {name: float(s) for name, s in zip(names, sigma, strict=True)},
        {
            name: ((float(lo), float(hi)) if np.isfinite(s) else (-np.inf, np.inf))
            for name, lo, hi, s in zip(names, low, high, sigma, strict=True)
        },
        flat,
        at_bound=unknowns.at_bound(values),
    )
