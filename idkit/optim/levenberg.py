"""Levenberg–Marquardt for a robust loss of residuals, with nuisance blocks eliminated exactly.

Minimises ``Σ ρ(r(x))`` (:mod:`idkit.optim.robust`) over ``x = [z, δ_1, …, δ_S]``: ``z`` (``dense``
variables, in a box) reaches every residual, each block ``δ_s`` (unbounded) only its own rows — the
initial states of multiple-shooting segments. Each iteration builds the Gauss–Newton system
``(H + μ diag(H)) dx = −g`` (Marquardt's scaling makes the damping independent of the variables'
units), eliminates the blocks by their Schur complement (each a small dense solve), solves the reduced
bounded problem for ``dz`` with ``mujoco.mju_boxQP``, and back-substitutes. A step is accepted when it
lowers the loss; ``μ`` follows Nielsen's rule. It stops when an accepted step lowers the loss by less
than ``ftol`` of it, moves ``z`` by less than ``xtol`` (relative), or after ``max_iter`` iterations.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np

from idkit.optim.robust import Loss, psi, psi_slope, rho, weights

Blocks = Sequence[tuple[int, int, int, int]]  # (row_start, row_stop, column_start, column_stop)


@dataclass
class Trace:
    """What a solve did: the loss after each iteration, and the evaluations it cost."""

    losses: list[float] = field(default_factory=list)
    residuals: int = 0
    jacobians: int = 0
    status: str = "max_iter"


def _system(
    jac: np.ndarray, r: np.ndarray, loss: Loss, k: float, hessian: str, dense: int, blocks: Blocks
) -> tuple[np.ndarray, np.ndarray]:
    """Gradient ``[p]`` and Gauss–Newton Hessian ``[p, p]``, assembled block by block."""
    w = weights(loss, r, k) if hessian == "irls" else np.maximum(psi_slope(loss, r, k), 0.0)
    grad = jac.T @ psi(loss, r, k)
    if not blocks:
        return grad, jac.T @ (w[:, None] * jac)
    weighted = w[:, None] * jac[:, :dense]
    hess = np.zeros((jac.shape[1], jac.shape[1]))
    hess[:dense, :dense] = jac[:, :dense].T @ weighted
    for row_start, row_stop, col_start, col_stop in blocks:
        block = jac[row_start:row_stop, col_start:col_stop]
        cross = block.T @ weighted[row_start:row_stop]
        hess[col_start:col_stop, :dense], hess[:dense, col_start:col_stop] = cross, cross.T
        hess[col_start:col_stop, col_start:col_stop] = block.T @ (w[row_start:row_stop, None] * block)
    return grad, hess


def _step(
    hess: np.ndarray,
    grad: np.ndarray,
    mu: float,
    x: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    dense: int,
    blocks: Blocks,
) -> np.ndarray | None:
    """The damped step, the blocks eliminated, ``z`` kept in its box; ``None`` if not solvable."""
    damped = hess + mu * np.diag(np.maximum(np.diag(hess), 1e-12 * max(np.diag(hess).max(), 1e-300)))
    a, g = damped[:dense, :dense].copy(), grad[:dense].copy()
    solved = []
    for _, _, col_start, col_stop in blocks:
        c = damped[col_start:col_stop, col_start:col_stop]
        b = damped[:dense, col_start:col_stop]
        try:
            inverse_bt = np.linalg.solve(c, np.column_stack([b.T, grad[col_start:col_stop]]))
        except np.linalg.LinAlgError:
            return None
        a -= b @ inverse_bt[:, :-1]
        g -= b @ inverse_bt[:, -1]
        solved.append(inverse_bt)
    dz = np.zeros((dense, 1))
    scratch = np.zeros((dense, dense + 7))
    free = mujoco.mju_boxQP(
        dz,
        scratch,
        None,
        0.5 * (a + a.T),
        g[:, None],
        (lower - x[:dense])[:, None],
        (upper - x[:dense])[:, None],
    )
    if free < 0:
        return None
    step = np.zeros_like(x)
    step[:dense] = dz[:, 0]
    for (_, _, col_start, col_stop), inverse_bt in zip(blocks, solved, strict=True):
        step[col_start:col_stop] = -(inverse_bt[:, -1] + inverse_bt[:, :-1] @ dz[:, 0])
    return step


def least_squares(
    x0: np.ndarray,
    residual: Callable[[np.ndarray], np.ndarray],
    jacobian: Callable[[np.ndarray, np.ndarray], np.ndarray],
    lower: np.ndarray,
    upper: np.ndarray,
    loss: Loss,
    k: float,
    dense: int | None = None,
    blocks: Blocks = (),
    hessian: str = "newton",
    max_iter: int = 50,
    ftol: float = 1e-8,
    xtol: float = 1e-8,
) -> tuple[np.ndarray, Trace]:
    """Minimise ``Σ ρ(residual(x))`` from ``x0`` (module docstring).

    Args:
        x0: ``[p]`` the start (its first ``dense`` entries clipped into ``[lower, upper]``).
        residual: ``[M, B]`` residuals of ``[p, B]`` points.
        jacobian: ``[M, p]`` at ``x[p, 1]`` with residual ``r[M, 1]``.
        lower, upper: ``[dense]`` the box of the dense variables.
        loss, k: the loss and its threshold in the residual's units.
        dense: how many leading variables are dense (default all: no blocks).
        blocks: the other variables' ``(row_start, row_stop, column_start, column_stop)``.
        hessian: ``"newton"`` (``ρ''`` weights) or ``"irls"`` (``ψ(r)/r``).
        max_iter, ftol, xtol: the stopping rules.
    """
    dense = x0.size if dense is None else dense
    x = np.array(x0, dtype=np.float64)
    x[:dense] = np.clip(x[:dense], lower, upper)
    trace = Trace()
    r = residual(x[:, None])[:, 0]
    trace.residuals += 1
    value = float(rho(loss, r, k).sum())
    trace.losses.append(value)
    mu, nu = 1e-3, 2.0
    for _ in range(max_iter):
        jac = jacobian(x[:, None], r[:, None])
        trace.jacobians += 1
        grad, hess = _system(jac, r, loss, k, hessian, dense, blocks)
        while True:
            step = _step(hess, grad, mu, x, lower, upper, dense, blocks)
            if step is None:
                mu, nu = mu * nu, 2 * nu
                if mu > 1e12:
                    trace.status = "no_step"
                    return x, trace
                continue
            candidate = x + step
            r_new = residual(candidate[:, None])[:, 0]
            trace.residuals += 1
            new = float(rho(loss, r_new, k).sum())
            predicted = -(grad @ step + 0.5 * step @ hess @ step)
            if np.isfinite(new) and new < value:
                ratio = (value - new) / predicted if predicted > 0 else 0.0
                mu *= max(1 / 3, 1 - (2 * ratio - 1) ** 3)
                nu = 2.0
                break
            mu, nu = mu * nu, 2 * nu
            if mu > 1e12:
                trace.status = "no_reduction"
                return x, trace
        moved = np.linalg.norm(step[:dense]) <= xtol * (xtol + np.linalg.norm(x[:dense]))
        reduced = value - new <= ftol * max(value, 1e-300)
        x, r, value = candidate, r_new, new
        trace.losses.append(value)
        if moved or reduced:
            trace.status = "xtol" if moved else "ftol"
            break
    return x, trace
