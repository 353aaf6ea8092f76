"""How data files become samples: the ``preprocess`` and ``recording`` config sections, typed and frozen.

A study's signature names them (``preprocess: Preprocessing | None``, ``recording: RecordingOptions |
None``), so the command line's option checker (:func:`idkit.options.check_setting`) sees every field:
``preprocess.velocitiez=measured`` is refused as that key, with the options closest first, and
``preprocess.trim=-1`` as that option's value. :class:`DataOptions` holds both for the data pipeline
(:mod:`idkit.data.pipeline`), which resolves ``cutoff=auto`` once, on the training files.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any, Literal, get_args

from idkit.data.preprocess import PreprocessOptions
from idkit.options import check_section

#: The largest torque lag (s) ``recording.torque_lag`` takes: more is a unit mistake, not a lag.
MAX_DELAY_S = 1.0
#: When preprocessing runs (``preprocess.apply``, :mod:`idkit.data.load`).
Apply = Literal["auto", "on", "off"]


@dataclass(frozen=True)
class Preprocessing(PreprocessOptions):
    """The ``preprocess`` config section: :class:`PreprocessOptions` plus when to apply them.

    Attributes:
        cutoff: as :class:`PreprocessOptions`, but ``"auto"`` by default: chosen on the training
            recordings with the robot's model (:func:`idkit.data.cutoff.choose_cutoff`).
        apply: ``"auto"`` preprocesses raw recordings only (samples files keep their derivatives),
            ``"on"`` every file with timestamps, ``"off"`` none (a raw recording is then an error).
    """

    cutoff: float | Literal["auto"] = "auto"
    apply: Apply = "auto"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.apply not in get_args(Apply):
            raise ValueError(
                f"preprocess.apply must be one of {', '.join(get_args(Apply))}, got {self.apply!r}"
            )

    def options(self) -> PreprocessOptions:
        """The options :func:`idkit.data.preprocess.preprocess_recording` takes (without ``apply``)."""
        return PreprocessOptions(**{f.name: getattr(self, f.name) for f in fields(PreprocessOptions)})


@dataclass(frozen=True)
class RecordingOptions:
    """How raw recordings are read (the ``recording`` config section).

    Attributes:
        topic: a ROS log's ``sensor_msgs/JointState`` topic of positions (and efforts); ``None``: the
            log's only one (:mod:`idkit.data.logs`), or with ``effort_topic`` the only other one.
        effort_topic: a ``JointState`` topic carrying the efforts, if not ``topic``.
        torque_lag: seconds by which the torques trail the states (the torque at ``t`` is read at
            ``t + torque_lag``; at most :data:`MAX_DELAY_S`), or ``"auto"``: the lag at which the
            robot's regressor explains the shifted torques best (:mod:`idkit.data.delay`). ``0``: none.
            Not the rollout's ``command_delay`` (states behind commands, :mod:`idkit.sim.timing`).
        delay: the former name of ``torque_lag`` (``recording.delay=…``), still read with a
            ``FutureWarning``; ``None``: not given.
    """

    topic: str | None = None
    effort_topic: str | None = None
    torque_lag: float | Literal["auto"] = 0.0
    delay: float | Literal["auto"] | None = None

    def __post_init__(self) -> None:
        for name in ("topic", "effort_topic"):
            value = getattr(self, name)
            if value is not None and not str(value).strip():
                raise ValueError(
                    f"recording.{name} is empty; name a JointState topic (e.g. /joint_states), or leave it "
                    "null"
                    + (" (the log's only one)" if name == "topic" else " (efforts on the topic's messages)")
                )
        key = "torque_lag"
        if self.delay is not None:
            key = "delay"
            if self.torque_lag != 0.0 and self.torque_lag != self.delay:
                raise ValueError(
                    f"recording.torque_lag={self.torque_lag} and its old name recording.delay={self.delay} "
                    "are both set; give recording.torque_lag only"
                )
            warnings.warn(
                "recording.delay is now recording.torque_lag (seconds by which the torques trail the states; "
                "not the rollout's command_delay): recording.delay still works but is deprecated",
                FutureWarning,
                stacklevel=3,
            )
            object.__setattr__(self, "torque_lag", self.delay)
            object.__setattr__(self, "delay", None)
        lag = self.torque_lag
        if lag != "auto":
            if isinstance(lag, bool) or not isinstance(lag, (int, float)):
                raise ValueError(f"recording.{key} must be 'auto' or seconds, got {lag!r}")
            if not math.isfinite(lag):
                raise ValueError(f"recording.{key} must be 'auto' or finite seconds, got {lag!r}")
            if abs(lag) > MAX_DELAY_S:
                raise ValueError(
                    f"recording.{key}={lag:g} s: a torque lag is a filter's or a bus's, "
                    f"milliseconds (at most ±{MAX_DELAY_S:g} s here); milliseconds given as seconds? "
                    f"({lag:g} ms is {lag / 1000:g})"
                )
            object.__setattr__(self, "torque_lag", float(lag))


@dataclass(frozen=True)
class DataOptions:
    """Everything that says how a study's files become samples, checked once.

    Attributes:
        preprocess: the ``preprocess`` section (with ``apply``); after the training files are read
            its ``cutoff`` is a number (:class:`idkit.data.pipeline.Training`).
        recording: the ``recording`` section.
    """

    preprocess: Preprocessing = field(default_factory=Preprocessing)
    recording: RecordingOptions = field(default_factory=RecordingOptions)

    @classmethod
    def of(cls, preprocess: Any = None, recording: Any = None) -> DataOptions:
        """From the config sections: ``None`` (the defaults), a mapping (checked key by key as the
        command line checks it) or the section's object. A bare :class:`PreprocessOptions` means
        ``apply=on`` with those options.

        Raises:
            ValueError: an unknown key (naming it, the options closest first), a value of the
                wrong type or out of range (naming the option).
        """
        if isinstance(preprocess, PreprocessOptions) and not isinstance(preprocess, Preprocessing):
            preprocess = Preprocessing(**vars(preprocess), apply="on")
        return cls(
            section("preprocess", preprocess, Preprocessing),
            section("recording", recording, RecordingOptions),
        )

    @property
    def apply(self) -> Apply:
        return self.preprocess.apply

    def with_cutoff(self, cutoff: float) -> DataOptions:
        """These options with ``cutoff=auto`` resolved to ``cutoff`` Hz."""
        return replace(self, preprocess=replace(self.preprocess, cutoff=cutoff))

    def held_out(self) -> DataOptions:
        """The options of a held-out file: every sample kept (``decimate`` and ``min_speed`` select
        training samples; a held-out score covers the whole recording)."""
        return replace(self, preprocess=replace(self.preprocess, decimate=1, min_speed=0.0))

    def preprocess_dict(self) -> dict[str, Any]:
        """The preprocessing options for ``result.json`` (without ``apply``)."""
        return vars(self.preprocess.options())


def section(name: str, value: Any, cls: type) -> Any:
    """Config section ``name`` as a ``cls`` object (:meth:`DataOptions.of`)."""
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if isinstance(value, Mapping):
        return check_section(name, cls, value)
    known = ", ".join(f.name for f in fields(cls))
    raise ValueError(f"{name} must be a mapping of options ({known}), got {value!r}")
