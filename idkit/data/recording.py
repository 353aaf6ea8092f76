"""Raw recordings (timestamps, positions, torques, maybe velocities) and stacking of samples.

A raw recording is what a robot controller logs: ``t[N]`` (s, increasing, possibly irregular),
``q[N, n]`` and ``tau[N, n]``, and sometimes ``qd[N, n]``; no accelerations.
:func:`idkit.data.preprocess.preprocess` turns it into ``Samples``.

Files:
    ``.csv``: one header line naming the columns ``t, q1..qn, tau1..taun`` and optionally
    ``qd1..qdn`` (joint numbers from 1, any column order, other columns ignored), then one line per
    sample.
    ``.npz``: arrays ``t`` ``[N]``, ``q`` and ``tau`` ``[N, n]``, optionally ``qd``. Other names map
    through ``keys``, e.g. :data:`FLOBAROID_RECORDING_KEYS` for the KUKA/FloBaRoID files.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from idkit.problem import SAMPLE_ARRAYS, Samples

RECORDING_ARRAYS = ("t", "q", "tau", "qd")
#: File names of the arrays in the FloBaRoID recordings (``shared/data/kuka-lwr4``).
FLOBAROID_RECORDING_KEYS: Mapping[str, str] = {
    "t": "times",
    "q": "positions",
    "tau": "torques",
    "qd": "velocities",
}


@dataclass(frozen=True)
class Recording:
    """A raw recording of an ``n``-joint robot (float64 numpy arrays).

    Attributes:
        t: ``[N]`` timestamps (s), strictly increasing.
        q: ``[N, n]`` joint positions.
        tau: ``[N, n]`` joint torques (or forces).
        qd: ``[N, n]`` measured joint velocities, or ``None``.
        source: where it came from, for error messages.
    """

    t: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    qd: np.ndarray | None = None
    source: str = "<recording>"

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
        steps = np.diff(t)
        if (steps <= 0).any():
            i = int(np.flatnonzero(steps <= 0)[0])
            raise ValueError(
                f"{self.source}: timestamps must increase strictly; t[{i + 1}] = {float(t[i + 1])!r} follows "
                f"t[{i}] = {float(t[i])!r}"
            )

    @property
    def n_joints(self) -> int:
        return self.q.shape[1]


def load_recording(path: str | Path, keys: Mapping[str, str] | None = None) -> Recording:
    """Read a raw recording from ``.csv`` or ``.npz`` (module doc).

    Args:
        path: the file.
        keys: file name of each array (npz key or CSV column prefix) where it differs from
            ``t``, ``q``, ``tau``, ``qd``.

    Raises:
        FileNotFoundError: no such file.
        ValueError: unknown suffix, missing arrays/columns, non-numeric values (naming file, column
            and line), or what :class:`Recording` rejects.
    """
    path = Path(path)
    names = {k: k for k in RECORDING_ARRAYS}
    unknown = sorted(set(keys or {}) - set(RECORDING_ARRAYS))
    if unknown:
        raise ValueError(f"keys: unknown array name(s) {unknown}; map some of {', '.join(RECORDING_ARRAYS)}")
    names.update(keys or {})
    if not path.is_file():
        raise FileNotFoundError(f"recording not found: {path}")
    suffix = path.suffix.lower()
    if suffix == ".npz":
        with np.load(path, allow_pickle=False) as data:
            missing = [names[k] for k in ("t", "q", "tau") if names[k] not in data.files]
            if missing:
                raise ValueError(
                    f"{path}: missing array(s) {missing}; the file has {sorted(data.files)} (map other "
                    "names with keys=..., e.g. FLOBAROID_RECORDING_KEYS)"
                )
            arrays = {k: np.asarray(data[v]) for k, v in names.items() if v in data.files}
    elif suffix == ".csv":
        arrays = _read_csv_columns(path, names)
    else:
        raise ValueError(f"{path}: unsupported file type {path.suffix!r}; use .npz or .csv")
    return Recording(arrays["t"], arrays["q"], arrays["tau"], arrays.get("qd"), source=str(path))


def _read_csv_columns(path: Path, names: dict[str, str]) -> dict[str, np.ndarray]:
    with path.open(newline="") as handle:
        rows = list(csv.reader(handle))
    if len(rows) < 2:
        raise ValueError(f"{path}: expected a header line (t, q1.., tau1.., [qd1..]) and samples")
    header = [cell.strip() for cell in rows[0]]
    try:
        table = np.array([[float(cell) for cell in row] for row in rows[1:]])
    except ValueError:
        for i, row in enumerate(rows[1:]):
            for col, cell in enumerate(row):
                try:
                    float(cell)
                except ValueError:
                    column = header[col] if col < len(header) else f"#{col + 1}"
                    raise ValueError(
                        f"{path}: line {i + 2}, column {column!r}: not a number: {cell!r}"
                    ) from None
        raise ValueError(f"{path}: rows have different numbers of values") from None
    if table.ndim != 2 or table.shape[1] != len(header):
        raise ValueError(f"{path}: every line needs {len(header)} values like the header")
    if names["t"] not in header:
        raise ValueError(f"{path}: no timestamp column {names['t']!r}; found {header}")
    arrays = {"t": table[:, header.index(names["t"])]}
    for k in ("q", "tau", "qd"):
        numbered = {}
        for col, label in enumerate(header):
            match = re.fullmatch(re.escape(names[k]) + r"(\d+)", label)
            if match:
                numbered[int(match.group(1))] = col
        if not numbered and k == "qd":
            continue
        n = len(numbered)
        if n == 0 or sorted(numbered) != list(range(1, n + 1)):
            raise ValueError(f"{path}: header needs columns {names[k]}1..{names[k]}n; found {header}")
        arrays[k] = table[:, [numbered[j] for j in range(1, n + 1)]]
    if arrays["tau"].shape[1] != arrays["q"].shape[1]:
        raise ValueError(
            f"{path}: {arrays['q'].shape[1]} position columns but {arrays['tau'].shape[1]} torque columns"
        )
    return arrays


def stack_samples(parts: Sequence[Samples], labels: Sequence[str] | None = None) -> Samples:
    """Concatenate the samples of several recordings (``data=[a, b]``) along the sample axis.

    Preprocess each recording on its own first (a filter must not run across the seam).

    Raises:
        ValueError: no parts, or parts with different numbers of joints (naming both).
    """
    if not parts:
        raise ValueError("stack_samples: no recordings to stack")
    labels = list(labels) if labels is not None else [f"recording {i}" for i in range(len(parts))]
    first = parts[0]
    for label, part in zip(labels, parts, strict=True):
        if part.n_joints != first.n_joints:
            raise ValueError(
                f"stack_samples: {label} has {part.n_joints} joints but {labels[0]} has {first.n_joints}"
            )
    device, dtype = first.q.device, first.q.dtype
    return Samples(
        *(torch.cat([getattr(p, k).to(device=device, dtype=dtype) for p in parts]) for k in SAMPLE_ARRAYS)
    )


def save_recording(recording: Recording, path: str | Path, velocities: bool = False) -> Path:
    """Write ``recording`` as a raw CSV (``t, q1..qn, tau1..taun`` and, with ``velocities``, ``qd1..``)
    that :func:`load_recording` reads back; 17 significant digits round-trip float64."""
    n = recording.n_joints
    columns = [recording.t[:, None], recording.q, recording.tau]
    header = ["t", *(f"q{j}" for j in range(1, n + 1)), *(f"tau{j}" for j in range(1, n + 1))]
    if velocities:
        if recording.qd is None:
            raise ValueError(f"{recording.source}: no velocities to write")
        columns.append(recording.qd)
        header += [f"qd{j}" for j in range(1, n + 1)]
    path = Path(path)
    np.savetxt(path, np.hstack(columns), fmt="%.17g", delimiter=",", header=",".join(header), comments="")
    return path


def main(argv: Sequence[str] | None = None) -> None:
    """``python -m idkit.data.recording IN OUT.csv``: a recording (e.g. a FloBaRoID/KUKA ``.npz``) as a
    raw CSV of timestamps, positions and torques — what a robot controller logs."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m idkit.data.recording", description=main.__doc__)
    parser.add_argument("source", help=".npz or .csv recording (FloBaRoID array names are recognised)")
    parser.add_argument("target", help="the raw .csv to write (t, q1.., tau1..)")
    parser.add_argument("--velocities", action="store_true", help="also write the measured qd1..qdn")
    args = parser.parse_args(argv)
    keys = None
    if Path(args.source).suffix.lower() == ".npz":
        with np.load(args.source, allow_pickle=False) as data:
            keys = FLOBAROID_RECORDING_KEYS if FLOBAROID_RECORDING_KEYS["t"] in data.files else None
    recording = load_recording(args.source, keys=keys)
    path = save_recording(recording, args.target, velocities=args.velocities)
    print(f"{path}: {recording.t.size} samples, {recording.n_joints} joints")


if __name__ == "__main__":
    main()
