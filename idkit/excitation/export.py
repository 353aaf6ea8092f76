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

import csv
import math
import os
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

#: The per-joint quantities of a trajectory file, in column order.
QUANTITIES = ("q", "qd", "qdd")


def controller_times(t_end: float, rate: float) -> Tensor:
    """``t[T]`` (float64): ``T = t_end · rate + 1`` evenly spaced instants over ``[0, t_end]``.

    Raises:
        ValueError: ``rate`` not positive, or ``t_end · rate`` not a whole number of steps.
    """
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not 0 < rate < math.inf:
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
    return torch.linspace(0.0, t_end, round(steps) + 1, dtype=torch.float64)


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

    Columns are matched by joint name; the result is in ``joint_names`` order.

    Raises:
        ValueError: not such a file, a missing joint or quantity, a joint the robot does not have,
            a value that is not a finite number; the message names the file and the column.
        FileNotFoundError: no such file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"trajectory file not found: {path}")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return _read_csv(path, tuple(joint_names))
    if suffix == ".npz":
        return _read_npz(path, tuple(joint_names))
    raise ValueError(f"{path}: unsupported trajectory file type {path.suffix!r}; use .csv or .npz")


def _by_joint(path: Path, joints: Sequence[str], named: Sequence[str]) -> None:
    """Refuse a file whose joints differ from the robot's (missing ones, or ones it does not have)."""
    missing = [j for j in joints if j not in named]
    unknown = [j for j in named if j not in joints]
    if missing or unknown:
        parts = [f"no columns for joint(s) {', '.join(missing)}"] if missing else []
        parts += [f"joint(s) {', '.join(unknown)} that the robot does not have"] if unknown else []
        raise ValueError(f"{path}: {'; '.join(parts)} (robot joints: {', '.join(joints)})")


def _read_csv(path: Path, joints: tuple[str, ...]) -> Trajectory:
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            table = list(csv.reader(handle))
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read it as UTF-8 CSV text: {exc}") from None
    table = [row for row in table if row]
    if len(table) < 3:
        raise ValueError(f"{path}: expected a header line and at least two samples, got {len(table) - 1}")
    header = [name.strip() for name in table[0]]
    named = sorted({name.rpartition(".")[0] for name in header if name.rpartition(".")[2] in QUANTITIES})
    _by_joint(path, joints, named)
    wanted = columns(joints)
    absent = [name for name in wanted if name not in header]
    if absent:
        raise ValueError(f"{path}: missing column(s) {', '.join(absent)} (it has: {', '.join(header)})")
    index = [header.index(name) for name in wanted]
    values = np.empty((len(table) - 1, len(wanted)))
    for line, row in enumerate(table[1:], start=2):
        if len(row) != len(header):
            raise ValueError(f"{path} line {line}: {len(row)} values for {len(header)} columns")
        for k, i in enumerate(index):
            try:
                values[line - 2, k] = float(row[i])
            except ValueError:
                raise ValueError(
                    f"{path} line {line}, column {wanted[k]}: {row[i]!r} is not a number"
                ) from None
    _check_finite(path, values, wanted)
    per_joint = values[:, 1:].reshape(len(values), len(joints), len(QUANTITIES))
    return Trajectory(joints, values[:, 0], *(per_joint[..., k] for k in range(len(QUANTITIES))))


def _check_finite(path: Path, values: np.ndarray, names: Sequence[str]) -> None:
    bad = np.argwhere(~np.isfinite(values))
    if len(bad):
        sample, column = bad[0]
        raise ValueError(
            f"{path}: {names[column]} is not finite at sample {sample} ({values[sample, column]})"
        )


def _read_npz(path: Path, joints: tuple[str, ...]) -> Trajectory:
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{path}: not an archive of arrays (.npz): {exc}") from None
    if "joint_names" not in arrays:
        raise ValueError(
            f"{path}: no joint_names array to tell which column is which joint (it has: "
            f"{', '.join(sorted(arrays))}); an excitation.npz written by idkit has one"
        )
    named = [str(name) for name in np.atleast_1d(arrays["joint_names"])]
    _by_joint(path, joints, named)
    absent = [name for name in ("t", *QUANTITIES) if name not in arrays]
    if absent:
        raise ValueError(
            f"{path}: missing array(s) {', '.join(absent)} (it has: {', '.join(sorted(arrays))})"
        )
    t = arrays["t"]
    if t.dtype.kind not in "iuf" or t.ndim != 1:
        raise ValueError(f"{path}: t must be one-dimensional numbers, got {t.dtype} {list(t.shape)}")
    t = t.astype(np.float64)
    if len(t) < 2:
        raise ValueError(f"{path}: expected at least two samples, got {len(t)}")
    order = [named.index(joint) for joint in joints]
    matrices = []
    for name in QUANTITIES:
        value = arrays[name]
        if value.dtype.kind not in "iuf" or value.shape != (len(t), len(named)):
            raise ValueError(
                f"{path}: {name} must be numbers of shape [{len(t)}, {len(named)}] (t, joint_names), "
                f"got {value.dtype} {list(value.shape)}"
            )
        matrices.append(value.astype(np.float64)[:, order])
    stacked = np.concatenate([t[:, None], *matrices], axis=1)
    names = ["t"] + [f"{j}.{q}" for q in QUANTITIES for j in joints]
    _check_finite(path, stacked, names)
    return Trajectory(joints, t, *matrices)
