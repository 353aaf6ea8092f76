"""The polish's least-squares view of a rollout problem: a residual vector and its Jacobian.

The variables are the unknowns' coordinates (:mod:`idkit.sim.quantities`) and, with ``free_initial``,
each segment's initial positions and velocities, as offsets from the start states in units of each
channel's scale (multiple shooting: a segment's noisy or glitched first sample no longer sets its whole
rollout; every sample of the segment weighs on where it starts). The residual is the problem's scaled
error ``E[2n, k]`` sample by sample (``E[:, 0]``, then ``E[:, 1]``, …: a vector of ``M = 2n·k`` in which
each segment's entries are contiguous), each channel divided by ``divisor[c]`` (the caller's robust
scale; times ``√M`` so that a loss sums to O(1)).

The Jacobian is by forward differences, all columns in one batch of rollouts: one per unknown, and for
the initial states one per channel — that channel's offset moved in *every* segment at once, since a
segment's residuals depend on its own start only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from idkit.optim.levenberg import BlockJacobian
from idkit.sim.problem import RolloutProblem
from idkit.sim.simulate import BatchSimulator

#: Finite-difference steps: of a coordinate (a relative 1e-6 of a log-scaled value), and of an
#: initial-state offset (in channel scales).
STEP = 1e-6
STATE_STEP = 1e-2
#: How far an initial state may move from its start, in channel scales.
STATE_RANGE = 1e6


@dataclass
class Shooting:
    """Residuals and Jacobians of ``problem`` on ``simulator`` (module docstring)."""

    problem: RolloutProblem
    simulator: BatchSimulator
    free_initial: bool

    def __post_init__(self) -> None:
        self.unknowns = self.problem.robot.unknowns
        self.n_unknowns = len(self.unknowns)
        self.n_channels = 2 * self.problem.samples.n_joints
        self.n_segments = len(self.simulator.segments)
        self.measured = self.problem.measured(self.simulator)  # [C, k]
        self.scales = self.problem.scales()
        self.divisor = np.ones(self.n_channels)
        edges = np.cumsum([0, *(v.samples.size for v in self.simulator.views)]) * self.n_channels
        self._rows = list(zip(edges[:-1], edges[1:], strict=True))
        self._q0, self._qd0 = self.simulator.initial_states

    @property
    def size(self) -> int:
        """How many variables: the unknowns, then (``free_initial``) ``S × 2n`` offsets."""
        return self.n_unknowns + (self.n_segments * self.n_channels if self.free_initial else 0)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lower, upper = self.unknowns.coordinate_bounds()
        extra = self.size - self.n_unknowns
        return np.r_[lower, np.full(extra, -STATE_RANGE)], np.r_[upper, np.full(extra, STATE_RANGE)]

    def start(self, z: np.ndarray, offsets: dict[int, np.ndarray] | None = None) -> np.ndarray:
        """The variables at coordinates ``z``, each segment's initial state offset by ``offsets[first
        sample]`` (in channel scales; 0 where not given: where the simulator starts it)."""
        x = np.r_[z, np.zeros(self.size - self.n_unknowns)]
        if self.free_initial and offsets:
            c = self.n_channels
            for s, (first, _) in enumerate(self.simulator.segments):
                if first in offsets:
                    x[self.n_unknowns + s * c : self.n_unknowns + (s + 1) * c] = offsets[first]
        return x

    def offsets(self, x: np.ndarray) -> dict[int, np.ndarray]:
        """``{first sample: offset [2n]}`` of each segment's initial state at variables ``x``."""
        if not self.free_initial:
            return {}
        c = self.n_channels
        block = x[self.n_unknowns :].reshape(self.n_segments, c)
        return {first: block[s] for s, (first, _) in enumerate(self.simulator.segments)}

    def split(self, x: np.ndarray) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
        """``(values [B, P], initial states ([B, S, n], [B, S, n]) or None)`` of variables ``x[size, B]``."""
        values = self.unknowns.from_coordinates(x[: self.n_unknowns].T)
        if not self.free_initial:
            return values, None
        n = self.n_channels // 2
        offsets = x[self.n_unknowns :].T.reshape(x.shape[1], self.n_segments, self.n_channels) * self.scales
        return values, (self._q0[None] + offsets[..., :n], self._qd0[None] + offsets[..., n:])

    def errors(self, x: np.ndarray) -> np.ndarray:
        """The scaled errors ``E[B, C, k]`` at variables ``x[size, B]``."""
        values, initial = self.split(x)
        return self.problem.error(values, self.simulator, initial)

    def residual(self, x: np.ndarray) -> np.ndarray:
        """``[M, B]`` residual vectors of variables ``x[size, B]`` (a diverged rollout: large, finite)."""
        e = self.errors(x) / self.divisor[None, :, None]
        e = np.where(np.isfinite(e), e, 1e150)
        return e.transpose(0, 2, 1).reshape(e.shape[0], -1).T

    def channel_of_entry(self) -> np.ndarray:
        """``[M]`` the channel of each residual vector entry."""
        k = self.measured.shape[1]
        return np.tile(np.arange(self.n_channels), k)

    def jacobian(self, x: np.ndarray, r: np.ndarray) -> BlockJacobian:
        """Forward differences at ``x[size, 1]`` with residual ``r[M, 1]``: the unknowns' columns dense,
        each segment's initial state a block of its own rows."""
        lower, upper = self.unknowns.coordinate_bounds()
        p, c = self.n_unknowns, self.n_channels
        steps = np.where(x[:p, 0] > 0.5 * (lower + upper), -STEP, STEP)  # towards the box's inside
        columns = p + (c if self.free_initial else 0)
        shifted = np.repeat(x, columns, axis=1)
        shifted[np.arange(p), np.arange(p)] += steps
        if self.free_initial:
            for channel in range(c):
                shifted[p + np.arange(self.n_segments) * c + channel, p + channel] += STATE_STEP
        moved = self.residual(shifted) - r
        dense = moved[:, :p] / steps
        if not self.free_initial:
            return BlockJacobian(dense)
        states = moved[:, p:] / STATE_STEP
        blocks = tuple((a, b, p + s * c, states[a:b]) for s, (a, b) in enumerate(self._rows))
        return BlockJacobian(dense, blocks)
