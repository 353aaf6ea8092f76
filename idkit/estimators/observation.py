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

Equilibration (unit-norm columns) makes the test independent of the units of the base parameters:
a column that is small only because its parameter is measured in small units is not "rank
deficient", a column that is exactly zero (a parameter the trajectory never excites) is.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import torch
from torch import Tensor

from idkit.problem import IdentificationError as IdentificationError  # re-exported: the LS family raises it
from idkit.problem import Problem
from idkit.relative import DEFAULT_FLOOR, relative_denominator


class IdentificationWarning(UserWarning):
    """The estimate exists but deserves suspicion (ill-conditioning, an inaccurate solver status)."""


@dataclass(frozen=True)
class LinearSystem:
    """``W[M, B]`` and ``tau[M]`` (``M = N·n``) on the problem's device and dtype."""

    W: Tensor
    tau: Tensor
    base_names: tuple[str, ...]
    robot_name: str
    relative: bool

    @property
    def shape(self) -> tuple[int, int]:
        return self.W.shape[0], self.W.shape[1]


def linear_system(problem: Problem, relative: bool = False, floor: float = DEFAULT_FLOOR) -> LinearSystem:
    """Build ``W`` (eq. 8) and ``τ_s`` (eq. 9), or ``W_r``, ``τ_r`` (eqs. 36–37) if ``relative``.

    Args:
        problem: robot with a regressor, and samples ``[N, n]``.
        relative: divide each row by its (floored) measured torque.
        floor: near-zero torque floor, a fraction of each joint's RMS (see ``idkit.relative``).

    Raises:
        IdentificationError: the robot has no linear regressor.
    """
    robot = problem.robot
    name = type(robot).__name__
    if not robot.has_regressor:
        raise IdentificationError(
            f"robot {name} has no linear regressor (Robot.regressor), which the least-squares "
            "family (ls, tls, rls) needs; use a search-based estimator (pso, adam) instead"
        )
    s = problem.tensors()
    Y = robot.regressor(s.q, s.qd, s.qdd)  # [N, n, B]
    n_samples, n_joints, n_base = Y.shape
    if len(robot.base_param_names) != n_base:
        raise IdentificationError(
            f"robot {name}: regressor has {n_base} columns but base_param_names lists "
            f"{len(robot.base_param_names)}"
        )
    W = Y.reshape(n_samples * n_joints, n_base)
    tau = s.tau.reshape(-1)
    if relative:
        denominator = relative_denominator(s.tau.T, floor).T.reshape(-1)  # [M], sample-major
        W = W / denominator[:, None]
        tau = tau / denominator
    return LinearSystem(W, tau, tuple(robot.base_param_names), name, relative)


def default_max_cond(dtype: torch.dtype) -> float:
    """``1/√eps``: beyond it a relative data error of √eps may change the estimate by 100 %."""
    return 1.0 / math.sqrt(torch.finfo(dtype).eps)


@dataclass(frozen=True)
class Conditioning:
    """Diagnostics of ``W`` after scaling its columns to unit norm.

    ``U[M, B]``, ``sigma[B]``, ``Vh[B, B]`` is the thin SVD of ``W / scale`` (``scale[B]`` the
    column norms), kept so that LS can reuse it; ``cond = sigma[0] / sigma[-1]``.
    """

    scale: Tensor
    U: Tensor
    sigma: Tensor
    Vh: Tensor
    rank: int
    cond: float


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


def check_conditioning(system: LinearSystem, max_cond: float | None = None) -> Conditioning:
    """Rank and condition of ``W``; raises or warns per the module's policy.

    Raises:
        IdentificationError: fewer rows than base parameters, or numerical rank ``< B``.
    """
    W = system.W
    M, B = system.shape
    who = f"robot {system.robot_name}"
    if M < B:
        raise IdentificationError(
            f"{who}: {M} equations (samples × joints) cannot identify {B} base parameters "
            f"({', '.join(system.base_names)}); give at least {B} equations"
        )
    scale = torch.linalg.vector_norm(W, dim=0)  # [B]
    unexcited = [name for name, c in zip(system.base_names, scale.tolist(), strict=True) if c == 0.0]
    safe = torch.where(scale > 0, scale, torch.ones_like(scale))
    U, sigma, Vh = torch.linalg.svd(W / safe, full_matrices=False)
    eps = torch.finfo(W.dtype).eps
    tol = max(M, B) * eps * float(sigma[0]) if float(sigma[0]) > 0 else 0.0
    rank = int((sigma > tol).sum())
    if rank < B:
        what = (
            f"not excited at all (zero columns): {', '.join(unexcited)}"
            if unexcited
            else "not separable by these samples: "
            + "; ".join(_null_directions(Vh, sigma, tol, system.base_names))
        )
        raise IdentificationError(
            f"{who}: observation matrix W ({M}×{B}) has numerical rank {rank} < {B}; base "
            f"parameter combinations {what}. Use samples that excite every base parameter."
        )
    cond = float(sigma[0] / sigma[-1])
    limit = default_max_cond(W.dtype) if max_cond is None else max_cond
    if cond > limit:
        warnings.warn(
            f"{who}: observation matrix W ({M}×{B}) is ill-conditioned (column-equilibrated "
            f"condition number {cond:.3g} > {limit:.3g}); the estimate may be dominated by noise",
            IdentificationWarning,
            stacklevel=3,
        )
    return Conditioning(scale, U, sigma, Vh, rank, cond)
