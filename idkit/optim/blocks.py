"""A cooperative swarm: one swarm per block of coordinates, every particle one full candidate.

When a cost is a sum of parts each of which depends mostly on its own few coordinates — a robot's
per-joint errors on that joint's friction and gains — one swarm over all coordinates wastes its
evaluations: a particle that improves joint 1 and spoils joint 5 is rejected whole. Here block ``g``
has its own swarm (:mod:`idkit.optim.swarm`, batch dimension ``G``) that sees only its part of the cost;
particle ``k`` of every swarm together form candidate ``k``, so one evaluation of ``K`` candidates
serves all ``G`` swarms (cooperative coevolution, van den Bergh & Engelbrecht 2004, with the particles
of equal index as each other's context). Coordinates shared by all parts form a block whose part is the
whole cost. What comes back is the best candidate evaluated, or the blocks' bests put together when that
is better.

Each swarm searches the unit cube; ``0.5`` is the start and ``0``/``1`` the bounds (linearly on each side),
so that the start is one particle of every swarm.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from idkit.optim import swarm


@dataclass(frozen=True)
class SearchResult:
    """The best candidate ``x[P]`` found, its ``cost``, the best cost after each evaluation of the
    candidates (one per iteration, then the blocks' bests put together) and how many were evaluated."""

    x: np.ndarray
    cost: float
    history: list[float]
    evaluations: int


def _to_box(u: np.ndarray, start: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    below = start + (u - 0.5) * 2.0 * (start - lower)
    above = start + (u - 0.5) * 2.0 * (upper - start)
    return np.where(u < 0.5, below, above)


def cooperative_search(
    objective: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    lower: np.ndarray,
    upper: np.ndarray,
    start: np.ndarray,
    blocks: Sequence[np.ndarray],
    particles: int,
    iterations: int,
    generator: torch.Generator,
    rules: swarm.SwarmRules | None = None,
) -> SearchResult:
    """Minimise a cost of ``x[P]`` in a box with one swarm per block (module docstring).

    Args:
        objective: ``(parts [K, G], total [K])`` of candidates ``[K, P]``: each block's part of the
            cost and the whole cost (non-finite: worst).
        lower, upper, start: ``[P]`` the box and a known point in it.
        blocks: ``G`` index arrays partitioning ``0..P-1``.
        particles, iterations: per swarm; ``iterations`` evaluations of ``particles`` candidates.
        generator: the only source of randomness.
        rules: the swarm's constants (default: the paper's).
    """
    covered = np.sort(np.concatenate(blocks))
    if not np.array_equal(covered, np.arange(lower.size)):
        raise ValueError("blocks must partition the coordinates")
    width = max(len(b) for b in blocks)
    best: dict[str, Any] = {"cost": np.inf, "x": np.array(start, dtype=np.float64)}
    evaluations = 0
    trace: list[float] = []

    def candidates(u: np.ndarray) -> np.ndarray:
        x = np.empty((u.shape[1], lower.size))
        for g, block in enumerate(blocks):
            x[:, block] = _to_box(u[g, :, : len(block)], start[block], lower[block], upper[block])
        return x

    def evaluate(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        nonlocal evaluations
        parts, total = objective(x)
        evaluations += len(x)
        parts = np.where(np.isfinite(parts), parts, np.inf)
        total = np.where(np.isfinite(total), total, np.inf)
        k = int(np.argmin(total))
        if total[k] < best["cost"]:
            best["cost"], best["x"] = float(total[k]), x[k].copy()
        trace.append(best["cost"])
        return parts, total

    def block_costs(position: torch.Tensor) -> torch.Tensor:
        parts, _ = evaluate(candidates(position.numpy()))
        return torch.from_numpy(np.ascontiguousarray(parts.T))  # [G, K]

    zero = torch.zeros(width, dtype=torch.float64)
    draws = swarm.Draws([swarm.Uniform(generator, zero)])
    state, _ = swarm.run(
        block_costs,
        zero,
        torch.ones(width, dtype=torch.float64),
        (len(blocks),),
        particles,
        iterations,
        rules or swarm.SwarmRules(),
        draws,
        start=torch.full((1, width), 0.5, dtype=torch.float64),
    )
    joined = candidates(state.global_position.numpy()[:, None, :])
    evaluate(joined)
    return SearchResult(best["x"], best["cost"], trace, evaluations)
