"""Which files a study was given: ``data=`` / ``validate=`` as a list, each file once, none held out
that the fit sees.

A ``validate=`` file that is a training file — the same path, the same bytes, or the same samples —
is refused: its score would not be held-out validation. So is a file given twice in one list:
stacked twice, its samples would count double in the fit.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from idkit.data.load import DataFile
from idkit.problem import SAMPLE_ARRAYS, Samples

#: What ``data=`` and ``validate=`` take, for messages.
RECORDINGS = "a file path (CSV, .npz, ROS log), Samples, or a list of them"


def as_paths(files: Any, role: str = "data") -> list[Any]:
    """``data=`` / ``validate=`` (the ``role``) as a list: one path, a list of paths, or ``Samples``.

    Raises:
        TypeError: something else (``data=3.5``, a list holding a number), named with its role.
    """
    if files is None:
        return []
    items = [files] if isinstance(files, (str, os.PathLike, Samples)) else files
    if isinstance(items, Mapping) or not isinstance(items, Iterable):
        raise TypeError(f"{role}={files!r} ({type(files).__name__}) is not recordings: give {RECORDINGS}")
    items = list(items)
    for item in items:
        if not isinstance(item, (str, os.PathLike, Samples)):
            raise TypeError(
                f"{role}= holds {item!r} ({type(item).__name__}), not a recording: give {RECORDINGS}"
            )
    return items


def refuse_training_files(data: Any, validate: Any) -> None:
    """Refuse a ``validate=`` file that is a ``data=`` file: the same path, the same bytes (a copy),
    or the same ``Samples`` object.

    A model scored on its own training data is not validated on held-out data, and the report would
    call the score "held-out validation". (A copy in another format — a CSV exported from the same
    log — is not recognised.)

    Raises:
        ValueError: naming both files and how they are the same.
    """
    training = as_paths(data)
    for held in as_paths(validate, "validate"):
        for train in training:
            same = _sameness(train, held)
            if same:
                raise ValueError(
                    f"validate file {_shown(held)} is the training file {_shown(train)} ({same}): a score on "
                    "the data the model was fitted to is not held-out validation; validate on a recording "
                    "the fit does not see"
                )


def refuse_repeated_files(files: Any, role: str) -> None:
    """Refuse a file that ``data=`` (or ``validate=``, the ``role``) gives twice: the same path, the
    same bytes, or the same ``Samples`` object. Stacked twice, a training file's samples would count
    double in the fit, silently; a held-out file would be scored twice.

    Raises:
        ValueError: naming the file, the earlier one it repeats and how they are the same.
    """
    items = as_paths(files, role)
    effect = (
        "would be stacked twice and count double in the fit" if role == "data" else "would be scored twice"
    )
    for k, later in enumerate(items):
        for earlier in items[:k]:
            same = _sameness(earlier, later)
            if same:
                first = "" if _shown(earlier) == _shown(later) else f" as {_shown(earlier)}"
                raise ValueError(
                    f"{role}= gives {_shown(later)} twice ({same}{first}): its samples "
                    f"{effect}; give each recording once"
                )


def _shown(item: Any) -> str:
    return "<Samples>" if isinstance(item, Samples) else os.fspath(item)


def _sameness(a: Any, b: Any) -> str | None:
    """How two ``data=`` items are the same (``"same file"``, ``"same content"``), or ``None``."""
    if isinstance(a, Samples) or isinstance(b, Samples):
        return "the same samples" if a is b else None
    first, second = Path(a), Path(b)
    if not (first.exists() and second.exists()):
        return None  # the loader names a missing file
    if first.resolve() == second.resolve():
        return "same file"
    fingerprints = [_fingerprint(p) for p in (first, second)]
    sizes = [sorted((name, size) for name, size, _ in f) for f in fingerprints]
    if sizes[0] != sizes[1]:
        return None
    return "same content" if _digest(first) == _digest(second) else None


def _fingerprint(path: Path) -> list[tuple[str, int, Path]]:
    """``(relative name, size, path)`` of a file, or of every file in a folder (a ROS 2 bag)."""
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    return [(str(p.relative_to(path)) if path.is_dir() else "", p.stat().st_size, p) for p in files]


def _digest(path: Path) -> str:
    """SHA-256 over a file's bytes, or over a folder's files (names and bytes)."""
    digest = hashlib.sha256()
    for name, _, file in _fingerprint(path):
        digest.update(name.encode())
        with file.open("rb") as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                digest.update(block)
    return digest.hexdigest()


def refuse_seen_samples(training: Samples, held_out: list[DataFile]) -> None:
    """Refuse a ``validate=`` file whose samples are a block of the training samples: the same
    recording in other bytes (a copy saved with a byte-order mark, other column names or order,
    another file format holding the same values), which :func:`refuse_training_files` cannot see.

    Raises:
        ValueError: naming the file and the training rows it repeats.
    """
    for held in held_out:
        rows = _repeated_rows(training, held.samples)
        if rows is not None:
            raise ValueError(
                f"validate file {held.path} holds the same samples as the training data (its rows "
                f"{rows.start}–{rows.stop - 1}): a score on the data the model was fitted to is not "
                "held-out validation; validate on a recording the fit does not see"
            )


def _repeated_rows(training: Samples, block: Samples) -> slice | None:
    """The rows of ``training`` that ``block`` repeats exactly (every array), or ``None``."""
    import torch

    if block.n_joints != training.n_joints or block.n_samples > training.n_samples:
        return None
    first = (training.q == block.q[0].to(training.q)).all(dim=1)
    for start in first.nonzero().flatten().tolist():
        rows = slice(start, start + block.n_samples)
        if rows.stop <= training.n_samples and all(
            torch.equal(getattr(training, k)[rows], getattr(block, k).to(getattr(training, k)))
            for k in SAMPLE_ARRAYS
        ):
            return rows
    return None


def refuse_data_file(role: str, path: Any, data: Any) -> None:
    """Refuse another recording of the study (a payload's reference, ``role`` names it) that is a
    ``data=`` file (the same path or bytes): compared with itself a recording shows nothing, and a
    fit would say so with a number (a payload of about 0 kg)."""
    for train in as_paths(data):
        same = _sameness(train, path)
        if same:
            raise ValueError(
                f"{role} file {_shown(path)} is the data file {_shown(train)} ({same}); compared with itself "
                "it shows nothing: give a recording of its own"
            )


def refuse_data_samples(role: str, item: DataFile, training: Samples) -> None:
    """Refuse another recording whose samples are a block of the training samples (the same
    recording in another file), for the reason of :func:`refuse_data_file`."""
    rows = _repeated_rows(training, item.samples)
    if rows is not None:
        raise ValueError(
            f"{role} file {item.path} holds the same samples as the data (its rows {rows.start}–"
            f"{rows.stop - 1}); compared with itself it shows nothing: give a recording of its own"
        )
