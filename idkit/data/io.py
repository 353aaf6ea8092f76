"""Load and save user samples (``q, qd, qdd, tau``, each ``[N, n]``) as ``.npz`` or ``.csv``.

Formats (read by :mod:`idkit.data.table`, which says what is refused and how):
    ``.npz``: one 2-D array ``[N samples, n joints]`` per quantity, under the keys ``q``, ``qd``,
    ``qdd``, ``tau`` by default. Other names map through ``keys``, e.g. the FloBaRoID/KUKA files:
    ``load_samples(path, keys=FLOBAROID_KEYS)`` reads ``positions``, ``velocities``,
    ``accelerations``, ``torques``. Extra arrays in the file are ignored.

    ``.csv``: comma-separated UTF-8, one header line, then one line per sample. The header names the
    columns ``q1..qn, qd1..qdn, qdd1..qddn, tau1..taun`` (joint numbers from 1), or per joint
    ``<joint>.q, <joint>.qd, <joint>.qdd, <joint>.tau``; any column order, any case; extra columns
    such as ``t`` are ignored. ``keys`` renames the prefixes. Values are parsed as float64 (``nan``/
    ``inf`` parse, and are then rejected).

Errors name the file, the array or column, and the sample (for CSV also the line).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import torch

from idkit.data.table import Table, read_quantities, read_table
from idkit.problem import SAMPLE_ARRAYS, Samples
from idkit.untrusted import csv_header

#: Default file names of the four arrays (and CSV column prefixes).
DEFAULT_KEYS: Mapping[str, str] = {name: name for name in SAMPLE_ARRAYS}
#: The FloBaRoID recordings, e.g. the KUKA LWR4+ files ``measurements_1.npz``.
FLOBAROID_KEYS: Mapping[str, str] = {
    "q": "positions",
    "qd": "velocities",
    "qdd": "accelerations",
    "tau": "torques",
}


def _resolve_keys(keys: Mapping[str, str] | None) -> dict[str, str]:
    merged = dict(DEFAULT_KEYS)
    if keys is not None:
        unknown = sorted(set(keys) - set(SAMPLE_ARRAYS))
        if unknown:
            raise ValueError(f"keys: unknown array name(s) {unknown}; map some of {', '.join(SAMPLE_ARRAYS)}")
        merged.update(keys)
    return merged


def load_samples(path: str | Path, keys: Mapping[str, str] | None = None, stride: int = 1) -> Samples:
    """Read samples from ``path`` (``.npz`` or ``.csv``, see the module docstring).

    Args:
        path: the file.
        keys: file name of each array (``.npz`` key or CSV column prefix) for those that differ
            from ``q``, ``qd``, ``qdd``, ``tau``.
        stride: keep every ``stride``-th sample (e.g. thin a densely logged recording).

    Returns:
        Validated ``Samples`` (float64, CPU), joints in the file's order.

    Raises:
        FileNotFoundError: no such file.
        ValueError: a directory, unknown suffix, a file that is not of its suffix's format, missing
            arrays/columns (the message lists those present), non-numeric or non-finite values,
            inconsistent shapes — naming file, array and sample.
    """
    if isinstance(stride, bool) or not isinstance(stride, int) or stride < 1:
        raise ValueError(f"load_samples: stride must be an integer >= 1, got {stride!r}")
    samples, _ = samples_from_table(read_table(path), keys)
    return Samples(*(getattr(samples, k)[::stride] for k in SAMPLE_ARRAYS)) if stride > 1 else samples


def samples_from_table(
    table: Table, keys: Mapping[str, str] | None = None, joints: Sequence[str] | None = None
) -> tuple[Samples, tuple[str, ...] | None]:
    """``(samples, joint names)`` from an open table (:func:`idkit.data.table.read_quantities`): the
    joint names of per-joint CSV columns (in ``joints``' order when given), else ``None``."""
    names = _resolve_keys(keys)
    arrays, found = read_quantities(table, names, joints)
    try:
        samples = Samples(*(torch.as_tensor(arrays[k], dtype=torch.float64) for k in SAMPLE_ARRAYS))
    except ValueError as exc:
        renamed = {k: v for k, v in names.items() if k != v}
        note = f" (file names: {', '.join(f'{k}={v!r}' for k, v in renamed.items())})" if renamed else ""
        raise ValueError(f"{table.path}: {exc}{note}") from None
    return samples, found


def save_samples(samples: Samples, path: str | Path, keys: Mapping[str, str] | None = None) -> Path:
    """Write ``samples`` to ``path`` (``.npz`` or ``.csv``) so that ``load_samples`` reads them back.

    CSV values are written with 17 significant digits, which round-trips float64 exactly.
    Returns the path written.
    """
    path = Path(path)
    names = _resolve_keys(keys)
    arrays = {k: getattr(samples, k).detach().cpu().double().numpy() for k in SAMPLE_ARRAYS}
    suffix = path.suffix.lower()
    if suffix == ".npz":
        np.savez(path, **{names[k]: v for k, v in arrays.items()})
    elif suffix == ".csv":
        n = samples.n_joints
        header = [f"{names[k]}{j}" for k in SAMPLE_ARRAYS for j in range(1, n + 1)]
        table = np.concatenate([arrays[k] for k in SAMPLE_ARRAYS], axis=1)
        np.savetxt(path, table, fmt="%.17g", delimiter=",", header=csv_header(header), comments="")
    else:
        raise ValueError(f"{path}: unsupported file type {path.suffix!r}; use .npz or .csv")
    return path
