"""Rollouts of many parameter sets at once: one ``MjModel`` per set, ``mujoco.rollout`` on threads.

:class:`BatchSimulator` turns parameter values ``[B, P]`` into the positions and velocities the model
predicts at the log's samples, ``[B, k, n]`` (every segment's samples, its start first, in order),
following :mod:`idkit.sim.timing`. It keeps one model copy per batch slot and one ``MjData`` per
thread between calls, so a swarm's iterations and a Jacobian's columns only write numbers into them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from idkit.data.commands import RobotLog
from idkit.robots.mjcf import import_mujoco
from idkit.runtime import available_cores
from idkit.sim.drive import Drive, match_commands
from idkit.sim.model import SimModel, logged_state
from idkit.sim.quantities import Unknowns
from idkit.sim.timing import Readout, held_averages, interpolate, readout


@dataclass
class Counter:
    """Rollouts and simulator steps run so far (a fit's cost, as the bench reports it)."""

    rollouts: int = 0
    steps: int = 0


@dataclass
class BatchSimulator:
    """The model, the log, the unknowns and the segments, ready to roll out (module docstring).

    Attributes:
        sim, log, unknowns: what is simulated, against what, with which numbers free.
        segments: ``(start, end)`` sample indices (:mod:`idkit.sim.segments`).
        threads: rollout threads (``None``: every CPU this process may use).
        initial: ``[S, n]`` positions and ``[S, n]`` velocities each segment starts from (``None``:
            the logged ones).
    """

    sim: SimModel
    log: RobotLog
    unknowns: Unknowns
    segments: Sequence[tuple[int, int]]
    threads: int | None = None
    initial: tuple[np.ndarray, np.ndarray] | None = None
    counter: Counter = field(default_factory=Counter)

    def __post_init__(self) -> None:
        mujoco = import_mujoco()
        self._mujoco = mujoco
        model = self.sim.model
        self.drive: Drive = match_commands(self.sim, self.log)
        self.dt = self.sim.timestep
        ids = [self.sim.joint_id(j) for j in self.log.joint_names]
        self._qpos = 1 + np.array([model.jnt_qposadr[j] for j in ids])  # state = [time, qpos, qvel, ...]
        self._qvel = 1 + model.nq + np.array([model.jnt_dofadr[j] for j in ids])
        self.views: list[Readout] = [readout(self.log.t, s, e, self.dt) for s, e in self.segments]
        self.nstep = max(v.nstep for v in self.views)
        self.samples = np.concatenate([v.samples for v in self.views])
        starts = np.array([s for s, _ in self.segments])
        q0, qd0 = (self.log.q[starts], self.log.qd[starts]) if self.initial is None else self.initial
        self._q0, self._qd0 = np.asarray(q0, dtype=np.float64), np.asarray(qd0, dtype=np.float64)
        self._states = np.stack(
            [
                logged_state(self.sim, self.log.joint_names, a, b)
                for a, b in zip(self._q0, self._qd0, strict=True)
            ]
        )
        self._starts = self.log.t[starts]
        self._commands = self.log.commands[:, list(self.drive.columns)]
        self._fixed = None if self.unknowns.delay_index is not None else self._controls(np.zeros(1))
        self._threads = self.threads or available_cores()
        from mujoco import rollout

        self._pool = rollout.Rollout(nthread=self._threads if self._threads > 1 else 0)
        self._datas = [mujoco.MjData(model) for _ in range(self._threads)]
        self._models: list[Any] = []
        self._scratch = mujoco.MjData(model)

    def close(self) -> None:
        """Stop the rollout threads."""
        if self._pool is not None:
            self._pool.close()
            self._pool = None

    def __del__(self) -> None:
        pool = getattr(self, "_pool", None)
        if pool is not None:
            pool.close()

    def _controls(self, delays: np.ndarray) -> np.ndarray:
        """``[B, S, nstep, nu]`` controls for delays ``[B]`` (:mod:`idkit.sim.timing`), computed once per
        distinct delay (a Jacobian's columns share one but for the delay's own)."""
        distinct, index = np.unique(delays, return_inverse=True)
        starts = self._starts[None, :] - distinct[:, None]
        return held_averages(self.log.command_t, self._commands, starts, self.nstep, self.dt)[
            index.reshape(-1)
        ]

    def models(self, values: np.ndarray) -> list[Any]:
        """``B`` models with ``values[B, P]`` written in (the pool's copies, reused between calls)."""
        while len(self._models) < len(values):
            self._models.append(self._copy())
        for model, row in zip(self._models, values, strict=False):
            self.unknowns.apply(model, row)
            if self.unknowns.needs_set_const:
                self._mujoco.mj_setConst(model, self._scratch)
        return self._models[: len(values)]

    def _copy(self) -> Any:
        import copy

        return copy.copy(self.sim.model)

    @property
    def initial_states(self) -> tuple[np.ndarray, np.ndarray]:
        """``([S, n], [S, n])``: the positions and velocities each segment starts from by default."""
        return self._q0, self._qd0

    def predict(
        self, values: np.ndarray, initial: tuple[np.ndarray, np.ndarray] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities ``[B, k, n]`` at the predicted samples for ``values[B, P]``.

        Args:
            values: ``[B, P]`` the unknowns' values.
            initial: ``([B, S, n], [B, S, n])`` positions and velocities each segment of each set starts
                from (``None``: ``initial_states``, for every set).

        Non-finite predictions (a diverged rollout) come back as they are; the caller scores them.
        """
        values = np.atleast_2d(np.asarray(values, dtype=np.float64))
        batch, segments = values.shape[0], len(self.segments)
        if initial is None:
            q0 = np.broadcast_to(self._q0, (batch, *self._q0.shape))
            qd0 = np.broadcast_to(self._qd0, (batch, *self._qd0.shape))
            states = np.tile(self._states, (batch, 1))
        else:
            q0, qd0 = (np.asarray(x, dtype=np.float64) for x in initial)
            states = np.tile(self._states[None], (batch, 1, 1))
            states[..., self._qpos] = q0
            states[..., self._qvel] = qd0
            states = states.reshape(batch * segments, -1)
        models = self.models(values)
        if self._fixed is not None:
            controls = np.broadcast_to(self._fixed, (batch, *self._fixed.shape[1:]))
        else:
            controls = self._controls(values[:, self.unknowns.delay_index])
        controls = np.ascontiguousarray(controls.reshape(batch * segments, self.nstep, -1))
        listed = [m for m in models for _ in range(segments)]
        state, _ = self._pool.rollout(listed, self._datas, np.ascontiguousarray(states), controls)
        self.counter.rollouts += batch * segments
        self.counter.steps += batch * segments * self.nstep
        state = state.reshape(batch, segments, self.nstep, -1)
        q_parts, qd_parts = [], []
        for s, view in enumerate(self.views):
            rows = state[:, s, : view.nstep]
            q, qd = interpolate(
                q0[:, s], qd0[:, s], rows[..., self._qpos], rows[..., self._qvel], view, self.dt
            )
            q_parts.append(q)
            qd_parts.append(qd)
        return np.concatenate(q_parts, axis=1), np.concatenate(qd_parts, axis=1)
