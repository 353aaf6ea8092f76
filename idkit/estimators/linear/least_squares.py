"""Least squares (eqs. 10–11) and total least squares (eqs. 12–15), plain and relative (eqs. 36–37).

Both solve in the base parameters ``α`` of ``robot.regressor`` and report physical parameters via
``robot.params_from_base``. Neither forms ``WᵀW``: LS uses the SVD of the column-equilibrated ``W``
(already computed for the rank check, and backward stable where the normal equations square the
condition number); TLS uses the SVD of ``[W | τ_s]`` (Golub & Van Loan). ``LinearEstimator`` is the
shared ``fit`` of the family (``rls`` too): build the system, check it, solve, report.

The family works on stacks of trials: ``fit_trials`` builds ``W[T, M, B]`` for ``T`` trials (a
study's noise draws) and every decomposition is one batched call, so a trial costs a few
microseconds of arithmetic instead of a millisecond of per-call overhead; ``fit`` is a stack of one.
Each trial's estimate is the one ``fit`` gives it — every check, warning and ``details`` entry is
per trial — except for the batch's shared wall time (``wall_time_s`` is its share,
``details["batch_wall_time_s"]`` the whole) and ``details["batched_trials"]``.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import torch
from torch import Tensor

from idkit.estimate import Estimate, to_python
from idkit.estimators.linear.observation import (
    Conditioning,
    IdentificationError,
    IdentificationWarning,
    LinearSystem,
    check_conditioning,
    default_max_cond,
    stacked_system,
)
from idkit.estimators.linear.uncertainty import base_uncertainties
from idkit.estimators.trials import TrialWarnings, fit_stacked_systems, in_trial
from idkit.interfaces import Cost, Estimator
from idkit.problem import Problem
from idkit.relative import DEFAULT_FLOOR
from idkit.runtime import resolve_threads, torch_threads


@dataclass
class Solution:
    """What a solver hands back to ``LinearEstimator``: ``alpha[T, B]``, its own criterion, and per
    trial the criterion's value and the solver's ``details``."""

    alpha: Tensor
    criterion: str
    values: list[float]
    details: list[dict[str, Any]] = field(default_factory=list)


@dataclass(frozen=True)
class LinearSettings:
    """A least-squares estimator's options, checked: what its fit reads.

    The estimator keeps every option unchanged under its own name (the plugin contract, so a config
    maps onto the constructor); ``resolve()`` makes this typed, checked copy from them, at
    construction (an early refusal) and at every fit (so that a changed option counts).

    Attributes:
        relative: solve the relative system of eqs. (36)–(37).
        floor: near-zero torque floor of the relative system, ``>= 0`` (``idkit.relative``).
        max_cond: warning threshold ``> 0`` of the equilibrated condition number; ``None`` = ``1/√eps``
            of the problem's dtype (known only at the fit).
        threads: torch intra-op threads ``>= 1``; ``None`` = ``idkit.runtime``'s size rule.
    """

    relative: bool
    floor: float
    max_cond: float | None
    threads: int | None

    @classmethod
    def checked(
        cls, who: str, relative: bool, floor: float, max_cond: float | None, threads: int | None
    ) -> LinearSettings:
        """The settings, or ``ValueError`` naming ``who`` and the option a fit could not use."""
        if not (math.isfinite(floor) and floor >= 0):
            raise ValueError(f"{who}: floor must be a finite number >= 0, got {floor!r}")
        if max_cond is not None and not max_cond > 0:
            raise ValueError(f"{who}: max_cond must be None or a number > 0, got {max_cond!r}")
        if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
            raise ValueError(f"{who}: threads must be None or an integer >= 1, got {threads!r}")
        return cls(relative, float(floor), max_cond, threads)

    def condition_limit(self, dtype: torch.dtype) -> float:
        """``max_cond``, or ``1/√eps`` of ``dtype`` when it is ``None``."""
        return default_max_cond(dtype) if self.max_cond is None else self.max_cond


class LinearEstimator(Estimator):
    """``fit`` and ``fit_trials`` of the least-squares family; subclasses implement ``solve``.

    Warnings raised while fitting a trial (near-zero torques floored, ill-conditioning, an
    inaccurate solver) are both re-issued to the caller and listed in that trial's
    ``details["warnings"]``. An error in one trial of a batch (rank deficiency, ...) is the
    error that trial's ``fit`` raises, its message prefixed with the trial's index and seed.

    Args:
        relative: solve the relative system of eqs. (36)–(37) (labels "LS-rel", ...).
        floor: near-zero torque floor of the relative system (see ``idkit.relative``).
        max_cond: warn above this column-equilibrated condition number of ``W``; ``None`` =
            ``1/√eps`` of the problem's dtype (see ``idkit.estimators.linear.observation``).
        threads: torch intra-op threads during the fit; ``None`` = ``idkit.runtime``'s size rule
            (one thread for the paper's problems; docs/speed.md, "Measurements behind design
            choices").
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
        self.resolve()  # a bad option is refused now; every fit resolves again (idkit.hyperparameters)

    def resolve(self) -> LinearSettings:
        """The options checked (``ValueError`` naming the option at fault)."""
        who = self.label.lower()
        return LinearSettings.checked(who, self.relative, self.floor, self.max_cond, self.threads)

    def solve(
        self, system: LinearSystem, conditioning: Conditioning, log: TrialWarnings, settings: LinearSettings
    ) -> Solution:
        """Base parameters ``alpha[T, B]`` of the checked systems, under the fit's ``settings``
        (``resolve()``); trial ``t``'s warnings go to ``log.recording(t)``, its errors are marked with
        ``in_trial``."""
        raise NotImplementedError

    @property
    def name(self) -> str:
        return f"{self.label}-rel" if self.relative else self.label

    def fit(self, problem: Problem) -> Estimate:
        """Fit one problem (a stack of one trial)."""
        return self._fit_stack([problem])[0][0]

    def fit_trials(
        self, problems: Sequence[Problem], costs: Sequence[Cost] | None = None, chunk: int | None = None
    ) -> list[list[Estimate]]:
        """One estimate per trial, each the one the trial's own ``fit`` gives, from batched solves.

        Args:
            problems: ``T`` trials of one robot, device and dtype (trials of equal sample counts
                are stacked).
            costs: ignored: the criterion is fixed (each estimate's ``cost`` is its problem's
                ``cost`` at the estimate, as in ``fit``).
            chunk: trials per stack; ``None``: as many as fit ``CHUNK_ELEMENTS`` elements of ``W``.

        Returns:
            ``T`` lists of one estimate.

        Raises:
            IdentificationError: a trial cannot be fitted; the message starts with
                ``trial <index> (seed <seed>):`` and goes on as that trial's ``fit`` would.
        """
        return fit_stacked_systems(problems, chunk, self._fit_stack)

    def _fit_stack(self, problems: list[Problem]) -> list[list[Estimate]]:
        """``fit_trials`` of one stack of trials with equal sample counts."""
        start = time.perf_counter()
        robot, trials = problems[0].robot, len(problems)
        work = trials * problems[0].samples.tau.numel() * len(robot.base_param_names)
        settings = self.resolve()
        threads = resolve_threads(settings.threads, work)
        log = TrialWarnings(trials)
        try:
            with torch_threads(threads), torch.no_grad():
                system = stacked_system(problems, settings.relative, settings.floor, log)
                conditioning = check_conditioning(system, settings.max_cond, log)
                solution = self.solve(system, conditioning, log, settings)
                params = robot.params_from_base(solution.alpha)  # [T, P]
                costs = self._costs(problems, params, solution, log)
                uncertainty = base_uncertainties(
                    system.W,
                    system.tau,
                    solution.alpha,
                    system.base_names,
                    conditioning,
                    robot.unidentifiable,
                    joints=robot.n_joints,
                )
        finally:  # every trial's warnings, also when a later trial fails
            log.reissue()
        wall = time.perf_counter() - start
        M, _ = system.shape
        max_cond = settings.condition_limit(system.W.dtype)
        place = {"device": str(system.W.device), "threads": threads}
        dtype = str(system.W.dtype).removeprefix("torch.")
        alpha, values = solution.alpha.tolist(), params.tolist()
        return [
            [
                Estimate(
                    estimator=self.name,
                    params=dict(zip(robot.param_names, values[t], strict=True)),
                    cost=costs[t],
                    wall_time_s=wall / trials,
                    base_params=dict(zip(system.base_names, alpha[t], strict=True)),
                    details=to_python(
                        {
                            "criterion": solution.criterion,
                            "criterion_value": solution.values[t],
                            "relative": settings.relative,
                            "floor": settings.floor,
                            "equations": M,
                            "rank": conditioning.rank[t],
                            "cond": conditioning.cond[t],
                            "max_cond": max_cond,
                            **solution.details[t],
                            **uncertainty[t].to_details(),
                            **place,
                            "dtype": dtype,
                            "warnings": log.messages(t),
                            "batched_trials": trials,
                            "batch_wall_time_s": wall,
                        }
                    ),
                )
            ]
            for t in range(trials)
        ]

    def _costs(
        self, problems: list[Problem], params: Tensor, solution: Solution, log: TrialWarnings
    ) -> list[float]:
        """Each estimate's ``cost``: its problem's cost at ``params[T, P]`` if it has one, else the
        criterion's value; warns about parameters that are not finite."""
        for t, finite in enumerate(torch.isfinite(params).all(-1).tolist()):
            if not finite:
                with log.recording(t):
                    warnings.warn(
                        f"{self.name}: physical parameters {params[t].tolist()} are not finite "
                        f"(base parameters {solution.alpha[t].tolist()}; params_from_base divides by "
                        "an estimate that came out 0)",
                        IdentificationWarning,
                        stacklevel=2,
                    )
        costs = list(solution.values)
        for t, problem in enumerate(problems):
            if problem.cost is not None:
                with log.recording(t):
                    costs[t] = float(problem.evaluate(params[t]))
        return costs


def residual_norms(system: LinearSystem, alpha: Tensor) -> Tensor:
    """``‖τ_s − W α‖₂`` (eq. 10) of each trial: ``[T]`` for ``alpha[T, B]``."""
    return torch.linalg.vector_norm(system.tau - (system.W @ alpha[..., None])[..., 0], dim=-1)


class LeastSquares(LinearEstimator):
    """LS / LS-rel: ``argmin ‖τ_s − W α‖₂`` (eq. 10).

    Solved with the SVD of the column-equilibrated ``W`` (``W D⁻¹ = U S Vᵀ``, ``α = D⁻¹ V S⁻¹ Uᵀ
    τ_s``), the decomposition the rank check already made. Eq. (11)'s ``(WᵀW)⁻¹`` is never formed.
    """

    label = "LS"

    def solve(
        self, system: LinearSystem, conditioning: Conditioning, log: TrialWarnings, settings: LinearSettings
    ) -> Solution:
        c = conditioning
        projected = (c.U.mT @ system.tau[..., None]) / c.sigma[..., None]  # [T, B, 1]
        alpha = (c.Vh.mT @ projected)[..., 0] / c.scale
        values = residual_norms(system, alpha).tolist()
        return Solution(
            alpha,
            "||tau_s - W alpha||_2 (eq. 10)",
            values,
            [{"solver": "svd of column-equilibrated W"} for _ in values],
        )


@dataclass(frozen=True)
class TLSSolution:
    """``alpha[B]``, ``rho`` = ‖[ΔW | Δτ]‖_F (eq. 14) and the existence gap ``σ_B(W) − rho``."""

    alpha: Tensor
    rho: float
    gap: float
    sigma_max: float


def smallest_singular_values(W: Tensor, tau: Tensor) -> list[float]:
    """``σ_{B+1}([W | τ])`` of each ``W[T, M, B]``, ``tau[T, M]``: the TLS ``rho`` of eq. (14); 0 when
    ``[W | τ]`` has fewer rows than columns."""
    C = torch.cat((W, tau[..., None]), dim=-1)
    if C.shape[-2] < C.shape[-1]:
        return [0.0] * C.shape[0]
    return torch.linalg.svdvals(C)[..., -1].tolist()


def stacked_total_least_squares(W: Tensor, tau: Tensor) -> list[TLSSolution]:
    """Classical TLS (Golub & Van Loan) of ``T`` systems in one batched SVD: the right singular
    vector ``v`` of ``[W | τ]`` for its smallest singular value gives ``α = −v[:B] / v[B]``; ``rho``
    is that singular value.

    Args:
        W: ``[T, M, B]`` with ``M ≥ B`` and full column rank.
        tau: ``[T, M]``.

    Raises:
        IdentificationError: a trial's TLS problem has no unique solution (``σ_B(W) ≤
            σ_{B+1}([W|τ])`` to working precision — then ``v[B]`` is 0 or the minimiser is not
            unique); marked with the trial (``in_trial``).
    """
    M, B = W.shape[-2:]
    C = torch.cat((W, tau[..., None]), dim=-1)  # [T, M, B+1]
    _, S, Vh = torch.linalg.svd(C, full_matrices=M < B + 1)
    v = Vh[..., -1, :]  # [T, B+1], right singular vector of the smallest singular value
    rho = S[..., -1] if M >= B + 1 else torch.zeros_like(S[..., -1])
    sigma_w = torch.linalg.svdvals(W)[..., -1]
    sigma_max = S[..., 0]
    gap = sigma_w - rho
    tol = max(M, B + 1) * torch.finfo(W.dtype).eps * sigma_max
    alpha = -v[..., :B] / v[..., B:]
    rho_, gap_, sigma_max_ = rho.tolist(), gap.tolist(), sigma_max.tolist()
    for t, unique in enumerate((gap > tol).tolist()):
        if not unique:
            raise in_trial(
                IdentificationError(
                    "total least squares has no unique solution: smallest singular value of W "
                    f"({float(sigma_w[t]):.6g}) does not exceed that of [W | tau_s] ({rho_[t]:.6g}); τ_s "
                    "is (nearly) orthogonal to the smallest right singular direction of W"
                ),
                t,
            )
    return [TLSSolution(alpha[t], rho_[t], gap_[t], sigma_max_[t]) for t in range(len(rho_))]


def total_least_squares(W: Tensor, tau: Tensor) -> TLSSolution:
    """``stacked_total_least_squares`` of one system ``W[M, B]``, ``tau[M]``."""
    return stacked_total_least_squares(W[None], tau[None])[0]


class TotalLeastSquares(LinearEstimator):
    """TLS / TLS-rel (eqs. 12–15): the smallest perturbation ``Δ = [ΔW | Δτ]`` that makes the system
    consistent. Own criterion: ``rho = ‖Δ‖_F`` (eq. 14). ``details["tls_cond"] = σ_1 / (σ_B(W) −
    rho)`` measures how close the problem is to having no solution; it is warned about above
    ``max_cond`` like the condition number of ``W``.
    """

    label = "TLS"

    def solve(
        self, system: LinearSystem, conditioning: Conditioning, log: TrialWarnings, settings: LinearSettings
    ) -> Solution:
        solutions = stacked_total_least_squares(system.W, system.tau)
        alpha = torch.stack([tls.alpha for tls in solutions])
        residuals = residual_norms(system, alpha).tolist()
        limit = settings.condition_limit(system.W.dtype)
        details = []
        for t, tls in enumerate(solutions):
            tls_cond = tls.sigma_max / tls.gap
            if tls_cond > limit:
                with log.recording(t):
                    warnings.warn(
                        f"{self.name}: the TLS problem of robot {system.robot_name} is nearly degenerate "
                        f"(sigma_1 / (sigma_B(W) - rho) = {tls_cond:.3g} > {limit:.3g})",
                        IdentificationWarning,
                        stacklevel=2,
                    )
            details.append(
                {
                    "solver": "svd of [W | tau_s]",
                    "rho": tls.rho,
                    "tls_cond": tls_cond,
                    "residual_norm": residuals[t],
                }
            )
        return Solution(alpha, "rho = ||[dW | dtau]||_F (eq. 14)", [tls.rho for tls in solutions], details)
