"""``SimulatorModel``: the simulator a rollout fit gives you to hold — the rollout side's ``IdentifiedModel``.

* ``values``, ``std``, ``interval95``: every fitted quantity by name with its standard deviation and 95 %
  interval; ``flat``: the combinations the log could not separate; ``model_limited``: whether the
  residual is the model's, not the noise's (``None`` where the fit did not say);
* ``held_out``: the validation records of the run it came from;
* ``simulate(log_or_commands, initial=None, horizon=None)``: the model rolled out by MuJoCo under given
  commands, from a given or the logged state, whole or in segments of ``horizon`` seconds, on idkit's
  time convention (:mod:`idkit.sim.timing`), the one the fit used;
* ``save("identified.xml")`` and ``to_mujoco()``: the model with the fitted values written in.

A study builds one (:meth:`SimulatorModel.from_result`, the one place that reads a rollout study's
result); this module imports no study (``tests/test_layout.py``).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from idkit.data.commands import COMMAND_KINDS, RobotLog
from idkit.robots.mjcf import import_mujoco
from idkit.sim.model import SimModel
from idkit.sim.quantities import Unknowns
from idkit.sim.segments import split

#: Suffixes ``save`` writes (MJCF).
MJCF_SUFFIXES = (".xml", ".mjcf")
_UMASK = os.umask(0)
os.umask(_UMASK)
_NEW_FILE_MODE = 0o666 & ~_UMASK  # what open() would give a new file


@dataclass(frozen=True)
class Trajectory:
    """A simulated motion, beside the logged one where there was a log.

    Attributes:
        t: ``[k]`` the times predicted (s, the log's clock).
        q, qd: ``[k, n]`` simulated joint positions and velocities.
        joints: the ``n`` joints.
        segments: how many rollouts it took (1: one from the first state).
        measured_q, measured_qd: ``[k, n]`` the logged ones (``None``: simulated from commands alone).
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    joints: tuple[str, ...]
    segments: int
    measured_q: np.ndarray | None = None
    measured_qd: np.ndarray | None = None

    def rms(self) -> dict[str, tuple[float, float]]:
        """Per joint, the RMS error of position and velocity against the log.

        Raises:
            ValueError: simulated from commands alone: no log to compare with.
        """
        if self.measured_q is None or self.measured_qd is None:
            raise ValueError("simulated from commands alone: there is no logged motion to compare with")
        eq = np.sqrt(np.mean((self.measured_q - self.q) ** 2, axis=0))
        eqd = np.sqrt(np.mean((self.measured_qd - self.qd) ** 2, axis=0))
        return {j: (float(a), float(b)) for j, a, b in zip(self.joints, eq, eqd, strict=True)}


@dataclass(frozen=True)
class SimulatorModel:
    """A MuJoCo model with identified values (module docstring).

    Attributes:
        sim: the model the fit started from.
        unknowns: the fitted quantities (names, kinds, bounds).
        values: name → fitted value.
        std: name → standard deviation (``inf`` along a flat direction).
        interval95: name → ``(low, high)``, a 95 % interval.
        joints: the joints the fit's log held, in its order (a log's default joints).
        flat: the flat directions, each ``{"direction": {name: weight}, "sigma": …}``.
        model_limited: ``True`` when the fit's residual is the model's error rather than noise (its
            intervals then account for it); ``None`` where the fit did not assess it.
        held_out: the run's validation records (whatever its study recorded per ``validate=`` log).
        mjcf: the ``identified.xml`` text (``None``: MuJoCo refused it, ``mjcf_problem`` says why).
    """

    sim: SimModel = field(repr=False)
    unknowns: Unknowns = field(repr=False)
    values: Mapping[str, float]
    std: Mapping[str, float]
    interval95: Mapping[str, tuple[float, float]]
    joints: tuple[str, ...]
    flat: Sequence[Mapping[str, Any]] = ()
    model_limited: bool | None = None
    held_out: Sequence[Any] = field(default=(), repr=False)
    mjcf: str | None = field(default=None, repr=False)
    mjcf_problem: str | None = None
    _cache: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def of(
        cls,
        sim: SimModel,
        unknowns: Unknowns,
        values: Mapping[str, float] | np.ndarray,
        joints: Sequence[str] | None = None,
        **record: Any,
    ) -> SimulatorModel:
        """The model ``sim`` at ``values`` (by name, or ``[P]`` in ``unknowns`` order); ``record``: the
        other fields (``std``, ``interval95``, ``flat``, ``model_limited``, ``held_out``). Without
        ``std`` every standard deviation is unknown (NaN)."""
        from idkit.sim.export import identified_xml

        if isinstance(values, Mapping):
            missing = [n for n in unknowns.names if n not in values]
            if missing:
                raise ValueError(f"SimulatorModel: no value for {', '.join(missing)}")
            vector = np.array([float(values[n]) for n in unknowns.names])
        else:
            vector = np.asarray(values, dtype=np.float64).reshape(-1)
            if vector.size != len(unknowns):
                raise ValueError(f"SimulatorModel: {vector.size} values for {len(unknowns)} unknowns")
        named = dict(zip(unknowns.names, vector.tolist(), strict=True))
        if "mjcf" not in record:
            try:
                record["mjcf"], record["mjcf_problem"] = identified_xml(sim, unknowns, vector), None
            except ValueError as error:
                record["mjcf"], record["mjcf_problem"] = None, str(error)
        record.setdefault("std", {n: float("nan") for n in named})
        record.setdefault("interval95", {n: (float("nan"), float("nan")) for n in named})
        return cls(sim, unknowns, named, joints=tuple(joints or sim.joint_names()), **record)

    @classmethod
    def from_result(cls, result: Any) -> SimulatorModel:
        """The model of a rollout study's result (``idkit.studies.rollout.RolloutResult``): the one
        place that reads one. It needs the result's ``robot`` (the model and the unknowns fitted)."""
        robot = getattr(result, "robot", None)
        if robot is None:
            raise ValueError("this rollout result holds no model (its robot is None)")
        estimate = result.estimate
        found = _uncertainty(estimate.details)
        return cls.of(
            robot.sim,
            robot.unknowns,
            {name: float(estimate.params[name]) for name in robot.unknowns.names},
            robot.joint_names,
            **found,
            held_out=tuple(result.validation),
            mjcf=result.mjcf,
            mjcf_problem=result.mjcf_problem,
        )

    def simulate(
        self,
        log_or_commands: RobotLog | str | os.PathLike[str] | Mapping[str, Any],
        initial: tuple[Sequence[float], Sequence[float]] | None = None,
        horizon: float | None = None,
    ) -> Trajectory:
        """The model rolled out under a log's commands (or commands alone), at the log's times.

        Args:
            log_or_commands: a log (a CSV or ``.npz`` path; a ``RobotLog``, e.g. a ROS log read by
                :func:`idkit.data.commands.read_robot_log` with its ``command_topic``), or commands as
                ``{"t": [N], "<actuator>.ctrl" | "<joint>.q_ref" | "<joint>.qd_ref": [N], …}``.
            initial: ``(q [n], qd [n])`` of the log's joints (``joints`` for commands alone) to start
                from; default: the logged state (commands alone: the model's ``qpos0``, at rest). With
                ``horizon`` it is the first segment's start.
            horizon: seconds per rollout, each from the logged state at its start (the fit's
                segments); ``None``: one rollout from the first state (per stretch between gaps).

        Raises:
            ValueError: commands alone with a ``horizon`` (no logged state to restart from), a
                malformed commands table, or an ``initial`` of the wrong size.
        """
        from idkit.sim.simulate import BatchSimulator

        log, logged = self._log(log_or_commands, initial)
        if horizon is not None and not logged:
            raise ValueError("simulate: horizon restarts from logged states; commands alone have none")
        segments = split(log.t, horizon)
        starts = [s for s, _ in segments]
        q0, qd0 = log.q[starts].copy(), log.qd[starts].copy()
        if initial is not None:
            q0[0], qd0[0] = _state(initial, log.n_joints)
        simulator = BatchSimulator(self.sim, log, self.unknowns, segments, initial=(q0, qd0))
        try:
            q, qd = simulator.predict(self._vector()[None])
        finally:
            simulator.close()
        rows = simulator.samples
        measured = (log.q[rows], log.qd[rows]) if logged else (None, None)
        return Trajectory(log.t[rows], q[0], qd[0], log.joint_names, len(segments), *measured)

    def _vector(self) -> np.ndarray:
        return np.array([self.values[name] for name in self.unknowns.names])

    def _log(self, source: Any, initial: Any) -> tuple[RobotLog, bool]:
        """``(log, has logged states)`` of ``simulate``'s input."""
        if isinstance(source, RobotLog):
            return self._own_joints(source), True
        if isinstance(source, Mapping):
            return self._commands_log(source, initial), False
        from idkit.data.commands import read_robot_log

        return self._own_joints(read_robot_log(source)), True

    def _own_joints(self, log: RobotLog) -> RobotLog:
        """``log`` restricted to the model's hinge and slide joints (others would not simulate)."""
        mine = set(self.sim.joint_names())
        kept = [j for j, name in enumerate(log.joint_names) if name in mine]
        if not kept:
            raise ValueError(
                f"{log.source}: none of the model's joints ({', '.join(self.sim.joint_names())}) is in it"
            )
        if len(kept) == log.n_joints:
            return log
        names = tuple(log.joint_names[j] for j in kept)
        return RobotLog(
            log.t, log.q[:, kept], log.qd[:, kept], log.command_t, log.commands, names,
            log.command_names, log.source,
        )  # fmt: skip

    def _commands_log(self, table: Mapping[str, Any], initial: Any) -> RobotLog:
        """A log holding ``table``'s commands and, at every sample, the start state (never compared)."""
        if "t" not in table:
            raise ValueError("simulate: the commands need their times, a column 't'")
        t = np.asarray(table["t"], dtype=np.float64).reshape(-1)
        names = tuple(k for k in table if k != "t")
        wrong = [k for k in names if k.rsplit(".", 1)[-1] not in COMMAND_KINDS]
        if wrong or not names:
            raise ValueError(
                f"simulate: command columns are <name>.ctrl, <joint>.q_ref or <joint>.qd_ref; got "
                f"{', '.join(wrong) if wrong else 'none'}"
            )
        columns = []
        for name in names:
            column = np.asarray(table[name], dtype=np.float64).reshape(-1)
            if column.size != t.size:
                raise ValueError(f"simulate: column {name!r} has {column.size} values for {t.size} times")
            columns.append(column)
        if initial is None:
            q0 = np.array([self.sim.model.qpos0[self.sim.model.jnt_qposadr[self.sim.joint_id(j)]]
                           for j in self.joints])  # fmt: skip
            qd0 = np.zeros(len(self.joints))
        else:
            q0, qd0 = _state(initial, len(self.joints))
        q, qd = np.tile(q0, (t.size, 1)), np.tile(qd0, (t.size, 1))
        return RobotLog(t, q, qd, t, np.column_stack(columns), self.joints, names, "<commands>")

    def to_mujoco(self) -> Any:
        """The identified model as a ``mujoco.MjModel`` (what ``save`` writes, compiled; a fitted delay is
        each actuator's ``delay``: start it with :meth:`mujoco_state` to fill the buffer)."""
        mujoco = import_mujoco()
        return mujoco.MjModel.from_xml_string(self._text())

    def mujoco_state(
        self, q: Sequence[float], qd: Sequence[float], first_command: Sequence[float]
    ) -> np.ndarray:
        """The ``mjSTATE_FULLPHYSICS`` vector of :meth:`to_mujoco`'s model with ``joints`` at ``q``, ``qd``
        and delayed actuators' buffers holding ``first_command[nu]`` (the commands before a log are its
        first, held: :mod:`idkit.sim.timing`) — the state a rollout on idkit's convention starts from."""
        from idkit.sim.export import start_state
        from idkit.sim.model import load_model

        if "identified" not in self._cache:
            self._cache["identified"] = load_model(self._text())
        qs, qds = _state((q, qd), len(self.joints))
        return start_state(self._cache["identified"], self.joints, qs, qds, np.asarray(first_command, float))

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write ``identified.xml`` (MJCF) to ``path`` in one step: the whole text first, then the file
        replaced, keeping an existing file's permissions; a refused model never leaves a half-written
        (or emptied) file.

        Raises:
            ValueError: a suffix other than ``.xml``/``.mjcf``, or MuJoCo refused the identified model.
        """
        path = Path(path)
        if path.suffix.lower() not in MJCF_SUFFIXES:
            raise ValueError(f"save: {str(path)!r} has suffix {path.suffix or '(none)'!r}; use .xml (MJCF)")
        _write_atomic(path, self._text())
        return path

    def _text(self) -> str:
        if self.mjcf is None:
            raise ValueError(self.mjcf_problem or "identified.xml: MuJoCo refused the identified model")
        return self.mjcf

    def table(self) -> str:
        """Each value with its standard deviation and 95 % interval, one line each."""
        lines = [f"{'quantity':<24}{'value':>12}{'std':>11}   95 % interval"]
        for name, value in self.values.items():
            low, high = self.interval95[name]
            lines.append(f"{name:<24}{value:12.6g}{self.std[name]:11.3g}   [{low:.5g}, {high:.5g}]")
        if self.model_limited:
            lines.append("model-limited: the residual is above the noise; the intervals account for it")
        return "\n".join(lines)


def _state(initial: Any, n: int) -> tuple[np.ndarray, np.ndarray]:
    q, qd = (np.asarray(x, dtype=np.float64).reshape(-1) for x in initial)
    if q.size != n or qd.size != n:
        raise ValueError(f"initial: (q, qd) of {n} joints each, got {q.size} and {qd.size} values")
    return q, qd


def _uncertainty(details: Any) -> dict[str, Any]:
    """``std``, ``interval95``, ``flat`` and ``model_limited`` from a rollout estimate's details: the typed
    record (``details.uncertainty``) or the dictionary of ``Estimate.details``."""
    typed = getattr(details, "uncertainty", None)
    if typed is not None:
        intervals = getattr(typed, "interval95", None) or typed.ci95
        return {
            "std": dict(getattr(typed, "std", None) or typed.sigma),
            "interval95": {k: tuple(v) for k, v in intervals.items()},
            "flat": list(typed.flat),
            "model_limited": getattr(typed, "model_limited", None),
        }
    found: Mapping[str, Any] = details if isinstance(details, Mapping) else {}
    nested = found.get("uncertainty")
    sub: Mapping[str, Any] = nested if isinstance(nested, Mapping) else found
    return {
        "std": dict(sub.get("std") or sub.get("sigma") or {}),
        "interval95": {k: tuple(v) for k, v in (sub.get("interval95") or sub.get("ci95") or {}).items()},
        "flat": list(sub.get("flat") or sub.get("flat_directions") or []),
        "model_limited": sub.get("model_limited"),
    }


def _write_atomic(path: Path, text: str) -> None:
    """``text`` into ``path`` through a temporary file renamed over it, with the existing file's mode
    (else what ``open`` would give). ``idkit.reports.files`` does the same for run folders; the
    simulator layer may not import reports (``tests/test_layout.py``)."""
    try:
        mode = path.stat().st_mode & 0o7777
    except FileNotFoundError:
        mode = _NEW_FILE_MODE
    folder = path.parent if str(path.parent) else Path(".")
    handle, temporary = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "w", encoding="utf-8") as stream:
            stream.write(text)
        os.chmod(temporary, mode)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
