"""Load and save user samples (``q, qd, qdd, tau``, each ``[N, n]``) as ``.npz`` or ``.csv``.

Formats:
    ``.npz``: one 2-D array ``[N samples, n joints]`` per quantity, under the keys ``q``, ``qd``,
    ``qdd``, ``tau`` by default. Other names map through ``keys``, e.g. the FloBaRoID/KUKA files:
    ``load_samples(path, keys=FLOBAROID_KEYS)`` reads ``positions``, ``velocities``,
    ``accelerations``, ``torques``. Extra arrays in the file are ignored.

    ``.csv``: comma-separated, one header line, then one line per sample. The header names the
    columns ``q1..qn, qd1..qdn, qdd1..qddn, tau1..taun`` (joint numbers from 1; any column order;
    extra columns such as ``t`` are ignored). ``keys`` renames the prefixes. Values are parsed as
    float64 (``nan``/``inf`` parse, and are then rejected).

Validation reuses ``Samples`` (2-D, equal shapes, finite) and adds where the problem is: the file,
the file's array or column name, and the sample (for CSV also the line). A path that is a directory,
an ``.npz`` that is not a NumPy archive (a text file renamed, an empty file), an archive without
arrays, text or object arrays, and a CSV that is not text are each refused with one message naming
the file. Object arrays are never loaded (that would need ``allow_pickle=True``, which lets a data
file run code).
"""

from __future__ import annotations

import csv
import re
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import torch

from idkit.problem import SAMPLE_ARRAYS, Samples

#: Default file names of the four arrays (and CSV column prefixes).
DEFAULT_KEYS: Mapping[str, str] = {name: name for name in SAMPLE_ARRAYS}
#: First bytes of a zip archive (an ``.npz``); ``PK\x05\x06`` starts an empty one.
ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")
#: Array kinds (``numpy.dtype.kind``) read as samples: signed, unsigned integers and floats.
NUMERIC_KINDS = "iuf"
_KIND_NAMES = {
    "U": "text",
    "S": "bytes",
    "b": "booleans",
    "c": "complex numbers",
    "M": "dates",
    "m": "time spans",
}
#: The FloBaRoID recordings, e.g. ``shared/data/kuka-lwr4/measurements_1.npz``.
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
        Validated ``Samples`` (float64, CPU).

    Raises:
        FileNotFoundError: no such file.
        ValueError: a directory, unknown suffix, a file that is not of its suffix's format, missing
            arrays/columns (the message lists those present), non-numeric or non-finite values,
            inconsistent shapes — naming file, array and sample.
    """
    path = Path(path)
    names = _resolve_keys(keys)
    if isinstance(stride, bool) or not isinstance(stride, int) or stride < 1:
        raise ValueError(f"load_samples: stride must be an integer >= 1, got {stride!r}")
    path = check_data_path(path)
    arrays = _read_npz(path, names) if path.suffix.lower() == ".npz" else _read_csv(path, names)
    try:
        return Samples(*(torch.as_tensor(arrays[k][::stride], dtype=torch.float64) for k in SAMPLE_ARRAYS))
    except ValueError as exc:
        renamed = {k: v for k, v in names.items() if k != v}
        note = f" (file names: {', '.join(f'{k}={v!r}' for k, v in renamed.items())})" if renamed else ""
        raise ValueError(f"{path}: {exc}{note}") from None


def check_data_path(path: str | Path) -> Path:
    """``path`` as a ``Path`` if it is an existing ``.npz`` or ``.csv`` file.

    Raises:
        FileNotFoundError: no such file.
        ValueError: a directory (listing the data files in it) or another suffix.
    """
    path = Path(path)
    if path.is_dir():
        found = sorted(p.name for p in path.iterdir() if p.suffix.lower() in (".npz", ".csv"))
        inside = f"; data files in it: {', '.join(found[:5])}{' …' * (len(found) > 5)}" if found else ""
        raise ValueError(f"{path} is a directory, not a samples file (.npz or .csv){inside}")
    if not path.is_file():
        raise FileNotFoundError(f"data file not found: {path}")
    if path.suffix.lower() not in (".npz", ".csv"):
        raise ValueError(f"{path}: unsupported file type {path.suffix!r}; use .npz or .csv")
    return path


def open_npz(path: Path, expected: str) -> np.lib.npyio.NpzFile:
    """Open an ``.npz`` archive of arrays without pickles (close it, e.g. ``with open_npz(...)``).

    Args:
        path: the file.
        expected: the arrays it should hold, for the message when it holds none.

    Raises:
        ValueError: not a zip (an empty or text file), a damaged archive, or no arrays in it.
    """
    with path.open("rb") as handle:
        head = handle.read(4)
    if head not in ZIP_MAGIC:
        what = "an empty file" if not head else f"a file starting with {head!r}"
        raise ValueError(
            f"{path}: not a NumPy .npz archive (a zip of arrays, as numpy.savez writes) but {what}; "
            "text data go in a .csv file (see idkit.data.io)"
        )
    try:
        archive = np.load(path, allow_pickle=False)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise ValueError(f"{path}: a damaged .npz archive ({type(exc).__name__}: {exc})") from None
    if not archive.files:
        archive.close()
        raise ValueError(f"{path}: the .npz archive contains no arrays; expected {expected}")
    return archive


def _read_npz(path: Path, names: dict[str, str]) -> dict[str, np.ndarray]:
    with open_npz(path, ", ".join(names.values())) as data:
        missing = [v for v in names.values() if v not in data.files]
        if missing:
            raise ValueError(
                f"{path}: missing array(s) {missing}; the file has {sorted(data.files)} "
                f"(map other names with keys={{'q': ..., ...}}, e.g. FLOBAROID_KEYS for FloBaRoID/KUKA files)"
            )
        return {k: _numeric_array(path, data, v, k) for k, v in names.items()}


def _numeric_array(path: Path, data: np.lib.npyio.NpzFile, key: str, name: str) -> np.ndarray:
    """Array ``key`` of an open archive if it holds numbers; else a ValueError naming file and array."""
    label = f"array {key!r}" + (f" (for {name})" if key != name else "")
    try:
        array = np.asarray(data[key])
    except ValueError:  # numpy refuses object arrays without allow_pickle
        raise ValueError(
            f"{path}: {label} holds Python objects (dtype object), which idkit never loads (that would "
            "need allow_pickle=True, which lets the file run code); save numeric arrays"
        ) from None
    except (zipfile.BadZipFile, OSError, EOFError) as exc:
        raise ValueError(f"{path}: {label} cannot be read ({type(exc).__name__}: {exc})") from None
    if array.dtype.kind not in NUMERIC_KINDS:
        raise ValueError(
            f"{path}: {label} has dtype {array.dtype} ({_KIND_NAMES.get(array.dtype.kind, 'not numbers')}); "
            "expected numbers (int or float)"
        )
    return array


def _read_csv(path: Path, names: dict[str, str]) -> dict[str, np.ndarray]:
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            rows = list(csv.reader(handle))
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not a UTF-8 text CSV file (byte {exc.start} cannot be decoded)") from None
    if not rows:
        raise ValueError(f"{path}: empty file; expected a header line q1..qn, qd1.., qdd1.., tau1..")
    header = [cell.strip() for cell in rows[0]]
    columns: dict[str, dict[int, int]] = {k: {} for k in SAMPLE_ARRAYS}
    for col, label in enumerate(header):
        for k, prefix in names.items():
            match = re.fullmatch(re.escape(prefix) + r"(\d+)", label)
            if match:
                columns[k][int(match.group(1))] = col
    n = len(columns["q"])
    for k, prefix in names.items():
        wanted = [f"{prefix}{j}" for j in range(1, max(n, 1) + 1)]
        if sorted(columns[k]) != list(range(1, n + 1)) or n == 0:
            raise ValueError(f"{path}: header must have columns {wanted}; found {header}")
    data = rows[1:]
    if not data:
        raise ValueError(f"{path}: no samples after the header line")
    table = np.empty((len(data), len(header)))
    for i, row in enumerate(data):
        if len(row) != len(header):
            raise ValueError(
                f"{path}: line {i + 2} (sample {i}) has {len(row)} values but the header has {len(header)}"
            )
        for col, cell in enumerate(row):
            try:
                table[i, col] = float(cell)
            except ValueError:
                raise ValueError(
                    f"{path}: line {i + 2} (sample {i}), column {header[col]!r}: not a number: {cell!r}"
                ) from None
    arrays = {k: table[:, [columns[k][j] for j in range(1, n + 1)]] for k in SAMPLE_ARRAYS}
    for k in SAMPLE_ARRAYS:
        bad = np.argwhere(~np.isfinite(arrays[k]))
        if len(bad):
            i, j = (int(x) for x in bad[0])
            raise ValueError(
                f"{path}: array {k!r} (column {names[k]}{j + 1!s}) has a non-finite value "
                f"({arrays[k][i, j]}) at sample {i} (line {i + 2}), joint {j}"
            )
    return arrays


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
        np.savetxt(path, table, fmt="%.17g", delimiter=",", header=",".join(header), comments="")
    else:
        raise ValueError(f"{path}: unsupported file type {path.suffix!r}; use .npz or .csv")
    return path
