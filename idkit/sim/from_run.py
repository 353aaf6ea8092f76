"""A torque fit's run folder as the start of a rollout identification (``rollout.model=<run folder>``).

The torque fit (``idkit robot=urdf robot.urdf=arm.urdf data=train.csv``) leaves in its run folder
``result.json`` (the robot's config: joints, ``effort_scale``; the fitted parameters, among them each
joint's torque ``offset``) and, when asked (``identified_mjcf=true``; always for an ``mjcf`` robot),
``identified.xml``: its rigid body, friction and armature as MuJoCo reads them. The rollout refines
that model with the same logs as commands (:mod:`idkit.data.effort_commands`): each joint's logged
effort × its drive scale − its fitted offset is the torque its motor applies. A folder without
``identified.xml`` has it rebuilt from ``result.json`` (the robot's config and the fitted values,
:func:`idkit.robots.mjcf_export.identified_mjcf`), said in a note.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from idkit.data.commands import RobotLog
from idkit.data.options import RecordingOptions
from idkit.notes import Note
from idkit.robots.model_xml import model_text
from idkit.sim.model import SimModel
from idkit.sim.quantities import servo_kind

RESULT_FILE = "result.json"
MJCF_FILE = "identified.xml"


@dataclass(frozen=True)
class TorqueRun:
    """What a rollout takes from a torque fit's run folder.

    Attributes:
        folder: the run folder.
        mjcf: the identified model's MJCF text.
        joint_names: the robot's joints, in the order of ``effort_scale`` and ``offsets``.
        effort_scale: ``[n]`` joint torque per recorded effort unit (1 where efforts are torques).
        offsets: ``[n]`` the fitted constant torque offsets (0 where the fit had none).
        recording: the torque fit's ROS topics, to read the same kind of log.
    """

    folder: Path
    mjcf: str
    joint_names: tuple[str, ...]
    effort_scale: np.ndarray
    offsets: np.ndarray
    recording: RecordingOptions

    def model(self) -> SimModel:
        """The identified model as a simulator of the motion the torque fit modelled: free of contacts.

        The torque fit explained the torques by the rigid body and friction alone; a converted URDF's
        collision geoms often overlap where links meet (a wrist's links, the base and the first link),
        and MuJoCo would push them apart with forces the fit never saw — at every step. Contacts are
        disabled in the simulator and so in the refined ``identified.xml`` (``<flag contact>``), said
        in a note when the model had any."""
        from idkit.robots.mjcf import import_mujoco
        from idkit.sim.model import load_model

        mujoco = import_mujoco()
        loaded = load_model(self.mjcf)
        if loaded.spec.option.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT or not loaded.model.ngeom:
            return loaded
        spec = loaded.spec
        spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
        data = mujoco.MjData(loaded.model)
        mujoco.mj_forward(loaded.model, data)
        warnings.warn(
            f"{self.folder / MJCF_FILE}: contacts disabled (the torque fit modelled none; {data.ncon} "
            "geom pair(s) of the arm touch at its reference configuration)",
            Note,
            stacklevel=2,
        )
        return SimModel(spec, spec.compile(), loaded.label, loaded.folder)

    def reader(self, sim: SimModel) -> Callable[..., RobotLog]:
        """A reader of logs for ``sim`` (``(path, joints=None, *topics) -> RobotLog``): the efforts as
        motor commands (:mod:`idkit.data.effort_commands`), each divided by its motor's gear, the joints
        ``joints`` kept in that order; a joint no single motor drives is refused."""
        from idkit.data.effort_commands import read_effort_log

        def read(path: Any, joints: Any = None, *_topics: Any) -> RobotLog:
            log = read_effort_log(path, self.joint_names, self.effort_scale, self.offsets, self.recording)
            if joints is not None and tuple(joints) != log.joint_names:
                index = [log.joint_names.index(j) for j in joints]
                log = RobotLog(
                    log.t, log.q[:, index], log.qd[:, index], log.command_t, log.commands[:, index],
                    tuple(joints), tuple(log.command_names[i] for i in index), log.source,
                )  # fmt: skip
            modelled = tuple(j for j in log.joint_names if j in sim.joint_names())
            check_motor_driven(sim, modelled, str(path))
            return motor_commands(sim, log)

        return read


def is_run_folder(model: Any) -> bool:
    """Whether ``rollout.model`` names a run folder (a directory holding ``result.json``)."""
    if not isinstance(model, (str, Path)) or (isinstance(model, str) and model.lstrip().startswith("<")):
        return False
    return Path(model).is_dir()


def read_torque_run(folder: str | Path, build_robot: Callable[[Any], Any]) -> TorqueRun:
    """The :class:`TorqueRun` of a torque fit's run folder (module docstring); ``build_robot`` makes a
    robot from the run's robot config (the study's builder: this module sits below the studies).

    Raises:
        ValueError: no ``result.json``, not a torque fit's, or no joint names, naming the folder.
    """
    folder = Path(folder)
    result_path = folder / RESULT_FILE
    if not result_path.is_file():
        raise ValueError(f"rollout.model={folder}: a folder, but not a run folder (no {RESULT_FILE})")
    try:
        result = json.loads(result_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise ValueError(f"{result_path}: not readable JSON ({error})") from None
    task = result.get("task")
    robot = (result.get("config") or {}).get("robot")
    payload = result.get("payload") or {}
    params = (payload.get("estimate") or {}).get("params")
    joints = payload.get("joint_names")
    if task != "single" or not isinstance(robot, dict) or not isinstance(params, dict) or not joints:
        raise ValueError(
            f"{result_path}: not a torque fit's result (task {task!r}); give the run folder of "
            "`idkit robot=urdf robot.urdf=<arm.urdf> data=<log>`"
        )
    joints = tuple(str(j) for j in joints)
    scale = robot.get("effort_scale")
    effort_scale = np.ones(len(joints)) if scale is None else np.asarray(scale, dtype=np.float64)
    if effort_scale.shape != (len(joints),) or not (
        np.isfinite(effort_scale).all() and (effort_scale > 0).all()
    ):
        raise ValueError(f"{result_path}: robot.effort_scale {scale} is not {len(joints)} factors > 0")
    offsets = np.array([float(params.get(f"{j}.offset", 0.0)) for j in joints])
    topics = (result.get("config") or {}).get("recording") or {}
    recording = RecordingOptions(topic=topics.get("topic"), effort_topic=topics.get("effort_topic"))
    mjcf_path = folder / MJCF_FILE
    if mjcf_path.is_file():
        mjcf = model_text(mjcf_path.read_bytes(), str(mjcf_path), "rollout.model")  # the one XML policy
    else:
        mjcf = _rebuild(result_path, lambda: build_robot(robot), params)
    return TorqueRun(folder, mjcf, joints, effort_scale, offsets, recording)


def _rebuild(result_path: Path, build: Callable[[], Any], params: dict[str, float]) -> str:
    """``identified.xml``'s text from the run's robot (``build`` makes it from the run's config) and
    fitted values."""
    from idkit.registry import PluginLoadError
    from idkit.robots.mjcf_export import identified_mjcf

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the torque fit said these already
            text = identified_mjcf(build(), params)
    except (ValueError, PluginLoadError, TypeError) as error:
        raise ValueError(
            f"{result_path.parent}: no {MJCF_FILE}, and it cannot be rebuilt from {RESULT_FILE} ({error}); "
            "rerun the torque fit with identified_mjcf=true"
        ) from None
    warnings.warn(
        f"{result_path.parent} has no {MJCF_FILE}: rebuilt from {RESULT_FILE} (the robot and fitted values)",
        Note,
        stacklevel=3,
    )
    return text


def check_motor_driven(sim: SimModel, joints: tuple[str, ...], source: str) -> None:
    """Refuse, in one line, a joint a logged effort cannot drive: no actuator, several, or a servo.

    A torque log is the command of a motor (an actuator whose force is ``gear × ctrl``); a position or
    velocity servo's command is a reference, which the log does not hold."""
    by_joint: dict[int, list[int]] = {}
    for a in range(sim.model.nu):
        joint = sim.actuated_joint(a)
        if joint is not None:
            by_joint.setdefault(joint, []).append(a)
    for name in joints:
        actuators = by_joint.get(sim.joint_id(name), [])
        if len(actuators) != 1:
            raise ValueError(
                f"{source}: joint {name} has {len(actuators)} actuators; a logged effort drives a joint "
                "through exactly one motor"
            )
        a = actuators[0]
        if servo_kind(sim.model, a) != "other" or sim.model.actuator_biastype[a] != 0:
            raise ValueError(
                f"{source}: joint {name} is driven by a servo ({sim.model.actuator(a).name or f'#{a}'}), "
                "not a motor: a logged effort is not its command"
            )


def motor_commands(sim: SimModel, log: RobotLog) -> RobotLog:
    """``log`` with each joint's torque divided by its motor's gear (a motor applies ``gear × ctrl``)."""
    gears = np.ones(len(log.command_names))
    for a in range(sim.model.nu):
        joint = sim.actuated_joint(a)
        if joint is None:
            continue
        name = f"{sim.model.joint(joint).name}.ctrl"
        if name in log.command_names:
            gears[log.command_names.index(name)] = sim.model.actuator_gear[a, 0]
    if np.all(gears == 1.0):
        return log
    return RobotLog(
        log.t, log.q, log.qd, log.command_t, log.commands / gears, log.joint_names, log.command_names,
        log.source,
    )  # fmt: skip
