"""The linear system ``W α ≈ τ_s`` of the least-squares family, and when to refuse to solve it.

``W`` stacks the robot's regressor over the samples (eq. 8) and ``τ_s`` the measured torques
(eq. 9), sample-major: rows ``i·n … i·n + n − 1`` belong to sample ``i``. The relative variant
(eqs. 36–37) divides every row by its measured torque. Near-zero torques follow the one policy of
``idkit.relative`` (floored at ``floor × joint RMS``, with a ``RelativeFloorWarning``), so
the LS-rel criterion ``‖τ_r − W_r α‖₂`` is exactly the relative PSO cost f9 = ‖E_rel‖_F. Where a
torque is floored, ``τ_r`` is ``τ/floored`` rather than the paper's 1 — that keeps the identity.

Policy for bad systems (never a silent garbage estimate):

- ``W`` of numerical rank ``< B`` (column-equilibrated, tolerance ``max(M, B)·eps(dtype)``) raises
  ``IdentificationError`` naming the rank and the base-parameter combinations the data cannot
  separate (the null directions of ``W``).
- A full-rank but ill-conditioned ``W`` (equilibrated condition number above ``max_cond``; by
  default ``1/√eps`` of the dtype, ≈ 6.7e7 in float64 and ≈ 2.9e3 in float32, beyond which a
  perturbation of √eps in the data can move the estimate by O(1)) gives an
  ``IdentificationWarning`` and is recorded in the estimate's ``details["warnings"]``.

The least-squares family works on stacks of trials (``stacked_system``: ``W[T, M, B]``,
``τ_s[T, M]``; one problem is a stack of one): a study's thousands of noise draws are solved by a
few batched decompositions instead of thousands of small ones. Every check is made per trial and
names the failing trial (``idkit.estimators.trials.in_trial``).

Equilibration (unit-norm columns) makes the test independent of the units of the base parameters:
a column that is small only because its parameter is measured in small units is not "rank
deficient", a column that is exactly zero (a parameter the trajectory never excites) is.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from contextlib import nullcontext
from dataclasses import dataclass, replace

import torch
from torch import Tensor

from idkit.estimators.trials import TrialWarnings, in_trial
from idkit.problem import IdentificationError as IdentificationError  # re-exported: the LS family raises it
from idkit.problem import Problem
from idkit.relative import DEFAULT_FLOOR, relative_denominator


class IdentificationWarning(UserWarning):
    """The estimate exists but deserves suspicion (ill-conditioning, an inaccurate solver status)."""


@dataclass(frozen=True)
class LinearSystem:
    """``W[..., M, B]`` and ``tau[..., M]`` (``M = N·n``) on the problems' device and dtype: one
    problem's system (``linear_system``) or ``T`` trials' stacked along a leading dimension
    (``stacked_system``)."""

    W: Tensor
    tau: Tensor
    base_names: tuple[str, ...]
    robot_name: str
    relative: bool

    @property
    def shape(self) -> tuple[int, int]:
        """``(M, B)``: equations and base parameters of each system."""
        return self.W.shape[-2], self.W.shape[-1]


def stacked_system(
    problems: Sequence[Problem],
    relative: bool = False,
    floor: float = DEFAULT_FLOOR,
    log: TrialWarnings | None = None,
) -> LinearSystem:
    """``W[T, M, B]`` (eq. 8) and ``τ_s[T, M]`` (eq. 9) of ``T`` trials, or eqs. 36–37 if ``relative``.

    A regressor row depends only on its own sample's state (rigid-body dynamics are
    instantaneous), so the trials' states are concatenated and the regressor is called once.

    Args:
        problems: trials of one robot and sample shape ``[N, n]``, on one device and dtype.
        relative: divide each row by its (floored) measured torque; the floor uses each trial's
            own joint RMS.
        floor: near-zero torque floor, a fraction of each joint's RMS (see ``idkit.relative``).
        log: where each trial's floor warnings go (``None``: straight to the caller).

    Raises:
        IdentificationError: the robot has no linear regressor, or its column count differs from
            its base parameter names.
        ValueError: a trial's relative error is undefined (marked with its trial).
    """
    robot = problems[0].robot
    name = type(robot).__name__
    if not robot.has_regressor:
        raise IdentificationError(
            f"robot {name} has no linear regressor (Robot.regressor), which the least-squares "
            "family (ls, tls, rls) needs; use a search-based estimator (pso, adam) instead"
        )
    samples = [p.tensors() for p in problems]
    states = [torch.cat([getattr(s, k) for s in samples]) for k in ("q", "qd", "qdd")]
    Y = robot.regressor(*states)  # [T·N, n, B]
    n_base = Y.shape[-1]
    if len(robot.base_param_names) != n_base:
        raise IdentificationError(
            f"robot {name}: regressor has {n_base} columns but base_param_names lists "
            f"{len(robot.base_param_names)}"
        )
    trials, (n_samples, n_joints) = len(samples), samples[0].tau.shape
    W = Y.reshape(trials, n_samples * n_joints, n_base)
    tau = torch.stack([s.tau for s in samples]).reshape(trials, -1)
    if relative:
        denominator = relative_denominators(torch.stack([s.tau.mT for s in samples]), floor, log)
        denominator = denominator.mT.reshape(trials, -1)  # [T, M], sample-major
        W = W / denominator[..., None]
        tau = tau / denominator
    return LinearSystem(W, tau, tuple(robot.base_param_names), name, relative)


def relative_denominators(measured: Tensor, floor: float, log: TrialWarnings | None) -> Tensor:
    """``relative_denominator`` of each trial's ``measured[T, n, N]``, with each trial's own floor
    warning (to ``log``, or the caller if ``None``) or error (marked with the trial).

    One batched call serves the usual case of nothing to floor; only when it warns or fails are
    the trials redone one by one, so that each warning or error belongs to its trial.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            batched = relative_denominator(measured, floor)
        except ValueError:
            batched = None
    if batched is not None and not caught:
        return batched
    denominators = []
    for t, trial in enumerate(measured):
        with nullcontext() if log is None else log.recording(t):
            try:
                denominators.append(relative_denominator(trial, floor))
            except ValueError as error:
                raise in_trial(error, t) from None
    return torch.stack(denominators)


def linear_system(problem: Problem, relative: bool = False, floor: float = DEFAULT_FLOOR) -> LinearSystem:
    """``W[M, B]`` (eq. 8) and ``τ_s[M]`` (eq. 9) of one problem, or ``W_r``, ``τ_r`` (eqs. 36–37).

    Args:
        problem: robot with a regressor, and samples ``[N, n]``.
        relative: divide each row by its (floored) measured torque.
        floor: near-zero torque floor, a fraction of each joint's RMS (see ``idkit.relative``).

    Raises:
        IdentificationError: the robot has no linear regressor.
    """
    stack = stacked_system([problem], relative, floor)
    return replace(stack, W=stack.W[0], tau=stack.tau[0])


def default_max_cond(dtype: torch.dtype) -> float:
    """``1/√eps``: beyond it a relative data error of √eps may change the estimate by 100 %."""
    return 1.0 / math.sqrt(torch.finfo(dtype).eps)


@dataclass(frozen=True)
class Conditioning:
    """Diagnostics of each trial's ``W[T, M, B]`` after scaling its columns to unit norm.

    ``U[T, M, B]``, ``sigma[T, B]``, ``Vh[T, B, B]`` is the thin SVD of ``W / scale`` (``scale[T, B]``
    the column norms), kept so that LS can reuse it; per trial, ``cond = sigma[0] / sigma[-1]``.
    """

    scale: Tensor
    U: Tensor
    sigma: Tensor
    Vh: Tensor
    rank: list[int]
    cond: list[float]


def _null_directions(Vh: Tensor, sigma: Tensor, tol: float, names: tuple[str, ...]) -> list[str]:
    """Human-readable null directions of the equilibrated ``W`` (terms with |weight| ≥ 0.05)."""
    out = []
    for row in Vh[sigma <= tol].tolist():
        big = max(row, key=abs)
        terms = [
            f"{w / big:+.3g}*{name}" for w, name in zip(row, names, strict=True) if abs(w) >= 0.05 * abs(big)
        ]
        out.append(" ".join(terms))
    return out


def check_conditioning(system: LinearSystem, max_cond: float | None, log: TrialWarnings) -> Conditioning:
    """Rank and condition of each trial's ``W[T, M, B]``; raises or warns per the module's policy.

    One batched SVD; the checks are per trial, the warnings recorded in ``log``.

    Raises:
        IdentificationError: fewer rows than base parameters, a non-finite entry, or numerical
            rank ``< B`` (marked with the failing trial).
    """
    W, tau = system.W, system.tau
    M, B = system.shape
    who = f"robot {system.robot_name}"
    if M < B:
        raise in_trial(
            IdentificationError(
                f"{who}: {M} equations (samples × joints) cannot identify {B} base parameters "
                f"({', '.join(system.base_names)}); give at least {B} equations"
            ),
            0,
        )
    finite = (torch.isfinite(W).all(-1).all(-1) & torch.isfinite(tau).all(-1)).tolist()
    if not all(finite):
        t = finite.index(False)
        raise in_trial(
            IdentificationError(
                f"{who}: the linear system W alpha = tau_s has non-finite entries "
                f"({int((~torch.isfinite(W[t])).sum())} in W, {int((~torch.isfinite(tau[t])).sum())} "
                "in tau_s): the robot's regressor or the relative denominators overflowed"
            ),
            t,
        )
    scale = torch.linalg.vector_norm(W, dim=-2)  # [T, B]
    safe = torch.where(scale > 0, scale, torch.ones_like(scale))
    U, sigma, Vh = torch.linalg.svd(W / safe[..., None, :], full_matrices=False)
    tol = max(M, B) * torch.finfo(W.dtype).eps * sigma[..., 0]  # [T]; 0 where sigma_max is 0
    rank = (sigma > tol[..., None]).sum(-1).tolist()
    cond = (sigma[..., 0] / sigma[..., -1]).tolist()
    limit = default_max_cond(W.dtype) if max_cond is None else max_cond
    for t in range(len(rank)):
        if rank[t] < B:
            unexcited = [n for n, c in zip(system.base_names, scale[t].tolist(), strict=True) if c == 0.0]
            what = (
                f"not excited at all (zero columns): {', '.join(unexcited)}"
                if unexcited
                else "not separable by these samples: "
                + "; ".join(_null_directions(Vh[t], sigma[t], float(tol[t]), system.base_names))
            )
            raise in_trial(
                IdentificationError(
                    f"{who}: observation matrix W ({M}×{B}) has numerical rank {rank[t]} < {B}; base "
                    f"parameter combinations {what}. Use samples that excite every base parameter."
                ),
                t,
            )
        if cond[t] > limit:
            with log.recording(t):
                warnings.warn(
                    f"{who}: observation matrix W ({M}×{B}) is ill-conditioned (column-equilibrated "
                    f"condition number {cond[t]:.3g} > {limit:.3g}); the estimate may be dominated by noise",
                    IdentificationWarning,
                    stacklevel=2,
                )
    return Conditioning(scale, U, sigma, Vh, rank, cond)
