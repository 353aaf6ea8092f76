"""A motion as the samples a controller runs: ``t, q, qd, qdd`` per joint name, at a fixed rate.

Columns (CSV) and arrays (NPZ) follow the named-joint convention of idkit's data files: ``t``, then
``<joint>.q``, ``<joint>.qd``, ``<joint>.qdd`` for every joint (the joint name as the robot spells
it). The NPZ holds ``t[T]``, ``q``, ``qd``, ``qdd`` ``[T, n]`` and ``joint_names[n]`` (the columns'
joints, in order) — names, not positions, say which column is which joint. Floats are written in
full (``repr``), so a file read back gives the same numbers it was checked with.

:func:`controller_times` is the sample grid: ``T = t_end · rate + 1`` instants from 0 to ``t_end``
inclusive, so a motion at rest at both ends is sampled at rest; ``t_end · rate`` must be a whole
number (otherwise the last step would be shorter than the others).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from idkit.memory import check_memory
from idkit.options import positive_number

#: The per-joint quantities of a trajectory file, in column order.
QUANTITIES = ("q", "qd", "qdd")
#: ``[T, joints]`` float64 arrays a task holds at the controller times at least: the motion's
#: ``q, qd, qdd`` and the exported trajectory's copy of them.
SAMPLE_ARRAYS = 2 * len(QUANTITIES)


def controller_times(t_end: float, rate: float, joints: int = 1) -> Tensor:
    """``t[T]`` (float64): ``T = t_end · rate + 1`` evenly spaced instants over ``[0, t_end]``.

    ``joints``: how many joints will be sampled at them, for the memory check (the samples of
    ``excitation.t_end=1e9`` at 1 kHz would need terabytes).

    Raises:
        ValueError: ``t_end`` or ``rate`` not a finite number > 0, or ``t_end · rate`` not a whole
            number of steps; ``idkit.memory.SizeError`` for samples that do not fit in memory.
    """
    if not positive_number(t_end):
        raise ValueError(f"excitation.t_end must be a finite number of seconds > 0, got {t_end!r}")
    if not positive_number(rate):
        raise ValueError(
            f"excitation.rate must be a positive number of samples per second (Hz), got {rate!r}"
        )
    steps = t_end * rate
    if abs(steps - round(steps)) > 1e-9 * max(1.0, steps) or round(steps) < 1:
        raise ValueError(
            f"excitation.t_end={t_end:g} s is not a whole number of {1 / rate:g} s steps at rate {rate:g} Hz "
            f"({steps:.6g} steps); choose t_end = {max(1, math.floor(steps)) / rate:g} or "
            f"{math.ceil(steps) / rate:g} s"
        )
    count = round(steps) + 1
    check_memory(
        f"excitation.t_end × excitation.rate = {t_end:g} s × {rate:g} Hz = {count:.3g} samples of "
        f"{joints} joint(s), which",
        8 * count * (SAMPLE_ARRAYS * joints + 1),
        "lower excitation.t_end or excitation.rate",
    )
    return torch.linspace(0.0, t_end, count, dtype=torch.float64)


def columns(joint_names: Sequence[str]) -> list[str]:
    """CSV header: ``t``, then ``<joint>.q, <joint>.qd, <joint>.qdd`` per joint."""
    return ["t"] + [f"{joint}.{quantity}" for joint in joint_names for quantity in QUANTITIES]


@dataclass(frozen=True)
class Trajectory:
    """Samples of a motion: ``t[T]`` and ``q, qd, qdd`` ``[T, n]`` (float64 numpy), joints by name."""

    joint_names: tuple[str, ...]
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray

    @classmethod
    def of(cls, joint_names: Sequence[str], t: Tensor, q: Tensor, qd: Tensor, qdd: Tensor) -> Trajectory:
        """From tensors (any device)."""
        return cls(tuple(joint_names), *(x.detach().cpu().double().numpy() for x in (t, q, qd, qdd)))

    def rows(self) -> np.ndarray:
        """``[T, 1 + 3n]`` in :func:`columns` order."""
        per_joint = np.stack((self.q, self.qd, self.qdd), axis=-1).reshape(len(self.t), -1)
        return np.concatenate((self.t[:, None], per_joint), axis=1)

    def arrays(self) -> dict[str, np.ndarray]:
        """The NPZ's arrays (module docstring)."""
        return {
            "t": self.t,
            "q": self.q,
            "qd": self.qd,
            "qdd": self.qdd,
            "joint_names": np.array(self.joint_names, dtype=str),
        }


def read_trajectory(path: str | os.PathLike[str], joint_names: Sequence[str]) -> Trajectory:
    """Read a trajectory file (``.csv`` or ``.npz``, module docstring) for the joints ``joint_names``.

    Read through idkit's one table reader (``idkit.data.table``: encodings, duplicate columns,
    non-numbers and non-finite values refused naming file, line and column); columns are matched
    by joint name and the result is in ``joint_names`` order.

    Raises:
        ValueError: not such a file, a missing quantity, a missing joint or one the robot does not
            have, columns without joint names, fewer than two samples.
        FileNotFoundError: no such file.
    """
    from idkit.data.table import NpzTable, open_npz, read_table

    table = read_table(path)
    table.require(matrices=QUANTITIES, vectors=["t"])
    joints = tuple(joint_names)
    named: Sequence[str] | None
    if isinstance(table, NpzTable):
        with open_npz(table.path, "t, q, qd, qdd and joint_names") as archive:
            if "joint_names" not in archive.files:
                raise ValueError(
                    f"{table.path}: no joint_names array to tell which column is which joint (it has: "
                    f"{', '.join(sorted(archive.files))}); an excitation.npz written by idkit has one"
                )
            named = [str(name) for name in np.atleast_1d(archive["joint_names"])]
    else:
        named = table.matrix("q").joints
        if named is None:
            raise ValueError(f"{table.path}: columns q1..qn do not name their joints; name them <joint>.q")
    _same_joints(table.path, joints, named)
    t = table.vector("t")
    if len(t) < 2:
        raise ValueError(f"{table.path}: expected at least two samples, got {len(t)}")
    order = [named.index(joint) for joint in joints]
    matrices = []
    for name in QUANTITIES:
        values = table.matrix(name, joints).values
        if values.shape != (len(t), len(joints)):
            raise ValueError(
                f"{table.path}: {name} must be [{len(t)}, {len(joints)}] (samples of t, joints), got "
                f"{list(values.shape)}"
            )
        matrices.append(values[:, order] if isinstance(table, NpzTable) else values)
    return Trajectory(joints, t, *matrices)


def _same_joints(path: Path, joints: Sequence[str], named: Sequence[str]) -> None:
    """Refuse a file whose joints differ from the robot's (missing ones, or ones it does not have)."""
    missing = [j for j in joints if j not in named]
    unknown = [j for j in named if j not in joints]
    if missing or unknown:
        parts = [f"no columns for joint(s) {', '.join(missing)}"] if missing else []
        parts += [f"joint(s) {', '.join(unknown)} that the robot does not have"] if unknown else []
        raise ValueError(f"{path}: {'; '.join(parts)} (robot joints: {', '.join(joints)})")
