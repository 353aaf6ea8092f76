"""What real drivers do to a log of joint states: stalled rows and dropped stretches.

* **Stalled rows.** A driver that misses its sensor's update repeats its last row: the same positions
  and velocities, exactly, for a stretch. Those rows are not measurements of the robot: fitted as data
  they pull the model towards an arm that stood still while it was moving (three stalls of 40 ms biased
  a 36-unknown fit by up to 9 %). A stall is a run of at least ``STALL_ROWS`` identical consecutive
  rows (every joint's ``q`` and ``qd``) that the log itself contradicts: a repeated velocity that is not
  zero and says the joint moved more than ``STALL_QUANTA`` of its position resolution over the run, or
  commands that changed meanwhile. A robot at rest, or a quantised encoder whose velocity is its
  positions' difference (zero while the count does not change), repeats rows that are true: they are
  kept. The repeats (every row of the run after its first) are left out.
* **Dropped stretches.** Steps between samples longer than ``DROPPED`` median steps: the samples the
  driver did not log. Nothing is invented for them; the rollout segments restart after a long gap
  (:mod:`idkit.sim.segments`). They are counted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Identical consecutive rows (the first one and its repeats) that make a stall.
STALL_ROWS = 3
#: A repeated velocity that moves the joint more than this many position quanta contradicts the repeat.
STALL_QUANTA = 2.0
#: A step longer than this many median steps drops the samples between.
DROPPED = 1.5


@dataclass(frozen=True)
class Artefacts:
    """The driver's artefacts of one log.

    Attributes:
        stalled: ``[N]`` the rows left out as stalled repeats.
        stalls: how many stalls (runs of repeats).
        dropped: how many samples the log's gaps miss (at its median step).
    """

    stalled: np.ndarray
    stalls: int
    dropped: int

    def counts(self) -> dict[str, int]:
        """``{"stalled": rows left out, "stalls": runs, "dropped": samples missing}``."""
        return {"stalled": int(self.stalled.sum()), "stalls": self.stalls, "dropped": self.dropped}


def resolution(q: np.ndarray) -> np.ndarray:
    """``[n]`` each joint's position resolution: its smallest non-zero step between samples (the
    encoder's count for a quantised one; tiny for a float one)."""
    steps = np.abs(np.diff(q, axis=0))
    steps = np.where(steps > 0, steps, np.inf)
    smallest = steps.min(axis=0) if steps.size else np.full(q.shape[1], np.inf)
    return np.where(np.isfinite(smallest), smallest, 0.0)


def find_artefacts(
    t: np.ndarray, q: np.ndarray, qd: np.ndarray, command_t: np.ndarray, commands: np.ndarray
) -> Artefacts:
    """The stalled rows and dropped samples of a log (module docstring): states ``t[N]``, ``q``,
    ``qd [N, n]`` and commands ``command_t[M]``, ``commands [M, m]``."""
    stalled = np.zeros(t.size, dtype=bool)
    same = np.all(q[1:] == q[:-1], axis=1) & np.all(qd[1:] == qd[:-1], axis=1)
    quantum = resolution(q)
    stalls = 0
    for first, last in _runs(same):  # rows first+1 .. last+1 repeat row first
        if last - first + 2 < STALL_ROWS:
            continue
        begin, end = t[first], t[last + 1]
        moving = qd[first] != 0
        travel = np.abs(qd[first]) * (end - begin)
        contradicted = bool(np.any(moving & (travel > STALL_QUANTA * quantum)))
        if contradicted or (moving.any() and _commands_move(command_t, commands, begin, end)):
            stalled[first + 1 : last + 2] = True
            stalls += 1
    steps = np.diff(t)
    median = float(np.median(steps)) if steps.size else 0.0
    long = steps[steps > DROPPED * median] if median > 0 else steps[:0]
    dropped = int(np.sum(np.round(long / median) - 1)) if long.size else 0
    return Artefacts(stalled, stalls, dropped)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(first, last)`` index of each run of ``True`` in ``mask``."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _commands_move(command_t: np.ndarray, commands: np.ndarray, begin: float, end: float) -> bool:
    """Whether a command changed between ``begin`` (excluded) and ``end`` (included)."""
    inside = np.flatnonzero((command_t > begin) & (command_t <= end))
    if inside.size == 0:
        return False
    before = max(int(inside[0]) - 1, 0)
    rows = commands[before : int(inside[-1]) + 1]
    return bool(np.any(rows[1:] != rows[:-1]))
