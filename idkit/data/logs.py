"""ROS logs of ``sensor_msgs/JointState`` as raw recordings: ``data=run.mcap``, a ROS 2 bag folder,
a ``.db3`` file or a ROS 1 ``.bag``.

Read with ``rosbags`` (pure Python, no ROS install; ``pip install robot-idkit[logs]``), imported only
when a log is read. What :func:`read_log` does, in order:

1. **Topic.** The one ``JointState`` topic of the log, or ``recording.topic``; several without a
   choice, none, or an unknown topic are refused in one line listing the log's topics. Other topics
   are ignored. Efforts come from the same messages, or from the ``JointState`` topic
   ``recording.effort_topic`` when the driver publishes them apart.
2. **Joints by name.** Each message's ``name`` list says which value is which joint, in any order
   (the driver's). The robot's joints are taken in the robot's order; other joints are ignored; a
   joint the robot needs and the log lacks, or a message naming a joint twice, is refused naming it.
3. **One clock.** Each stream's time is its header stamps. A stream whose header stamps are all zero
   (some drivers never set them) uses the log's receive time instead, and says so (a
   :class:`LogWarning`); stamps zero in only some messages, all-zero receive times, and stamps that
   repeat or go back are refused naming the message. A separate effort stream is interpolated
   linearly onto the state stream's times; state samples outside the effort stream, or inside a gap
   of it (a step over 5 of its median steps), are dropped — said in one line (a :class:`LogWarning`)
   with how many and where — so that the gap reaches preprocessing (:mod:`idkit.data.preprocess`),
   which splits there.
4. The result is the :class:`~idkit.data.recording.Recording` a CSV gives (``t`` from the first
   stamp, ``q``, ``tau``, ``qd`` when every message has velocities), with ``joint_names``.
"""

from __future__ import annotations

import struct
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from idkit.data.options import RecordingOptions
from idkit.data.raw import Recording

JOINT_STATE = "sensor_msgs/msg/JointState"
#: Single-file logs: ROS 2 storage files and ROS 1 bags (a ROS 2 bag folder holds ``metadata.yaml``).
LOG_SUFFIXES = (".mcap", ".db3", ".bag")
#: What a log reader raises on garbage inside a file it opened (a length or count read from damaged
#: bytes), beside its own errors.
DAMAGE = (OverflowError, MemoryError, IndexError, EOFError, UnicodeDecodeError, struct.error)
#: A step of the effort stream longer than this many of its median steps is a gap (as
#: ``preprocess.max_gap`` for the state stream).
EFFORT_GAP = 5.0
INSTALL = "pip install robot-idkit[logs]"


class LogWarning(UserWarning):
    """Something a log reader chose that changes the data: receive time instead of header stamps, state
    samples dropped for want of an effort."""


def is_log(path: str | Path) -> bool:
    """Whether ``path`` names a log: a ROS 2 bag folder (with ``metadata.yaml``) or a log file."""
    path = Path(path)
    return (path.is_dir() and (path / "metadata.yaml").is_file()) or path.suffix.lower() in LOG_SUFFIXES


@dataclass(frozen=True)
class Stream:
    """One topic's messages: ``t[M]`` (ns, on the stream's clock) and per message its joint names and
    arrays; ``clock`` says which clock."""

    topic: str
    stamps: np.ndarray
    names: list[tuple[str, ...]]
    position: list[np.ndarray]
    velocity: list[np.ndarray]
    effort: list[np.ndarray]
    clock: str


def read_log(
    path: str | Path, joints: Sequence[str] | None = None, options: RecordingOptions | None = None
) -> tuple[Recording, dict[str, Any]]:
    """A raw recording from a log (module doc) and what was read (for ``result.json``).

    Args:
        path: a ROS 2 bag folder, ``.mcap`` or ``.db3`` file, or a ROS 1 ``.bag``.
        joints: the robot's joint names, in its order; ``None``: every joint of the first message.
        options: topic choices (:class:`RecordingOptions`).

    Returns:
        ``(recording, description)``: the description names the topics, clocks, joints used and
        ignored.

    Raises:
        FileNotFoundError: no such file or folder.
        ValueError: rosbags missing (how to install it), not a readable log, the topic problems of
            step 1, a missing joint, missing efforts, the clock problems of step 3 — naming the log.
    """
    path = Path(path)
    options = options or RecordingOptions()
    if not path.exists():
        raise FileNotFoundError(f"data file not found: {path}")
    states, efforts, topics = _read_streams(path, options)
    wanted = list(joints) if joints is not None else list(states.names[0])
    q = joint_values(path, states, "position", wanted)
    qd = joint_values(path, states, "velocity", wanted) if _complete(states.velocity, states.names) else None
    t = states.stamps
    if efforts is None:
        if not _complete(states.effort, states.names):
            k = next(k for k, e in enumerate(states.effort) if len(e) != len(states.names[k]))
            raise ValueError(
                f"{path}: topic {states.topic} carries no effort (message {k} has {len(states.effort[k])} "
                f"efforts for {len(states.names[k])} joints); if the efforts are on another JointState "
                "topic, name it with recording.effort_topic=…"
            )
        tau = joint_values(path, states, "effort", wanted)
        origin = int(t[0])
        seconds = seconds_after(t, origin)
        dropped = 0
    else:
        origin = int(min(t[0], efforts.stamps[0]))
        seconds, tau, rows = _onto(
            path, efforts, wanted, seconds_after(t, origin), seconds_after(efforts.stamps, origin)
        )
        q, qd = q[rows], (None if qd is None else qd[rows])
        dropped = int(t.size - rows.size)
    all_names = sorted({name for names in states.names for name in names})
    description = {
        "topic": states.topic,
        "clock": states.clock,
        "messages": int(t.size),
        "joints": wanted,
        "ignored_joints": [name for name in all_names if name not in wanted],
        "ignored_topics": [topic for topic in topics if topic not in (states.topic, options.effort_topic)],
    }
    if efforts is not None:
        description["effort_topic"] = {
            "topic": efforts.topic,
            "clock": efforts.clock,
            "dropped_samples": dropped,
        }
    recording = Recording(seconds, q, tau, qd, source=str(path), joint_names=tuple(wanted))
    return recording, description


def seconds_after(stamps: np.ndarray, origin: int) -> np.ndarray:
    """Nanosecond stamps ``[M]`` (int64, since the epoch) as seconds after ``origin`` (ns): subtracted in
    integers, then divided (one rounding), so no digit of a stamp is lost to float64's 16."""
    return (stamps - np.int64(origin)) / 1e9


def _rosbags(path: Path) -> Any:
    try:
        from rosbags.highlevel import AnyReader
    except ImportError:
        raise ValueError(f"{path}: reading ROS logs needs the optional package rosbags: {INSTALL}") from None
    return AnyReader


def _read_streams(path: Path, options: RecordingOptions) -> tuple[Stream, Stream | None, list[str]]:
    """The state stream, the effort stream (or ``None``) and every topic of the log."""
    any_reader = _rosbags(path)
    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as Reader1Error
    from rosbags.rosbag2 import ReaderError as Reader2Error
    from rosbags.serde import SerdeError
    from rosbags.typesys import Stores, TypesysError, get_typestore

    errors = (AnyReaderError, Reader1Error, Reader2Error, SerdeError, TypesysError, OSError, KeyError)
    try:
        with any_reader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            connections = list(reader.connections)
            types = {c.topic: c.msgtype for c in connections}
            effort = None
            if options.effort_topic is not None:
                effort = choose_topic(path, types, options.effort_topic, "recording.effort_topic")
            state = choose_topic(path, types, options.topic, "recording.topic", besides=effort)
            if effort == state:  # the efforts are on the state messages themselves
                effort = None
            streams = {}
            for topic in dict.fromkeys(t for t in (state, effort) if t is not None):
                chosen = [c for c in connections if c.topic == topic]
                streams[topic] = read_stream(path, reader, chosen, topic)
    except FileNotFoundError:
        raise
    except errors as exc:  # a damaged or foreign file
        raise ValueError(f"{path}: not a readable ROS log ({type(exc).__name__}: {exc})") from None
    return streams[state], (streams[effort] if effort is not None else None), sorted(types)


def choose_topic(
    path: Path,
    types: dict[str, str],
    topic: str | None,
    option: str,
    besides: str | None = None,
    shared: bool = True,
) -> str:
    """The ``JointState`` topic to read (every reader of ROS logs chooses here): ``topic``, or the log's
    only one besides the topic ``besides`` already chosen for something else (the efforts' topic, the
    commands'). When ``besides`` is the only one, it is returned if it may carry this stream too
    (``shared``: efforts on the state messages), else refused.

    Raises:
        ValueError: no such topic, not a ``JointState``, none, or several to choose from (naming the
            option that chooses and listing the log's topics).
    """
    joint_states = sorted(t for t, kind in types.items() if kind == JOINT_STATE)
    listing = ", ".join(f"{t} ({kind})" for t, kind in sorted(types.items())) or "none"
    if topic is None:
        others = [t for t in joint_states if t != besides]
        apart = f" besides {besides}" if besides else ""
        if not joint_states:
            raise ValueError(f"{path}: no sensor_msgs/JointState topic; the log's topics: {listing}")
        if not others:
            if shared:  # the effort topic is the only one: it carries the positions too
                return joint_states[0]
            raise ValueError(
                f"{path}: no sensor_msgs/JointState topic{apart}; name it with {option}=…; the log's "
                f"topics: {listing}"
            )
        if len(others) > 1:
            raise ValueError(
                f"{path}: several JointState topics{apart}: {', '.join(others)}; choose the one of the "
                f"positions with {option}=…"
            )
        return others[0]
    if topic not in types:
        raise ValueError(f"{path}: no topic {topic!r} ({option}); the log's topics: {listing}")
    if types[topic] != JOINT_STATE:
        raise ValueError(f"{path}: topic {topic} ({option}) holds {types[topic]}, not sensor_msgs/JointState")
    return topic


def read_stream(path: Path, reader: Any, connections: list[Any], topic: str) -> Stream:
    stamps: list[int] = []
    received: list[int] = []
    names: list[tuple[str, ...]] = []
    position: list[np.ndarray] = []
    velocity: list[np.ndarray] = []
    effort: list[np.ndarray] = []
    try:
        for connection, receive_time, raw in reader.messages(connections=connections):
            message = reader.deserialize(raw, connection.msgtype)
            stamps.append(_stamp(path, topic, len(stamps), message.header.stamp))
            received.append(int(receive_time))
            names.append(tuple(message.name))
            position.append(np.asarray(message.position, dtype=np.float64))
            velocity.append(np.asarray(message.velocity, dtype=np.float64))
            effort.append(np.asarray(message.effort, dtype=np.float64))
    except DAMAGE as exc:  # a reader meeting garbage past the header: not one of its own errors
        raise ValueError(
            f"{path}: damaged: reading {topic} failed after {len(stamps)} messages ({type(exc).__name__}: "
            f"{exc}); the log cannot be read past there"
        ) from None
    listed = sum(int(getattr(c, "msgcount", 0) or 0) for c in connections)
    if listed and listed != len(stamps):
        raise ValueError(
            f"{path}: damaged: {len(stamps)} messages of {topic} read where the log's index lists {listed}"
        )
    if not stamps:
        raise ValueError(f"{path}: topic {topic} has no messages")
    header, receive = np.array(stamps, dtype=np.int64), np.array(received, dtype=np.int64)
    zero = header == 0
    if zero.all():
        if (receive == receive[0]).all():
            raise ValueError(
                f"{path}: every stamp of {topic} is zero and so is every receive time: the log has no clock"
            )
        clock = "receive time (every header stamp is zero)"
        warnings.warn(
            f"{path}: {topic} has header stamps all zero; its receive times are used", LogWarning, 2
        )
        header = receive
    elif zero.any():
        raise ValueError(
            f"{path}: header stamps of {topic} are zero in {int(zero.sum())} of {zero.size} messages (first: "
            f"message {int(np.flatnonzero(zero)[0])}); which clock holds cannot be known"
        )
    else:
        clock = "header stamps"
    steps = np.diff(header)
    if (steps <= 0).any():
        k = int(np.flatnonzero(steps <= 0)[0]) + 1
        seconds = (header - header[0]) * 1e-9
        raise ValueError(
            f"{path}: stamps of {topic} must increase: message {k} (t = {seconds[k]:.9g} s) follows message "
            f"{k - 1} (t = {seconds[k - 1]:.9g} s) ({clock})"
        )
    return Stream(topic, header, names, position, velocity, effort, clock)


def _stamp(path: Path, topic: str, k: int, stamp: Any) -> int:
    """A header stamp in ns since the epoch, or a ``ValueError`` naming a stamp no clock writes."""
    sec, nanosec = int(stamp.sec), int(stamp.nanosec)
    if not (0 <= sec < 2**33 and 0 <= nanosec < 1_000_000_000):
        raise ValueError(
            f"{path}: damaged: message {k} of {topic} has the stamp sec={sec}, nanosec={nanosec}, which no "
            "clock writes"
        )
    return sec * 1_000_000_000 + nanosec


def _complete(values: list[np.ndarray], names: list[tuple[str, ...]]) -> bool:
    """Whether every message has one value per joint name."""
    return all(len(v) == len(n) for v, n in zip(values, names, strict=True))


def joint_values(path: Path, stream: Stream, field: str, joints: Sequence[str]) -> np.ndarray:
    """``[M, n]`` values of ``field`` for ``joints`` (by name, per message)."""
    arrays = getattr(stream, field)
    out = np.empty((len(arrays), len(joints)))
    order: dict[tuple[str, ...], list[int]] = {}
    for k, (names, values) in enumerate(zip(stream.names, arrays, strict=True)):
        if names not in order:
            index = {name: i for i, name in enumerate(names)}
            if len(index) < len(names):  # which of the two values is the joint's cannot be known
                twice = next(name for name in names if names.count(name) > 1)
                raise ValueError(
                    f"{path}: {stream.topic} message {k} names joint {twice!r} twice; the log's joints: "
                    + ", ".join(names)
                )
            missing = [j for j in joints if j not in index]
            if missing:
                everywhere = all(missing[0] not in n for n in stream.names)
                where = (
                    f"the log has no joint {missing[0]!r}"
                    if everywhere
                    else f"message {k} lacks joint {missing[0]!r}"
                )
                raise ValueError(
                    f"{path}: {stream.topic}: {where} (the robot needs it); the log's joints: "
                    + ", ".join(names)
                )
            order[names] = [index[j] for j in joints]
        if len(values) != len(names):
            raise ValueError(
                f"{path}: {stream.topic} message {k} has {len(values)} {field} values for {len(names)} joints"
            )
        out[k] = values[order[names]]
    return out


def _onto(
    path: Path, efforts: Stream, joints: Sequence[str], t: np.ndarray, te: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The effort stream interpolated onto the state times ``t`` (s): ``(t kept, tau, kept rows)``."""
    if not _complete(efforts.effort, efforts.names):
        raise ValueError(f"{path}: effort topic {efforts.topic} has messages without an effort per joint")
    tau_e = joint_values(path, efforts, "effort", joints)
    covered = (t >= te[0]) & (t <= te[-1])
    inside = covered.copy()
    steps = np.diff(te)
    for k in np.flatnonzero(steps > EFFORT_GAP * np.median(steps)):
        inside &= ~((t > te[k]) & (t < te[k + 1]))
    rows = np.flatnonzero(inside)
    if rows.size < 2:
        raise ValueError(
            f"{path}: the effort topic {efforts.topic} does not overlap the state topic in time "
            "(different clocks?)"
        )
    if rows.size < t.size:
        _say_dropped(path, efforts.topic, t, covered, inside)
    tau = np.stack([np.interp(t[rows], te, column) for column in tau_e.T], axis=1)
    return t[rows], tau, rows


def _say_dropped(path: Path, topic: str, t: np.ndarray, covered: np.ndarray, inside: np.ndarray) -> None:
    """Say in one line how many state samples have no effort (outside the effort stream's span, or in
    its gaps) and are dropped: a topic recorded over part of the log must not halve the data silently."""
    before, after = int((t < t[covered][0]).sum()), int((t > t[covered][-1]).sum())
    gaps = int((covered & ~inside).sum())
    where = [
        f"{n} {what}"
        for n, what in (
            (before, "before its first message"),
            (after, "after its last"),
            (gaps, "in its gaps"),
        )
        if n
    ]
    dropped = before + after + gaps
    warnings.warn(
        f"{path}: the effort topic {topic} covers {t[inside][0]:.4g}–{t[inside][-1]:.4g} s of the state "
        f"topic's {t[0]:.4g}–{t[-1]:.4g} s: {dropped} of {t.size} state samples "
        f"({100 * dropped / t.size:.3g} %) have no effort and are dropped ({', '.join(where)})",
        LogWarning,
        stacklevel=4,
    )
