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

from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np

from idkit.optim.robust import Loss, psi, psi_slope, rho, weights


@dataclass
class Trace:
    """What a solve did: the loss after each iteration, and the evaluations it cost."""

    losses: list[float] = field(default_factory=list)
    residuals: int = 0
    jacobians: int = 0
    status: str = "max_iter"


@dataclass(frozen=True)
class BlockJacobian:
    """A Jacobian ``[M, p]`` stored as its dense columns and its blocks.

    Attributes:
        dense: ``[M, d]`` the columns of the variables every residual may depend on.
        blocks: ``(row_start, row_stop, column_start, values [rows, k])``: the other columns, each
            block zero outside its rows (the columns are ``d, d + 1, …`` in block order).
    """

    dense: np.ndarray
    blocks: tuple[tuple[int, int, int, np.ndarray], ...] = ()

    @property
    def shape(self) -> tuple[int, int]:
        return self.dense.shape[0], self.dense.shape[1] + sum(b[3].shape[1] for b in self.blocks)

    def t_dot(self, v: np.ndarray) -> np.ndarray:
        """``Jᵀ v`` ``[p]`` of ``v[M]``."""
        out = np.zeros(self.shape[1])
        out[: self.dense.shape[1]] = self.dense.T @ v
        for row_start, row_stop, col_start, values in self.blocks:
            out[col_start : col_start + values.shape[1]] = values.T @ v[row_start:row_stop]
        return out

    def gram(self, w: np.ndarray) -> np.ndarray:
        """``Jᵀ diag(w) J`` ``[p, p]``, block by block."""
        d = self.dense.shape[1]
        weighted = w[:, None] * self.dense
        out = np.zeros((self.shape[1], self.shape[1]))
        out[:d, :d] = self.dense.T @ weighted
        for row_start, row_stop, col_start, values in self.blocks:
            columns = slice(col_start, col_start + values.shape[1])
            cross = values.T @ weighted[row_start:row_stop]
            out[columns, :d], out[:d, columns] = cross, cross.T
            out[columns, columns] = values.T @ (w[row_start:row_stop, None] * values)
        return out

    def column_blocks(self) -> list[tuple[int, int]]:
        """``(column_start, column_stop)`` of each block."""
        return [(c, c + v.shape[1]) for _, _, c, v in self.blocks]

    def broyden(self, dx: np.ndarray, dr: np.ndarray) -> BlockJacobian:
        """The Jacobian updated by a step ``dx`` that changed the residual by ``dr`` (Schubert's sparse
        Broyden update: each row moves within its own non-zeros — the dense columns and its block's —
        just enough that ``J dx = dr``)."""
        d = self.dense.shape[1]
        miss = dr - self.dense @ dx[:d]
        norm = np.full(dr.shape, float(dx[:d] @ dx[:d]))
        for row_start, row_stop, col_start, values in self.blocks:
            part = dx[col_start : col_start + values.shape[1]]
            miss[row_start:row_stop] -= values @ part
            norm[row_start:row_stop] += part @ part
        scale = np.divide(miss, norm, out=np.zeros_like(miss), where=norm > 0)
        dense = self.dense + scale[:, None] * dx[None, :d]
        blocks = tuple(
            (a, b, c, v + scale[a:b, None] * dx[None, c : c + v.shape[1]]) for a, b, c, v in self.blocks
        )
        return BlockJacobian(dense, blocks)


def gauss_newton(
    jac: BlockJacobian, r: np.ndarray, loss: Loss, k: float, hessian: str
) -> tuple[np.ndarray, np.ndarray]:
    """Gradient ``[p]`` and Gauss–Newton Hessian ``[p, p]`` of ``Σ ρ(r)`` (``hessian``: ``"newton"``
    weighs each residual by ``ρ''``, ``"irls"`` by ``ψ(r)/r``)."""
    w = weights(loss, r, k) if hessian == "irls" else np.maximum(psi_slope(loss, r, k), 0.0)
    return jac.t_dot(psi(loss, r, k)), jac.gram(w)


def _step(
    hess: np.ndarray,
    grad: np.ndarray,
    mu: float,
    x: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    dense: int,
    blocks: list[tuple[int, int]],
) -> np.ndarray | None:
    """The damped step, the blocks eliminated, ``z`` kept in its box; ``None`` if not solvable."""
    damped = hess + mu * np.diag(np.maximum(np.diag(hess), 1e-12 * max(np.diag(hess).max(), 1e-300)))
    a, g = damped[:dense, :dense].copy(), grad[:dense].copy()
    solved = []
    for col_start, col_stop in blocks:
        c = damped[col_start:col_stop, col_start:col_stop]
        b = damped[:dense, col_start:col_stop]
        try:
            inverse_bt = np.linalg.solve(c, np.column_stack([b.T, grad[col_start:col_stop]]))
        except np.linalg.LinAlgError:
            return None
        if not np.isfinite(inverse_bt).all():
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
    for (col_start, col_stop), inverse_bt in zip(blocks, solved, strict=True):
        step[col_start:col_stop] = -(inverse_bt[:, -1] + inverse_bt[:, :-1] @ dz[:, 0])
    return step


def least_squares(
    x0: np.ndarray,
    residual: Callable[[np.ndarray], np.ndarray],
    jacobian: Callable[[np.ndarray, np.ndarray], BlockJacobian],
    lower: np.ndarray,
    upper: np.ndarray,
    loss: Loss,
    k: float,
    hessian: str = "newton",
    max_iter: int = 50,
    ftol: float = 1e-8,
    xtol: float = 1e-8,
    refresh: int = 1,
) -> tuple[np.ndarray, Trace]:
    """Minimise ``Σ ρ(residual(x))`` from ``x0`` (module docstring).

    Args:
        x0: ``[p]`` the start (its first ``dense`` entries clipped into ``[lower, upper]``).
        residual: ``[M, B]`` residuals of ``[p, B]`` points.
        jacobian: the Jacobian at ``x[p, 1]`` with residual ``r[M, 1]``; its dense columns are the
            leading variables, the ones in the box.
        lower, upper: ``[d]`` the box of the dense variables.
        loss, k: the loss and its threshold in the residual's units.
        hessian: ``"newton"`` (``ρ''`` weights) or ``"irls"`` (``ψ(r)/r``).
        max_iter, ftol, xtol: the stopping rules.
        refresh: at most this many iterations on one evaluated Jacobian, updated between them by
            :meth:`BlockJacobian.broyden` (1: a new Jacobian every iteration). An updated one is
            replaced by an evaluated one as soon as its step is rejected or predicts the loss badly,
            and before any stop: a solve ends only on a step from an evaluated Jacobian.
    """
    dense = lower.size
    x = np.array(x0, dtype=np.float64)
    x[:dense] = np.clip(x[:dense], lower, upper)
    trace = Trace()
    r = residual(x[:, None])[:, 0]
    trace.residuals += 1
    value = float(rho(loss, r, k).sum())
    trace.losses.append(value)
    mu, nu = 1e-3, 2.0
    jac: BlockJacobian | None = None
    age = 0  # iterations since the Jacobian was evaluated
    for _ in range(max_iter):
        if jac is None or age >= refresh:
            jac, age = jacobian(x[:, None], r[:, None]), 0
            trace.jacobians += 1
        grad, hess = gauss_newton(jac, r, loss, k, hessian)
        attempt = _damped_step(hess, grad, mu, nu, x, value, lower, upper, jac, residual, loss, k, age > 0)
        trace.residuals += attempt.residuals
        mu, nu = attempt.mu, attempt.nu
        if attempt.status == "stale":  # an updated Jacobian's step failed: evaluate one
            age = refresh
            continue
        if attempt.status != "accepted":
            trace.status = attempt.status
            return x, trace
        step, r_new, new = attempt.step, attempt.residual, attempt.value
        moved = np.linalg.norm(step[:dense]) <= xtol * (xtol + np.linalg.norm(x[:dense]))
        reduced = value - new <= ftol * max(value, 1e-300)
        stop = (moved or reduced) and attempt.fresh  # a stop is confirmed on an evaluated Jacobian
        if refresh > 1 and attempt.ratio > 0.25 and not (moved or reduced):
            jac, age = jac.broyden(step, r_new - r), age + 1
        else:
            age = refresh
        x, r, value = x + step, r_new, new
        trace.losses.append(value)
        if stop:
            trace.status = "xtol" if moved else "ftol"
            break
    return x, trace


@dataclass
class _Attempt:
    """The outcome of one Levenberg–Marquardt iteration's damped steps."""

    status: str  # accepted, stale, no_step or no_reduction
    mu: float
    nu: float
    fresh: bool
    residuals: int = 0
    step: np.ndarray = field(default_factory=lambda: np.zeros(0))
    residual: np.ndarray = field(default_factory=lambda: np.zeros(0))
    value: float = np.inf
    ratio: float = 0.0


def _damped_step(
    hess: np.ndarray,
    grad: np.ndarray,
    mu: float,
    nu: float,
    x: np.ndarray,
    value: float,
    lower: np.ndarray,
    upper: np.ndarray,
    jac: BlockJacobian,
    residual: Callable[[np.ndarray], np.ndarray],
    loss: Loss,
    k: float,
    stale: bool,
) -> _Attempt:
    """Damp until a step lowers the loss (Nielsen's rule for ``μ``); a ``stale`` (updated) Jacobian's
    first failure hands back instead, to evaluate a new one before damping further."""
    dense, blocks = lower.size, jac.column_blocks()
    attempt = _Attempt("no_step", mu, nu, not stale)
    while True:
        step = _step(hess, grad, attempt.mu, x, lower, upper, dense, blocks)
        if step is not None:
            r_new = residual((x + step)[:, None])[:, 0]
            attempt.residuals += 1
            new = float(rho(loss, r_new, k).sum())
            predicted = -(grad @ step + 0.5 * step @ hess @ step)
            if np.isfinite(new) and new < value:
                attempt.ratio = (value - new) / predicted if predicted > 0 else 0.0
                attempt.mu *= max(1 / 3, 1 - (2 * attempt.ratio - 1) ** 3)
                attempt.nu = 2.0
                attempt.status, attempt.step, attempt.residual, attempt.value = "accepted", step, r_new, new
                return attempt
            if stale:
                attempt.status = "stale"
                return attempt
            attempt.status = "no_reduction"
        attempt.mu, attempt.nu = attempt.mu * attempt.nu, 2 * attempt.nu
        if attempt.mu > 1e12:
            return attempt
