"""One data file → identification samples, whatever it holds: samples as they are, or a raw recording
preprocessed (the command line's ``data=`` and ``validate=`` files).

A file holds either **samples** (``q, qd, qdd, tau``: :mod:`idkit.data.io`) or a **raw recording**
(``t, q, tau`` and maybe ``qd``, no accelerations: :mod:`idkit.data.recording`). Both are read by
the one table reader, :mod:`idkit.data.table`. The FloBaRoID names (``times, positions, velocities,
accelerations, torques``, e.g. the KUKA files) are recognised in an ``.npz``. ``apply`` says when
:func:`idkit.data.preprocess.preprocess` runs:

* ``"auto"`` (default): only for raw recordings — samples keep their own derivatives;
* ``"on"``: always; a samples file is read as a recording (its ``t``/``times``, positions, torques,
  velocities), so idkit's filter replaces the file's derivatives;
* ``"off"``: never; a raw recording is an error (it has no accelerations).

A ROS log (a bag folder, ``.mcap``, ``.db3``, ``.bag``: :mod:`idkit.data.logs`) is a raw recording.
Files whose columns name joints (``<joint>.q``) and logs are matched to the robot's joints by name, in
any order; extra joints are ignored and a joint the robot needs and the file lacks is refused by name.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from idkit.data.delay import shift_torques
from idkit.data.io import FLOBAROID_KEYS, samples_from_table
from idkit.data.logs import LogWarning, is_log, read_log
from idkit.data.options import RecordingOptions
from idkit.data.preprocess import PreprocessOptions, preprocess_recording
from idkit.data.raw import Recording
from idkit.data.recording import FLOBAROID_RECORDING_KEYS, recording_from_table
from idkit.data.table import Table, read_table
from idkit.problem import SAMPLE_ARRAYS, Samples

APPLY = ("auto", "on", "off")


@dataclass(frozen=True)
class FileKind:
    """What a data file holds: ``samples`` (has accelerations) and/or ``timestamps``, and its names."""

    samples: bool
    timestamps: bool
    flobaroid: bool


@dataclass(frozen=True)
class DataFile:
    """One loaded file: its ``samples`` ``[N, n]`` (joints in the robot's order when the file names
    them), ``times[N]`` (s from the file's start, or ``None``), whether idkit ``preprocessed`` it, and
    what preprocessing reported (``preprocessing``: the segments between gaps and a ``note``) and, for a
    ROS log, what was read (``log``: topics, clocks, joints used and ignored); ``delay``: the torque
    delay applied to a raw recording (seconds, samples dropped); ``raw_tau`` ``[N, n]``: the measured
    torques at ``times`` before any filter (``None``: ``samples.tau`` are those, the file's own)."""

    path: str
    samples: Samples
    times: np.ndarray | None
    preprocessed: bool
    preprocessing: dict[str, Any] | None = None
    log: dict[str, Any] | None = None
    delay: dict[str, Any] | None = None
    raw_tau: np.ndarray | None = None

    @property
    def measured_tau(self) -> np.ndarray:
        """The measured torques ``[N, n]`` as recorded (resampled, never filtered), float64; joint
        torques when the data pipeline read the file (:mod:`idkit.data.pipeline`: ``effort_scale``)."""
        if self.raw_tau is not None:
            return self.raw_tau
        return self.samples.tau.detach().cpu().double().numpy()


@dataclass(frozen=True)
class Source:
    """A data file read but not yet preprocessed: the raw ``recording`` that preprocessing will turn
    into samples, or the ``samples`` used as they are (with their ``times``, if the file has any);
    ``log``: what was read from a ROS log."""

    path: str
    recording: Recording | None
    samples: Samples | None = None
    times: np.ndarray | None = None
    log: dict[str, Any] | None = None


def file_kind(table: Table) -> FileKind:
    """What an open table holds, from its column or array names.

    Raises:
        ValueError: the file names one quantity twice, by idkit's name and by FloBaRoID's
            (``tau`` and ``torques``): which one is meant cannot be known.
    """
    both = [
        (ours, theirs)
        for ours, theirs in {**FLOBAROID_KEYS, **FLOBAROID_RECORDING_KEYS}.items()
        if table.has(ours) and table.has(theirs)
    ]
    if both:
        ours, theirs = both[0]
        raise ValueError(
            f"{table.path}: both {ours!r} and {theirs!r} (FloBaRoID's name for {ours}); which one is "
            "meant? Keep one of them"
        )
    flobaroid = table.has(FLOBAROID_KEYS["q"])
    time = (FLOBAROID_RECORDING_KEYS if flobaroid else {"t": "t"})["t"]
    accelerations = (FLOBAROID_KEYS if flobaroid else {"qdd": "qdd"})["qdd"]
    return FileKind(samples=table.has(accelerations), timestamps=table.has(time), flobaroid=flobaroid)


def load_data_file(
    path: str | Path,
    options: PreprocessOptions | None = None,
    apply: str = "auto",
    stride: int = 1,
    joints: Sequence[str] | None = None,
    log: RecordingOptions | None = None,
    delay: float = 0.0,
) -> DataFile:
    """Samples from one file (module doc): :func:`read_source`, then :func:`from_source`.

    Args:
        path: ``.npz`` or ``.csv`` file of samples or of a raw recording, or a ROS log
            (:mod:`idkit.data.logs`: always a raw recording).
        options: preprocessing options (default :class:`PreprocessOptions`).
        apply: ``"auto"``, ``"on"`` or ``"off"`` (module doc).
        stride: keep every ``stride``-th sample (after preprocessing, which sees them all).
        joints: the robot's joint names: per-joint columns and log joints are taken in this order.
        log: which topics of a log to read (its ``delay`` is not read here: see ``delay``).
        delay: seconds by which a raw recording's torques trail its states
            (:func:`idkit.data.delay.shift_torques`); a samples file used as it is refuses it.

    Raises:
        ValueError: ``apply`` unknown; ``"on"`` for a file without timestamps; ``"off"`` (or
            ``"auto"``) for a file with neither accelerations nor timestamps; torques that are all
            zero — naming the file; what the readers refuse.
    """
    return from_source(read_source(path, apply, joints, log), options, stride, delay)


def read_source(
    path: str | Path,
    apply: str = "auto",
    joints: Sequence[str] | None = None,
    log: RecordingOptions | None = None,
) -> Source:
    """Read one file: the raw recording that ``apply`` says to preprocess, or the samples to use as
    they are (arguments and errors as :func:`load_data_file`)."""
    if apply not in APPLY:
        raise ValueError(f"preprocess.apply must be one of {', '.join(APPLY)}, got {apply!r}")
    if is_log(path):
        if apply == "off":
            raise ValueError(f"{path}: a ROS log is a raw recording (no accelerations); preprocess it")
        recording, description = read_log(path, joints, log)
        _refuse_zero_torques(path, recording.tau)
        return Source(str(path), recording, log=description)
    _say_topics_unused(path, log)
    table = read_table(path)
    kind = file_kind(table)
    run = apply == "on" or (apply == "auto" and not kind.samples)
    if not run:
        if not kind.samples:
            raise ValueError(
                f"{path}: a raw recording (no accelerations qdd); preprocess it (preprocess=auto or on)"
            )
        samples, _ = samples_from_table(table, FLOBAROID_KEYS if kind.flobaroid else None, joints)
        _refuse_zero_torques(path, samples.tau.numpy())
        times = None
        if kind.timestamps:
            times = table.times(FLOBAROID_RECORDING_KEYS["t"] if kind.flobaroid else "t")
        return Source(str(path), None, samples, times)
    if not kind.timestamps:
        found = ", ".join(table.names()[:12]) + (" …" if len(table.names()) > 12 else "")
        if kind.samples:
            raise ValueError(
                f"{path}: preprocess=on needs timestamps (a 't' column or array) and the file has none "
                f"(it has {found}); preprocess=auto uses the file's own qd, qdd"
            )
        raise ValueError(
            f"{path}: neither samples (q, qd, qdd, tau) nor a raw recording (t, q, tau): no accelerations "
            f"qdd and no timestamps t; it has {found}"
        )
    recording = recording_from_table(table, FLOBAROID_RECORDING_KEYS if kind.flobaroid else None, joints)
    _refuse_zero_torques(path, recording.tau)
    return Source(str(path), recording)


def _say_topics_unused(path: str | Path, log: RecordingOptions | None) -> None:
    """A topic option given for a table (CSV, npz) does nothing there: say so rather than let the user
    think the efforts came from the topic named."""
    given = [
        f"recording.{name}" for name in ("topic", "effort_topic") if getattr(log, name, None) is not None
    ]
    if given:
        warnings.warn(
            f"{path}: {' and '.join(given)} {'name' if len(given) > 1 else 'names'} a ROS log's topics; this "
            "file is a table, read from its own columns",
            LogWarning,
            stacklevel=3,
        )


def _refuse_zero_torques(path: str | Path, tau: np.ndarray) -> None:
    """Refuse a file whose torques ``[N, n]`` are all exactly zero: an empty effort column or topic,
    never a measurement. Least squares fits it exactly with every base parameter 0, and every relative
    error divides by it, so the run would report numbers with exit status 0."""
    if not np.any(tau):
        raise ValueError(
            f"{path}: every torque in the file is exactly zero ({tau.shape[0]} samples × {tau.shape[1]} "
            "joints): an empty effort column or topic? Nothing can be identified or scored from it"
        )


def from_source(
    source: Source, options: PreprocessOptions | None = None, stride: int = 1, delay: float = 0.0
) -> DataFile:
    """The :class:`DataFile` of a read file: its recording preprocessed with ``options`` (its torques
    shifted back by ``delay`` s first), or its samples as they are; every ``stride``-th sample."""
    if source.recording is not None:
        return _preprocessed(source.path, source.recording, options, stride, delay, source.log)
    refuse_delay_on_samples(source.path, delay)
    assert source.samples is not None
    times = None if source.times is None else source.times[::stride]
    return DataFile(source.path, _thin(source.samples, stride), times, False)


def refuse_delay_on_samples(path: str, delay: float | str) -> None:
    """Refuse a torque ``delay`` (seconds or ``"auto"``; ``0``: none) for samples used as they are.

    A delay moves a raw recording's torques along its timestamps before preprocessing; samples keep
    their torques, so a delay given for them (``auto`` too: there is nothing to estimate it on) would
    be silently ignored.
    """
    if delay == 0:
        return
    shown = delay if isinstance(delay, str) else f"{delay:g}"
    raise ValueError(
        f"{path}: recording.torque_lag={shown} shifts a raw recording's torques, but this file holds samples "
        "used as they are (preprocess=on reads a samples file with timestamps as a recording)"
    )


def _preprocessed(
    path: str | Path,
    recording: Recording,
    options: PreprocessOptions | None,
    stride: int,
    delay: float,
    log: dict[str, Any] | None = None,
) -> DataFile:
    recording, dropped = shift_torques(recording, delay)
    done = preprocess_recording(recording, options)
    shifted = {"seconds": delay, "dropped_samples": dropped} if delay else None
    thinned = _thin(done.samples, stride)
    return DataFile(
        str(path), thinned, done.times[::stride], True, done.to_dict(), log, shifted, done.raw_tau[::stride]
    )


def _thin(samples: Samples, stride: int) -> Samples:
    return Samples(*(getattr(samples, k)[::stride] for k in SAMPLE_ARRAYS)) if stride > 1 else samples
