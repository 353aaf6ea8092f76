"""How well the data determine each base parameter: standard deviations, rank, conditioning.

For a linear model ``tau = W alpha + e`` the LS estimate's error is ``(WᵀW)⁻¹ Wᵀ e``. The textbook
covariance ``σ² (WᵀW)⁻¹`` (``σ²`` the residual sum of squares over ``M − B``) holds only for
independent errors of equal variance. A robot's are neither: the joints' torques differ in scale and
noise, and the residuals of a recording are correlated in time (filtered states, unmodelled
dynamics), which made the textbook σ a fraction of the real error. So the covariance here is the
*sandwich*

    Cov(alpha) = (WᵀW)⁻¹ · S · (WᵀW)⁻¹,    S = Σ_{|l| ≤ L} (1 − |l| / (L + 1)) Σ_i g_i g_{i+l}ᵀ,

with ``g_i = W_iᵀ e_i`` the score of sample ``i`` (its ``n`` joint rows together, so any correlation
between joints at one instant is kept), the Bartlett-weighted autocovariances of Newey & West (1987)
summed over time lags as in Driscoll & Kraay (1998), and the bandwidth ``L`` chosen from the data by
Andrews' (1991) AR(1) plug-in rule: a few lags for white residuals (``L = 0`` is White's
heteroscedasticity-consistent estimate), hundreds of samples for residuals correlated over a second.
Each sample's residuals are leverage-adjusted first (:func:`sandwich`: the jackknife's
``(1 − H_ii)⁻¹``), which on a long recording changes nothing and on the paper's 10 samples is what
brings the coverage of its 95 % intervals from 70–80 % towards 95 %. Where the σ come from, in
words, is :mod:`idkit.std_source`'s record (``method`` and ``std_source`` in the details).
Measured coverage on the README's tour: ``docs/uncertainty.md``.

An estimate pulled away from least squares — ``pcls``'s, by its prior towards the CAD model and by its
constraints — is biased by the pull, which the sandwich (the scatter of the data) does not see. With
``pulled=True`` the difference from the least-squares solution of the same system, ``α − α_LS``, is
added in quadrature: ``std = sqrt(std_data² + pull²)``, a root-mean-square error that counts the pull
as a bias. It is conservative: the prior also narrows the scatter, which the sandwich of the
unconstrained fit does not credit.

``(WᵀW)⁻¹`` is never formed: with ``W D⁻¹ = U S Vᵀ`` (``D`` the column norms, the same
equilibration as :mod:`idkit.estimators.linear.observation`), ``(WᵀW)⁻¹ = D⁻¹ V S⁻² Vᵀ D⁻¹``. Directions of
``V`` with singular value below the rank tolerance are the combinations the data cannot separate;
every parameter touching them gets an infinite standard deviation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

from idkit.estimators.linear.observation import Conditioning, _null_directions
from idkit.std_source import describe

#: The largest lag-1 correlation of a score column the bandwidth rule takes (``long_run_covariance``).
MAX_LAG_CORRELATION = 0.99
#: The largest eigenvalue of a sample's leverage the sandwich takes (``sandwich``): a sample that
#: alone fixes a direction has a zero residual along it, which no factor would make an error.
MAX_LEVERAGE = 0.99


@dataclass(frozen=True)
class BaseUncertainty:
    """Uncertainty of base parameters ``alpha[B]`` fitted on ``W[M, B]``.

    Attributes:
        names: base parameter names ``[B]``.
        std: standard deviation of each ``[B]`` (``inf`` along unidentifiable directions).
        relative_pct: ``100 std / |alpha|`` ``[B]`` (``inf`` where ``alpha = 0``).
        sigma2: residual variance ``‖tau − W alpha‖² / (M − B)``.
        dof: degrees of freedom ``M − B``.
        bandwidth: the lags ``L`` of the sandwich's autocovariance sum (module doc).
        pull: ``α − α_LS`` ``[B]`` of an estimate pulled away from least squares (``None``: not one);
            ``std`` includes it (module doc).
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
    bandwidth: int
    rank: int
    cond: float
    unidentifiable: tuple[str, ...]
    pull: Tensor | None = None

    @property
    def method(self) -> str:
        """The key of :data:`idkit.std_source.METHODS` these σ follow."""
        return "hac" if self.pull is None else "hac+pull"

    def to_details(self) -> dict[str, Any]:
        """``{"uncertainty": {...}}`` for an estimate's ``details`` (name-keyed maps)."""
        pull = {} if self.pull is None else {"pull": dict(zip(self.names, self.pull.tolist(), strict=True))}
        return {
            "uncertainty": {
                "std": dict(zip(self.names, self.std.tolist(), strict=True)),
                "std_rel_pct": dict(zip(self.names, self.relative_pct.tolist(), strict=True)),
                "sigma2": self.sigma2,
                "dof": self.dof,
                "method": self.method,
                "std_source": describe(self.method),
                "bandwidth": self.bandwidth,
                "rank": self.rank,
                "cond": self.cond,
                "unidentifiable": list(self.unidentifiable),
                **pull,
            }
        }


def base_uncertainties(
    W: Tensor,
    tau: Tensor,
    alpha: Tensor,
    names: Sequence[str],
    conditioning: Conditioning | None = None,
    structural: Sequence[str] = (),
    joints: int = 1,
    pulled: bool = False,
) -> list[BaseUncertainty]:
    """Standard deviations of each trial's ``alpha[T, B]`` fitted on ``W[T, M, B]``, ``tau[T, M]``: the
    sandwich of the module doc, in float64 whatever the input dtype.

    Args:
        W, tau, alpha: the (possibly relative) linear systems and their estimates; rows sample-major,
            ``joints`` consecutive rows per sample (``M = N · joints``).
        names: base parameter names ``[B]``.
        conditioning: the SVD of the equilibrated ``W`` if already computed (the LS family has it).
        structural: what the robot says no data can identify (``Robot.unidentifiable``), listed first.
        joints: rows per sample: the joints' rows of one instant share a score.
        pulled: ``alpha`` is not the least-squares solution but pulled from it (a prior, constraints):
            the pull is added in quadrature (module doc).
    """
    W, tau, alpha = W.detach().double(), tau.detach().double(), alpha.detach().to(W).double()
    M, B = W.shape[-2:]
    if M % joints:
        raise ValueError(f"base_uncertainties: {M} rows are not a whole number of samples of {joints} rows")
    if conditioning is None:
        scale = torch.linalg.vector_norm(W, dim=-2)
        scale = torch.where(scale > 0, scale, torch.ones_like(scale))
        U, sigma, Vh = torch.linalg.svd(W / scale[..., None, :], full_matrices=False)
    else:
        U, sigma, Vh = (getattr(conditioning, k).double() for k in ("U", "sigma", "Vh"))
        scale = conditioning.scale.double()
    tol = max(M, B) * torch.finfo(torch.float64).eps * sigma[..., :1]  # [T, 1]; 0 if sigma_max is 0
    kept = sigma > tol  # [T, B]
    ranks = kept.sum(-1).tolist()
    dof = M - B
    residual = tau - (W @ alpha[..., None])[..., 0]
    sigma2 = residual.square().sum(-1) / dof if dof > 0 else torch.full_like(residual[..., 0], math.nan)
    inverse = torch.where(kept, 1 / sigma, torch.zeros_like(sigma))  # 1/s_k on kept directions only
    bread = (Vh.mT * inverse[..., None, :].square()) @ Vh  # (W̃ᵀW̃)⁺ of the equilibrated W̃
    covariance, bandwidths = sandwich(W / scale[..., None, :], residual, bread, joints)
    bandwidth = [b[0] for b in bandwidths]
    variance = covariance.diagonal(dim1=-2, dim2=-1) / scale.square()
    pull = None
    if pulled:
        least_squares = (Vh.mT @ (inverse * (U.mT @ tau[..., None])[..., 0])[..., None])[..., 0] / scale
        pull = alpha - least_squares
        variance = variance + pull.square()
    touched = ((Vh.abs() > 1e-8) & ~kept[..., None]).any(-2)  # parameters in a null direction
    std = torch.where(touched, torch.full_like(variance, math.inf), variance.clamp_min(0).sqrt())
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
            bandwidth[t],
            ranks[t],
            cond[t],
            (*structural, *(_null_directions(Vh[t], sigma[t], float(tol[t]), names) if ranks[t] < B else ())),
            None if pull is None else pull[t].cpu(),
        )
        for t in range(len(ranks))
    ]


def sandwich(
    X: Tensor, residual: Tensor, bread: Tensor, joints: int, starts: Sequence[int] = (0,)
) -> tuple[Tensor, list[list[int]]]:
    """``Cov[T, B, B] = bread · S · bread`` of the module doc for rows ``X[T, M, B]`` and their
    least-squares residuals ``residual[T, M]`` (``bread[T, B, B] = (XᵀX)⁺``), and each trial's
    bandwidths.

    Each sample's residuals (its ``joints`` rows) are leverage-adjusted first, ``e*_i = (1 − H_ii)⁻¹ e_i``
    with ``H_ii = X_i bread X_iᵀ`` (the jackknife's, MacKinnon & White 1985, per sample as for
    clustered rows): a fitted residual is smaller than the error it stands for, by a share the
    sample's own leverage sets — nothing on a long recording, a third on the paper's 10 samples, where
    the plain sandwich covered 70–80 % instead of 95 %. Eigenvalues of ``H_ii`` are taken at most
    :data:`MAX_LEVERAGE`.

    ``starts``: the first row of each recording (sample-aligned, ascending): recordings are
    independent of one another, so their long-run covariances add and no lag crosses from one into
    the next.
    """
    T, M, B = X.shape
    grouped = X.reshape(T, M // joints, joints, B)
    leverage = grouped @ bread[:, None] @ grouped.mT  # [T, N, n, n]
    eigenvalues, vectors = torch.linalg.eigh(leverage)
    factor = 1 / (1 - eigenvalues.clamp(max=MAX_LEVERAGE))
    errors = residual.reshape(T, M // joints, joints, 1)
    adjusted = vectors @ (factor[..., None] * (vectors.mT @ errors))
    scores = (grouped * adjusted).sum(-2)  # [T, N, B]: each sample's g_i
    edges = [start // joints for start in starts] + [M // joints]
    meat = torch.zeros_like(bread)
    bandwidths: list[list[int]] = [[] for _ in range(T)]
    for first, last in zip(edges[:-1], edges[1:], strict=True):
        part, lags = long_run_covariance(scores[:, first:last])
        meat = meat + part
        for t, lag in enumerate(lags):
            bandwidths[t].append(lag)
    return bread @ meat @ bread, bandwidths


def long_run_covariance(scores: Tensor) -> tuple[Tensor, list[int]]:
    """``S[T, B, B]``, the Bartlett-weighted sum of the autocovariances of each trial's ``scores[T, N, B]``
    (module doc), and the bandwidth ``L`` of each trial, from Andrews' AR(1) plug-in rule: each score
    column's lag-1 correlation ``ρ`` and innovation variance ``s²`` give
    ``a = Σ 4ρ²s⁴ / ((1 − ρ)⁶ (1 + ρ)²) / Σ s⁴ / (1 − ρ)⁴`` and ``L = ⌈1.1447 (a N)^⅓⌉``, at most
    ``N / 4`` (``ρ`` is clipped at ±:data:`MAX_LAG_CORRELATION`: a score correlated to 1 would ask for
    every lag)."""
    N = scores.shape[-2]
    before, after = scores[..., :-1, :], scores[..., 1:, :]
    power = before.square().sum(-2)
    rho = torch.where(power > 0, (before * after).sum(-2) / power.clamp_min(1e-300), torch.zeros_like(power))
    rho = rho.clamp(-MAX_LAG_CORRELATION, MAX_LAG_CORRELATION)
    s4 = (after - rho[..., None, :] * before).square().mean(-2).square()
    numerator = (4 * rho.square() * s4 / ((1 - rho) ** 6 * (1 + rho) ** 2)).sum(-1)
    denominator = (s4 / (1 - rho) ** 4).sum(-1)
    a = torch.where(denominator > 0, numerator / denominator.clamp_min(1e-300), torch.zeros_like(numerator))
    bandwidth = torch.ceil(1.1447 * (a * N) ** (1 / 3)).clamp(0, max(N // 4, 0)).long()
    meat = scores.mT @ scores
    for lag in range(1, int(bandwidth.max()) + 1):
        weight = (1 - lag / (bandwidth + 1)).clamp_min(0).to(scores)  # [T]
        product = scores[..., :-lag, :].mT @ scores[..., lag:, :]
        meat = meat + weight[..., None, None] * (product + product.mT)
    return meat, bandwidth.tolist()


def base_uncertainty(
    W: Tensor,
    tau: Tensor,
    alpha: Tensor,
    names: Sequence[str],
    structural: Sequence[str] = (),
    joints: int = 1,
    pulled: bool = False,
) -> BaseUncertainty:
    """``base_uncertainties`` of one system ``W[M, B]``, ``tau[M]`` and its ``alpha[B]``."""
    return base_uncertainties(
        W[None], tau[None], alpha[None], names, structural=structural, joints=joints, pulled=pulled
    )[0]
