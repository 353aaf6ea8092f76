"""``swarm.init``'s known starting positions: they replace the first drawn particles, never the stream."""

from __future__ import annotations

import pytest
import torch

from idkit.optim import swarm


def _draws(seed: int, like: torch.Tensor) -> swarm.Draws:
    return swarm.Draws([swarm.Uniform(torch.Generator().manual_seed(seed), like)])


def test_start_positions_replace_the_first_particles_and_leave_the_stream_alone():
    lower, upper = torch.zeros(3, dtype=torch.float64), torch.ones(3, dtype=torch.float64)
    objective = lambda x: (x - 0.25).square().sum(-1)  # noqa: E731
    start = torch.tensor([[0.25, 0.25, 0.25], [2.0, -1.0, 0.5]], dtype=torch.float64)  # the second outside
    plain_draws, started_draws = _draws(3, lower), _draws(3, lower)
    plain = swarm.init(objective, lower, upper, (2,), 5, plain_draws)
    started = swarm.init(objective, lower, upper, (2,), 5, started_draws, start)
    expected = start.clamp(0, 1)
    assert torch.equal(started.position[:, :2], expected.expand(2, 2, 3))  # in every swarm, clamped
    assert torch.equal(started.position[:, 2:], plain.position[:, 2:])
    assert torch.equal(plain_draws.draw((1, 4)), started_draws.draw((1, 4)))  # same numbers used
    assert torch.equal(started.global_position, expected[0].expand(2, 3))  # the known optimum is the best
    assert torch.equal(started.best_cost, objective(started.position))


def test_more_start_positions_than_particles_are_refused():
    lower, upper = torch.zeros(2, dtype=torch.float64), torch.ones(2, dtype=torch.float64)
    with pytest.raises(ValueError, match=r"start positions must be \[S <= 2, 2\]"):
        swarm.run(
            lambda x: x.sum(-1),
            lower,
            upper,
            (),
            2,
            3,
            swarm.SwarmRules(),
            _draws(0, lower),
            start=torch.zeros(3, 2),
        )
