"""Numerical base parameters of a linear-in-parameters model ``tau = W p``.

The standard parameters ``p[P]`` of a robot are not all identifiable: some columns of the
regressor are identically zero, others are fixed linear combinations of earlier ones (e.g. the
mass of a distal link acts like a first moment of its parent). Stacking the regressor over many
random states gives ``W[M, P]`` whose column space is the structural one; from it:

* **base columns** are chosen greedily in the standard order: a column is kept when its
  component orthogonal to the columns already kept is larger than ``tolerance`` times its norm
  (Gram–Schmidt on unit-norm columns, reorthogonalised). Walking in the standard order (links from
  the root outwards, ``m, mc, I`` within a link) regroups distal parameters onto proximal ones, as
  the classical symbolic rules do (Khalil & Dombre's ``MX_{j-1}R = MX_{j-1} + a_j M_j``), so each
  base parameter is named after a standard parameter and reads like the textbook groups. A pivoted
  QR would pick the columns by norm instead, which is rank-revealing too but mixes the names.
* **regrouping**: every dependent column satisfies ``W_d = W_b beta`` exactly (structurally, for
  all states); ``beta`` is fitted by least squares on the stacked states. Then
  ``tau = W p = W_b (p_b + beta p_d) = W_b alpha`` with ``alpha = K p``, ``K[B, P]`` having the
  identity on the base columns and ``beta`` on the dependent ones.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BaseParameters:
    """The map from standard to base parameters.

    Attributes:
        indices: ``[B]`` standard-parameter columns kept as base columns, increasing.
        matrix: ``K[B, P]`` with ``alpha = K @ p``; ``K[:, indices]`` is the identity.
        singular_ratio: smallest/largest singular value of the unit-norm base columns: a
            well-separated ratio (not ~``tolerance``) says the rank decision was clear-cut.
        residual: largest relative residual of ``W_d - W_b beta`` (should be round-off).
    """

    indices: tuple[int, ...]
    matrix: np.ndarray
    singular_ratio: float
    residual: float

    def groups(self, names: Sequence[str], digits: int = 6) -> tuple[str, ...]:
        """Readable ``alpha_k = p_base + sum beta p_dep`` expressions, one per base parameter."""
        out = []
        for k, row in enumerate(self.matrix):
            terms = [names[self.indices[k]]]
            for j in np.flatnonzero(row).tolist():
                if j != self.indices[k]:
                    terms.append(f"{row[j]:+.{digits}g}*{names[j]}")
            out.append(" ".join(terms))
        return tuple(out)


def find_base_parameters(stacked: np.ndarray, tolerance: float = 1e-8) -> BaseParameters:
    """Base columns and regrouping matrix of a stacked regressor ``stacked[M, P]`` (``M >> P``).

    Args:
        stacked: the regressor evaluated on many random states, rows stacked.
        tolerance: relative size below which a column (or its new orthogonal component) counts as
            zero. Structural dependencies leave ~1e-14; independent columns of a generic robot
            leave far more.

    Raises:
        ValueError: when ``stacked`` has fewer rows than columns, or when the regrouping does not
            reproduce the dependent columns (the rank decision was not clear-cut at ``tolerance``).
    """
    n_rows, n_cols = stacked.shape
    if n_rows < n_cols:
        raise ValueError(f"base parameters: need more stacked rows than columns, got {stacked.shape}")
    norms = np.linalg.norm(stacked, axis=0)
    biggest = norms.max()
    basis = np.zeros((n_rows, 0))
    kept: list[int] = []
    for j in range(n_cols):
        if norms[j] <= tolerance * biggest:
            continue  # an identically zero column: unidentifiable parameter
        residual = stacked[:, j] / norms[j]
        for _ in range(2):  # twice is enough (Kahan–Parlett)
            residual = residual - basis @ (basis.T @ residual)
        size = np.linalg.norm(residual)
        if size > tolerance:
            kept.append(j)
            basis = np.column_stack([basis, residual / size])
    if not kept:
        raise ValueError("base parameters: the stacked regressor is zero (no identifiable parameter)")
    zero = [j for j in range(n_cols) if norms[j] <= tolerance * biggest]  # alpha ignores them
    dependent = [j for j in range(n_cols) if j not in kept and j not in zero]
    scaled_base = stacked[:, kept] / norms[kept]
    singular = np.linalg.svd(scaled_base, compute_uv=False)
    matrix = np.zeros((len(kept), n_cols))
    matrix[:, kept] = np.eye(len(kept))
    residual = 0.0
    if dependent:
        # Unit-norm columns on both sides: beta_unit[i, j] is the share of base column i in dependent j.
        beta_unit, *_ = np.linalg.lstsq(scaled_base, stacked[:, dependent] / norms[dependent], rcond=None)
        misfit = scaled_base @ beta_unit - stacked[:, dependent] / norms[dependent]
        residual = float(np.linalg.norm(misfit, axis=0).max())
        if residual > np.sqrt(tolerance):
            raise ValueError(
                f"base parameters: the dependent columns are not reproduced (relative residual "
                f"{residual:.2e}); the rank decision at tolerance={tolerance:g} is not clear-cut"
            )
        beta_unit[np.abs(beta_unit) < tolerance] = 0.0  # round-off, not a structural share
        matrix[:, dependent] = beta_unit * norms[dependent] / norms[kept][:, None]
    return BaseParameters(tuple(kept), matrix, float(singular[-1] / singular[0]), residual)
