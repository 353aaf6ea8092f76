"""The ``data=`` and ``validate=`` files of a study: loaded, preprocessed and checked against the robot.

One or several files (``data=a.npz`` or ``data=[a.npz, b.csv, run.mcap]``) are each read by
:func:`idkit.data.load.read_source` (samples as they are, raw recordings through the
``preprocess`` options), checked to have the robot's number of joints, and — for training — stacked
into one ``Samples`` (:func:`idkit.data.recording.stack_samples`; each file is filtered on its own, so
no filter runs across a seam). A ``validate=`` file that is a training file — the same path, the
same bytes, or the same samples — is refused: its score would not be held-out validation. So is a file
given twice in one list: stacked twice, its samples would count double in the fit.

``preprocess.cutoff=auto`` (the default) is resolved by :func:`load_training` from the training
recordings alone (:func:`idkit.data.cutoff.choose_cutoff`, scored in the validation's band), said in
one line (a :class:`CutoffNote`) and then used for every file, the held-out ones too: their states are
made as the training states were. Held-out files keep every sample (``decimate`` and ``min_speed``
select training samples only), so their score covers the whole recording.
"""

from __future__ import annotations

import hashlib
import os
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from idkit.data.cutoff import CutoffChoice, choose_cutoff, lowest_rate
from idkit.data.delay import shift_torques, torque_delay
from idkit.data.load import DataFile, Source, from_source, read_source, refuse_delay_on_samples
from idkit.data.preprocess import FILTER_CUTOFF_HZ, PreprocessOptions
from idkit.data.recording import Recording, RecordingOptions
from idkit.interfaces import Robot
from idkit.notes import Note
from idkit.problem import SAMPLE_ARRAYS, Samples
from idkit.studies.build import plain
from idkit.studies.validation import BAND_OF_RATE, SCORE_BAND_HZ


def preprocess_options(spec: Any) -> tuple[PreprocessOptions, str]:
    """``(options, apply)`` from the ``preprocess`` config node, a ``PreprocessOptions`` or ``None``.

    The node is :class:`PreprocessOptions`'s fields plus ``apply`` (``auto``/``on``/``off``, see
    :mod:`idkit.data.load`); ``None`` is ``auto`` with the default options.

    Raises:
        ValueError: a key that is not an option (naming the options).
    """
    spec = plain(spec)
    if spec is None:
        return PreprocessOptions(cutoff="auto"), "auto"
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
    cutoff = options.get("cutoff", "auto")
    if cutoff != "auto":
        try:
            options["cutoff"] = float(cutoff)
        except (TypeError, ValueError):
            raise ValueError(f"preprocess.cutoff must be 'auto' or a number of Hz, got {cutoff!r}") from None
    else:
        options["cutoff"] = "auto"
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


class CutoffNote(Note):
    """The low-pass cut-off was chosen automatically (``preprocess.cutoff=auto``): which, and why."""


@dataclass(frozen=True)
class Training:
    """The ``data=`` files loaded for training.

    Attributes:
        files: each file's samples (a raw recording preprocessed at ``options.cutoff``).
        preprocess: the ``preprocess`` node with the cut-off resolved: the held-out files are
            preprocessed with it, so their states are made as the training states were.
        cutoff: how ``cutoff=auto`` was resolved (``None``: a cut-off was given).
    """

    files: list[DataFile]
    preprocess: dict[str, Any]
    cutoff: CutoffChoice | None


def load_training(
    robot: Robot, files: Any, preprocess: Any = None, stride: int = 1, recording: Any = None
) -> Training:
    """Load the ``data=`` files (:func:`load_files`), resolving ``preprocess.cutoff=auto`` from them.

    The raw recordings among them choose the cut-off (:func:`idkit.data.cutoff.choose_cutoff` with
    the robot's base regressor, scored in the band held-out files are scored in); without one, or for
    a robot without a linear regressor, it is :data:`~idkit.data.preprocess.FILTER_CUTOFF_HZ`, and the
    reason says why. When any file is preprocessed, a :class:`CutoffNote` says the choice in one line.
    """
    options, apply = preprocess_options(preprocess)
    log = recording_options(recording)
    paths = as_paths(files)
    refuse_repeated_files(paths, "data")
    joints = list(robot.joint_names)
    sources = [
        path if isinstance(path, Samples) else read_source(os.fspath(path), apply, joints, log)
        for path in paths
    ]
    for source in sources:  # before the cut-off is chosen on the recordings among them
        _check_delay(source, log)
    choice = None
    if options.cutoff == "auto":
        raw = [s for s in sources if isinstance(s, Source) and s.recording is not None]
        for source in raw:
            _check_joints(robot, source.path, source.recording.n_joints, "data")
        recordings = [_aligned(robot, source, options, log) for source in raw]
        choice = _auto_cutoff(robot, recordings, options)
        options = replace(options, cutoff=choice.cutoff)
        if recordings:
            warnings.warn(choice.line(), CutoffNote, stacklevel=2)
    resolved = {"apply": apply, **vars(options)}
    return Training(
        load_files(robot, sources, resolved, stride=stride, recording=recording), resolved, choice
    )


def _aligned(robot: Robot, source: Source, options: PreprocessOptions, log: RecordingOptions) -> Recording:
    """A training recording with its torques shifted back by ``recording.delay`` for choosing the
    cut-off; ``delay=auto`` is estimated here at the default cut-off (and again at the chosen one)."""
    assert source.recording is not None
    delay = log.delay
    if delay == "auto":
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            provisional = from_source(source, replace(options, cutoff=FILTER_CUTOFF_HZ))
        delay, _ = _estimated_delay(robot, provisional)
    return shift_torques(source.recording, float(delay))[0]


def _auto_cutoff(robot: Robot, recordings: list[Recording], options: PreprocessOptions) -> CutoffChoice:
    """``cutoff=auto`` for ``recordings``: cross-validated, or the fixed default with the reason."""

    def fixed(why: str) -> CutoffChoice:
        return CutoffChoice(FILTER_CUTOFF_HZ, f"auto: {why}; the default {FILTER_CUTOFF_HZ:g} Hz", {}, 0.0, 0)

    if not recordings:
        return fixed("no training file is a raw recording to choose from")
    band = min(SCORE_BAND_HZ, BAND_OF_RATE * lowest_rate(recordings, options))

    import torch

    def regressor(samples: Samples) -> torch.Tensor:
        with torch.no_grad():
            return robot.regressor(samples.q, samples.qd, samples.qdd)

    try:
        regressor(Samples(*(torch.zeros(1, robot.n_joints, dtype=torch.float64),) * 4))
    except NotImplementedError:
        return fixed(f"robot {type(robot).__name__} has no linear regressor to cross-validate filters with")
    # in joint torque, as the fit will see them (robot.effort_scale)
    recordings = [replace(r, tau=robot.joint_torques(torch.as_tensor(r.tau)).numpy()) for r in recordings]
    return choose_cutoff(recordings, regressor, options, band)


def load_files(
    robot: Robot,
    files: Any,
    preprocess: Any = None,
    role: str = "data",
    stride: int = 1,
    recording: Any = None,
) -> list[DataFile]:
    """Load every file of ``data=`` or ``validate=`` (``role``) for ``robot``; ``stride`` thins them;
    ``recording`` (the ``recording`` config node) says which topics of a ROS log to read. ``files``
    may hold :class:`~idkit.data.load.Source` objects already read. A ``validate`` file keeps every
    sample (``decimate`` and ``min_speed`` apply to training files).

    The recorded efforts become joint torques here (``robot.joint_torques``: a ``urdf`` robot's
    ``effort_scale``), so fits, validation errors (N·m) and identified models are in joint torque.

    Raises:
        ValueError: an empty list, ``cutoff=auto`` (resolved by :func:`load_training`), or a file
            whose number of joints is not the robot's (naming the file, both counts and the robot's
            joints); what the loader refuses.
    """
    options, apply = preprocess_options(preprocess)
    if role == "validate":
        options = replace(options, decimate=1, min_speed=0.0)
    log = recording_options(recording)
    paths = as_paths(files)
    if not paths:
        raise ValueError(f"{role}= is an empty list; give a file or a list of files")
    refuse_repeated_files(paths, role)
    joints = list(robot.joint_names)
    loaded = []
    for path in paths:
        if isinstance(path, Samples):
            _check_delay(path, log)
            item = DataFile("<Samples>", path, None, False)
        else:
            source = path if isinstance(path, Source) else read_source(os.fspath(path), apply, joints, log)
            _check_delay(source, log)
            if source.recording is not None and options.cutoff == "auto":
                raise ValueError(
                    f"{role} file {source.path}: preprocess.cutoff=auto is resolved on the training data"
                )
            delay = 0.0 if log.delay == "auto" else float(log.delay)
            with warnings.catch_warnings():
                if log.delay == "auto":  # the first reading only serves the estimate: say things once
                    warnings.simplefilter("ignore")
                item = from_source(source, options, stride, delay)
        _check_joints(robot, item.path, item.samples.n_joints, role)
        if log.delay == "auto" and item.preprocessed:
            item = _with_estimated_delay(robot, item, source, options, stride)
        loaded.append(item)
    # Where recorded efforts become joint torques (robot.effort_scale): every figure after is in N·m.
    return [replace(f, samples=replace(f.samples, tau=robot.joint_torques(f.samples.tau))) for f in loaded]


def _check_delay(source: Source | Samples, log: RecordingOptions) -> None:
    """Refuse ``recording.delay`` (a number or ``auto``) for samples used as they are: only a raw
    recording's torques can be shifted, and ``auto`` has no recording to estimate the delay on."""
    if isinstance(source, Samples):
        refuse_delay_on_samples("<Samples>", log.delay)
    elif source.recording is None:
        refuse_delay_on_samples(source.path, log.delay)


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


class DelayWarning(UserWarning):
    """A torque delay was estimated and applied to a recording."""


def _estimated_delay(robot: Robot, item: DataFile) -> tuple[float, float]:
    """``(delay, explained)``: the lag (s) at which the robot's regressor explains ``item``'s torques
    best, and the share it explains there (:func:`idkit.data.delay.torque_delay`)."""
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
        return torque_delay(robot.joint_torques(samples.tau).numpy(), regressor, item.times)
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


def refuse_repeated_files(files: Any, role: str) -> None:
    """Refuse a file that ``data=`` (or ``validate=``, the ``role``) gives twice: the same path, the
    same bytes, or the same ``Samples`` object. Stacked twice, a training file's samples would count
    double in the fit, silently; a held-out file would be scored twice. (Files already read, as
    :func:`load_training` hands them to :func:`load_files`, were checked before.)

    Raises:
        ValueError: naming the file, the earlier one it repeats and how they are the same.
    """
    items = [item for item in as_paths(files) if not isinstance(item, Source)]
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


def reader_like_data(
    robot: Robot, data: Any, training: Samples, preprocess: Any, recording: Any
) -> Callable[[str, str], DataFile]:
    """``read(path, role)``: another recording of the study (a payload's reference, ``role`` names it
    in messages) read exactly as the ``data=`` files were — ``preprocess`` with the cut-off the
    training resolved, the ``recording`` node's torque delay and topics, the robot's effort scale —
    so that its rows and the data's are filtered alike (``Problem.read_like_data``).

    ``read`` raises ``ValueError`` for a ``data=`` file given again (the same path or bytes,
    :func:`refuse_training_files`'s test, or the same samples in another file): compared with itself a
    recording shows nothing, and the fit would say so with a number (a payload of about 0 kg).
    """

    def read(path: str, role: str) -> DataFile:
        for train in as_paths(data):
            same = _sameness(train, path)
            if same:
                raise ValueError(
                    f"{role} file {path} is the data file {_shown(train)} ({same}); compared with itself "
                    "it shows nothing: give a recording of its own"
                )
        item = load_files(robot, [path], preprocess, role=role, recording=recording)[0]
        rows = _repeated_rows(training, item.samples)
        if rows is not None:
            raise ValueError(
                f"{role} file {path} holds the same samples as the data (its rows {rows.start}–"
                f"{rows.stop - 1}); compared with itself it shows nothing: give a recording of its own"
            )
        return item

    return read
