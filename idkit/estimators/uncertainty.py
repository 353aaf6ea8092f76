"""How well the data determine each base parameter: standard deviations, rank, conditioning.

For a linear model ``tau = W alpha + e`` with independent errors of equal variance ``σ²``, the LS
estimate has covariance ``σ² (WᵀW)⁻¹``; ``σ²`` is estimated by the residual sum of squares over the
degrees of freedom, ``‖tau − W alpha‖² / (M − B)`` (Gautier & Khalil's classical "relative
standard deviation" of each identified parameter, ``100 σ_k / |alpha_k|`` %). Real residuals are
correlated in time and not of equal variance across joints, so these numbers are *optimistic*
lower bounds; they are most useful to rank parameters (a base parameter at 50 % is not identified
by this trajectory, whatever its value).

``(WᵀW)⁻¹`` is never formed: with ``W D⁻¹ = U S Vᵀ`` (``D`` the column norms, the same
equilibration as :mod:`idkit.estimators.observation`), ``(WᵀW)⁻¹ = D⁻¹ V S⁻² Vᵀ D⁻¹``. Directions of
``V`` with singular value below the rank tolerance are the combinations the data cannot separate;
every parameter touching them gets an infinite standard deviation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

from idkit.estimators.observation import Conditioning, LinearSystem, _null_directions


@dataclass(frozen=True)
class BaseUncertainty:
    """Uncertainty of base parameters ``alpha[B]`` fitted on ``W[M, B]``.

    Attributes:
        names: base parameter names ``[B]``.
        std: standard deviation of each ``[B]`` (``inf`` along unidentifiable directions).
        relative_pct: ``100 std / |alpha|`` ``[B]`` (``inf`` where ``alpha = 0``).
        sigma2: residual variance ``‖tau − W alpha‖² / (M − B)``.
        dof: degrees of freedom ``M − B``.
        rank: numerical rank of the column-equilibrated ``W``.
        cond: its condition number ``σ_max / σ_min``.
        unidentifiable: readable null directions (combinations the data cannot separate).
    """

    names: tuple[str, ...]
    std: Tensor
    relative_pct: Tensor
    sigma2: float
    dof: int
    rank: int
    cond: float
    unidentifiable: tuple[str, ...]

    def to_details(self) -> dict[str, Any]:
        """``{"uncertainty": {...}}`` for an estimate's ``details`` (name-keyed maps)."""
        return {
            "uncertainty": {
                "std": dict(zip(self.names, self.std.tolist(), strict=True)),
                "std_rel_pct": dict(zip(self.names, self.relative_pct.tolist(), strict=True)),
                "sigma2": self.sigma2,
                "dof": self.dof,
                "rank": self.rank,
                "cond": self.cond,
                "unidentifiable": list(self.unidentifiable),
            }
        }


def base_uncertainty(
    W: Tensor,
    tau: Tensor,
    alpha: Tensor,
    names: Sequence[str],
    conditioning: Conditioning | None = None,
) -> BaseUncertainty:
    """Standard deviations ``sqrt(diag(σ² (WᵀW)⁻¹))`` of ``alpha[B]`` fitted on ``W[M, B]``, ``tau[M]``.

    Args:
        W, tau, alpha: the (possibly relative) linear system and its estimate.
        names: base parameter names ``[B]``.
        conditioning: the SVD of the equilibrated ``W`` if already computed (the LS family has it).
    """
    W, tau, alpha = W.detach().double(), tau.detach().double(), alpha.detach().to(W).double()
    M, B = W.shape
    if conditioning is None:
        scale = torch.linalg.vector_norm(W, dim=0)
        scale = torch.where(scale > 0, scale, torch.ones_like(scale))
        _, sigma, Vh = torch.linalg.svd(W / scale, full_matrices=False)
    else:
        scale, sigma, Vh = conditioning.scale.double(), conditioning.sigma.double(), conditioning.Vh.double()
    tol = max(M, B) * torch.finfo(torch.float64).eps * float(sigma[0]) if float(sigma[0]) > 0 else 0.0
    kept = sigma > tol
    rank = int(kept.sum())
    dof = M - B
    residual = tau - W @ alpha
    sigma2 = float(residual @ residual) / dof if dof > 0 else float("nan")
    V = Vh.mT[:, kept] / sigma[kept]  # columns V_k / s_k
    variance = sigma2 * (V.square().sum(1)) / scale.square()
    touched = (Vh[~kept].abs() > 1e-8).any(0) if rank < B else torch.zeros(B, dtype=torch.bool)
    std = torch.where(touched, torch.full_like(variance, float("inf")), variance.sqrt())
    relative = 100.0 * std / alpha.abs()
    cond = float(sigma[0] / sigma[-1]) if float(sigma[-1]) > 0 else float("inf")
    null = tuple(_null_directions(Vh, sigma, tol, tuple(names))) if rank < B else ()
    return BaseUncertainty(tuple(names), std.cpu(), relative.cpu(), sigma2, dof, rank, cond, null)


def uncertainty_details(system: LinearSystem, alpha: Tensor, conditioning: Conditioning) -> dict[str, Any]:
    """``details`` entry of the least-squares family: :func:`base_uncertainty` of its system and fit."""
    return base_uncertainty(system.W, system.tau, alpha, system.base_names, conditioning).to_details()
