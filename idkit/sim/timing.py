"""Which time each logged sample stands for, and what the simulator is fed: the convention, once.

* A logged state ``(t_i, q_i, qd_i)`` is the joint state measured at ``t_i``.
* A logged command ``c_j`` at ``τ_j`` acts from ``τ_j`` until the next command (zero-order hold, what a
  digital controller does); before the first it is the first, after the last the last.
* ``command_delay`` ``d`` (an unknown, or 0; not the torque path's ``recording.torque_lag``): the
  states measured at ``t`` are the robot's at ``t − d`` (sensor and transport lag). Equivalently the
  commands reach the robot ``d`` late; both are modelled by running the simulator ``d`` behind the
  log's clock.
* A segment starting at sample ``s`` starts the simulator at physical time ``t_s − d`` from the logged
  state ``(q_s, qd_s)``. Simulator step ``k`` spans ``[t_s − d + k·dt, t_s − d + (k+1)·dt]`` and gets
  the held command's average over that span: one command when the span lies within its hold, a blend
  where a command changes mid-step (so a delay that is no multiple of ``dt`` changes the rollout
  smoothly, and a log on the simulator's grid with ``d = 0`` gives the commands themselves).
* ``mujoco.rollout`` returns for step ``k`` the *state row after integrating* (time
  ``t_s − d + (k+1)·dt``) and the *sensor row computed before integrating* (time ``t_s − d + k·dt``).
  idkit reads state rows only: row ``k`` predicts the logged sample at ``t_s + (k+1)·dt``. A logged
  sample between two rows is interpolated (cubic Hermite for positions, with the velocities as
  slopes; linear for velocities); a log on the simulator's grid needs no interpolation.

So a log written from a MuJoCo run — ``ctrl[k]`` applied at ``t_k = k·dt``, the state at ``t_k``
(``mj_step``'s sensors of step ``k``, or the state rows of step ``k − 1``) — is reproduced exactly by
the same model: the residual at the truth is zero (``tests/sim/test_timing.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Times closer than this fraction of a step to a grid point are on it (rounding of logged times).
SNAP = 1e-6


def held_averages(
    times: np.ndarray, values: np.ndarray, starts: np.ndarray, nstep: int, dt: float
) -> np.ndarray:
    """Average of the held commands over each simulator step.

    Args:
        times: ``[M]`` command times, strictly increasing.
        values: ``[M, m]`` commands.
        starts: ``[...]`` start time of each rollout (``t_s − d``).
        nstep: steps per rollout.
        dt: the step.

    Returns:
        ``[..., nstep, m]``: step ``k`` of each rollout gets the average over ``[start + k·dt,
        start + (k+1)·dt]``.
    """
    times = np.asarray(times, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    a = np.asarray(starts, dtype=np.float64)[..., None] + dt * np.arange(nstep)  # [..., K]
    b = a + dt
    tol = SNAP * dt
    first = _piece(
        times, a + tol
    )  # the hold containing the step's start (a start just short of a knot is on it)
    last = _piece(times, b - tol)  # the hold containing its end
    inside = first == last
    out = values[first]  # [..., K, m]
    if not inside.all():
        widths = np.diff(times)
        cumulative = np.concatenate(
            [[np.zeros(values.shape[1])], np.cumsum(values[:-1] * widths[:, None], axis=0)]
        )

        def integral(x: np.ndarray, piece: np.ndarray) -> np.ndarray:
            return cumulative[piece] + (x - times[piece])[..., None] * values[piece]

        blend = (integral(b, last) - integral(a, first)) / dt
        out = np.where(inside[..., None], out, blend)
    return out


def _piece(times: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Index of the hold containing ``x``: the last knot at or before it (0 before the first)."""
    return np.clip(np.searchsorted(times, x, side="right") - 1, 0, times.size - 1)


@dataclass(frozen=True)
class Readout:
    """Where the logged samples of one segment lie among its simulated state rows.

    Row ``-1`` is the segment's initial state. A sample at an exact row has ``fraction`` 0 and
    ``lower`` that row; otherwise it lies ``fraction`` of a step after row ``lower``.

    Attributes:
        samples: ``[k]`` the log's sample indices the segment predicts (its start first).
        lower: ``[k]`` the row at or before each sample (``-1``: the initial state).
        fraction: ``[k]`` in ``[0, 1)``.
        nstep: the simulator steps the segment needs.
    """

    samples: np.ndarray
    lower: np.ndarray
    fraction: np.ndarray
    nstep: int


def readout(t: np.ndarray, start: int, stop: int, dt: float) -> Readout:
    """The rows that predict samples ``start .. stop - 1`` of a log with times ``t`` (the first is the
    initial state, row ``-1``)."""
    samples = np.arange(start, stop)
    steps = (t[samples] - t[start]) / dt
    nearest = np.round(steps)
    on_grid = np.abs(steps - nearest) < SNAP
    whole = np.where(on_grid, nearest, np.floor(steps))
    fraction = np.where(on_grid, 0.0, steps - whole)
    lower = whole.astype(np.int64) - 1
    nstep = int(lower.max() + 1 + (fraction[-1] > 0))
    return Readout(samples, lower, fraction, max(nstep, 1))


def interpolate(
    q0: np.ndarray, qd0: np.ndarray, q: np.ndarray, qd: np.ndarray, view: Readout, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities ``[B, k, n]`` at the logged samples of one segment.

    Args:
        q0, qd0: ``[B, n]`` the initial state.
        q, qd: ``[B, nstep, n]`` the state rows.
        view: where the samples lie.
        dt: the step.
    """
    rows_q = np.concatenate([q0[:, None], q], axis=1)  # row r + 1 holds state row r
    rows_qd = np.concatenate([qd0[:, None], qd], axis=1)
    below = view.lower + 1
    pq, pv = rows_q[:, below], rows_qd[:, below]
    if not view.fraction.any():
        return pq, pv
    above = np.minimum(below + 1, rows_q.shape[1] - 1)
    nq, nv = rows_q[:, above], rows_qd[:, above]
    f = view.fraction[None, :, None]
    h00, h10, h01, h11 = 2 * f**3 - 3 * f**2 + 1, f**3 - 2 * f**2 + f, -2 * f**3 + 3 * f**2, f**3 - f**2
    q_at = h00 * pq + h10 * dt * pv + h01 * nq + h11 * dt * nv
    return q_at, (1 - f) * pv + f * nv
