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
  the fused torch form (``idkit.optim.fused.NormProducts``), or handed to the fast kernel as a
  ``ProductSpec`` (``spec``); other costs are called as they are.

Per-op overhead (microseconds per tensor op) dominates a paper-sized swarm, so op count is what
this module minimises. Estimators report the final cost through the cost's own ``__call__``.
"""

from __future__ import annotations

import hashlib
import inspect
import pickle
from collections.abc import Sequence
from functools import cached_property

import torch
from torch import Tensor

from idkit.costs.factors import FACTORS, factor_parameters
from idkit.estimators.trials import check_same_setting
from idkit.interfaces import Cost, NormStructure, Robot
from idkit.optim.base_map import Tape, cached_tape, identity
from idkit.optim.fast import ProductSpec
from idkit.optim.fused import NormProducts, selector
from idkit.problem import Problem, Samples
from idkit.relative import relative_denominator

SPACES = ("physical", "base")


def fast_structure(cost: Cost) -> NormStructure | None:
    """``cost.structure()`` when the fast path can evaluate it (known factors), else ``None``.

    A structure naming only known factors but with invalid parameters is the cost's mistake: a
    ``ValueError`` names the cost and what is wrong (rather than a silently slower path).
    """
    declared = getattr(cost, "structure", None)  # a cost by contract need not subclass Cost
    structure = declared() if callable(declared) else None
    if structure is None or not structure.norms or not set(structure.norms) <= FACTORS.keys():
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

    @cached_property
    def products(self) -> NormProducts:
        """The fused torch form of the structured costs' slots (the eager engine's; built on first
        use, so a fit on the fast kernel never builds it)."""
        count = len(self.costs)
        declared = {c: structure for c, structure in enumerate(self.structures) if structure is not None}
        n, samples = self.shape
        return NormProducts([declared[s % count] for s in self.fast], n, samples, self.measured)

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

    def spec(self) -> ProductSpec:
        """What the fast kernel minimises for this objective (``idkit.optim.fast``): per slot the
        divided ``T/d`` and ``−Yᵀ/d``, the declared structure, and the base map with its tape.

        Needs the regressor and a structure for every cost. ``map_seconds`` is then the time this
        call spent tracing the robot's base map (or reading its tape from the cache).
        """
        declared = [s for s in self.structures if s is not None]
        if not self.use_regressor or len(declared) < len(self.structures):
            raise ValueError("the fast kernel needs the regressor and a declared structure for every cost")
        tape: Tape | None
        if self.space == "base":
            tape, self.map_seconds = identity(self.dimension), 0.0
        else:
            robot = self.problem.robot
            tape, self.map_seconds = cached_tape(
                robot, robot.base_params, self.dimension, lambda: _map_key(robot, self.dimension)
            )
        count = len(self.costs)
        structures = tuple(declared[s % count] for s in range(self.slots))
        return ProductSpec(
            self.linear, self.offset.reshape(self.slots, -1), self.shape[0], structures, self.base, tape
        )

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
        """Cost of ``slot`` at positions ``x[..., D]`` by the cost's own ``__call__`` (for reporting),
        of the error the search minimised (``error``: through the regressor where it is used, which
        equals inverse dynamics up to rounding at a fifth of the time)."""
        trial, cost = divmod(slot, len(self.costs))
        return self.costs[cost](self.error(x, trial), self.measured[trial])

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
            index = selector(self.fast, error.device)
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


def _map_key(robot: Robot, dimension: int) -> str | None:
    """What identifies a robot's base map across processes (hashed): its pickled state, its class's
    source, the dimension, and what made the tape — idkit's version, the translator's source
    (:mod:`idkit.optim.base_map`) and torch's version (its tracer); ``None`` if the robot cannot be
    pickled. A base map inherited from another module is not in the key: ``cached_tape`` checks a
    tape read back against the map itself."""
    import idkit
    from idkit.optim import base_map

    try:
        state = pickle.dumps(robot)
        code = inspect.getsource(type(robot))
    except Exception:  # not picklable, or no source: traced once per process
        return None
    made_by = (idkit.__version__, inspect.getsource(base_map), torch.__version__)
    parts = (state, code.encode(), str(dimension).encode(), *(part.encode() for part in made_by))
    return hashlib.sha256(b"\n".join(parts)).hexdigest()[:32]


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
