"""The data pipeline: a study's files → ``Samples`` for one robot, with what was done on the way.

Every file (``data=``, ``validate=``, or another recording an estimator names, e.g. a payload's
reference) goes through the same steps, in order:

1. **read** (:func:`idkit.data.load.read_source`): a CSV or npz table, or a ROS log with its topics
   chosen, its joints matched by name and its clocks aligned (:mod:`idkit.data.logs`); samples files
   are used as they are, raw recordings preprocessed (``preprocess.apply``);
2. **checked against the robot**: its number of joints, then its timestamps, its positions and
   velocities against the robot's limits, its torques (:mod:`idkit.data.plausible`: degrees where
   radians are due, milliseconds where seconds are due, angles wrapped at ±π are refused);
3. **unit scaling**: the recorded efforts become joint torques (``robot.joint_torques``: a URDF
   robot's ``effort_scale``). From here on every torque — fitted, held out, plotted, in
   ``result.json`` — is a joint torque (N·m, N on a prismatic joint);
4. **preprocessed** (:mod:`idkit.data.preprocess`: split at gaps, resampled, filtered, differentiated,
   trimmed), the torques first shifted back by ``recording.torque_lag``.

What is automatic is resolved once, on the training files (:func:`read_training`):
``preprocess.cutoff=auto`` is chosen on the training recordings alone
(:func:`idkit.data.cutoff.choose_cutoff`, scored in the band held-out files are scored in) and said in
one line (a :class:`CutoffNote`); the resolved :class:`~idkit.data.options.DataOptions` then read
every other file, so their states are made as the training states were. ``recording.torque_lag=auto`` is
estimated per recording (the lag at which the robot's regressor explains its torques best) and said
per file (a :class:`DelayWarning`). Held-out files (:func:`read_held_out`) keep every sample
(``decimate`` and ``min_speed`` select training samples only), so their score covers the whole
recording. :func:`describe` writes what was done for ``result.json``, in one place.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import torch

from idkit.data.cutoff import CutoffChoice, choose_cutoff, lowest_rate
from idkit.data.delay import estimate_torque_lag, shift_torques
from idkit.data.files import as_paths, refuse_data_file, refuse_data_samples, refuse_repeated_files
from idkit.data.load import DataFile, Source, from_source, read_source, refuse_delay_on_samples
from idkit.data.options import DataOptions
from idkit.data.plausible import check_recording
from idkit.data.preprocess import BAND_OF_RATE, FILTER_CUTOFF_HZ, SCORE_BAND_HZ, PreprocessOptions
from idkit.data.raw import Recording
from idkit.data.recording import stack_samples
from idkit.interfaces import Robot
from idkit.notes import Note
from idkit.problem import Recorded, Samples


class CutoffNote(Note):
    """The low-pass cut-off was chosen automatically (``preprocess.cutoff=auto``): which, and why."""


class DelayWarning(UserWarning):
    """A torque delay was estimated and applied to a recording."""


@dataclass(frozen=True)
class Training:
    """The ``data=`` files read for training.

    Attributes:
        files: each file's samples (a raw recording preprocessed at ``options``' cut-off).
        options: the data options with ``cutoff=auto`` resolved: every other file is read with them.
        cutoff: how ``cutoff=auto`` was resolved (``None``: a cut-off was given).
        torques: what the recorded torques were and what the fit sees (:func:`torque_units`).
    """

    files: list[DataFile]
    options: DataOptions
    cutoff: CutoffChoice | None
    torques: dict[str, Any]

    def samples(self) -> Samples:
        """Every file's samples stacked (each filtered on its own: no filter ran across a seam)."""
        return stack_samples([f.samples for f in self.files], [f.path for f in self.files])


def read_training(robot: Robot, files: Any, options: DataOptions, stride: int = 1) -> Training:
    """Read the ``data=`` files (module doc), resolving ``preprocess.cutoff=auto`` on them.

    The raw recordings among them choose the cut-off with the robot's base regressor; without one,
    or for a robot without a linear regressor, it is :data:`~idkit.data.preprocess.FILTER_CUTOFF_HZ`
    and the reason says why. When any file is preprocessed, a :class:`CutoffNote` says the choice.

    Args:
        robot: the robot the samples are for.
        files: a path, ``Samples``, or a list of them.
        options: how files become samples.
        stride: keep every ``stride``-th sample (after preprocessing).

    Raises:
        ValueError: an empty list, a file given twice, a file the robot cannot use (naming it).
    """
    sources = _read_all(robot, files, options, "data")
    choice = None
    if options.preprocess.cutoff == "auto":
        raw = [source for source in sources if source.recording is not None]
        recordings = [_aligned(robot, source, options) for source in raw]
        choice = _auto_cutoff(robot, recordings, options.preprocess)
        options = options.with_cutoff(choice.cutoff)
        if recordings:
            warnings.warn(choice.line(), CutoffNote, stacklevel=2)
    made = [_made(robot, source, options, stride, "data") for source in sources]
    return Training(made, options, choice, torque_units(robot))


def simulated(robot: Robot, options: DataOptions) -> Training:
    """The training of a study whose samples are simulated: no file, the options as given (held-out
    samples files are read with them; a raw recording needs a cut-off given, nothing chooses one)."""
    return Training([], options, None, torque_units(robot))


def recorded(item: DataFile) -> Recorded:
    """An estimator's other recording as the ``Problem`` carries it: samples, and how they were made."""
    about: dict[str, Any] = {
        "preprocessed": item.preprocessed,
        "preprocess": "as data=" if item.preprocessed else "none",
    }
    if item.delay:
        about["delay"] = item.delay
    return Recorded(item.samples, about)


def read_held_out(robot: Robot, files: Any, training: Training, stride: int = 1) -> list[DataFile]:
    """Read ``validate=`` files with the training's options, every sample kept (module doc)."""
    options = training.options.held_out()
    return [
        _made(robot, source, options, stride, "validate")
        for source in _read_all(robot, files, options, "validate")
    ]


def read_other(robot: Robot, path: str, role: str, training: Training, data: Any) -> DataFile:
    """Another recording of the study that an estimator names (``role``: ``"payload: reference"``),
    read exactly as the ``data=`` files were — the resolved cut-off, the torque delay, the log's
    topics, the effort scale — so that its rows and the data's are filtered alike.

    Raises:
        ValueError: a ``data=`` file given again (the same path or bytes, or the same samples in
            another file): compared with itself a recording shows nothing; what reading refuses.
    """
    refuse_data_file(role, path, data)
    (source,) = _read_all(robot, [path], training.options, role)
    item = _made(robot, source, training.options, 1, role)
    if training.files:
        refuse_data_samples(role, item, training.samples())
    return item


def torque_units(robot: Robot) -> dict[str, Any]:
    """What a recording's efforts are and what the fit sees (``result.json``'s ``data.torques``)."""
    fitted = "joint torque (N·m; N on a prismatic joint)"
    scale = getattr(robot, "effort_scales", None)
    if scale is not None:
        return {
            "recorded": "efforts as logged (e.g. motor currents), times robot.effort_scale per joint",
            "effort_scale": [float(k) for k in scale],
            "fitted": fitted,
        }
    if type(robot).joint_torques is not Robot.joint_torques and not hasattr(robot, "effort_scales"):
        return {
            "recorded": f"efforts as logged, converted by {type(robot).__name__}.joint_torques",
            "fitted": fitted,
        }
    return {"recorded": fitted, "fitted": fitted}


def describe(
    files: Sequence[DataFile], training: Training, before: dict[str, Any] | None = None
) -> dict[str, Any]:
    """``result.json``'s ``data``: ``{"file": path}`` or ``{"files": [...]}`` of the training files
    (``before`` is ``None``), or ``before`` plus the ``validate`` files; the logs' topics and clocks,
    the torque delays, the preprocessing options with the files they were applied to (and the
    automatic cut-off's choice, recorded here only), and the torques' units."""
    paths = [f.path for f in files]
    if before is None:
        out: dict[str, Any] = {"file": paths[0]} if len(paths) == 1 else {"files": paths}
    else:
        out = {**before, "validate": paths}
    earlier = out.get("preprocess") or {}
    for key in ("log", "delay"):  # a ROS log's topics and clocks; a torque delay applied
        found = {**out.get(f"{key}s", {}), **{f.path: getattr(f, key) for f in files if getattr(f, key)}}
        if found:
            out[f"{key}s"] = found
    processed = [*earlier.get("files", []), *(f.path for f in files if f.preprocessed)]
    gaps = {**earlier.get("gaps", {}), **{f.path: f.preprocessing for f in files if _split(f)}}
    if processed:
        chosen = {} if training.cutoff is None else {"cutoff_choice": training.cutoff.to_dict()}
        out["preprocess"] = {
            "files": processed,
            **training.options.preprocess_dict(),
            **chosen,
            **({"gaps": gaps} if gaps else {}),
        }
    out["torques"] = training.torques
    return out


def _split(file: DataFile) -> bool:
    """Whether preprocessing split ``file`` at gaps in its timestamps."""
    return bool(file.preprocessing and file.preprocessing.get("note"))


def _read_all(robot: Robot, files: Any, options: DataOptions, role: str) -> list[Source]:
    """Steps 1–3 of the module doc for every file of a list."""
    paths = as_paths(files, role)
    if not paths:
        raise ValueError(f"{role}= is an empty list; give a file or a list of files")
    refuse_repeated_files(paths, role)
    return [_read(robot, path, options, role) for path in paths]


def _read(robot: Robot, path: Any, options: DataOptions, role: str) -> Source:
    """One file read, checked against the robot and in joint torques (steps 1–3 of the module doc)."""
    if isinstance(path, Samples):
        source = Source("<Samples>", None, path)
    else:
        source = read_source(os.fspath(path), options.apply, list(robot.joint_names), options.recording)
    held = source.recording if source.recording is not None else source.samples
    assert held is not None  # a Source holds one of them
    _check_joints(robot, source.path, held.n_joints, role)
    if source.recording is None:
        refuse_delay_on_samples(source.path, options.recording.torque_lag)
    source = _in_joint_torques(robot, source)
    measured = options.preprocess.velocities == "measured"
    check_recording(robot, source, role, measured_velocities=measured, max_gap=options.preprocess.max_gap)
    return source


def _in_joint_torques(robot: Robot, source: Source) -> Source:
    """``source`` with its efforts turned into joint torques (``robot.joint_torques``), before any
    filter: every torque after this — fitted, held out, plotted — is a joint torque."""
    if source.recording is not None:
        tau = robot.joint_torques(torch.from_numpy(source.recording.tau)).numpy()
        return replace(source, recording=replace(source.recording, tau=tau))
    assert source.samples is not None
    return replace(source, samples=replace(source.samples, tau=robot.joint_torques(source.samples.tau)))


def _check_joints(robot: Robot, path: str, joints: int, role: str) -> None:
    """Refuse a file whose number of ``joints`` is not the robot's, naming both."""
    if joints != robot.n_joints:
        source = getattr(robot, "urdf", None)
        shown = isinstance(source, str) and "<" not in source
        which = f"robot {type(robot).__name__}" + (f" ({source})" if shown else "")
        raise ValueError(
            f"{role} file {path} has {joints} joints but {which} has "
            f"{robot.n_joints}: {', '.join(robot.joint_names)}"
        )


def _made(robot: Robot, source: Source, options: DataOptions, stride: int, role: str) -> DataFile:
    """Step 4 of the module doc: the file's samples, its torque delay applied (estimated first for
    ``delay=auto``)."""
    delay = options.recording.torque_lag
    if source.recording is not None and options.preprocess.cutoff == "auto":
        raise ValueError(
            f"{role} file {source.path}: preprocess.cutoff=auto is chosen on the training (data=) "
            "recordings, and there are none; give preprocess.cutoff=<Hz>"
        )
    with warnings.catch_warnings():
        if delay == "auto":  # the first reading only serves the estimate: say things once
            warnings.simplefilter("ignore")
        item = from_source(source, options.preprocess, stride, 0.0 if delay == "auto" else float(delay))
    if delay == "auto" and item.preprocessed:
        item = _with_estimated_delay(robot, item, source, options.preprocess, stride)
    return item


def _aligned(robot: Robot, source: Source, options: DataOptions) -> Recording:
    """A training recording with its torques shifted back by ``recording.torque_lag`` for choosing the
    cut-off; ``delay=auto`` is estimated here at the default cut-off (and again at the chosen one)."""
    assert source.recording is not None
    delay = options.recording.torque_lag
    if delay == "auto":
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            provisional = from_source(source, replace(options.preprocess, cutoff=FILTER_CUTOFF_HZ))
        delay, _ = _estimated_delay(robot, provisional)
    return shift_torques(source.recording, float(delay))[0]


def _auto_cutoff(robot: Robot, recordings: list[Recording], options: PreprocessOptions) -> CutoffChoice:
    """``cutoff=auto`` for ``recordings``: cross-validated, or the fixed default with the reason."""

    def fixed(why: str) -> CutoffChoice:
        return CutoffChoice(FILTER_CUTOFF_HZ, f"auto: {why}; the default {FILTER_CUTOFF_HZ:g} Hz", {}, 0.0, 0)

    if not recordings:
        return fixed("no training file is a raw recording to choose from")
    band = min(SCORE_BAND_HZ, BAND_OF_RATE * lowest_rate(recordings, options))

    def regressor(samples: Samples) -> torch.Tensor:
        with torch.no_grad():
            return robot.regressor(samples.q, samples.qd, samples.qdd)

    if not robot.has_regressor:
        return fixed(f"robot {type(robot).__name__} has no linear regressor to cross-validate filters with")
    return choose_cutoff(recordings, regressor, options, band)


def _estimated_delay(robot: Robot, item: DataFile) -> tuple[float, float]:
    """``(delay, explained)``: the lag (s) at which the robot's regressor explains ``item``'s torques
    best, and the share it explains there (:func:`idkit.data.delay.estimate_torque_lag`)."""
    samples = item.samples
    assert item.times is not None  # a preprocessed recording has its times
    if not robot.has_regressor:
        raise ValueError(
            f"{item.path}: recording.torque_lag=auto needs a robot with a linear regressor; give the lag in s"
        )
    with torch.no_grad():
        regressor = robot.regressor(samples.q, samples.qd, samples.qdd).double().numpy()
    try:
        return estimate_torque_lag(samples.tau.double().numpy(), regressor, item.times)
    except ValueError as exc:
        raise ValueError(f"{item.path}: {exc}") from None


def _with_estimated_delay(
    robot: Robot, item: DataFile, source: Source, options: PreprocessOptions, stride: int
) -> DataFile:
    """``item`` preprocessed again with its torques shifted by :func:`_estimated_delay`."""
    delay, peak = _estimated_delay(robot, item)
    shifted = from_source(source, options, stride, delay)
    shifted = replace(shifted, delay={**(shifted.delay or {}), "estimated": True, "explained": peak})
    warnings.warn(
        f"{item.path}: the torques trail the states by {delay * 1e3:.3g} ms (recording.torque_lag=auto: "
        f"there the robot's regressor explains {100 * peak:.4g} % of them); shifted back",
        DelayWarning,
        stacklevel=4,
    )
    return shifted
