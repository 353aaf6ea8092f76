"""One data file → identification samples, whatever it holds: samples as they are, or a raw recording
preprocessed (the command line's ``data=`` and ``validate=`` files).

A file holds either **samples** (``q, qd, qdd, tau``: :mod:`idkit.data.io`) or a **raw recording**
(``t, q, tau`` and maybe ``qd``, no accelerations: :mod:`idkit.data.recording`). The FloBaRoID names
(``times, positions, velocities, accelerations, torques``, e.g. the KUKA files) are recognised in an
``.npz``. ``apply`` says when :func:`idkit.data.preprocess.preprocess` runs:

* ``"auto"`` (default): only for raw recordings — samples keep their own derivatives;
* ``"on"``: always; a samples file is read as a recording (its ``t``/``times``, positions, torques,
  velocities), so idkit's filter replaces the file's derivatives;
* ``"off"``: never; a raw recording is an error (it has no accelerations).
"""

from __future__ import annotations

import csv
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from idkit.data.io import FLOBAROID_KEYS, check_data_path, load_samples, open_npz
from idkit.data.preprocess import PreprocessOptions, preprocess_with_times
from idkit.data.recording import FLOBAROID_RECORDING_KEYS, load_recording
from idkit.problem import SAMPLE_ARRAYS, Samples

APPLY = ("auto", "on", "off")


@dataclass(frozen=True)
class FileKind:
    """What a data file holds: ``samples`` (has accelerations) and/or ``timestamps``, and its names."""

    samples: bool
    timestamps: bool
    flobaroid: bool


def file_kind(path: str | Path) -> FileKind:
    """Look at a file's array names (``.npz``) or header (``.csv``) without reading the values.

    Raises:
        FileNotFoundError: no such file.
        ValueError: a directory, neither ``.npz`` nor ``.csv``, or not a readable archive of arrays.
    """
    path = check_data_path(path)
    if path.suffix.lower() == ".npz":
        with open_npz(path, "samples (q, qd, qdd, tau) or a recording (t, q, tau)") as data:
            names = set(data.files)
    else:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            header = next(csv.reader(handle), [])
        names = {cell.strip().rstrip("0123456789") for cell in header}
    flobaroid = FLOBAROID_KEYS["q"] in names
    keys = FLOBAROID_RECORDING_KEYS if flobaroid else {"t": "t"}
    accelerations = (FLOBAROID_KEYS if flobaroid else {"qdd": "qdd"})["qdd"]
    return FileKind(samples=accelerations in names, timestamps=keys["t"] in names, flobaroid=flobaroid)


def load_data_file(
    path: str | Path, options: PreprocessOptions | None = None, apply: str = "auto", stride: int = 1
) -> tuple[Samples, np.ndarray | None, bool]:
    """Samples from one file (module doc): ``(samples, times[N] or None, preprocessed)``.

    Args:
        path: ``.npz`` or ``.csv`` file of samples or of a raw recording.
        options: preprocessing options (default :class:`PreprocessOptions`).
        apply: ``"auto"``, ``"on"`` or ``"off"`` (module doc).
        stride: keep every ``stride``-th sample (after preprocessing, which sees them all).

    Raises:
        ValueError: ``apply`` unknown; ``"on"`` for a file without timestamps; ``"off"`` (or
            ``"auto"``) for a file with neither accelerations nor timestamps — naming the file.
    """
    if apply not in APPLY:
        raise ValueError(f"preprocess.apply must be one of {', '.join(APPLY)}, got {apply!r}")
    kind = file_kind(path)
    run = apply == "on" or (apply == "auto" and not kind.samples)
    if not run:
        if not kind.samples:
            raise ValueError(
                f"{path}: a raw recording (no accelerations qdd); preprocess it (preprocess=auto or on)"
            )
        samples = load_samples(path, keys=FLOBAROID_KEYS if kind.flobaroid else None, stride=stride)
        times = _times(path, kind)[::stride] if kind.timestamps else None
        return samples, times, False
    if not kind.timestamps:
        raise ValueError(
            f"{path}: preprocessing needs timestamps (a 't' column or array) and the file has none; "
            "use preprocess=off for samples with their own qd, qdd"
        )
    keys: Mapping[str, str] | None = FLOBAROID_RECORDING_KEYS if kind.flobaroid else None
    samples, times = preprocess_with_times(load_recording(path, keys=keys), options)
    if stride > 1:
        samples = Samples(*(getattr(samples, k)[::stride] for k in SAMPLE_ARRAYS))
    return samples, times[::stride], True


def _times(path: str | Path, kind: FileKind) -> np.ndarray:
    """The timestamps of a samples file, from its start (s)."""
    name = FLOBAROID_RECORDING_KEYS["t"] if kind.flobaroid else "t"
    if Path(path).suffix.lower() == ".npz":
        with np.load(path, allow_pickle=False) as data:
            t = np.asarray(data[name], dtype=np.float64)
    else:
        t = load_recording(path).t
    return t - t[0]
