"""How well the data determine each base parameter: standard deviations, rank, conditioning.

For a linear model ``tau = W alpha + e`` with independent errors of equal variance ``σ²``, the LS
estimate has covariance ``σ² (WᵀW)⁻¹``; ``σ²`` is estimated by the residual sum of squares over the
degrees of freedom, ``‖tau − W alpha‖² / (M − B)`` (Gautier & Khalil's classical "relative
standard deviation" of each identified parameter, ``100 σ_k / |alpha_k|`` %). Real residuals are
correlated in time and not of equal variance across joints, so these numbers are *optimistic*
lower bounds; they are most useful to rank parameters (a base parameter at 50 % is not identified
by this trajectory, whatever its value).

``(WᵀW)⁻¹`` is never formed: with ``W D⁻¹ = U S Vᵀ`` (``D`` the column norms, the same
equilibration as :mod:`idkit.estimators.linear.observation`), ``(WᵀW)⁻¹ = D⁻¹ V S⁻² Vᵀ D⁻¹``. Directions of
``V`` with singular value below the rank tolerance are the combinations the data cannot separate;
every parameter touching them gets an infinite standard deviation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import torch
from torch import Tensor

from idkit.estimators.linear.observation import Conditioning, _null_directions


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
        unidentifiable: the robot's structural statements (``Robot.unidentifiable``), then the
            readable null directions (combinations the data cannot separate).
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


class Spectrum(NamedTuple):
    """What the report reads of the SVD of each trial's column-equilibrated ``W``: ``scale[T, B]``
    (the column norms), ``sigma[T, B]``, ``Vh[T, B, B]``. A ``Conditioning`` has them too (and ``U``,
    which a caller that factored ``W`` another way need not form)."""

    scale: Tensor
    sigma: Tensor
    Vh: Tensor


def base_uncertainties(
    W: Tensor,
    tau: Tensor,
    alpha: Tensor,
    names: Sequence[str],
    conditioning: Conditioning | Spectrum | None = None,
    structural: Sequence[str] = (),
) -> list[BaseUncertainty]:
    """Standard deviations ``sqrt(diag(σ² (WᵀW)⁻¹))`` of each trial's ``alpha[T, B]`` fitted on
    ``W[T, M, B]``, ``tau[T, M]``, in float64 whatever the input dtype.

    Args:
        W, tau, alpha: the (possibly relative) linear systems and their estimates.
        names: base parameter names ``[B]``.
        conditioning: the SVD of the equilibrated ``W`` if already computed (the LS family has it,
            varpro assembles it from its QR).
        structural: what the robot says no data can identify (``Robot.unidentifiable``), listed first.
    """
    W, tau, alpha = W.detach().double(), tau.detach().double(), alpha.detach().to(W).double()
    M, B = W.shape[-2:]
    if conditioning is None:
        scale = torch.linalg.vector_norm(W, dim=-2)
        scale = torch.where(scale > 0, scale, torch.ones_like(scale))
        _, sigma, Vh = torch.linalg.svd(W / scale[..., None, :], full_matrices=False)
    else:
        scale, sigma, Vh = conditioning.scale.double(), conditioning.sigma.double(), conditioning.Vh.double()
    tol = max(M, B) * torch.finfo(torch.float64).eps * sigma[..., :1]  # [T, 1]; 0 if sigma_max is 0
    kept = sigma > tol  # [T, B]
    ranks = kept.sum(-1).tolist()
    dof = M - B
    residual = tau - (W @ alpha[..., None])[..., 0]
    sigma2 = residual.square().sum(-1) / dof if dof > 0 else torch.full_like(residual[..., 0], math.nan)
    inverse = torch.where(kept, 1 / sigma, torch.zeros_like(sigma))  # 1/s_k on kept directions only
    variance = sigma2[..., None] * (Vh.mT * inverse[..., None, :]).square().sum(-1) / scale.square()
    touched = ((Vh.abs() > 1e-8) & ~kept[..., None]).any(-2)  # parameters in a null direction
    std = torch.where(touched, torch.full_like(variance, math.inf), variance.sqrt())
    relative = 100.0 * std / alpha.abs()
    cond = torch.where(sigma[..., -1] > 0, sigma[..., 0] / sigma[..., -1], math.inf).tolist()
    sigma2_list, std, relative = sigma2.tolist(), std.cpu(), relative.cpu()
    names = tuple(names)
    return [
        BaseUncertainty(
            names,
            std[t],
            relative[t],
            sigma2_list[t],
            dof,
            ranks[t],
            cond[t],
            (*structural, *(_null_directions(Vh[t], sigma[t], float(tol[t]), names) if ranks[t] < B else ())),
        )
        for t in range(len(ranks))
    ]


def base_uncertainty(
    W: Tensor, tau: Tensor, alpha: Tensor, names: Sequence[str], structural: Sequence[str] = ()
) -> BaseUncertainty:
    """``base_uncertainties`` of one system ``W[M, B]``, ``tau[M]`` and its ``alpha[B]``."""
    return base_uncertainties(W[None], tau[None], alpha[None], names, structural=structural)[0]
