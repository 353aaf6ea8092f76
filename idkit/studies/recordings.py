"""The ``data=`` and ``validate=`` files of a study: loaded, preprocessed and checked against the robot.

One or several files (``data=a.npz`` or ``data=[a.npz, b.csv, run.mcap]``) are each read by
:func:`idkit.data.load.load_data_file` (samples as they are, raw recordings through the
``preprocess`` options), checked to have the robot's number of joints, and — for training — stacked
into one ``Samples`` (:func:`idkit.data.recording.stack_samples`; each file is filtered on its own, so
no filter runs across a seam). A ``validate=`` file that is a training file — the same path, the
same bytes, or the same samples — is refused: its score would not be held-out validation.
"""

from __future__ import annotations

import hashlib
import os
import warnings
from collections.abc import Mapping
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from idkit.data.delay import torque_delay
from idkit.data.load import DataFile, load_data_file
from idkit.data.preprocess import PreprocessOptions
from idkit.data.recording import RecordingOptions
from idkit.interfaces import Robot
from idkit.problem import SAMPLE_ARRAYS, Samples
from idkit.studies.build import plain


def preprocess_options(spec: Any) -> tuple[PreprocessOptions, str]:
    """``(options, apply)`` from the ``preprocess`` config node, a ``PreprocessOptions`` or ``None``.

    The node is :class:`PreprocessOptions`'s fields plus ``apply`` (``auto``/``on``/``off``, see
    :mod:`idkit.data.load`); ``None`` is ``auto`` with the default options.

    Raises:
        ValueError: a key that is not an option (naming the options).
    """
    spec = plain(spec)
    if spec is None:
        return PreprocessOptions(), "auto"
    if isinstance(spec, PreprocessOptions):
        return spec, "on"
    if not isinstance(spec, Mapping):
        raise ValueError(f"preprocess must be a mapping of options, got {spec!r}")
    options = dict(spec)
    apply = str(options.pop("apply", "auto"))
    known = {f.name for f in fields(PreprocessOptions)}
    unknown = sorted(set(options) - known)
    if unknown:
        raise ValueError(
            f"preprocess.{unknown[0]} is not a preprocessing option; "
            f"they are apply, {', '.join(sorted(known))}"
        )
    return PreprocessOptions(**options), apply


def recording_options(spec: Any) -> RecordingOptions:
    """:class:`~idkit.data.recording.RecordingOptions` from the ``recording`` config node (``None``:
    defaults); ``delay`` is ``"auto"`` or a number of seconds.

    Raises:
        ValueError: a key that is not an option (naming the options), a delay that is neither.
    """
    spec = plain(spec)
    if spec is None:
        return RecordingOptions()
    if isinstance(spec, RecordingOptions):
        return spec
    if not isinstance(spec, Mapping):
        raise ValueError(f"recording must be a mapping of options, got {spec!r}")
    known = [f.name for f in fields(RecordingOptions)]
    unknown = sorted(set(spec) - set(known))
    if unknown:
        raise ValueError(f"recording.{unknown[0]} is not a recording option; they are {', '.join(known)}")
    options = {k: (None if v is None else str(v)) for k, v in spec.items() if k != "delay"}
    delay = spec.get("delay", 0.0)
    if delay != "auto":
        try:
            delay = float(delay)
        except (TypeError, ValueError):
            raise ValueError(f"recording.delay must be 'auto' or seconds, got {delay!r}") from None
        if not np.isfinite(delay):
            raise ValueError(f"recording.delay must be 'auto' or finite seconds, got {delay!r}")
    return RecordingOptions(**options, delay=delay)


def as_paths(files: Any) -> list[Any]:
    """``data=`` / ``validate=`` as a list: one path, a list of paths, or ``Samples`` objects."""
    files = plain(files)
    if files is None:
        return []
    if isinstance(files, (str, os.PathLike, Samples)):
        return [files]
    return list(files)


def load_files(
    robot: Robot,
    files: Any,
    preprocess: Any = None,
    role: str = "data",
    stride: int = 1,
    recording: Any = None,
) -> list[DataFile]:
    """Load every file of ``data=`` or ``validate=`` (``role``) for ``robot``; ``stride`` thins them;
    ``recording`` (the ``recording`` config node) says which topics of a ROS log to read.

    The recorded efforts become joint torques here (``robot.joint_torques``: a ``urdf`` robot's
    ``effort_scale``), so fits, validation errors (N·m) and identified models are in joint torque.

    Raises:
        ValueError: an empty list, or a file whose number of joints is not the robot's (naming the
            file, both counts and the robot's joints); what the loader refuses.
    """
    options, apply = preprocess_options(preprocess)
    log = recording_options(recording)
    paths = as_paths(files)
    if not paths:
        raise ValueError(f"{role}= is an empty list; give a file or a list of files")
    loaded = []
    for path in paths:
        if isinstance(path, Samples):
            item = DataFile("<Samples>", path, None, False)
        else:
            path = os.fspath(path)
            delay = 0.0 if log.delay == "auto" else float(log.delay)
            with warnings.catch_warnings():
                if log.delay == "auto":  # the first reading only serves the estimate: say things once
                    warnings.simplefilter("ignore")
                item = load_data_file(path, options, apply, stride, list(robot.joint_names), log, delay)
        _check_joints(robot, item, role)
        if log.delay == "auto" and item.preprocessed:
            item = _with_estimated_delay(robot, item, options, apply, stride, log)
        loaded.append(item)
    # Where recorded efforts become joint torques (robot.effort_scale): every figure after is in N·m.
    return [replace(f, samples=replace(f.samples, tau=robot.joint_torques(f.samples.tau))) for f in loaded]


def _check_joints(robot: Robot, item: DataFile, role: str) -> None:
    if item.samples.n_joints != robot.n_joints:
        source = getattr(robot, "urdf", None)
        shown = isinstance(source, str) and "<" not in source
        which = f"robot {type(robot).__name__}" + (f" ({source})" if shown else "")
        raise ValueError(
            f"{role} file {item.path} has {item.samples.n_joints} joints but {which} has "
            f"{robot.n_joints}: {', '.join(robot.joint_names)}"
        )


class DelayWarning(UserWarning):
    """A torque delay was estimated and applied to a recording."""


def _with_estimated_delay(
    robot: Robot,
    item: DataFile,
    options: PreprocessOptions,
    apply: str,
    stride: int,
    log: RecordingOptions,
) -> DataFile:
    """``item`` read again with its torques shifted by the delay at which the robot's regressor
    explains them best (:func:`idkit.data.delay.torque_delay`)."""
    import torch

    samples = item.samples
    try:
        with torch.no_grad():
            regressor = robot.regressor(samples.q, samples.qd, samples.qdd).double().numpy()
    except NotImplementedError:
        raise ValueError(
            f"{item.path}: recording.delay=auto needs a robot with a linear regressor; give the delay in s"
        ) from None
    try:
        delay, peak = torque_delay(robot.joint_torques(samples.tau).numpy(), regressor, item.times)
    except ValueError as exc:
        raise ValueError(f"{item.path}: {exc}") from None
    joints = list(robot.joint_names)
    shifted = load_data_file(item.path, options, apply, stride, joints, log, delay)
    shifted = replace(shifted, delay={**(shifted.delay or {}), "estimated": True, "explained": peak})
    warnings.warn(
        f"{item.path}: the torques trail the states by {delay * 1e3:.3g} ms (recording.delay=auto: there "
        f"the robot's regressor explains {100 * peak:.4g} % of them); shifted back",
        DelayWarning,
        stacklevel=3,
    )
    return shifted


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
    for held in as_paths(validate):
        for train in training:
            same = _sameness(train, held)
            if same:
                raise ValueError(
                    f"validate file {_shown(held)} is the training file {_shown(train)} ({same}): a score on "
                    "the data the model was fitted to is not held-out validation; validate on a recording "
                    "the fit does not see"
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
    import torch

    for held in held_out:
        block = held.samples
        if block.n_joints != training.n_joints or block.n_samples > training.n_samples:
            continue
        first = (training.q == block.q[0].to(training.q)).all(dim=1)
        for start in first.nonzero().flatten().tolist():
            rows = slice(start, start + block.n_samples)
            if rows.stop <= training.n_samples and all(
                torch.equal(getattr(training, k)[rows], getattr(block, k).to(getattr(training, k)))
                for k in SAMPLE_ARRAYS
            ):
                raise ValueError(
                    f"validate file {held.path} holds the same samples as the training data (its rows "
                    f"{rows.start}–{rows.stop - 1}): a score on the data the model was fitted to is not "
                    "held-out validation; validate on a recording the fit does not see"
                )
