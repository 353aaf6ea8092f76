"""The fused torch form of products of factors: many structured costs of one stacked error.

``NormProducts`` evaluates the costs that declare a ``NormStructure`` with few tensor ops (per-op
overhead dominates a paper-sized swarm): one ``|E|``, row and column sums from one matmul, the
spectral norm of a 3-row matrix in closed form (``spectral_norm_3``), each entrywise reduction
once per group of costs with the same factors and parameters. Values agree with each factor's
reference (``idkit.costs.factors.FACTORS``) to rounding — 1e-12 relative, tested for every
registered factor — except the closed-form spectral norm where the two largest singular values
coincide (~1e-8, see ``spectral_norm_3``).
"""

from __future__ import annotations

import functools
import operator
from collections.abc import Callable, Sequence

import torch
from torch import Tensor

from idkit.costs.factors import FACTORS, factor_parameters
from idkit.interfaces import NormStructure


def spectral_norm_3(e: Tensor) -> Tensor:
    """Largest singular value ``[...]`` of ``e[..., 3, N]``: closed-form top eigenvalue of ``e eᵀ``.

    Smith's trigonometric solution for a symmetric 3 × 3 matrix ``G``: with ``q = tr G / 3``,
    ``p = ‖G − qI‖_F / √6`` and ``r = det(G − qI) / (2p³)``, ``λ_max = q + 2p cos(acos(r) / 3)``.
    About 30 elementwise ops on ``[...]``-sized tensors instead of a batched SVD (microseconds per
    matrix) or batched 3 × 3 matmuls.

    Accuracy: ~1e-15 relative, except where the two largest singular values (nearly) coincide —
    ``acos`` is ill-conditioned at ``r = −1`` — where it is ~1e-8 relative. That is harmless for a
    search (minimising a largest singular value tends to make it double, so this case is common
    near the optimum of f2-type costs); estimates report costs by the cost's own ``__call__``.
    """
    g00, g11, g22 = e.square().sum(-1).unbind(-1)
    g01, g12, g20 = (e * e.roll(-1, dims=-2)).sum(-1).unbind(-1)  # rows (0·1, 1·2, 2·0)
    g02 = g20
    q = (g00 + g11 + g22) / 3
    x, y, z = g00 - q, g11 - q, g22 - q
    off = g01.square() + g02.square() + g12.square()
    p = ((x.square() + y.square() + z.square() + 2 * off) / 6).sqrt()
    det = x * (y * z - g12.square()) - g01 * (g01 * z - g12 * g02) + g02 * (g01 * g12 - y * g02)
    positive = p > 0
    safe = torch.where(positive, p, 1.0)
    r = (det / (2 * safe * safe * safe)).clamp(-1.0, 1.0)
    top = torch.where(positive, q + 2 * p * torch.cos(torch.acos(r) / 3), q)
    return top.clamp_min(0).sqrt()


def norm_product(
    names: Sequence[str], n: int, samples: int, like: Tensor, parameters: Sequence[float] = ()
) -> Callable[[Tensor], Tensor]:
    """``e[..., n, N] → Π factor(e)`` with few ops; equal to the plain product up to rounding.

    Factors are names of ``idkit.costs.factors.FACTORS`` with ``parameters`` as in ``NormStructure``.
    ``"1"`` and ``"inf"`` (largest column / row absolute sum) come from one matmul of ``|e|`` with
    a 0/1 matrix that sums each column and each row; ``"2"`` uses ``spectral_norm_3`` when
    ``n == 3``; ``|e|`` and ``e²`` are computed once for all the norms that need them; an
    entrywise reduction is its reference (``FACTORS``), the function its cost calls.
    """
    values = factor_parameters(names, parameters)
    sums = None
    if "1" in names or "inf" in names:
        # [n·N, N + n]: column j < N sums sample j over the joints, column N + i sums joint i
        # (rows ordered joint-major, as e.reshape(..., n·N)).
        eye_n = torch.eye(n, dtype=like.dtype, device=like.device)
        eye_s = torch.eye(samples, dtype=like.dtype, device=like.device)
        sums = torch.cat((eye_s.repeat(n, 1), eye_n.repeat_interleave(samples, dim=0)), dim=1)
    uses_abs = sums is not None or "max_abs" in names
    uses_square = "fro" in names or "max_row_sq" in names

    def value(e: Tensor) -> Tensor:
        a = e.abs() if uses_abs else None
        s = a.reshape(*a.shape[:-2], n * samples) @ sums if sums is not None and a is not None else None
        square = e.square() if uses_square else None
        factors = []
        for name, parameter in zip(names, values, strict=True):
            if FACTORS[name].parameter is not None:
                v = FACTORS[name].reference(e, parameter)
            elif name == "1" and s is not None:
                v = s[..., :samples].amax(-1)
            elif name == "inf" and s is not None:
                v = s[..., samples:].amax(-1)
            elif name == "max_abs" and a is not None:
                v = a.amax(dim=(-2, -1))
            elif name == "fro" and square is not None:
                v = square.sum(dim=(-2, -1)).sqrt()
            elif name == "max_row_sq" and square is not None:
                v = square.sum(dim=-1).amax(dim=-1)
            elif name == "2" and n == 3:
                v = spectral_norm_3(e)
            else:
                v = FACTORS[name].reference(e, parameter)
            factors.append(v)
        return functools.reduce(operator.mul, factors)

    return value


class NormProducts:
    """Several structured costs of one stacked error: ``e[C, ..., n, N] → value[C, ...]``.

    Costs with the same factors and parameters (the paper's f_k and f_{k+8} differ only in the
    error matrix, which the caller has already divided by each structure's relative denominator)
    form one group, evaluated by one ``norm_product`` on its slices: a few tensor ops per group
    instead of per cost (per-op overhead dominates), and each factor computed only for the costs
    that use it.

    Args:
        structures: ``C`` structures, one per slice of ``e`` (their ``relative``/``floor`` are
            the caller's business).
        n, samples: the error matrix's ``n × N``; ``like``: a tensor of its dtype and device.
    """

    def __init__(self, structures: Sequence[NormStructure], n: int, samples: int, like: Tensor) -> None:
        groups: dict[tuple[tuple[str, ...], tuple[float, ...]], list[int]] = {}
        for c, structure in enumerate(structures):
            key = (structure.norms, factor_parameters(structure.norms, structure.parameters))
            groups.setdefault(key, []).append(c)
        self.count = len(structures)
        self.groups = [
            (selector(members, like.device), norm_product(names, n, samples, like, parameters))
            for (names, parameters), members in groups.items()
        ]

    def __call__(self, e: Tensor) -> Tensor:
        if len(self.groups) == 1:
            return self.groups[0][1](e)
        out = e.new_empty(e.shape[:-2])
        for members, value in self.groups:
            out[members] = value(e[members])
        return out


def selector(members: list[int], device: torch.device) -> slice | Tensor:
    """``members`` as a slice where they are evenly spaced (slots are trial-major, so a cost's
    slots are every ``C``-th: a view, no copy of the error), else as an index tensor."""
    step = members[1] - members[0] if len(members) > 1 else 1
    if members == list(range(members[0], members[-1] + 1, step)):
        return slice(members[0], members[-1] + 1, step)
    return torch.tensor(members, device=device)
