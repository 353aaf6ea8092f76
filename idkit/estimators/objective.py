"""Many costs of many parameter sets in one call: the hot loop of the search-based estimators.

``Objective(problems, costs)`` maps search positions ``x[S, ..., D]`` (one slice per trial and
cost, ``S = T · C``) to ``cost[S, ...]``. It precomputes everything that depends only on the
samples, once:

- the search space: the robot's physical parameters in ``bounds()`` (the paper's way) or, for
  robots with ``search_space == "base"``, the base parameters in ``base_bounds()``;
- the torque prediction: ``inverse_dynamics`` in general (``Problem.error``'s path); for a robot
  with a regressor, ``E = T − base_params(x) @ Yᵀ`` as one ``baddbmm`` — exact up to rounding,
  because ``tau = Y(q, qd, qdd) · alpha`` defines the regressor (tests check both paths agree);
  for relative costs ``T`` and ``Y`` are divided by the denominator of eq. (27) once, so the
  product gives ``E_rel`` directly;
- costs that declare a structure (``Cost.structure()``: a product of matrix norms or entrywise
  reductions, e.g. the paper's 16 and the robust ``huber``/``trimmed``), all at once through
  ``NormProducts``: the same factors with fewer tensor ops (one ``|E|``, row and column sums
  from one matmul, the spectral norm in closed form, each reduction once per group of costs with
  the same factors and parameters). Values agree with the cost's own ``__call__`` to 1e-12
  relative (tested), except the closed-form spectral norm where the two largest singular values
  coincide (~1e-8, see ``spectral_norm_3``); other costs are called as they are.

Per-op overhead (microseconds per tensor op) dominates a paper-sized swarm, so op count is what
this module minimises. Estimators report the final cost through the cost's own ``__call__``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
from torch import Tensor

from idkit.costs.norms import NORMS
from idkit.costs.reductions import PARAMETRIC
from idkit.estimators.trials import check_same_setting
from idkit.interfaces import Cost, NormStructure, Robot
from idkit.problem import Problem, Samples
from idkit.relative import relative_denominator

SPACES = ("physical", "base")

#: The factor names a structure may use: matrix norms, then parametric entrywise reductions.
FACTORS = frozenset(NORMS) | frozenset(PARAMETRIC)


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


def factor_parameters(names: Sequence[str], parameters: Sequence[float] = ()) -> tuple[float, ...]:
    """One checked parameter per factor of ``names`` (``NormStructure.norms``/``parameters``).

    A reduction's parameter must lie in its domain (``Reduction.check``); a matrix norm takes none
    (``0.0`` in its place). Raises ``ValueError`` naming the factor and what is wrong.
    """
    unknown = [name for name in names if name not in FACTORS]
    if unknown:
        raise ValueError(
            f"unknown factor(s) {unknown}; known norms: {', '.join(NORMS)}; "
            f"entrywise reductions: {', '.join(PARAMETRIC)}"
        )
    if parameters and len(parameters) != len(names):
        raise ValueError(f"parameters {tuple(parameters)} do not align with the factors {tuple(names)}")
    checked = []
    for i, name in enumerate(names):
        if name in PARAMETRIC:
            reduction = PARAMETRIC[name]
            if not parameters:
                raise ValueError(
                    f"factor {name!r} needs its {reduction.parameter} ({reduction.domain}) in the "
                    "structure's parameters; none given"
                )
            checked.append(reduction.check(name, parameters[i]))
        elif parameters and parameters[i] != 0:
            raise ValueError(f"norm {name!r} takes no parameter (0.0 in its place), got {parameters[i]!r}")
        else:
            checked.append(0.0)
    return tuple(checked)


def norm_product(
    names: Sequence[str], n: int, samples: int, like: Tensor, parameters: Sequence[float] = ()
) -> Callable[[Tensor], Tensor]:
    """``e[..., n, N] → Π factor(e)`` with few ops; equal to the plain product up to rounding.

    Factors are ``NORMS`` and ``PARAMETRIC`` names with ``parameters`` as in ``NormStructure``.
    ``"1"`` and ``"inf"`` (largest column / row absolute sum) come from one matmul of ``|e|`` with
    a 0/1 matrix that sums each column and each row; ``"2"`` uses ``spectral_norm_3`` when
    ``n == 3``; ``|e|`` and ``e²`` are computed once for all the norms that need them; an
    entrywise reduction is its own function (``idkit.costs.reductions``), the one its cost calls.
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
        s = a.reshape(*a.shape[:-2], n * samples) @ sums if sums is not None else None
        square = e.square() if uses_square else None
        out = None
        for name, parameter in zip(names, values, strict=True):
            if name in PARAMETRIC:
                v = PARAMETRIC[name].function(e, parameter)
            elif name == "1":
                v = s[..., :samples].amax(-1)
            elif name == "inf":
                v = s[..., samples:].amax(-1)
            elif name == "max_abs":
                v = a.amax(dim=(-2, -1))
            elif name == "fro":
                v = square.sum(dim=(-2, -1)).sqrt()
            elif name == "max_row_sq":
                v = square.sum(dim=-1).amax(dim=-1)
            elif name == "2" and n == 3:
                v = spectral_norm_3(e)
            else:
                v = NORMS[name](e)
            out = v if out is None else out * v
        return out

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
            (_selector(members, like.device), norm_product(names, n, samples, like, parameters))
            for (names, parameters), members in groups.items()
        ]

    def __call__(self, e: Tensor) -> Tensor:
        if len(self.groups) == 1:
            return self.groups[0][1](e)
        out = e.new_empty(e.shape[:-2])
        for members, value in self.groups:
            out[members] = value(e[members])
        return out


def _selector(members: list[int], device: torch.device) -> slice | Tensor:
    """``members`` as a slice where they are evenly spaced (slots are trial-major, so a cost's
    slots are every ``C``-th: a view, no copy of the error), else as an index tensor."""
    step = members[1] - members[0] if len(members) > 1 else 1
    if members == list(range(members[0], members[-1] + 1, step)):
        return slice(members[0], members[-1] + 1, step)
    return torch.tensor(members, device=device)


def fast_structure(cost: Cost) -> NormStructure | None:
    """``cost.structure()`` when the fast path can evaluate it (known factors), else ``None``.

    A structure naming only known factors but with invalid parameters is the cost's mistake: a
    ``ValueError`` names the cost and what is wrong (rather than a silently slower path).
    """
    structure = cost.structure()
    if structure is None or not structure.norms or not set(structure.norms) <= FACTORS:
        return None
    try:
        factor_parameters(structure.norms, structure.parameters)
    except ValueError as error:
        raise ValueError(
            f"cost {type(cost).__name__} declares an invalid structure {structure}: {error}"
        ) from None
    return structure


def cost_label(cost: Cost) -> str:
    """Short name of a cost for estimator labels: the class name (``f13`` for the paper's)."""
    return type(cost).__name__


class Objective:
    """Batched costs of search positions for one problem or a stack of trials.

    Positions carry a leading *slot* dimension ``S = T · C``, trial-major: slot ``t · C + c`` is
    evaluated with ``costs[c]`` on the samples of ``problems[t]``. With one problem (``T = 1``)
    slots are costs.

    Args:
        problems: one ``Problem`` or ``T`` trials of the same robot, sample count, device and dtype
            (their ``cost`` is not used here; their samples differ).
        costs: ``C`` costs.
        space: ``"physical"`` or ``"base"``; ``None`` follows ``robot.search_space``.
        use_regressor: predict torques by the regressor (requires one); ``None`` uses it when the
            robot has one.
    """

    def __init__(
        self,
        problems: Problem | Sequence[Problem],
        costs: Sequence[Cost],
        space: str | None = None,
        use_regressor: bool | None = None,
    ) -> None:
        self.problems = [problems] if isinstance(problems, Problem) else list(problems)
        if not self.problems:
            raise ValueError("Objective needs at least one problem")
        problem = self.problems[0]
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
        _check_stackable(self.problems)
        self.trials = [p.tensors() for p in self.problems]
        self.measured = torch.stack([s.measured_matrix() for s in self.trials])  # [T, n, N]
        self.shape = tuple(self.measured.shape[1:])
        # Per slot, the divisor of the error: the relative denominator (eq. 27) for costs that
        # declare a relative structure, 1 otherwise (other costs get the absolute error, as
        # their contract says).
        self.structures = [fast_structure(cost) for cost in self.costs]
        ones = torch.ones_like(self.measured[0])
        self.divisors = torch.stack(
            [
                relative_denominator(measured, structure.floor)
                if structure is not None and structure.relative
                else ones
                for measured in self.measured
                for structure in self.structures
            ]
        )  # [S, n, N]
        count = len(self.costs)
        self.fast = [t * count + c for t in range(len(self.trials)) for c in self.fast_costs]
        self.others = [s for s in range(self.slots) if s not in set(self.fast)]
        self.others_by_cost = {
            c: torch.tensor([s for s in self.others if s % count == c], device=device)
            for c in {s % count for s in self.others}
        }  # the slots of each cost without a structure (its trials), for one call per cost
        self.products = NormProducts(
            [self.structures[s % count] for s in self.fast], *self.shape, self.measured
        )
        if self.use_regressor:
            # -Yᵀ per trial as [T, B, n·N]: alpha[..., B] @ it is minus the prediction in the
            # joints × samples layout.
            minus_yt = torch.stack([-_regressor_t(robot, s) for s in self.trials])
            self.absolute = (self.measured.reshape(len(self.trials), 1, -1), minus_yt.contiguous())
            # Per slot, -Yᵀ / divisor and T / divisor, so that E (already divided) is one baddbmm.
            divisors = self.divisors.reshape(self.slots, 1, -1)
            self.linear = (minus_yt.repeat_interleave(count, 0) / divisors).contiguous()  # [S, B, n·N]
            self.offset = (
                self.absolute[0].repeat_interleave(count, 0) / divisors
            ).contiguous()  # [S, 1, n·N]

    @property
    def fast_costs(self) -> list[int]:
        """Indices of the costs evaluated through their declared structure (``NormProducts``)."""
        return [c for c, structure in enumerate(self.structures) if structure is not None]

    @property
    def slots(self) -> int:
        """``S = T · C``: the leading dimension of positions."""
        return len(self.trials) * len(self.costs)

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

    def error(self, x: Tensor, trial: int = 0) -> Tensor:
        """Torque error ``E[..., n, N] = measured − predicted`` of ``trial`` at positions ``x[..., D]``."""
        if self.use_regressor:
            t, minus_yt = (a[trial] for a in self.absolute)
            return (t + self.base(x) @ minus_yt).view(*x.shape[:-1], *self.shape)
        s = self.trials[trial]
        predicted = self.problem.robot.inverse_dynamics(x, s.q, s.qd, s.qdd)
        return (s.tau - predicted).transpose(-1, -2)

    def exact(self, slot: int, x: Tensor) -> Tensor:
        """Cost of ``slot`` at positions ``x[..., D]`` by the cost's own ``__call__`` (for reporting).

        Physical space goes through inverse dynamics, base space through the regressor.
        """
        trial, cost = divmod(slot, len(self.costs))
        if self.space == "base":
            error = self.error(x, trial)
        else:
            s = self.trials[trial]
            error = (s.tau - self.problem.robot.inverse_dynamics(x, s.q, s.qd, s.qdd)).transpose(-1, -2)
        return self.costs[cost](error, self.measured[trial])

    def __call__(self, x: Tensor) -> Tensor:
        """``cost[S, ...]`` of positions ``x[S, ..., D]``: slot ``t · C + c`` by cost ``c`` on trial ``t``."""
        if x.shape[0] != self.slots:
            raise ValueError(f"positions have {x.shape[0]} slices, the objective has {self.slots} slots")
        batch = x.shape[1:-1]
        count = len(self.costs)
        if self.use_regressor:
            alpha = self.base(x).reshape(self.slots, -1, self.linear.shape[1])
            error = torch.baddbmm(self.offset, alpha, self.linear)  # T/d − alpha·Yᵀ/d, one op
            error = error.view(self.slots, *batch, *self.shape)
        else:
            per_trial = x.view(len(self.trials), count, *batch, x.shape[-1])
            error = torch.cat([self.error(xt, t) for t, xt in enumerate(per_trial)])
            error = error / self.divisors.view(self.slots, *([1] * len(batch)), *self.shape)
        if not self.others:
            return self.products(error)
        out = error.new_empty((self.slots, *batch))
        if self.fast:
            index = _selector(self.fast, error.device)
            out[index] = self.products(error[index])
        for c in sorted({s % count for s in self.others}):
            cost, slots = self.costs[c], self.others_by_cost[c]
            if cost.stacked_measured:  # every trial in one call
                measured = self.measured.view(len(self.trials), *([1] * len(batch)), *self.shape)
                out[slots] = cost(error[slots], measured)
            else:
                for s in slots.tolist():
                    out[s] = cost(error[s], self.measured[s // count])
        return out


def _regressor_t(robot: Robot, samples: Samples) -> Tensor:
    """``Yᵀ`` as ``[B, n·N]`` (joint-major columns) of the regressor ``Y[N, n, B]``."""
    y = robot.regressor(samples.q, samples.qd, samples.qdd)
    return y.permute(2, 1, 0).reshape(y.shape[-1], -1)


def _check_stackable(problems: Sequence[Problem]) -> None:
    """Trials share one stacked error tensor: ``check_same_setting`` plus equal sample counts."""
    check_same_setting(problems)
    first = problems[0].samples.q.shape
    for trial, other in enumerate(problems[1:], start=1):
        if other.samples.q.shape != first:
            raise ValueError(
                f"trial {trial}: samples have shape {tuple(other.samples.q.shape)}, trial 0 has "
                f"{tuple(first)}; stacked trials need equal sample counts"
            )
