"""A raw recording: what a robot controller logs — timestamps, positions, torques, maybe velocities.

The one type every reader of raw data returns (:mod:`idkit.data.recording` for CSV/npz files,
:mod:`idkit.data.logs` for ROS logs) and :mod:`idkit.data.preprocess` turns into ``Samples``. It
checks what any reader must hand on: the shapes, finite values and strictly increasing timestamps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def check_increasing(source: str, t: np.ndarray, name: str = "t", what: str = "timestamps") -> None:
    """Refuse times ``t[N]`` that are not 1-D and strictly increasing, naming the first offending sample
    (every reader's check: torque recordings, command logs' states and commands).

    Args:
        source: the file, for the message.
        t: the times.
        name: the array's name in the message (``t``, ``command_t``).
        what: what the times are (``timestamps``, ``command times``).
    """
    if t.ndim != 1:
        raise ValueError(f"{source}: {what} {name!r} must be 1-D, got shape {list(t.shape)}")
    steps = np.diff(t)
    if (steps <= 0).any():
        i = int(np.flatnonzero(steps <= 0)[0])
        raise ValueError(
            f"{source}: {what} must increase strictly; {name}[{i + 1}] = {float(t[i + 1])!r} follows "
            f"{name}[{i}] = {float(t[i])!r}"
        )


@dataclass(frozen=True)
class Recording:
    """A raw recording of an ``n``-joint robot (float64 numpy arrays).

    Attributes:
        t: ``[N]`` timestamps (s), strictly increasing; read from a file, they count from its first
            stamp (subtracted exactly: :meth:`idkit.data.table.Table.times`).
        q: ``[N, n]`` joint positions.
        tau: ``[N, n]`` joint torques (or forces).
        qd: ``[N, n]`` measured joint velocities, or ``None``.
        source: where it came from, for error messages.
        joint_names: the ``n`` joints' names when the file names them (per-joint CSV columns, a log),
            else ``None`` (joints by position).
    """

    t: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    qd: np.ndarray | None = None
    source: str = "<recording>"
    joint_names: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=np.float64)
        object.__setattr__(self, "t", t)
        if t.ndim != 1 or t.size < 2:
            raise ValueError(f"{self.source}: timestamps 't' must be 1-D with >= 2 samples, got {t.shape}")
        for name in ("q", "tau", "qd"):
            value = getattr(self, name)
            if value is None:
                continue
            value = np.asarray(value, dtype=np.float64)
            object.__setattr__(self, name, value)
            if value.ndim != 2 or value.shape[0] != t.size or value.shape[1] != np.shape(self.q)[-1]:
                raise ValueError(
                    f"{self.source}: array {name!r} must be [N={t.size}, n] like 'q', got {value.shape}"
                )
        for name in ("t", "q", "tau", "qd"):
            value = getattr(self, name)
            if value is not None and not np.isfinite(value).all():
                index = np.argwhere(~np.isfinite(value))[0]
                raise ValueError(f"{self.source}: array {name!r} has a non-finite value at sample {index[0]}")
        check_increasing(self.source, t)

    @property
    def n_joints(self) -> int:
        return self.q.shape[1]
