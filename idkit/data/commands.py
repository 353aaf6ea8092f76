"""Logs of what a robot was told and what it did: commands beside joint states (``RobotLog``).

What rollout identification (:mod:`idkit.sim`) reads: the joint positions and velocities a robot
measured, and the commands it was sent, on one clock. Torques are not needed (often not measured).

CSV (read by :mod:`idkit.data.table`, which says what is refused and how): a column ``t`` (s), and per
joint ``<joint>.q`` and ``<joint>.qd``; the commands in columns named after what they drive:

* ``<actuator>.ctrl`` or ``<joint>.ctrl``: an actuator's control (a motor's torque command, or any
  actuator's ``ctrl``; by joint name when one actuator drives that joint);
* ``<joint>.q_ref``: a position reference (the control of the position servo on that joint);
* ``<joint>.qd_ref``: a velocity reference (the control of the velocity servo on that joint).

``.npz``: arrays ``t [N]``, ``q`` and ``qd [N, n]`` (joints in the model's order) and ``ctrl [N, nu]``
(every actuator's control, in the model's actuator order). Other columns and arrays are ignored.

ROS logs (a ROS 2 bag folder, ``.mcap``, ``.db3``; a ROS 1 ``.bag``), read with ``rosbags`` as
:mod:`idkit.data.logs` reads torque logs: states on a ``sensor_msgs/JointState`` topic (``position``,
``velocity`` per joint name, in any order; the topic is ``state_topic``, or the log's only one that
is not ``command_topic``), commands on another ``JointState`` topic (``command_topic``: each name's
``position`` is its ``q_ref``, ``velocity`` its ``qd_ref``, ``effort`` its ``ctrl``, for whichever
arrays the messages fill). Times are the header stamps (the receive times when every stamp is zero),
in seconds from the first state message, counted in integer nanoseconds before the conversion.
Commands keep their own stamps: the simulator holds each until the next (:mod:`idkit.sim.timing`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from idkit.data.files import as_paths, refuse_repeated_files
from idkit.data.logs import choose_topic, is_log, joint_values, read_stream, seconds_after
from idkit.data.raw import check_increasing
from idkit.data.table import NpzTable, read_quantities, read_table
from idkit.untrusted import csv_header

#: Column suffixes of commands, and what each drives (see the module docstring).
COMMAND_KINDS = ("ctrl", "q_ref", "qd_ref")
#: A ``JointState`` array of a command topic → the command it carries.
COMMAND_FIELDS = {"position": "q_ref", "velocity": "qd_ref", "effort": "ctrl"}
INSTALL = "pip install robot-idkit[logs]"
#: Logs joined into one are this many of their median steps apart: a gap (:mod:`idkit.sim.segments`).
JOIN_GAP = 100


@dataclass(frozen=True)
class RobotLog:
    """Joint states and commands of one run (float64 numpy arrays).

    Attributes:
        t: ``[N]`` times (s) of the states, strictly increasing.
        q, qd: ``[N, n]`` measured joint positions and velocities.
        command_t: ``[M]`` times (s, the states' clock) of the commands, strictly increasing.
        commands: ``[M, m]`` the commands, one column per name in ``command_names``.
        joint_names: the ``n`` joints.
        command_names: ``<name>.ctrl``, ``<joint>.q_ref`` or ``<joint>.qd_ref`` per column; an
            ``.npz``'s ``ctrl`` array is ``#<i>.ctrl`` (actuator ``i`` of the model).
        source: where it came from, for messages.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    command_t: np.ndarray
    commands: np.ndarray
    joint_names: tuple[str, ...]
    command_names: tuple[str, ...]
    source: str = "<log>"

    def __post_init__(self) -> None:
        for name in ("t", "q", "qd", "command_t", "commands"):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            object.__setattr__(self, name, value)
            if not np.isfinite(value).all():
                index = np.argwhere(~np.isfinite(value))[0]
                raise ValueError(f"{self.source}: array {name!r} has a non-finite value at sample {index[0]}")
        object.__setattr__(self, "joint_names", tuple(self.joint_names))
        object.__setattr__(self, "command_names", tuple(self.command_names))
        n, m = len(self.joint_names), len(self.command_names)
        for name, times, shape in (
            ("q", self.t, (self.t.size, n)),
            ("qd", self.t, (self.t.size, n)),
            ("commands", self.command_t, (self.command_t.size, m)),
        ):
            if getattr(self, name).shape != shape:
                raise ValueError(
                    f"{self.source}: array {name!r} must be {list(shape)} ({len(times)} times × "
                    f"{shape[1]} names), got {list(getattr(self, name).shape)}"
                )
        check_increasing(self.source, self.t, "t", "state times")
        check_increasing(self.source, self.command_t, "command_t", "command times")
        if self.t.size < 2:
            raise ValueError(f"{self.source}: a log needs at least 2 samples, got {self.t.size}")
        if not m:
            raise ValueError(
                f"{self.source}: no commands (columns <name>.ctrl, <joint>.q_ref, <joint>.qd_ref)"
            )

    @property
    def n_samples(self) -> int:
        return self.t.size

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    def head(self, n: int) -> RobotLog:
        """The first ``n`` state samples and the commands up to the last of them."""
        if not 1 <= n <= self.n_samples:
            raise ValueError(f"{self.source}: head({n}) of a log of {self.n_samples} samples")
        keep = max(1, int(np.searchsorted(self.command_t, self.t[n - 1], side="right")))
        return RobotLog(
            self.t[:n], self.q[:n], self.qd[:n], self.command_t[:keep], self.commands[:keep],
            self.joint_names, self.command_names, self.source,
        )  # fmt: skip


def read_robot_log(
    path: str | Path,
    joints: Sequence[str] | None = None,
    state_topic: str | None = None,
    command_topic: str | None = None,
) -> RobotLog:
    """Read a log of states and commands (module docstring) from CSV, ``.npz`` or a ROS log.

    Args:
        path: the file (or a ROS 2 bag folder).
        joints: the joints wanted, in this order (``None``: every joint the file names).
        state_topic, command_topic: a ROS log's ``JointState`` topics (``command_topic`` is needed
            for a ROS log; ``state_topic=None``: the log's other ``JointState`` topic).

    Raises:
        FileNotFoundError: no such file.
        ValueError: what is missing or malformed, naming the file, the column or the message.
    """
    if is_log(path):
        return _read_ros(Path(path), joints, state_topic, command_topic)
    table = read_table(path)
    table.require(vectors=["t"], matrices=["q", "qd"])
    states, names = read_quantities(table, {"q": "q", "qd": "qd"}, joints)
    t = table.vector("t")
    if isinstance(table, NpzTable):
        table.require(matrices=["ctrl"])
        ctrl = table.matrix("ctrl").values
        if ctrl.ndim != 2 or ctrl.shape[0] != t.size:
            raise ValueError(f"{path}: array 'ctrl' must be [N={t.size}, nu], got shape {list(ctrl.shape)}")
        columns = [f"#{i}.ctrl" for i in range(ctrl.shape[1])]
        joint_names = (
            tuple(joints) if joints is not None else tuple(f"#{j}" for j in range(states["q"].shape[1]))
        )
        return RobotLog(t, states["q"], states["qd"], t, ctrl, joint_names, tuple(columns), str(path))
    if names is None:
        raise ValueError(f"{path}: name the joints' columns (<joint>.q, <joint>.qd), not q1..qn")
    values, columns = [], []
    for kind in COMMAND_KINDS:
        if table.has(kind):
            column = table.matrix(kind)
            if column.joints is None:
                raise ValueError(f"{path}: name the command columns (<name>.{kind}), not {kind}1..")
            values.append(column.values)
            columns += [f"{name}.{kind}" for name in column.joints]
    if not values:
        raise ValueError(
            f"{path}: no command columns (<actuator or joint>.ctrl, <joint>.q_ref, <joint>.qd_ref); "
            f"found {table.names()}"
        )
    return RobotLog(t, states["q"], states["qd"], t, np.hstack(values), names, tuple(columns), str(path))


def read_robot_logs(
    files: Any,
    joints: Sequence[str] | None = None,
    state_topic: str | None = None,
    command_topic: str | None = None,
    reader: Callable[..., RobotLog] | None = None,
) -> RobotLog:
    """One log of ``files`` (a path or a list: :func:`idkit.data.files.as_paths`), each read by
    ``reader`` (default :func:`read_robot_log`; a torque run's reads efforts as motor commands:
    :meth:`idkit.sim.from_run.TorqueRun.reader`); several are joined one after another with a gap
    between them (the segments restart after a gap: :mod:`idkit.sim.segments`).

    Raises:
        ValueError: no file, a file given twice, or files of other joints or commands than the first.
    """
    paths = as_paths(files)
    if not paths:
        raise ValueError("data: no log given")
    refuse_repeated_files(paths, "data")
    logs = [(reader or read_robot_log)(p, joints, state_topic, command_topic) for p in paths]
    if len(logs) == 1:
        return logs[0]
    first = logs[0]
    for path, log in zip(paths[1:], logs[1:], strict=True):
        if log.joint_names != first.joint_names or log.command_names != first.command_names:
            raise ValueError(
                f"data: {path} has other joints or commands than {paths[0]}; join logs of one robot"
            )
    t, q, qd, ct, c = [], [], [], [], []
    offset = 0.0
    for log in logs:
        step = float(np.median(np.diff(log.t)))
        shift = offset - min(log.t[0], log.command_t[0])
        t.append(log.t + shift)
        q.append(log.q)
        qd.append(log.qd)
        ct.append(log.command_t + shift)
        c.append(log.commands)
        offset = max(log.t[-1], log.command_t[-1]) + shift + JOIN_GAP * step
    joined = ", ".join(str(p) for p in paths)
    return RobotLog(
        np.concatenate(t), np.vstack(q), np.vstack(qd), np.concatenate(ct), np.vstack(c),
        first.joint_names, first.command_names, joined,
    )  # fmt: skip


def save_robot_log(log: RobotLog, path: str | Path) -> Path:
    """Write ``log`` as the CSV :func:`read_robot_log` reads (17 significant digits round-trip float64);
    its commands must share the states' times."""
    if log.command_t.shape != log.t.shape or not np.array_equal(log.command_t, log.t):
        raise ValueError(f"{log.source}: a CSV has one time column; the commands have their own times")
    header = ["t", *(f"{j}.q" for j in log.joint_names), *(f"{j}.qd" for j in log.joint_names)]
    header += list(log.command_names)
    table = np.hstack([log.t[:, None], log.q, log.qd, log.commands])
    path = Path(path)
    np.savetxt(path, table, fmt="%.17g", delimiter=",", header=csv_header(header), comments="")
    return path


# --- ROS logs --------------------------------------------------------------------------------------


def _read_ros(
    path: Path, joints: Sequence[str] | None, state_topic: str | None, command_topic: str | None
) -> RobotLog:
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise ValueError(f"{path}: reading ROS logs needs the optional package rosbags: {INSTALL}") from None
    if not path.exists():
        raise FileNotFoundError(f"data file not found: {path}")
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            types = {c.topic: c.msgtype for c in reader.connections}
            if command_topic is None:
                listing = ", ".join(f"{t} ({kind})" for t, kind in sorted(types.items())) or "none"
                raise ValueError(
                    f"{path}: name the commands' JointState topic (command_topic=…); the log's topics: "
                    f"{listing}"
                )
            command = choose_topic(path, types, command_topic, "command_topic")
            state = choose_topic(path, types, state_topic, "state_topic", besides=command, shared=False)
            streams = {
                topic: read_stream(path, reader, [c for c in reader.connections if c.topic == topic], topic)
                for topic in (state, command)
            }
    except (FileNotFoundError, ValueError):
        raise
    except (AnyReaderError, OSError, KeyError) as exc:
        raise ValueError(f"{path}: not a readable ROS log ({type(exc).__name__}: {exc})") from None
    states, commands = streams[state], streams[command]
    wanted = list(joints) if joints is not None else list(states.names[0])
    q = joint_values(path, states, "position", wanted)
    qd = joint_values(path, states, "velocity", wanted)
    origin = int(states.stamps[0])
    columns, values = [], []
    every = sorted({name for names in commands.names for name in names})
    for field, kind in COMMAND_FIELDS.items():
        arrays = getattr(commands, field)
        if all(len(v) == len(n) and len(n) for v, n in zip(arrays, commands.names, strict=True)):
            values.append(joint_values(path, commands, field, every))
            columns += [f"{name}.{kind}" for name in every]
    if not values:
        raise ValueError(f"{path}: topic {command} has no message with position, velocity or effort per name")
    return RobotLog(
        seconds_after(states.stamps, origin), q, qd, seconds_after(commands.stamps, origin),
        np.hstack(values), tuple(wanted), tuple(columns), str(path),
    )  # fmt: skip
