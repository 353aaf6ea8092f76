"""Robust least squares (El Ghaoui & Lebret; eqs. 16–18), plain and relative.

RLS minimises the worst-case residual over perturbations ``‖[ΔW | Δτ]‖_F ≤ ρ`` (eqs. 16–17),
which equals

    f(α) = ‖W α − τ‖₂ + ρ ‖[α; 1]‖₂ ,

a convex function, strictly convex (the second term is), so its minimiser is unique. ``ρ``
defaults to the TLS ``ρ`` of eq. (14), the smallest singular value of ``[W | τ]``.

Two solvers, chosen by ``solver``:

``"cvxpy"`` — the reference: the SOCP of eq. (18) handed to cvxpy (numpy float64 on the CPU),
then by default a few Newton steps on ``f`` (``newton_polish``): the interior-point answer alone
is only ~1e-5 accurate on the paper's problems, the polished one agrees with the closed form to
~1e-14.

``"closed_form"`` — a secular equation. Where ``r = Wα − τ ≠ 0``, ``f`` is differentiable and
``∇f = Wᵀr/‖r‖ + ρ α/‖[α;1]‖ = 0`` reads ``(WᵀW + μI) α = Wᵀτ`` with ``μ = ρ‖r‖/‖[α;1]‖ > 0``.
With the thin SVD ``W = U S Vᵀ``, ``b = Uᵀτ`` and ``β = ‖τ − U b‖`` (the part of ``τ`` outside the
range of ``W``), ``α(μ) = V diag(sᵢ/(sᵢ² + μ)) b`` and

    ‖α(μ)‖² = Σ sᵢ² bᵢ² / (sᵢ² + μ)²,       ‖r(μ)‖² = Σ μ² bᵢ² / (sᵢ² + μ)² + β²,

so ``μ`` is the root of the scalar equation ``g(μ) = μ √(1 + ‖α(μ)‖²) − ρ ‖r(μ)‖ = 0``.
Facts used (all from the formulas above):

- ``g(μ) < 0`` below the root and ``> 0`` above it: the minimiser is unique and ``μ ↦ α(μ)`` is
  one-to-one (if ``b ≠ 0``), so there is one root.
- Bracket: ``μ_lo = ρβ / √(1 + ‖α_LS‖²)`` (there ``‖α‖ ≤ ‖α_LS‖``, ``‖r‖ ≥ β``, so ``g ≤ 0``) and
  ``μ_hi = ρ‖τ‖`` (there ``‖[α;1]‖ ≥ 1``, ``‖r‖ ≤ ‖τ‖``, so ``g ≥ 0``). Noisy data (``β > 0``)
  has ``μ_lo > 0``, and for the small ``ρ`` of a TLS problem ``μ_lo`` is already close to the root
  (``g`` is nearly linear there), so safeguarded Newton from ``μ_lo`` takes a few steps.
- Zero residual (``β = 0``: ``τ`` in the range of ``W``, e.g. exact data): ``μ = 0`` is a root
  of ``g`` too, and the minimiser is ``α_LS`` (with ``r = 0``, where ``f`` is not differentiable)
  iff the slope ``g'(0⁺) = √(1 + ‖α_LS‖²) − ρ ‖S⁻² b‖ ≥ 0``; otherwise the root lies in
  ``(0, μ_hi]``.
- No "α = 0 at μ → ∞" degeneracy here, unlike ridge-type RLS with ``ρ‖α‖``: ``‖[α;1]‖`` is
  smooth at ``α = 0``, so ``α = 0`` is optimal only when ``Wᵀτ = 0`` (``b = 0``), and then
  ``α(μ) = 0`` for every ``μ``; large ``ρ`` gives ``μ ≈ ρ‖τ‖`` and a small but nonzero ``α``.
- ``ρ = 0`` is ordinary least squares (``μ = 0``).

The closed form works in numpy float64 on the CPU (see ``stacked_rls_closed_form`` for why), on a
stack of trials at once (one batched SVD); the root find runs per trial on Python floats over the
``B`` singular values: for the few iterations it takes, cheaper than any vectorised form (its time
per trial: docs/speed.md, "Measurements behind design choices").
"""

from __future__ import annotations

import math
import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Literal, get_args

import numpy as np
import torch
from torch import Tensor

from idkit.estimators.linear.least_squares import (
    LinearEstimator,
    LinearSettings,
    Solution,
    residual_norms,
    smallest_singular_values,
)
from idkit.estimators.linear.observation import (
    Conditioning,
    IdentificationError,
    IdentificationWarning,
    LinearSystem,
)
from idkit.estimators.trials import TrialWarnings, in_trial
from idkit.relative import DEFAULT_FLOOR

#: RLS's two solvers (module doc); the annotation the registry checks ``solver`` against.
Solver = Literal["closed_form", "cvxpy"]
SOLVERS: tuple[str, ...] = get_args(Solver)

_MAX_ITERATIONS = 200
_EPS = sys.float_info.epsilon


@dataclass(frozen=True)
class RLSSolution:
    """``alpha[B]``, the multiplier ``mu`` of ``(WᵀW + μI)α = Wᵀτ`` and root-find iterations."""

    alpha: Tensor
    mu: float
    iterations: int


def _secular_terms(mu: float, s2: list[float], p: list[float], b2: list[float]) -> tuple[float, float, float]:
    """``Σ pᵢ wᵢ² = ‖α‖²``, ``Σ bᵢ² wᵢ²`` and ``Σ pᵢ wᵢ³`` with ``wᵢ = 1/(sᵢ² + μ)``, ``pᵢ = sᵢ² bᵢ²``."""
    a2 = q2 = d3 = 0.0
    for si2, pi, bi2 in zip(s2, p, b2, strict=True):
        w = 1.0 / (si2 + mu)
        w2 = w * w
        a2 += pi * w2
        q2 += bi2 * w2
        d3 += pi * w2 * w
    return a2, q2, d3


def secular_root(s: list[float], b: list[float], beta: float, rho: float) -> tuple[float, int]:
    """The ``μ ≥ 0`` of the RLS stationarity condition (see the module docstring) and the iteration count.

    ``g(μ) = μ A − ρ R`` with ``A² = 1 + ‖α(μ)‖²``, ``R² = ‖r(μ)‖² = μ² Σ bᵢ²wᵢ² + β²``;
    ``d‖α‖²/dμ = −2 Σ pᵢwᵢ³`` and ``dR²/dμ = 2μ Σ pᵢwᵢ³``. Safeguarded Newton: a step that leaves
    the bracket is replaced by bisection (geometric while the bracket spans > 4×).

    Args:
        s: singular values of ``W`` (all > 0).
        b: ``Uᵀτ``, same length.
        beta: ``‖τ − U Uᵀ τ‖ ≥ 0``.
        rho: perturbation bound ``≥ 0``.
    """
    s2 = [si * si for si in s]
    b2 = [bi * bi for bi in b]
    p = [si2 * bi2 for si2, bi2 in zip(s2, b2, strict=True)]
    norm_tau = math.sqrt(sum(b2) + beta * beta)
    if rho == 0.0 or norm_tau == 0.0:
        return 0.0, 0
    if not any(b2):  # Wᵀτ = 0: α(μ) = 0 for all μ; report the stationary μ = ρ‖r‖/‖[0;1]‖
        return rho * norm_tau, 0
    a2_ls, q2_ls, _ = _secular_terms(0.0, s2, p, b2)
    lo, hi = rho * beta / math.sqrt(1.0 + a2_ls), rho * norm_tau
    if beta == 0.0 and math.sqrt(1.0 + a2_ls) >= rho * math.sqrt(q2_ls):  # g'(0⁺) ≥ 0: r = 0 optimal
        return 0.0, 0
    mu = lo if lo > 0.0 else hi
    for iteration in range(1, _MAX_ITERATIONS + 1):
        a2, q2, d3 = _secular_terms(mu, s2, p, b2)
        a, r = math.sqrt(1.0 + a2), math.sqrt(mu * mu * q2 + beta * beta)
        g = mu * a - rho * r
        if g == 0.0:
            return mu, iteration
        if g < 0.0:
            lo = mu
        else:
            hi = mu
        slope = a - mu * d3 / a - (rho * mu * d3 / r if r > 0.0 else 0.0)
        step = mu - g / slope if slope > 0.0 else math.nan
        if not lo < step < hi:
            step = math.sqrt(lo * hi) if lo > 0.0 and hi > 4.0 * lo else 0.5 * (lo + hi)
        if abs(step - mu) <= 4.0 * _EPS * step or hi - lo <= 4.0 * _EPS * hi:
            return step, iteration
        mu = step
    raise IdentificationError(
        f"RLS secular equation did not converge in {_MAX_ITERATIONS} iterations (bracket [{lo}, {hi}])"
    )


def host_float64(x: Tensor) -> np.ndarray:
    """``x`` as a numpy float64 array on the CPU (zero-copy for a CPU float64 tensor)."""
    return x.detach().to(device="cpu", dtype=torch.float64).numpy()


def stacked_rls_closed_form(W: Tensor, tau: Tensor, rho: Sequence[float]) -> list[RLSSolution]:
    """``argmin ‖Wα − τ‖ + ρ‖[α; 1]‖`` of ``T`` systems by batched SVDs of ``W[T, M, B]`` and a 1-D
    root find per trial.

    Each ``W`` must have full column rank (``M ≥ B``); ``tau`` is ``[T, M]``, ``rho`` one bound per
    trial. The SVDs and the few products around them run in numpy float64 on the CPU whatever the
    input's device and dtype: for the thin matrices of identification (``B`` ≲ 100) LAPACK through
    numpy costs a fraction of torch's per-call overhead, and float32 inputs gain float64 accuracy.
    ``alpha`` comes back on ``W``'s device and dtype.

    Raises:
        ValueError: a ``rho`` is negative or not finite.
        IdentificationError: a trial's minimiser is not unique, or its root find failed (marked
            with the trial, ``in_trial``).
    """
    for r in rho:
        if r < 0 or not math.isfinite(r):
            raise ValueError(f"RLS: rho must be a finite number >= 0, got {r}")
    Wn, tn = host_float64(W), host_float64(tau)
    U, S, Vh = np.linalg.svd(Wn, full_matrices=False)  # [T, M, B], [T, B], [T, B, B]
    b = (U.swapaxes(-1, -2) @ tn[..., None])[..., 0]  # [T, B]
    beta = np.linalg.norm(tn - (U @ b[..., None])[..., 0], axis=-1)  # [T]
    roots = []
    for t, (s, bt, beta_t) in enumerate(zip(S.tolist(), b.tolist(), beta.tolist(), strict=True)):
        try:
            mu, iterations = secular_root(s, bt, beta_t, float(rho[t]))
        except IdentificationError as error:
            raise in_trial(error, t) from None
        if mu == 0.0 and s[-1] == 0.0:
            raise in_trial(
                IdentificationError("RLS: W is rank deficient and rho = 0 — the minimiser is not unique"), t
            )
        roots.append((mu, iterations))
    mus = np.array([m for m, _ in roots])[:, None]  # [T, 1]
    alpha = (Vh.swapaxes(-1, -2) @ (b * S / (S * S + mus))[..., None])[..., 0]  # α = V diag(s/(s²+μ)) b
    alpha_t = torch.from_numpy(alpha).to(device=W.device, dtype=W.dtype)
    return [RLSSolution(alpha_t[t], m, iterations) for t, (m, iterations) in enumerate(roots)]


def rls_closed_form(W: Tensor, tau: Tensor, rho: float) -> RLSSolution:
    """``stacked_rls_closed_form`` of one system ``W[M, B]``, ``tau[M]``."""
    return stacked_rls_closed_form(W[None], tau[None], [rho])[0]


def newton_polish(
    W: np.ndarray, tau: np.ndarray, rho: float, alpha: np.ndarray, steps: int = 5
) -> np.ndarray:
    """Refine a near-optimal RLS ``alpha[B]`` by Newton steps on ``f(α) = ‖Wα − τ‖ + ρ‖[α;1]‖``.

    Why: an interior-point solver stops at a duality gap of ~1e-10·f, and along the flattest
    direction of ``f`` that leaves ``α`` only ~1e-5 accurate; the gradient, unlike ``f`` itself,
    still resolves the optimum to machine precision. Generic Newton on ``f`` (its exact gradient
    and Hessian, nothing from the secular equation) — so it stays an independent check of the
    closed form. ``f`` is smooth where ``r = Wα − τ ≠ 0``; at (numerically) zero residual ``α``
    is returned unchanged. A step is taken only if it lowers the gradient norm.
    """
    B = W.shape[1]

    def gradient_hessian(a: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        r = W @ a - tau
        nr = float(np.linalg.norm(r))
        if nr <= 1e-12 * float(np.linalg.norm(tau)):
            return None
        na = float(np.sqrt(1.0 + a @ a))
        g1 = W.T @ r
        grad = g1 / nr + rho * a / na
        hess = (W.T @ W - np.outer(g1, g1) / nr**2) / nr + rho * (np.eye(B) - np.outer(a, a) / na**2) / na
        return grad, hess

    current = gradient_hessian(alpha)
    for _ in range(steps):
        if current is None:
            break
        grad, hess = current
        try:
            candidate = alpha - np.linalg.solve(hess, grad)
        except np.linalg.LinAlgError:
            break
        trial = gradient_hessian(candidate)
        if trial is None or np.linalg.norm(trial[0]) >= np.linalg.norm(grad):
            break
        alpha, current = candidate, trial
    return alpha


#: Clarabel's tolerances for the reference path: 100x tighter than its defaults (1e-8); much
#: tighter ones end in "optimal_inaccurate" without making ``α`` more accurate.
CLARABEL_TOLERANCES = {"tol_gap_abs": 1e-10, "tol_gap_rel": 1e-10, "tol_feas": 1e-10}


def rls_cvxpy(
    W: Tensor, tau: Tensor, rho: float, solver: str | None = None, polish: bool = True
) -> tuple[np.ndarray, str, str]:
    """The SOCP of eq. (18), solved by cvxpy in float64 on the CPU, optionally Newton-polished.

    Eq. (18) divides ``W`` and ``τ`` by ``ρ``, which blows up for the ``ρ ≈ 0`` of exact data. The
    same problem multiplied through by ``ρ / c`` keeps every number O(1)::

        minimise  λ + (ρ/c) γ   s.t.  ‖(Wα − τ)/c‖ ≤ λ,  ‖[α; 1]‖ ≤ γ

    with ``c = ‖Wα_LS − τ‖ + ρ‖[α_LS; 1]‖ ≥`` the optimum (≈ it when ρ is small), so that the
    solver's gap tolerances are relative to the objective (numpy's ``lstsq`` gives ``α_LS``); but
    ``c ≥ 1e-6 ‖τ‖``, since exact data (optimum ≈ 0) would otherwise scale ``W`` up by ~1e14.

    Args:
        polish: refine the solver's ``α`` with ``newton_polish`` (the raw interior-point ``α`` is
            only ~1e-5 accurate on the paper's scenarios).

    Returns:
        ``alpha[B]`` (numpy float64), cvxpy's status and the name of the conic solver used.

    Raises:
        IdentificationError: the solver fails or reports a status other than (inaccurately) optimal.
    """
    import cvxpy as cp

    Wn, tn = host_float64(W), host_float64(tau)
    alpha_ls = np.linalg.lstsq(Wn, tn, rcond=None)[0]
    bound = float(np.linalg.norm(Wn @ alpha_ls - tn) + rho * np.sqrt(1.0 + alpha_ls @ alpha_ls))
    scale = max(bound, 1e-6 * float(np.linalg.norm(tn))) or 1.0
    alpha = cp.Variable(Wn.shape[1])
    lam, gamma = cp.Variable(), cp.Variable()
    constraints: list[cp.Constraint] = [
        cp.SOC(lam, (Wn / scale) @ alpha - tn / scale),
        cp.SOC(gamma, cp.hstack([alpha, np.ones(1)])),
    ]
    problem = cp.Problem(cp.Minimize(lam + (rho / scale) * gamma), constraints)
    options = CLARABEL_TOLERANCES if solver in (None, "CLARABEL") else {}
    try:
        problem.solve(solver=solver or "CLARABEL", **options)
    except cp.error.SolverError as exc:
        raise IdentificationError(f"RLS: cvxpy solver failed: {exc}") from exc
    used = problem.solver_stats.solver_name if problem.solver_stats else str(solver)
    if problem.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or alpha.value is None:
        raise IdentificationError(f"RLS: cvxpy ({used}) returned status {problem.status!r}, no estimate")
    values = np.asarray(alpha.value, dtype=np.float64)
    if polish:
        values = newton_polish(Wn, tn, rho, values)
    return values, problem.status, used


def rls_objective(W: Tensor, tau: Tensor, alpha: Tensor, rho: Tensor) -> Tensor:
    """``‖Wα − τ‖ + ρ‖[α; 1]‖``, the worst-case residual r of eq. (16), of each trial: ``[T]`` for
    ``W[T, M, B]``, ``tau[T, M]``, ``alpha[T, B]`` and ``rho[T]``."""
    residual = torch.linalg.vector_norm((W @ alpha[..., None])[..., 0] - tau, dim=-1)
    return residual + rho * torch.sqrt(1.0 + alpha.square().sum(-1))


@dataclass(frozen=True)
class RLSSettings(LinearSettings):
    """RLS's options, checked (``RobustLeastSquares.resolve``): the family's (``LinearSettings``) and its own.

    Attributes:
        rho: perturbation bound ``>= 0`` of eq. (17), or ``None`` = the TLS ``rho`` of each system.
        solver: ``"closed_form"`` or ``"cvxpy"``.
        cvxpy_solver: conic solver for ``"cvxpy"`` (``None`` = Clarabel, tightened tolerances).
        polish: Newton-polish the conic solver's answer.
    """

    rho: float | None
    solver: Solver
    cvxpy_solver: str | None
    polish: bool

    @classmethod
    def extend(
        cls, base: LinearSettings, rho: float | None, solver: Solver, cvxpy_solver: str | None, polish: bool
    ) -> RLSSettings:
        """``base`` with RLS's own options, or ``ValueError`` naming the option."""
        if solver not in SOLVERS:
            raise ValueError(f"rls: unknown solver {solver!r}; use one of {', '.join(SOLVERS)}")
        if rho is not None and (not math.isfinite(rho) or rho < 0):
            raise ValueError(f"rls: rho must be None or a finite number >= 0, got {rho}")
        shared = {field.name: getattr(base, field.name) for field in fields(LinearSettings)}
        return cls(**shared, rho=rho, solver=solver, cvxpy_solver=cvxpy_solver, polish=polish)


class RobustLeastSquares(LinearEstimator):
    """RLS / RLS-rel: minimise ``‖Wα − τ_s‖₂ + ρ‖[α; 1]‖₂`` (eqs. 16–18).

    Args:
        relative: solve the relative system of eqs. (36)–(37).
        rho: perturbation bound of eq. (17); ``None`` = the TLS ``ρ`` of eq. (14) on the same
            (plain or relative) system, as in the paper.
        solver: ``"closed_form"`` (SVD + secular equation, fast) or ``"cvxpy"`` (eq. 18, reference).
        cvxpy_solver: conic solver for ``solver="cvxpy"`` (``None`` = Clarabel with tightened tolerances).
        polish: with ``solver="cvxpy"``, refine the solver's answer by Newton steps on the RLS
            objective (see ``newton_polish``); ``False`` gives the raw interior-point answer.
        floor, max_cond, threads: see ``LinearEstimator``.

    A cvxpy status other than optimal raises ``IdentificationError``; ``optimal_inaccurate`` gives
    an ``IdentificationWarning``.
    """

    label = "RLS"

    def __init__(
        self,
        relative: bool = False,
        rho: float | None = None,
        solver: Solver = "closed_form",
        cvxpy_solver: str | None = None,
        polish: bool = True,
        floor: float = DEFAULT_FLOOR,
        max_cond: float | None = None,
        threads: int | None = None,
    ) -> None:
        self.rho = rho
        self.solver = solver
        self.cvxpy_solver = cvxpy_solver
        self.polish = polish
        super().__init__(relative=relative, floor=floor, max_cond=max_cond, threads=threads)

    def resolve(self) -> RLSSettings:
        """The family's options and RLS's own, checked (``ValueError`` naming the option at fault)."""
        return RLSSettings.extend(super().resolve(), self.rho, self.solver, self.cvxpy_solver, self.polish)

    def solve(
        self, system: LinearSystem, conditioning: Conditioning, log: TrialWarnings, settings: LinearSettings
    ) -> Solution:
        assert isinstance(settings, RLSSettings)  # resolve() made them
        W, tau = system.W, system.tau
        trials = W.shape[0]
        rho = smallest_singular_values(W, tau) if settings.rho is None else [float(settings.rho)] * trials
        source = "tls (eq. 14)" if settings.rho is None else "given"
        details: list[dict] = [{"rho": r, "rho_source": source} for r in rho]
        if settings.solver == "closed_form":
            solutions = stacked_rls_closed_form(W, tau, rho)
            alpha = torch.stack([sol.alpha for sol in solutions])
            for record, sol in zip(details, solutions, strict=True):
                record.update(
                    solver="closed form (svd + secular equation)", mu=sol.mu, iterations=sol.iterations
                )
        else:
            alpha = torch.stack([self._cvxpy(W, tau, rho, details, log, t, settings) for t in range(trials)])
        for record, residual in zip(details, residual_norms(system, alpha).tolist(), strict=True):
            record["residual_norm"] = residual
        values = rls_objective(W, tau, alpha, torch.tensor(rho, dtype=W.dtype, device=W.device))
        return Solution(
            alpha, "||W alpha - tau_s||_2 + rho ||[alpha; 1]||_2 (eqs. 16-18)", values.tolist(), details
        )

    def _cvxpy(
        self,
        W: Tensor,
        tau: Tensor,
        rho: list[float],
        details: list[dict],
        log: TrialWarnings,
        trial: int,
        settings: RLSSettings,
    ) -> Tensor:
        """``alpha[B]`` of trial ``trial`` of ``W[T, M, B]`` by the reference SOCP (one conic solve
        per trial); fills in ``details[trial]``."""
        try:
            values, status, used = rls_cvxpy(
                W[trial], tau[trial], rho[trial], settings.cvxpy_solver, settings.polish
            )
        except IdentificationError as error:
            raise in_trial(error, trial) from None
        if status != "optimal":
            with log.recording(trial):
                warnings.warn(
                    f"{self.name}: cvxpy ({used}) reports status {status!r}; the estimate may be inaccurate",
                    IdentificationWarning,
                    stacklevel=2,
                )
        solver = f"cvxpy ({used})" + (" + newton polish" if settings.polish else "")
        details[trial].update(solver=solver, status=status)
        return torch.as_tensor(values, dtype=W.dtype, device=W.device)
