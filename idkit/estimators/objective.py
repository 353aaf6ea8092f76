"""Many costs of many parameter sets in one call: the hot loop of the search-based estimators.

``Objective(problem, costs)`` maps search positions ``x[C, ..., D]`` (one slice per cost) to
``cost[C, ...]``. It precomputes everything that depends only on the samples, once:

- the search space: the robot's physical parameters in ``bounds()`` (the paper's way) or, for
  robots with ``search_space == "base"``, the base parameters in ``base_bounds()``;
- the torque prediction: ``inverse_dynamics`` in general (``Problem.error``'s path); for a robot
  with a regressor, ``E = [base_params(x), 1] @ [−Yᵀ; T]`` as one matmul — exact up to rounding,
  because ``tau = Y(q, qd, qdd) · alpha`` defines the regressor (tests check both paths agree);
  for relative costs ``T`` and ``Y`` are divided by the denominator of eq. (27) once, so the
  product gives ``E_rel`` directly;
- the paper's norm-product costs (``idkit.costs.paper``), all at once through ``NormProducts``: the
  same norms with fewer tensor ops (one ``|E|``, row and column sums from one matmul, the
  spectral norm in closed form). Values agree with the cost's own ``__call__`` to rounding
  (tests: 1e-12 relative); other costs are called as they are.

Per-op overhead (microseconds per tensor op) dominates a paper-sized swarm, so op count is what
this module minimises. Estimators report the final cost through the cost's own ``__call__``.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from idkit.costs.norms import NORMS
from idkit.costs.paper import NormProductCost, RelativeNormProductCost
from idkit.costs.relative import relative_denominator
from idkit.interfaces import Cost
from idkit.problem import Problem

SPACES = ("physical", "base")

#: Gram entries (i, j) of a 3-row matrix, in the order G00, G11, G22, G01, G02, G12.
_GRAM_ROWS = ((0, 1, 2, 0, 0, 1), (0, 1, 2, 1, 2, 2))


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
    rows = torch.tensor(_GRAM_ROWS, device=e.device)
    g = (e.index_select(-2, rows[0]) * e.index_select(-2, rows[1])).sum(-1)  # [..., 6]
    g00, g11, g22, g01, g02, g12 = g.unbind(-1)
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


class NormProducts:
    """Several norm-product costs (``Π NORMS[name](E)`` each) of one stacked error, all at once.

    ``e[C, ..., n, N]`` → ``value[C, ...]``, slice ``c`` by the product ``norms[c]``. Each norm any
    cost uses is computed once over the whole stack — a few tensor ops for all costs instead of a
    few per cost, since per-op overhead dominates — then every cost multiplies its own. ``"1"``
    and ``"inf"`` (largest column / row absolute sum) come from one matmul of ``|e|`` with a 0/1
    matrix that sums each column and each row; ``"2"`` uses ``spectral_norm_3`` when ``n == 3``.
    Equal to the plain products up to rounding.
    """

    def __init__(self, norms: Sequence[Sequence[str]], n: int, samples: int, like: Tensor) -> None:
        self.n, self.samples = n, samples
        self.used = sorted({name for names in norms for name in names})
        unknown = set(self.used) - set(NORMS)
        if unknown:
            raise ValueError(f"unknown norm(s) {sorted(unknown)}; known: {', '.join(NORMS)}")
        power = torch.tensor([[list(names).count(u) for u in self.used] for names in norms])
        self.power = power.to(device=like.device, dtype=like.dtype)
        self.mask = (power > 0).to(like.device)
        self.all_once = bool((power == 1).all())  # every cost multiplies every used norm once
        self.at_most_once = bool((power <= 1).all())  # the paper's products: a 0/1 mask suffices
        self.sums = None
        if "1" in self.used or "inf" in self.used:
            # [n·N, N + n]: column j < N sums sample j over the joints, column N + i sums joint i
            # (rows ordered joint-major, as e.reshape(..., n·N)).
            eye_n = torch.eye(n, dtype=like.dtype, device=like.device)
            eye_s = torch.eye(samples, dtype=like.dtype, device=like.device)
            self.sums = torch.cat((eye_s.repeat(n, 1), eye_n.repeat_interleave(samples, dim=0)), dim=1)

    def __call__(self, e: Tensor) -> Tensor:
        n, samples = self.n, self.samples
        a = e.abs() if self.sums is not None or "max_abs" in self.used else None
        s = a.reshape(*a.shape[:-2], n * samples) @ self.sums if self.sums is not None else None
        square = e.square() if "fro" in self.used or "max_row_sq" in self.used else None
        values = []
        for name in self.used:
            if name == "1":
                values.append(s[..., :samples].amax(-1))
            elif name == "inf":
                values.append(s[..., samples:].amax(-1))
            elif name == "max_abs":
                values.append(a.amax(dim=(-2, -1)))
            elif name == "fro":
                values.append(square.sum(dim=(-2, -1)).sqrt())
            elif name == "max_row_sq":
                values.append(square.sum(dim=-1).amax(dim=-1))
            elif name == "2" and n == 3:
                values.append(spectral_norm_3(e))
            else:
                values.append(NORMS[name](e))
        if self.all_once:
            out = values[0]
            for v in values[1:]:
                out = out * v
            return out
        stacked = torch.stack(values, dim=-1)  # [C, ..., U]
        shape = (self.power.shape[0], *([1] * (stacked.ndim - 2)), -1)
        if self.at_most_once:
            return torch.where(self.mask.view(shape), stacked, 1.0).prod(dim=-1)
        return stacked.pow(self.power.view(shape)).prod(dim=-1)


def is_norm_product(cost: Cost) -> bool:
    """Whether ``cost`` is one of the plain norm products of ``idkit.costs.paper`` (not overridden)."""
    return (
        isinstance(cost, NormProductCost)
        and type(cost).__call__ is NormProductCost.__call__
        and type(cost).error_matrix in (NormProductCost.error_matrix, RelativeNormProductCost.error_matrix)
        and bool(cost.norms)
    )


def cost_label(cost: Cost) -> str:
    """Short name of a cost for estimator labels: the class name (``f13`` for the paper's)."""
    return type(cost).__name__


class Objective:
    """Batched costs of search positions for one problem.

    Args:
        problem: robot, samples, device and dtype (its ``cost`` is not used here).
        costs: ``C`` costs; positions carry a leading dimension of size ``C``, slice ``c`` is
            evaluated with ``costs[c]``.
        space: ``"physical"`` or ``"base"``; ``None`` follows ``robot.search_space``.
        use_regressor: predict torques by the regressor (requires one); ``None`` uses it when the
            robot has one.
    """

    def __init__(
        self,
        problem: Problem,
        costs: Sequence[Cost],
        space: str | None = None,
        use_regressor: bool | None = None,
    ) -> None:
        robot = problem.robot
        self.problem = problem
        self.costs = list(costs)
        if not self.costs:
            raise ValueError("Objective needs at least one cost")
        self.space = robot.search_space if space is None else space
        if self.space not in SPACES:
            raise ValueError(f"unknown search space {self.space!r}; use one of {', '.join(SPACES)}")
        if use_regressor is None:
            use_regressor = robot.has_regressor
        if self.space == "base" and not use_regressor:
            raise ValueError(
                "searching in base space predicts torques by the regressor; use_regressor=False is impossible"
            )
        if (use_regressor or self.space == "base") and not robot.has_regressor:
            raise ValueError(
                f"{type(robot).__name__} has no regressor: search in base space / use_regressor=True "
                "is impossible"
            )
        self.use_regressor = bool(use_regressor)
        dtype, device = problem.torch_dtype, problem.device
        box = robot.base_bounds() if self.space == "base" else robot.bounds()
        self.lower, self.upper = (b.to(device=device, dtype=dtype) for b in box)
        if not bool((self.lower < self.upper).all()):
            raise ValueError(f"{type(robot).__name__}: empty search box {self.lower} .. {self.upper}")
        s = problem.tensors()
        self.samples = s
        self.measured = s.measured_matrix()  # [n, N]
        self.shape = tuple(self.measured.shape)
        # Per cost, the divisor of the error: the relative denominator (eq. 27) for the paper's
        # relative costs, 1 otherwise (other costs get the absolute error, as their contract says).
        ones = torch.ones_like(self.measured)
        self.fast = [c for c, cost in enumerate(self.costs) if is_norm_product(cost)]
        self.others = [c for c in range(len(self.costs)) if c not in self.fast]
        self.divisors = torch.stack(
            [
                relative_denominator(self.measured, cost.floor)
                if c in self.fast and isinstance(cost, RelativeNormProductCost)
                else ones
                for c, cost in enumerate(self.costs)
            ]
        )  # [C, n, N]
        self.products = NormProducts([self.costs[c].norms for c in self.fast], *self.shape, self.measured)
        if self.use_regressor:
            y = robot.regressor(s.q, s.qd, s.qdd)  # [N, n, B]
            # -Yᵀ as [B, n·N]: alpha[..., B] @ it is minus the prediction in the joints × samples layout.
            minus_yt = -y.permute(2, 1, 0).reshape(y.shape[-1], -1)
            self.absolute = (self.measured.reshape(-1), minus_yt.contiguous())
            # Per cost, [-Yᵀ; T] / divisor as [B + 1, n·N], so that E = [alpha, 1] @ it is one
            # batched matmul for all costs, with no extra pass over the error tensor.
            augmented = torch.cat((minus_yt, self.measured.reshape(1, -1)))
            self.linear = (augmented / self.divisors.reshape(len(self.costs), 1, -1)).contiguous()

    @property
    def dimension(self) -> int:
        return self.lower.shape[-1]

    def params(self, x: Tensor) -> Tensor:
        """Physical parameters ``[..., P]`` of search positions ``x[..., D]``."""
        if self.space == "base":
            return self.problem.robot.params_from_base(x)
        return x

    def base(self, x: Tensor) -> Tensor:
        """Base parameters ``[..., B]`` of search positions ``x[..., D]`` (needs a regressor)."""
        return x if self.space == "base" else self.problem.robot.base_params(x)

    def error(self, x: Tensor) -> Tensor:
        """Torque error ``E[..., n, N] = measured − predicted`` at search positions ``x[..., D]``."""
        if self.use_regressor:
            t, minus_yt = self.absolute
            return (t + self.base(x) @ minus_yt).view(*x.shape[:-1], *self.shape)
        s = self.samples
        predicted = self.problem.robot.inverse_dynamics(x, s.q, s.qd, s.qdd)
        return (s.tau - predicted).transpose(-1, -2)

    def exact(self, index: int, x: Tensor) -> Tensor:
        """Cost ``index`` at positions ``x[..., D]`` by the cost's own ``__call__`` (for reporting).

        Physical space goes through ``Problem.error`` (inverse dynamics), base space through the
        regressor.
        """
        error = self.error(x) if self.space == "base" else self.problem.error(x)
        return self.costs[index](error, self.measured)

    def __call__(self, x: Tensor) -> Tensor:
        """``cost[C, ...]`` of positions ``x[C, ..., D]``: slice ``c`` by cost ``c``."""
        count = len(self.costs)
        if x.shape[0] != count:
            raise ValueError(f"positions have {x.shape[0]} cost slices, the objective has {count}")
        batch = x.shape[1:-1]
        if self.use_regressor:
            alpha = torch.nn.functional.pad(self.base(x), (0, 1), value=1.0).reshape(
                count, -1, self.linear.shape[1]
            )
            error = torch.bmm(alpha, self.linear).view(count, *batch, *self.shape)  # already / divisor
        else:
            error = self.error(x) / self.divisors.view(count, *([1] * len(batch)), *self.shape)
        if not self.others:
            return self.products(error)
        out = error.new_empty((count, *batch))
        if self.fast:
            index = torch.tensor(self.fast, device=error.device)
            out[index] = self.products(error[index])
        for c in self.others:
            out[c] = self.costs[c](error[c], self.measured)
        return out
