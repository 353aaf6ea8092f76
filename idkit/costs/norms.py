"""Matrix norms of error matrices ``E[..., n, N]`` (joints × samples), batched over ``...``.

Induced norms follow the paper's definitions on the n × N matrix: the 1-norm is the largest
column (sample) absolute sum, the ∞-norm the largest row (joint) absolute sum, the 2-norm the
largest singular value.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor


def frobenius(e: Tensor) -> Tensor:
    return e.square().sum(dim=(-2, -1)).sqrt()


def spectral(e: Tensor) -> Tensor:
    return torch.linalg.matrix_norm(e, ord=2)


def max_column_abs_sum(e: Tensor) -> Tensor:
    return e.abs().sum(dim=-2).amax(dim=-1)


def max_row_abs_sum(e: Tensor) -> Tensor:
    return e.abs().sum(dim=-1).amax(dim=-1)


def max_row_square_sum(e: Tensor) -> Tensor:
    return e.square().sum(dim=-1).amax(dim=-1)


def max_abs(e: Tensor) -> Tensor:
    return e.abs().amax(dim=(-2, -1))


NORMS: dict[str, Callable[[Tensor], Tensor]] = {
    "fro": frobenius,
    "2": spectral,
    "1": max_column_abs_sum,
    "inf": max_row_abs_sum,
    "max_row_sq": max_row_square_sum,
    "max_abs": max_abs,
}
