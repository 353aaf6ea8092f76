"""Least squares (eqs. 10–11) and total least squares (eqs. 12–15), plain and relative (eqs. 36–37).

Both solve in the base parameters ``α`` of ``robot.regressor`` and report physical parameters via
``robot.params_from_base``. Neither forms ``WᵀW``: LS uses the SVD of the column-equilibrated ``W``
(already computed for the rank check, and backward stable where the normal equations square the
condition number); TLS uses the SVD of ``[W | τ_s]`` (Golub & Van Loan). ``LinearEstimator`` is the
shared ``fit`` of the family (``rls`` too): build the system, check it, solve, report.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Any, ClassVar

import torch
from torch import Tensor

from idkit.estimate import Estimate, jsonable
from idkit.estimators.observation import (
    Conditioning,
    IdentificationError,
    IdentificationWarning,
    LinearSystem,
    check_conditioning,
    default_max_cond,
    linear_system,
)
from idkit.estimators.uncertainty import uncertainty_details
from idkit.interfaces import Estimator
from idkit.problem import Problem
from idkit.relative import DEFAULT_FLOOR
from idkit.runtime import resolve_threads, torch_threads


@dataclass
class Solution:
    """What a solver hands back to ``LinearEstimator.fit``: ``alpha[B]`` and its own criterion."""

    alpha: Tensor
    criterion: str
    value: float
    details: dict[str, Any] = field(default_factory=dict)


class LinearEstimator(Estimator):
    """``fit`` of the least-squares family; subclasses implement ``solve``.

    Warnings raised while fitting (near-zero torques floored, ill-conditioning, an inaccurate
    solver) are both re-issued to the caller and listed in ``details["warnings"]``.

    Args:
        relative: solve the relative system of eqs. (36)–(37) (labels "LS-rel", ...).
        floor: near-zero torque floor of the relative system (see ``idkit.relative``).
        max_cond: warn above this column-equilibrated condition number of ``W``; ``None`` =
            ``1/√eps`` of the problem's dtype (see ``idkit.estimators.observation``).
        threads: torch intra-op threads during the fit; ``None`` = ``idkit.runtime``'s size rule
            (one thread for the paper's problems: with the default pool an SVD of a 60 × 4 ``W``
            took ~0.3 s instead of ~30 µs on the loaded 2-core development machine).
    """

    label: ClassVar[str]

    def __init__(
        self,
        relative: bool = False,
        floor: float = DEFAULT_FLOOR,
        max_cond: float | None = None,
        threads: int | None = None,
    ) -> None:
        self.relative = relative
        self.floor = floor
        self.max_cond = max_cond
        self.threads = threads

    def solve(self, system: LinearSystem, conditioning: Conditioning) -> Solution:
        """Base parameters ``alpha[B]`` for the checked system."""
        raise NotImplementedError

    @property
    def name(self) -> str:
        return f"{self.label}-rel" if self.relative else self.label

    def fit(self, problem: Problem) -> Estimate:
        start = time.perf_counter()
        s = problem.samples
        threads = resolve_threads(
            self.threads, s.n_samples * s.n_joints * len(problem.robot.base_param_names)
        )
        caught: list[warnings.WarningMessage] = []
        try:
            with torch_threads(threads), warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                system = linear_system(problem, self.relative, self.floor)
                conditioning = check_conditioning(system, self.max_cond)
                solution = self.solve(system, conditioning)
                params = problem.robot.params_from_base(solution.alpha)
                if not bool(torch.isfinite(params).all()):
                    warnings.warn(
                        f"{self.name}: physical parameters {params.tolist()} are not finite "
                        f"(base parameters {solution.alpha.tolist()}; params_from_base divides by "
                        "an estimate that came out 0)",
                        IdentificationWarning,
                        stacklevel=2,
                    )
                cost = solution.value if problem.cost is None else float(problem.evaluate(params))
        finally:  # outside the recording context, else the re-issued warnings are recorded again
            for w in caught:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)
        robot = problem.robot
        M, B = system.shape
        details = {
            "criterion": solution.criterion,
            "criterion_value": solution.value,
            "relative": self.relative,
            "floor": self.floor,
            "equations": M,
            "rank": conditioning.rank,
            "cond": conditioning.cond,
            "max_cond": default_max_cond(system.W.dtype) if self.max_cond is None else self.max_cond,
            **solution.details,
            **uncertainty_details(system, solution.alpha, conditioning),
            "device": str(system.W.device),
            "threads": threads,
            "dtype": str(system.W.dtype).removeprefix("torch."),
            "warnings": [f"{w.category.__name__}: {w.message}" for w in caught],
        }
        return Estimate(
            estimator=self.name,
            params=dict(zip(robot.param_names, params.tolist(), strict=True)),
            cost=cost,
            wall_time_s=time.perf_counter() - start,
            base_params=dict(zip(system.base_names, solution.alpha.tolist(), strict=True)),
            details=jsonable(details),
        )


def residual_norm(system: LinearSystem, alpha: Tensor) -> float:
    """``‖τ_s − W α‖₂`` (eq. 10) for ``alpha[B]``."""
    return float(torch.linalg.vector_norm(system.tau - system.W @ alpha))


class LeastSquares(LinearEstimator):
    """LS / LS-rel: ``argmin ‖τ_s − W α‖₂`` (eq. 10).

    Solved with the SVD of the column-equilibrated ``W`` (``W D⁻¹ = U S Vᵀ``, ``α = D⁻¹ V S⁻¹ Uᵀ
    τ_s``), the decomposition the rank check already made. Eq. (11)'s ``(WᵀW)⁻¹`` is never formed.
    """

    label = "LS"

    def solve(self, system: LinearSystem, conditioning: Conditioning) -> Solution:
        c = conditioning
        alpha = (c.Vh.mT @ ((c.U.mT @ system.tau) / c.sigma)) / c.scale
        return Solution(
            alpha,
            "||tau_s - W alpha||_2 (eq. 10)",
            residual_norm(system, alpha),
            {"solver": "svd of column-equilibrated W"},
        )


@dataclass(frozen=True)
class TLSSolution:
    """``alpha[B]``, ``rho`` = ‖[ΔW | Δτ]‖_F (eq. 14) and the existence gap ``σ_B(W) − rho``."""

    alpha: Tensor
    rho: float
    gap: float
    sigma_max: float


def smallest_singular_value(W: Tensor, tau: Tensor) -> float:
    """``σ_{B+1}([W | τ])``, the TLS ``rho`` of eq. (14); 0 when ``[W | τ]`` has fewer rows than columns."""
    C = torch.cat((W, tau[:, None]), dim=1)
    if C.shape[0] < C.shape[1]:
        return 0.0
    return float(torch.linalg.svdvals(C)[-1])


def total_least_squares(W: Tensor, tau: Tensor) -> TLSSolution:
    """Classical TLS (Golub & Van Loan): the right singular vector ``v`` of ``[W | τ]`` for its
    smallest singular value gives ``α = −v[:B] / v[B]``; ``rho`` is that singular value.

    Args:
        W: ``[M, B]`` with ``M ≥ B`` and full column rank.
        tau: ``[M]``.

    Raises:
        IdentificationError: the TLS problem has no unique solution (``σ_B(W) ≤ σ_{B+1}([W|τ])``
            to working precision — then ``v[B]`` is 0 or the minimiser is not unique).
    """
    M, B = W.shape
    C = torch.cat((W, tau[:, None]), dim=1)  # [M, B+1]
    _, S, Vh = torch.linalg.svd(C, full_matrices=M < B + 1)
    v = Vh[-1]  # [B+1], right singular vector of the smallest singular value
    rho = float(S[-1]) if M >= B + 1 else 0.0
    sigma_w = float(torch.linalg.svdvals(W)[-1])
    sigma_max = float(S[0])
    gap = sigma_w - rho
    tol = max(M, B + 1) * torch.finfo(W.dtype).eps * sigma_max
    if gap <= tol:
        raise IdentificationError(
            f"total least squares has no unique solution: smallest singular value of W ({sigma_w:.6g}) "
            f"does not exceed that of [W | tau_s] ({rho:.6g}); τ_s is (nearly) orthogonal to the "
            "smallest right singular direction of W"
        )
    return TLSSolution(-v[:B] / v[B], rho, gap, sigma_max)


class TotalLeastSquares(LinearEstimator):
    """TLS / TLS-rel (eqs. 12–15): the smallest perturbation ``Δ = [ΔW | Δτ]`` that makes the system
    consistent. Own criterion: ``rho = ‖Δ‖_F`` (eq. 14). ``details["tls_cond"] = σ_1 / (σ_B(W) −
    rho)`` measures how close the problem is to having no solution; it is warned about above
    ``max_cond`` like the condition number of ``W``.
    """

    label = "TLS"

    def solve(self, system: LinearSystem, conditioning: Conditioning) -> Solution:
        tls = total_least_squares(system.W, system.tau)
        tls_cond = tls.sigma_max / tls.gap
        limit = default_max_cond(system.W.dtype) if self.max_cond is None else self.max_cond
        if tls_cond > limit:
            warnings.warn(
                f"{self.name}: the TLS problem of robot {system.robot_name} is nearly degenerate "
                f"(sigma_1 / (sigma_B(W) - rho) = {tls_cond:.3g} > {limit:.3g})",
                IdentificationWarning,
                stacklevel=2,
            )
        return Solution(
            tls.alpha,
            "rho = ||[dW | dtau]||_F (eq. 14)",
            tls.rho,
            {
                "solver": "svd of [W | tau_s]",
                "rho": tls.rho,
                "tls_cond": tls_cond,
                "residual_norm": residual_norm(system, tls.alpha),
            },
        )
