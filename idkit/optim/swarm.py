"""A functional, batched global-best particle swarm (EvoTorch/evosax style).

The whole state of any number of independent swarms is one ``SwarmState`` of tensors with leading
batch dimensions ``...`` (e.g. costs × runs); ``init`` and ``step`` are pure functions of it, so
many runs are one tensor computation and the loop in ``run`` only walks the iterations.

One iteration of the synchronous gbest PSO (the paper's eqs. 3–4):

1. ``v ← w v + c1 r1 (pbest − x) + c2 r2 (gbest − x)``, optionally clamped to ``±v_max``;
2. ``x ← x + v``, then the boundary rule puts ``x`` back in the box;
3. evaluate ``f(x)``; personal bests improve where ``f(x) < f(pbest)`` (strictly), and the
   global best is the best personal best.

``r1``, ``r2`` are uniform on [0, 1), drawn independently per particle *and per dimension* (the
usual reading of eq. 3 and what pyswarms does); ``per_particle=True`` draws one number per
particle for all dimensions instead.

Boundary rules (what happens to a coordinate that left ``[lower, upper]``):

- ``"clamp"``: put it on the wall and zero that velocity component. Simple, but a particle whose
  personal and global bests lie on the wall can stay there.
- ``"reflect"``: mirror it back into the box (repeatedly, so any overshoot lands inside) and
  reverse that velocity component, so the particle keeps exploring.
- ``"random"``: re-draw it uniformly between its previous position and the wall it crossed, and
  zero that velocity component (a "random-back" rule: the particle approaches the wall without
  sticking to it).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Literal, NamedTuple, get_args

import numpy as np
import torch
from torch import Tensor

from idkit.seeds import torch_generator

#: What happens to a coordinate that left the box (module docstring).
Boundary = Literal["clamp", "reflect", "random"]
BOUNDARIES: tuple[str, ...] = get_args(Boundary)

#: Upper limit on the elements of one block of pre-drawn random numbers (see ``random_blocks``).
RANDOM_BLOCK_ELEMENTS = 1 << 21


class SwarmState(NamedTuple):
    """Batched swarm state; ``...`` are independent swarms, ``K`` particles, ``P`` dimensions."""

    position: Tensor  #: [..., K, P] current positions
    velocity: Tensor  #: [..., K, P]
    best_position: Tensor  #: [..., K, P] personal bests
    best_cost: Tensor  #: [..., K] cost at the personal bests
    global_position: Tensor  #: [..., P] best position of each swarm
    global_cost: Tensor  #: [...] its cost


@dataclass(frozen=True)
class SwarmRules:
    """The update rule's constants.

    Args:
        c1, c2: cognitive and social learning rates of eq. (3).
        inertia: ``(w_start, w_end, ramp)``: ``w`` falls linearly from ``w_start`` to ``w_end`` over
            the first ``ramp`` moves and stays at ``w_end`` after (the paper: 0.9, 0.4, 100).
        boundary: one of ``BOUNDARIES`` (module docstring).
        velocity_limit: ``v_max`` as a fraction of each dimension's box width, or ``None``.
        per_particle: one ``r1``/``r2`` per particle instead of per particle and dimension.
    """

    c1: float = 1.3
    c2: float = 1.3
    inertia: tuple[float, float, int] = (0.9, 0.4, 100)
    boundary: Boundary = "clamp"
    velocity_limit: float | None = None
    per_particle: bool = False

    def __post_init__(self) -> None:
        if self.boundary not in BOUNDARIES:
            raise ValueError(f"unknown boundary rule {self.boundary!r}; use one of {', '.join(BOUNDARIES)}")
        if self.velocity_limit is not None and not self.velocity_limit > 0:
            raise ValueError(f"velocity_limit must be > 0 or None, got {self.velocity_limit}")
        if len(self.inertia) != 3 or int(self.inertia[2]) < 0:
            raise ValueError(f"inertia must be (w_start, w_end, ramp >= 0), got {self.inertia}")

    def weight(self, move: int) -> float:
        """Inertia ``w`` of move ``move`` (0-based): the linear ramp, then constant."""
        start, end, ramp = self.inertia
        if move >= ramp:
            return float(end)
        return float(start + (end - start) * move / ramp)


def _update_bests(state: SwarmState, position: Tensor, cost: Tensor) -> SwarmState:
    """Personal bests where ``cost`` is strictly lower, then each swarm's best of them."""
    better = cost < state.best_cost
    best_cost = torch.where(better, cost, state.best_cost)
    best_position = torch.where(better.unsqueeze(-1), position, state.best_position)
    global_cost, index = best_cost.min(dim=-1)
    index = index[..., None, None].expand(*index.shape, 1, position.shape[-1])
    global_position = best_position.gather(-2, index).squeeze(-2)
    return SwarmState(position, state.velocity, best_position, best_cost, global_position, global_cost)


def init(
    objective: Callable[[Tensor], Tensor],
    lower: Tensor,
    upper: Tensor,
    batch_shape: tuple[int, ...],
    particles: int,
    uniform: Draws,
    start: Tensor | None = None,
) -> SwarmState:
    """Uniform positions in the box, zero velocities, bests from one evaluation.

    Args:
        objective: ``cost[..., K]`` of ``positions[..., K, P]``.
        lower, upper: box ``[P]`` on the device/dtype to compute in.
        batch_shape: leading dimensions ``...`` (independent swarms).
        particles: ``K``.
        uniform: the only source of randomness.
        start: ``[S, P]`` (``S ≤ K``) known positions that replace the first ``S`` drawn particles of
            every swarm (e.g. a reference guess; clamped into the box). The numbers are drawn all
            the same, so the random stream does not depend on ``start``.
    """
    u = uniform.draw((*batch_shape, particles, lower.shape[-1]))
    position = lower + (upper - lower) * u
    if start is not None:
        if start.ndim != 2 or start.shape[0] > particles or start.shape[1] != lower.shape[-1]:
            raise ValueError(
                f"start positions must be [S <= {particles}, {lower.shape[-1]}], got {tuple(start.shape)}"
            )
        known = torch.minimum(torch.maximum(start.to(position), lower), upper)
        position[..., : start.shape[0], :] = known
    cost = objective(position)
    empty = SwarmState(
        position,
        torch.zeros_like(position),
        position,
        torch.full_like(cost, float("inf")),
        position[..., 0, :],
        cost[..., 0],
    )
    return _update_bests(empty, position, cost)


def _bound(
    position: Tensor,
    velocity: Tensor,
    previous: Tensor,
    lower: Tensor,
    upper: Tensor,
    rules: SwarmRules,
    u: Tensor | None,
) -> tuple[Tensor, Tensor]:
    """Apply the boundary rule to the moved ``position``; written with few ops (they dominate)."""
    if rules.boundary == "clamp":
        clamped = torch.clamp(position, lower, upper)
        return clamped, velocity * (clamped == position)
    if rules.boundary == "reflect":
        # Fold the line onto the box: t = (x − lower) mod 2·width, and the triangle wave
        # width − |width − t| is x reflected as often as needed. Odd reflection counts (t > width)
        # reverse the velocity.
        width = upper - lower
        folded = width - torch.remainder(position - lower, 2 * width)
        return (upper - folded.abs()), velocity * folded.sign()
    # "random": uniformly between the previous position and the crossed wall.
    assert u is not None
    low_out, high_out = position < lower, position > upper
    redrawn = torch.where(low_out, lower + (previous - lower) * u, position)
    redrawn = torch.where(high_out, upper - (upper - previous) * u, redrawn)
    return redrawn, torch.where(low_out | high_out, 0.0, velocity)


def step(
    state: SwarmState,
    objective: Callable[[Tensor], Tensor],
    weight: float,
    random: Sequence[Tensor],
    lower: Tensor,
    upper: Tensor,
    rules: SwarmRules,
) -> SwarmState:
    """One move of every particle of every swarm, then one evaluation.

    Args:
        state: the swarms (not modified).
        objective: ``cost[..., K]`` of ``positions[..., K, P]``.
        weight: inertia ``w`` of this move.
        random: ``c1·r1``, ``c2·r2`` (already scaled) and, for the ``"random"`` boundary rule, its
            uniform draw; each ``[..., K, P]`` (last dimension 1 for ``per_particle``).
        lower, upper: the box ``[P]``.
        rules: the constants.
    """
    x = state.position
    velocity = torch.addcmul(state.velocity * weight, random[0], state.best_position - x)
    velocity = torch.addcmul(velocity, random[1], state.global_position.unsqueeze(-2) - x)
    if rules.velocity_limit is not None:
        vmax = rules.velocity_limit * (upper - lower)
        velocity = torch.clamp(velocity, -vmax, vmax)
    position, velocity = _bound(
        x + velocity, velocity, x, lower, upper, rules, random[2] if rules.boundary == "random" else None
    )
    cost = objective(position)
    moved = SwarmState(position, velocity, *state[2:])
    return _update_bests(moved, position, cost)


class Uniform:
    """Uniform [0, 1) numbers for the swarm, from ``generator`` (the problem's seed).

    On the CPU torch's Mersenne Twister is slow enough that drawing alone would take most of a big
    batch's time (10,000 runs need 480 M numbers; the rates: docs/speed.md, "Measurements behind
    design choices"). So on the CPU the numbers come from a
    numpy ``Generator`` on the SFC64 bit generator, seeded by one draw from ``generator``:
    ``Generator.random`` in float64, one ``next_double`` of the bit generator per number — the
    call the fast kernel (``idkit.optim.kernel``) makes through numba's support for ``Generator``
    arguments, so both engines see the same numbers and leave the stream in the same place.
    Other devices use ``torch.rand`` with ``generator`` directly. Either way the seed fixes every
    number.
    """

    def __init__(self, generator: torch.Generator, like: Tensor) -> None:
        self.generator: torch.Generator | None = generator
        self.device, self.dtype = like.device, like.dtype
        self.numpy: np.random.Generator | None = None
        if self.device.type == "cpu":
            seed = int(torch.randint(0, 2**62, (), generator=generator))
            self.numpy = np.random.Generator(np.random.SFC64(seed))

    @classmethod
    def seeded(cls, seed: int, like: Tensor) -> Uniform:
        """``Uniform(torch_generator(seed, like.device), like)``: the same numbers, but on the CPU the
        numpy stream's seed is derived once per seed and process (``_stream_seed``: deriving it
        through a fresh torch generator costs more than a paper-sized run on the fast kernel)."""
        if like.device.type != "cpu":
            return cls(torch_generator(seed, like.device), like)
        uniform = cls.__new__(cls)
        uniform.generator = None
        uniform.device, uniform.dtype = like.device, like.dtype
        uniform.numpy = np.random.Generator(np.random.SFC64(_stream_seed(seed)))
        return uniform

    def __call__(self, shape: tuple[int, ...]) -> Tensor:
        if self.numpy is not None:
            return torch.from_numpy(self.numpy.random(shape)).to(self.dtype)
        return torch.rand(shape, generator=self.generator, device=self.device, dtype=self.dtype)


@lru_cache(maxsize=4096)
def _stream_seed(seed: int) -> np.random.SeedSequence:
    """The seed of the CPU numpy stream of ``Uniform(torch_generator(seed), ...)``, as the
    ``SeedSequence`` numpy makes of it (stateless for a bit generator's seeding: the same stream,
    a fifth of the set-up)."""
    return np.random.SeedSequence(int(torch.randint(0, 2**62, (), generator=torch_generator(seed))))


def random_blocks(
    shape: tuple[int, ...], scale: Sequence[float], moves: int, uniform: Uniform
) -> Iterator[Tensor]:
    """Yield blocks ``[count, len(scale), *shape]`` of uniform [0, 1) numbers times ``scale``.

    ``moves`` numbers per draw in all, in blocks of many moves: one call per block instead of per
    move saves most of the per-call overhead on small swarms. The block size depends only on
    ``shape``, so the same seed gives the same numbers.
    """
    draws = len(scale)
    per_move = draws * math.prod(shape)
    block = max(1, min(moves, RANDOM_BLOCK_ELEMENTS // max(per_move, 1)))
    factor = torch.tensor(scale, device=uniform.device, dtype=uniform.dtype)
    factor = factor.view(1, draws, *([1] * len(shape)))
    done = 0
    while done < moves:
        count = min(block, moves - done)
        yield uniform((count, draws, *shape)).mul_(factor)
        done += count


class Draws:
    """The random numbers of a batch of swarms whose leading dimension stacks ``T`` trials.

    Each trial has its own stream (``Uniform``), and draws for shape ``[T · C, ...]`` take
    ``[C, ...]`` from every trial's stream and stack them, so a trial's numbers never depend on
    which other trials share the batch (or on the chunk size of a trial-batched study).
    """

    def __init__(self, streams: Sequence[Uniform]) -> None:
        if not streams:
            raise ValueError("Draws needs at least one stream")
        self.streams = list(streams)

    def _per_trial(self, shape: tuple[int, ...]) -> tuple[int, ...]:
        trials = len(self.streams)
        if shape[0] % trials:
            raise ValueError(f"leading dimension {shape[0]} is not a multiple of {trials} trials")
        return (shape[0] // trials, *shape[1:])

    def draw(self, shape: tuple[int, ...]) -> Tensor:
        """Uniform [0, 1) numbers ``[*shape]``; ``shape[0]`` is ``T ·`` the per-trial size."""
        own = self._per_trial(shape)
        parts = [stream(own) for stream in self.streams]
        return parts[0] if len(parts) == 1 else torch.cat(parts)

    def blocks(self, shape: tuple[int, ...], scale: Sequence[float], moves: int) -> Iterator[Tensor]:
        """Yield blocks ``[count, len(scale), *shape]`` (uniform times ``scale``), ``moves`` in all."""
        own = self._per_trial(shape)
        for parts in zip(*(random_blocks(own, scale, moves, stream) for stream in self.streams), strict=True):
            yield parts[0] if len(parts) == 1 else torch.cat(parts, dim=2)

    def moves(self, shape: tuple[int, ...], scale: Sequence[float], moves: int) -> Iterator[Sequence[Tensor]]:
        """Yield ``moves`` tuples of ``len(scale)`` tensors ``[*shape]``: uniform times ``scale``."""
        for block in self.blocks(shape, scale, moves):
            for move in block.unbind(0):
                yield move.unbind(0)


def move_shape(
    batch_shape: tuple[int, ...], particles: int, lower: Tensor, rules: SwarmRules
) -> tuple[tuple[int, ...], tuple[float, ...]]:
    """Shape and scales of each move's random numbers (``c1·r1``, ``c2·r2``, the boundary's ``u``)."""
    scale = (rules.c1, rules.c2, 1.0) if rules.boundary == "random" else (rules.c1, rules.c2)
    return (*batch_shape, particles, 1 if rules.per_particle else lower.shape[-1]), scale


def move_draws(
    uniform: Draws,
    batch_shape: tuple[int, ...],
    particles: int,
    iterations: int,
    lower: Tensor,
    rules: SwarmRules,
) -> Iterator[Sequence[Tensor]]:
    """The scaled random numbers of every move (``c1·r1``, ``c2·r2`` and the boundary's ``u``)."""
    shape, scale = move_shape(batch_shape, particles, lower, rules)
    return uniform.moves(shape, scale, iterations - 1)


def history_rows(iterations: int, stride: int = 1) -> list[int]:
    """The iterations a history keeps: every ``stride``-th from the first, and always the last."""
    if stride < 1:
        raise ValueError(f"history stride must be >= 1, got {stride}")
    kept = list(range(0, iterations, stride))
    return kept if kept[-1] == iterations - 1 else [*kept, iterations - 1]


def run(
    objective: Callable[[Tensor], Tensor],
    lower: Tensor,
    upper: Tensor,
    batch_shape: tuple[int, ...],
    particles: int,
    iterations: int,
    rules: SwarmRules,
    uniform: Draws,
    stride: int = 1,
    start: Tensor | None = None,
) -> tuple[SwarmState, Tensor]:
    """``iterations`` evaluations per particle (``init`` is the first, with ``start`` as there),
    i.e. ``iterations − 1`` moves.

    Returns:
        The final state and the history ``[rows, ...]`` of each swarm's global best cost at the
        iterations ``history_rows(iterations, stride)``.
    """
    if particles < 1 or iterations < 1:
        raise ValueError(f"need particles >= 1 and iterations >= 1, got {particles}, {iterations}")
    kept = set(history_rows(iterations, stride))
    state = init(objective, lower, upper, batch_shape, particles, uniform, start)
    history = [state.global_cost]
    for move, random in enumerate(move_draws(uniform, batch_shape, particles, iterations, lower, rules)):
        state = step(state, objective, rules.weight(move), random, lower, upper, rules)
        if move + 1 in kept:
            history.append(state.global_cost)
    return state, torch.stack(history)
