"""The ``data=`` and ``validate=`` files of a study: loaded, preprocessed and checked against the robot.

One or several files (``data=a.npz`` or ``data=[a.npz, b.csv]``) are each read by
:func:`idkit.data.load.load_data_file` (samples as they are, raw recordings through the
``preprocess`` options), checked to have the robot's number of joints, and — for training — stacked
into one ``Samples`` (:func:`idkit.data.recording.stack_samples`; each file is filtered on its own, so
no filter runs across a seam).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from idkit.data.load import load_data_file
from idkit.data.preprocess import PreprocessOptions
from idkit.interfaces import Robot
from idkit.problem import Samples
from idkit.studies.build import plain


@dataclass(frozen=True)
class DataFile:
    """One loaded file: its ``samples`` ``[N, n]``, ``times[N]`` (s, or ``None``) and whether idkit
    preprocessed it."""

    path: str
    samples: Samples
    times: np.ndarray | None
    preprocessed: bool


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


def as_paths(files: Any) -> list[Any]:
    """``data=`` / ``validate=`` as a list: one path, a list of paths, or ``Samples`` objects."""
    files = plain(files)
    if files is None:
        return []
    if isinstance(files, (str, os.PathLike, Samples)):
        return [files]
    return list(files)


def load_files(
    robot: Robot, files: Any, preprocess: Any = None, role: str = "data", stride: int = 1
) -> list[DataFile]:
    """Load every file of ``data=`` or ``validate=`` (``role``) for ``robot``; ``stride`` thins them.

    The recorded efforts become joint torques here (``robot.joint_torques``: a ``urdf`` robot's
    ``effort_scale``), so fits, validation errors (N·m) and identified models are in joint torque.

    Raises:
        ValueError: an empty list, or a file whose number of joints is not the robot's (naming the
            file, both counts and the robot's joints); what the loader refuses.
    """
    options, apply = preprocess_options(preprocess)
    paths = as_paths(files)
    if not paths:
        raise ValueError(f"{role}= is an empty list; give a file or a list of files")
    loaded = []
    for path in paths:
        if isinstance(path, Samples):
            loaded.append(DataFile("<Samples>", path, None, False))
            continue
        samples, times, done = load_data_file(os.fspath(path), options, apply, stride)
        loaded.append(DataFile(os.fspath(path), samples, times, done))
    for item in loaded:
        if item.samples.n_joints != robot.n_joints:
            source = getattr(robot, "urdf", None)
            shown = isinstance(source, str) and "<" not in source
            which = f"robot {type(robot).__name__}" + (f" ({source})" if shown else "")
            raise ValueError(
                f"{role} file {item.path} has {item.samples.n_joints} joints but {which} has "
                f"{robot.n_joints}: {', '.join(robot.joint_names)}"
            )
    # Where recorded efforts become joint torques (robot.effort_scale): every figure after is in N·m.
    return [replace(f, samples=replace(f.samples, tau=robot.joint_torques(f.samples.tau))) for f in loaded]
